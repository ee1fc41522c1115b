"""Build the scene layout of a world: the generated city (if any) plus the world file's explicit objects.

Explicit roads, buildings and trees are appended after the generated objects, then explicit pads; a
pad without ``z_m`` rests on whatever is below its centre (a roof, a road or the ground). Impossible
combinations raise ``ValueError`` naming the world-file item, e.g.
``scene.pads[1]: duplicate pad name 'start_1'``.
"""

from __future__ import annotations

import math

import numpy as np

from .config import SceneConfig
from .primitives import (
    GROUND_THICKNESS_M,
    PAD_THICKNESS_M,
    ROAD_THICKNESS_M,
    ROAD_TOP_Z_M,
    Box,
    Pad,
    SceneClass,
    SceneLayout,
    SceneObject,
)
from .urban import GROUND_MARGIN_M, _tree_shapes, generate_urban

SUPPORT_TOLERANCE_M = 1e-3     # a pad straddling surfaces that differ by more than this is rejected


def _footprint_corners(cx: float, cy: float, hx: float, hy: float, yaw: float) -> np.ndarray:
    """Return (4, 2) [m] corners of a yawed rectangle."""
    c, s = math.cos(yaw), math.sin(yaw)
    local = np.array([[-hx, -hy], [hx, -hy], [hx, hy], [-hx, hy]])
    return local @ np.array([[c, s], [-s, c]]) + np.array([cx, cy])


def build_layout(config: SceneConfig, seed: int) -> SceneLayout:
    """Return the static scene of ``config``.

    Parameters
    ----------
    config : SceneConfig
    seed : int, seeds ``np.random.default_rng`` for the generator; same seed, same city

    Raises
    ------
    ValueError
        For duplicate object or pad names, a pad straddling two surfaces or buried in a building,
        overlapping pads, or a city whose pads do not fit.
    """
    if config.generator == "urban":
        base = generate_urban(config.urban, np.random.default_rng(seed))
        entries = [(o.name, o.cls, o.shapes) for o in base.objects]
        pads = dict(base.pads)
        parking = dict(base.parking)
        ext_min, ext_max = base.extent_min_m.copy(), base.extent_max_m.copy()
    else:
        half = 0.5 * config.ground_size_m
        ground = Box(np.array([0.0, 0.0, -0.5 * GROUND_THICKNESS_M]), np.array([half, half, 0.5 * GROUND_THICKNESS_M]))
        entries = [("ground", SceneClass.GROUND, (ground,))]
        pads, parking = {}, {}
        ext_min, ext_max = np.array([-half, -half]), np.array([half, half])

    names = {name: "generated" for name, _, _ in entries}

    def claim(name: str, where: str) -> None:
        if name in names:
            raise ValueError(f"{where}: duplicate object name {name!r} (already used by {names[name]})")
        names[name] = where

    next_k: dict[str, int] = {}

    def next_name(prefix: str) -> str:
        # the lowest free prefix_k; names are only added, so the search resumes where it stopped
        # (linear in the object count, where restarting at 1 was quadratic: 20 000 trees took 100 s)
        k = next_k.get(prefix, 1)
        while f"{prefix}_{k}" in names:
            k += 1
        next_k[prefix] = k
        return f"{prefix}_{k}"

    # Pads go last in the object list; keep the generated ones aside and re-append them below.
    gen_pad_ids = {p.object_id for p in pads.values()}
    pad_entries = [e for k, e in enumerate(entries) if k in gen_pad_ids]
    entries = [e for k, e in enumerate(entries) if k not in gen_pad_ids]

    for i, r in enumerate(config.roads):
        where = f"scene.roads[{i}]"
        name = next_name("road")
        claim(name, where)
        (x0, y0), (x1, y1) = r.start_m, r.end_m
        box = Box(
            np.array([0.5 * (x0 + x1), 0.5 * (y0 + y1), ROAD_TOP_Z_M - 0.5 * ROAD_THICKNESS_M]),
            np.array([0.5 * math.hypot(x1 - x0, y1 - y0), 0.5 * r.width_m, 0.5 * ROAD_THICKNESS_M]),
            math.atan2(y1 - y0, x1 - x0),
        )
        entries.append((name, SceneClass.ROAD, (box,)))
    for i, b in enumerate(config.buildings):
        where = f"scene.buildings[{i}]"
        name = b.name if b.name is not None else next_name("building")
        claim(name, where)
        box = Box(
            np.array([b.center_m[0], b.center_m[1], 0.5 * b.height_m]),
            np.array([0.5 * b.size_m[0], 0.5 * b.size_m[1], 0.5 * b.height_m]),
            math.radians(b.yaw_deg),
        )
        entries.append((name, SceneClass.BUILDING, (box,)))
    for i, t in enumerate(config.trees):
        name = next_name("tree")
        claim(name, f"scene.trees[{i}]")
        trunk_m = float(np.clip(0.035 * t.height_m, 0.12, 0.35))
        entries.append((name, SceneClass.TREE, _tree_shapes(t.position_m[0], t.position_m[1], 0.0, t.height_m, t.crown_radius_m, trunk_m)))

    # Supports for explicit pads: everything but pads (a pad never rests on another pad).
    support = SceneLayout(
        tuple(SceneObject(k, n, c, s) for k, (n, c, s) in enumerate(entries)), {}, {}, ext_min, ext_max
    )
    new_pads: list[tuple[str, str, float, float, float, float, bool]] = []   # name kind x y z0 size on_roof
    for i, ps in enumerate(config.pads):
        where = f"scene.pads[{i}]"
        if ps.name in pads or any(ps.name == q[0] for q in new_pads):
            raise ValueError(f"{where}: duplicate pad name {ps.name!r}")
        claim(ps.name, where)
        x, y = ps.position_m
        h = 0.5 * ps.size_m
        z_c, sup_id = support.support_at(x, y)
        corner_z = [support.support_at(cx, cy)[0] for cx, cy in _footprint_corners(x, y, h, h, 0.0)]
        if ps.z_m is None:
            if max(abs(z - z_c) for z in corner_z) > SUPPORT_TOLERANCE_M:
                raise ValueError(
                    f"{where}: pad {ps.name!r} straddles surfaces of heights "
                    f"{min(corner_z):.3f}..{max(corner_z):.3f} m; move it or give z_m"
                )
            z0 = z_c
        else:
            z0 = ps.z_m
            if max(corner_z + [z_c]) > z0 + SUPPORT_TOLERANCE_M:
                raise ValueError(
                    f"{where}: pad {ps.name!r} at z_m {z0:g} is below the surface {max(corner_z + [z_c]):.3f} m under it"
                )
        on_roof = support.objects[sup_id].cls == SceneClass.BUILDING and abs(z0 - z_c) <= SUPPORT_TOLERANCE_M
        new_pads.append((ps.name, ps.kind, x, y, z0, ps.size_m, on_roof))

    # Pads must not overlap each other (checked on axis-aligned squares, pads are never yawed).
    all_sq = [(n, p.center_enu_m[0], p.center_enu_m[1], 0.5 * p.size_m) for n, p in pads.items()]
    for k, (n, _, x, y, _, size, _) in enumerate(new_pads):
        for m, (other, ox, oy, oh) in enumerate(all_sq):
            if abs(x - ox) < 0.5 * size + oh and abs(y - oy) < 0.5 * size + oh:
                raise ValueError(f"scene.pads[{k}]: pad {n!r} overlaps pad {other!r}")
        all_sq.append((n, x, y, 0.5 * size))

    out_pads: dict[str, Pad] = {}
    for name, cls, shapes in pad_entries:
        old = pads[name]
        out_pads[name] = Pad(old.name, old.kind, old.center_enu_m, old.size_m, len(entries), old.on_roof)
        entries.append((name, cls, shapes))
    for name, kind, x, y, z0, size, on_roof in new_pads:
        box = Box(np.array([x, y, z0 + 0.5 * PAD_THICKNESS_M]), np.array([0.5 * size, 0.5 * size, 0.5 * PAD_THICKNESS_M]))
        out_pads[name] = Pad(name, kind, np.array([x, y, z0 + PAD_THICKNESS_M]), size, len(entries), on_roof)
        entries.append((name, SceneClass.PAD, (box,)))

    # Grow the ground so that it reaches past every explicit object.
    objects = [SceneObject(k, n, c, s) for k, (n, c, s) in enumerate(entries)]
    lo, hi = _xy_bounds(objects[1:])
    if lo is not None:
        ext_min, ext_max = np.minimum(ext_min, lo), np.maximum(ext_max, hi)
        g = objects[0].shapes[0]
        g_lo = np.minimum(g.center_enu_m[:2] - g.half_extents_m[:2], ext_min - GROUND_MARGIN_M)
        g_hi = np.maximum(g.center_enu_m[:2] + g.half_extents_m[:2], ext_max + GROUND_MARGIN_M)
        ground = Box(
            np.array([*(0.5 * (g_lo + g_hi)), g.center_enu_m[2]]), np.array([*(0.5 * (g_hi - g_lo)), g.half_extents_m[2]])
        )
        objects[0] = SceneObject(0, objects[0].name, SceneClass.GROUND, (ground,))
    return SceneLayout(tuple(objects), out_pads, parking, ext_min, ext_max)


def _xy_bounds(objects: list[SceneObject]) -> tuple[np.ndarray | None, np.ndarray | None]:
    """Return the ENU x/y bounds (2,), (2,) [m] of the objects' shapes, or (None, None) if there are none."""
    pts = []
    for o in objects:
        for s in o.shapes:
            if isinstance(s, Box):
                pts.append(_footprint_corners(s.center_enu_m[0], s.center_enu_m[1], s.half_extents_m[0], s.half_extents_m[1], s.yaw_rad))
            else:
                r = s.radius_m
                pts.append(s.center_enu_m[:2] + np.array([[-r, -r], [r, r]]))
    if not pts:
        return None, None
    a = np.concatenate(pts)
    return a.min(axis=0), a.max(axis=0)


__all__ = ["build_layout"]
