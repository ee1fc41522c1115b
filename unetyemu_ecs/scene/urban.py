"""Generate a seeded street-grid city: streets, curbed sidewalks, buildings, trees, pads, parking.

The city is a grid of ``blocks_x`` x ``blocks_y`` square blocks with streets between them and around
them, centred on the world origin (ENU, metres). Every block carries a raised sidewalk ring; the
inside of an ordinary block is split into lots with one building each (random footprint within the
lot minus half the building gap on each side, random height), so buildings never reach a street or
each other. The depot block is an open plaza with the start pads in rows; the target block is an open
plaza with the ground target pads. Roof pads sit on low/medium buildings, trees stand on sidewalks
clear of buildings, pads and parking spots, and parking spots lie on the road beside the curb away
from intersections. All randomness comes from the ``rng`` argument, so the same seed gives the same
city.
"""

from __future__ import annotations

import math

import numpy as np

from .config import UrbanParams
from .primitives import (
    GROUND_THICKNESS_M,
    PAD_THICKNESS_M,
    ROAD_THICKNESS_M,
    ROAD_TOP_Z_M,
    Box,
    Cylinder,
    Pad,
    ParkingSpot,
    SceneClass,
    SceneLayout,
    SceneObject,
    Sphere,
)

PAD_CLEARANCE_M = 2.0          # free ground kept around every ground pad and parking spot
ROOF_PAD_MARGIN_M = 1.0        # roof left free on each side of a roof pad
GROUND_MARGIN_M = 20.0         # ground extends this far beyond the outer streets
PARKING_LENGTH_M = 6.0
PARKING_WIDTH_M = 2.5
PARKING_CORNER_MARGIN_M = 6.0  # keep parked cars this far from the block corner (intersection)
TREE_CORNER_MARGIN_M = 3.0
TREE_BUILDING_CLEARANCE_M = 0.3
# What a parked vehicle may fill around its spot (along, across the street) and up to which height: the
# truck preset (6.4 x 2.4 m, 3.0 m tall) with a margin. No tree crown reaches into it, so that every
# preset can be parked on every spot (the world loader refuses bodies that start inside a crown).
PARKED_ENVELOPE_HALF_M = (3.5, 1.5)
PARKED_ENVELOPE_HEIGHT_M = 3.5


def _box(cx: float, cy: float, z0: float, z1: float, hx: float, hy: float, yaw: float = 0.0) -> Box:
    """Return a box spanning heights ``z0..z1`` [m] around footprint centre (cx, cy)."""
    return Box(
        np.array([cx, cy, 0.5 * (z0 + z1)]), np.array([hx, hy, 0.5 * (z1 - z0)]), float(yaw)
    )


def _split(length_m: float, size_range_m: tuple[float, float], rng: np.random.Generator) -> np.ndarray:
    """Return edges (K+1,) [m] of consecutive pieces of ``length_m`` with sizes in the range.

    The last piece takes the remainder; it may be shorter than the range's low end only when the
    whole length is.
    """
    lo, hi = size_range_m
    edges = [0.0]
    left = length_m
    while left > hi:
        w = rng.uniform(lo, min(hi, left - lo)) if left - lo > lo else left / 2.0
        edges.append(edges[-1] + w)
        left -= w
    edges.append(length_m)
    return np.array(edges)


def _rect_distance_m(px: np.ndarray, py: np.ndarray, rects: np.ndarray) -> np.ndarray:
    """Return distances (P, R) [m] from points to axis-aligned rectangles (R, 4) = (x0, y0, x1, y1)."""
    if rects.shape[0] == 0:
        return np.full((px.size, 0), np.inf)
    dx = np.maximum(np.maximum(rects[None, :, 0] - px[:, None], px[:, None] - rects[None, :, 2]), 0.0)
    dy = np.maximum(np.maximum(rects[None, :, 1] - py[:, None], py[:, None] - rects[None, :, 3]), 0.0)
    return np.hypot(dx, dy)


def _pad_grid(
    n: int, region: tuple[float, float, float, float], cell_m: float, what: str
) -> np.ndarray:
    """Return (n, 2) [m] pad centres in rows of cells of ``cell_m``, centred in region (x0, y0, x1, y1)."""
    if n == 0:
        return np.zeros((0, 2))
    x0, y0, x1, y1 = region
    cols = int((x1 - x0) // cell_m)
    rows = math.ceil(n / max(cols, 1))
    if cols < 1 or rows * cell_m > (y1 - y0):
        raise ValueError(
            f"{n} {what} pads of cell {cell_m:g} m do not fit in a {x1 - x0:.1f} x {y1 - y0:.1f} m plaza; "
            "use a larger block_size_m or fewer pads"
        )
    k = np.arange(n)
    r, c = k // cols, k % cols
    in_row = np.minimum(n - r * cols, cols)                    # pads in this pad's row
    x = 0.5 * (x0 + x1) + (c - 0.5 * (in_row - 1)) * cell_m
    y = 0.5 * (y0 + y1) + (r - 0.5 * (rows - 1)) * cell_m
    return np.stack([x, y], axis=1)


def generate_urban(params: UrbanParams, rng: np.random.Generator) -> SceneLayout:
    """Generate a procedural city.

    Parameters
    ----------
    params : UrbanParams
    rng : numpy Generator, the only source of randomness

    Returns
    -------
    SceneLayout
        Objects in the order ground, roads, sidewalks, buildings, trees, pads; pads named
        ``start_i``, ``target_i``, ``roof_i``; parking ``parking_i``; buildings ``building_i``.

    Raises
    ------
    ValueError
        If the pads do not fit their plazas or too few buildings can carry a roof pad.
    """
    p = params
    B, S, sw = p.block_size_m, p.street_width_m, p.sidewalk_width_m
    pitch = B + S
    width = p.blocks_x * B + (p.blocks_x + 1) * S
    depth = p.blocks_y * B + (p.blocks_y + 1) * S
    xmin, ymin = -0.5 * width, -0.5 * depth
    depot = tuple(p.depot_block)
    target = tuple(p.target_block) if p.target_block is not None else (p.blocks_x - 1, p.blocks_y - 1)

    def block_min(i: int, j: int) -> tuple[float, float]:
        return xmin + S + i * pitch, ymin + S + j * pitch

    entries: list[tuple[str, SceneClass, tuple]] = []   # (name, class, shapes); ids assigned at the end
    g = GROUND_MARGIN_M
    entries.append(("ground", SceneClass.GROUND, (
        _box(0.0, 0.0, -GROUND_THICKNESS_M, 0.0, 0.5 * width + g, 0.5 * depth + g),)))

    # Streets: north-south streets run the full depth; east-west streets are cut between them so that
    # no two road boxes overlap (coplanar overlaps would give ambiguous camera/LiDAR classes).
    road_z0 = ROAD_TOP_Z_M - ROAD_THICKNESS_M
    n_road = 0
    for k in range(p.blocks_x + 1):
        n_road += 1
        cx = xmin + 0.5 * S + k * pitch
        entries.append((f"road_{n_road}", SceneClass.ROAD, (_box(cx, 0.0, road_z0, ROAD_TOP_Z_M, 0.5 * S, 0.5 * depth),)))
    for j in range(p.blocks_y + 1):
        n_road += 1
        cy = ymin + 0.5 * S + j * pitch
        segs = tuple(
            _box(block_min(i, 0)[0] + 0.5 * B, cy, road_z0, ROAD_TOP_Z_M, 0.5 * B, 0.5 * S)
            for i in range(p.blocks_x)
        )
        entries.append((f"road_{n_road}", SceneClass.ROAD, segs))

    # Sidewalk rings: south and north strips full width, west and east strips between them.
    h = p.curb_height_m
    blocks = [(i, j) for j in range(p.blocks_y) for i in range(p.blocks_x)]
    for n, (i, j) in enumerate(blocks, start=1):
        x0, y0 = block_min(i, j)
        ring = (
            _box(x0 + 0.5 * B, y0 + 0.5 * sw, 0.0, h, 0.5 * B, 0.5 * sw),
            _box(x0 + 0.5 * B, y0 + B - 0.5 * sw, 0.0, h, 0.5 * B, 0.5 * sw),
            _box(x0 + 0.5 * sw, y0 + 0.5 * B, 0.0, h, 0.5 * sw, 0.5 * B - sw),
            _box(x0 + B - 0.5 * sw, y0 + 0.5 * B, 0.0, h, 0.5 * sw, 0.5 * B - sw),
        )
        entries.append((f"sidewalk_{n}", SceneClass.SIDEWALK, ring))

    # Ground pads in the plazas, kept clear of the sidewalk trees' crowns.
    cell = p.pad_size_m + 2.0 * PAD_CLEARANCE_M
    margin = PAD_CLEARANCE_M + p.crown_radius_m[1]

    def plaza(ij: tuple[int, int]) -> tuple[float, float, float, float]:
        x0, y0 = block_min(*ij)
        return x0 + sw + margin, y0 + sw + margin, x0 + B - sw - margin, y0 + B - sw - margin

    if depot == target:
        x0, y0, x1, y1 = plaza(depot)
        ym = 0.5 * (y0 + y1)
        start_xy = _pad_grid(p.start_pads, (x0, y0, x1, ym), cell, "start")
        target_xy = _pad_grid(p.target_pads, (x0, ym, x1, y1), cell, "target")
    else:
        start_xy = _pad_grid(p.start_pads, plaza(depot), cell, "start")
        target_xy = _pad_grid(p.target_pads, plaza(target), cell, "target")

    # Buildings: one per lot, inset by half the gap so that neighbours are >= building_gap_m apart.
    rects, heights = [], []
    half_gap = 0.5 * p.building_gap_m
    inner = B - 2.0 * sw
    for i, j in blocks:
        if (i, j) in (depot, target):
            continue
        bx0, by0 = block_min(i, j)
        xe = bx0 + sw + _split(inner, p.lot_size_m, rng)
        ye = by0 + sw + _split(inner, p.lot_size_m, rng)
        for a in range(xe.size - 1):
            for b in range(ye.size - 1):
                empty = rng.random() < p.empty_lot_frac
                fill = rng.uniform(p.building_fill_frac[0], p.building_fill_frac[1], size=2)
                jitter = rng.random(2)
                height = rng.uniform(*p.building_height_m)
                avail = np.array([xe[a + 1] - xe[a], ye[b + 1] - ye[b]]) - 2.0 * half_gap
                if empty or np.any(avail < 2.0):
                    continue
                size = avail * fill
                lo = np.array([xe[a], ye[b]]) + half_gap + (avail - size) * jitter
                rects.append((lo[0], lo[1], lo[0] + size[0], lo[1] + size[1]))
                heights.append(height)
    rects_a = np.array(rects, dtype=np.float64).reshape(-1, 4)
    heights_a = np.array(heights, dtype=np.float64)
    for n, (r, z) in enumerate(zip(rects_a, heights_a), start=1):
        shape = _box(0.5 * (r[0] + r[2]), 0.5 * (r[1] + r[3]), 0.0, z, 0.5 * (r[2] - r[0]), 0.5 * (r[3] - r[1]))
        entries.append((f"building_{n}", SceneClass.BUILDING, (shape,)))

    # Roof pads: prefer buildings no taller than roof_pad_max_height_m, then the lowest others.
    min_side = p.pad_size_m + 2.0 * ROOF_PAD_MARGIN_M
    fits = np.flatnonzero(np.minimum(rects_a[:, 2] - rects_a[:, 0], rects_a[:, 3] - rects_a[:, 1]) >= min_side)
    low = fits[heights_a[fits] <= p.roof_pad_max_height_m]
    high = fits[heights_a[fits] > p.roof_pad_max_height_m]
    if fits.size < p.roof_pads:
        raise ValueError(
            f"only {fits.size} buildings have a roof of at least {min_side:g} m for {p.roof_pads} roof pads"
        )
    chosen = rng.permutation(low)[: p.roof_pads]
    if chosen.size < p.roof_pads:
        chosen = np.concatenate([chosen, high[np.argsort(heights_a[high], kind="stable")][: p.roof_pads - chosen.size]])
    roof_bld = np.sort(chosen)

    # Parking spots along every block side, on the road beside the curb, away from intersections.
    cand: list[tuple[float, float, float]] = []
    off = 0.5 * PARKING_WIDTH_M + 0.25
    along = B - 2.0 * PARKING_CORNER_MARGIN_M
    n_side = int(along // PARKING_LENGTH_M)
    s_off = PARKING_CORNER_MARGIN_M + 0.5 * (along - n_side * PARKING_LENGTH_M) + (np.arange(n_side) + 0.5) * PARKING_LENGTH_M
    for i, j in blocks:
        x0, y0 = block_min(i, j)
        for s in s_off:
            # Right-hand traffic: the curb is on the driver's right.
            cand.append((x0 + s, y0 - off, math.pi))          # south side, street runs west
            cand.append((x0 + s, y0 + B + off, 0.0))          # north side, heading east
            cand.append((x0 - off, y0 + s, 0.5 * math.pi))    # west side, heading north
            cand.append((x0 + B + off, y0 + s, -0.5 * math.pi))  # east side, heading south
    if p.parking_spots > len(cand):
        raise ValueError(f"parking_spots {p.parking_spots} exceeds the {len(cand)} curb places of this grid")
    pick = np.sort(rng.choice(len(cand), size=p.parking_spots, replace=False)) if p.parking_spots else []
    parking = {
        f"parking_{n}": ParkingSpot(
            f"parking_{n}", np.array([cand[k][0], cand[k][1], ROAD_TOP_Z_M]), float(cand[k][2])
        )
        for n, k in enumerate(pick, start=1)
    }

    # Trees on the sidewalk centrelines, filtered against buildings, pads and parked cars.
    tx, ty = [], []
    for i, j in blocks:
        x0, y0 = block_min(i, j)
        run = B - 2.0 * TREE_CORNER_MARGIN_M
        k = int(run // p.tree_spacing_m) + 1
        s = TREE_CORNER_MARGIN_M + 0.5 * (run - (k - 1) * p.tree_spacing_m) + np.arange(k) * p.tree_spacing_m
        c = np.full(k, 0.5 * sw)
        tx += [x0 + s, x0 + s, x0 + c, x0 + B - c]
        ty += [y0 + c, y0 + B - c, y0 + s, y0 + s]
    tx_a, ty_a = np.concatenate(tx), np.concatenate(ty)
    t_height = rng.uniform(*p.tree_height_m, size=tx_a.size)
    t_crown = rng.uniform(*p.crown_radius_m, size=tx_a.size)
    t_trunk = np.clip(0.035 * t_height, 0.12, 0.35)
    half_pad = 0.5 * p.pad_size_m
    ground_pads = np.concatenate([start_xy, target_xy])
    pad_rects = np.concatenate([ground_pads - half_pad, ground_pads + half_pad], axis=1)
    park_xy = np.array([sp.center_enu_m[:2] for sp in parking.values()]).reshape(-1, 2)
    keep = np.ones(tx_a.size, dtype=bool)
    if rects_a.shape[0]:
        keep &= _rect_distance_m(tx_a, ty_a, rects_a).min(axis=1) > t_crown + TREE_BUILDING_CLEARANCE_M
    if pad_rects.shape[0]:
        keep &= _rect_distance_m(tx_a, ty_a, pad_rects).min(axis=1) > t_crown + PAD_CLEARANCE_M
    if park_xy.shape[0]:
        d = np.hypot(tx_a[:, None] - park_xy[None, :, 0], ty_a[:, None] - park_xy[None, :, 1]).min(axis=1)
        keep &= d > t_trunk + PAD_CLEARANCE_M
        along, across = PARKED_ENVELOPE_HALF_M
        across_x = np.array([abs(np.sin(sp.yaw_rad)) > 0.5 for sp in parking.values()])   # spot runs north-south
        hx = np.where(across_x, across, along)
        hy = np.where(across_x, along, across)
        envelopes = np.stack([park_xy[:, 0] - hx, park_xy[:, 1] - hy, park_xy[:, 0] + hx, park_xy[:, 1] + hy], axis=1)
        crown_bottom = h + t_height - 2.0 * t_crown
        clear = _rect_distance_m(tx_a, ty_a, envelopes).min(axis=1) > t_crown + TREE_BUILDING_CLEARANCE_M
        keep &= clear | (crown_bottom > PARKED_ENVELOPE_HEIGHT_M)
    for n, k in enumerate(np.flatnonzero(keep), start=1):
        entries.append((f"tree_{n}", SceneClass.TREE, _tree_shapes(tx_a[k], ty_a[k], h, t_height[k], t_crown[k], t_trunk[k])))

    # Pads last, so that their object ids follow everything they may rest on.
    pad_specs: list[tuple[str, str, float, float, float, bool]] = []
    pad_specs += [(f"start_{n}", "start", x, y, 0.0, False) for n, (x, y) in enumerate(start_xy, start=1)]
    pad_specs += [(f"target_{n}", "target", x, y, 0.0, False) for n, (x, y) in enumerate(target_xy, start=1)]
    for n, b in enumerate(roof_bld, start=1):
        r = rects_a[b]
        pad_specs.append((f"roof_{n}", "target", 0.5 * (r[0] + r[2]), 0.5 * (r[1] + r[3]), heights_a[b], True))
    first_pad_id = len(entries)
    pads: dict[str, Pad] = {}
    for n, (name, kind, x, y, z0, on_roof) in enumerate(pad_specs):
        shape = _box(x, y, z0, z0 + PAD_THICKNESS_M, half_pad, half_pad)
        entries.append((name, SceneClass.PAD, (shape,)))
        pads[name] = Pad(name, kind, np.array([x, y, z0 + PAD_THICKNESS_M]), p.pad_size_m, first_pad_id + n, on_roof)

    objects = tuple(SceneObject(k, name, cls, shapes) for k, (name, cls, shapes) in enumerate(entries))
    return SceneLayout(objects, pads, parking, np.array([xmin, ymin]), np.array([-xmin, -ymin]))


def _tree_shapes(x: float, y: float, base_z: float, height_m: float, crown_m: float, trunk_m: float) -> tuple:
    """Return (trunk Cylinder, crown Sphere) of a tree standing at height ``base_z`` [m]."""
    crown_z = base_z + height_m - crown_m
    trunk = Cylinder(np.array([x, y, 0.5 * (base_z + crown_z)]), float(trunk_m), 0.5 * (crown_z - base_z))
    return trunk, Sphere(np.array([x, y, crown_z]), float(crown_m))


__all__ = ["PAD_CLEARANCE_M", "PARKING_LENGTH_M", "PARKING_WIDTH_M", "generate_urban"]
