"""Which buildings stand in the way of a straight flight: a segment against the scene's building boxes.

Used when a target is commanded (the drone flies the straight line from where it is to the target)
to warn before it flies into a wall. Pure geometry on the frozen :class:`SceneLayout`, vectorised
over every building box (slab test in each box's own yawed frame).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .primitives import Box, SceneClass, SceneLayout


@dataclass(frozen=True)
class Obstruction:
    """A building a segment runs into: its name and where the segment enters it (ENU [m])."""

    name: str
    entry_enu_m: tuple[float, float, float]
    distance_m: float           # along the segment from its start [m]


def building_boxes(layout: SceneLayout) -> tuple[np.ndarray, list[str]]:
    """Every building box as rows ``[cx, cy, cz, hx, hy, hz, yaw]`` (ENU [m], [rad]) and their names."""
    rows, names = [], []
    for obj in layout.objects:
        if obj.cls != SceneClass.BUILDING:
            continue
        for shape in obj.shapes:
            if isinstance(shape, Box):
                rows.append((*shape.center_enu_m, *shape.half_extents_m, shape.yaw_rad))
                names.append(obj.name)
    return np.array(rows, dtype=np.float64).reshape(-1, 7), names


def buildings_on_segment(layout: SceneLayout, start_enu_m: np.ndarray, end_enu_m: np.ndarray,
                         clearance_m: float = 0.0) -> list[Obstruction]:
    """Buildings the straight segment ``start -> end`` passes through, nearest first.

    Parameters
    ----------
    start_enu_m, end_enu_m : (3,) [m], ENU
    clearance_m : every box is grown by this much on each side (the vehicle's own half size) [m]
    """
    boxes, names = building_boxes(layout)
    if boxes.shape[0] == 0:
        return []
    p0 = np.asarray(start_enu_m, dtype=np.float64)
    p1 = np.asarray(end_enu_m, dtype=np.float64)
    length = float(np.linalg.norm(p1 - p0))
    if length < 1e-9:
        return []
    c, s = np.cos(boxes[:, 6]), np.sin(boxes[:, 6])

    def local(p: np.ndarray) -> np.ndarray:            # (B, 3): p in each box's frame
        d = p - boxes[:, :3]
        return np.stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1], d[:, 2]], axis=1)

    a, b = local(p0), local(p1)
    half = boxes[:, 3:6] + clearance_m
    d = b - a
    with np.errstate(divide="ignore", invalid="ignore"):
        t1 = (-half - a) / d
        t2 = (half - a) / d
    lo, hi = np.minimum(t1, t2), np.maximum(t1, t2)
    parallel = d == 0.0                                  # inside the slab: any t; outside: never
    inside = np.abs(a) <= half
    lo = np.where(parallel, np.where(inside, -np.inf, np.inf), lo)
    hi = np.where(parallel, np.where(inside, np.inf, -np.inf), hi)
    t_in, t_out = lo.max(axis=1), hi.min(axis=1)
    hit = (t_in <= t_out) & (t_out >= 0.0) & (t_in <= 1.0)
    found: dict[str, Obstruction] = {}
    for k in np.flatnonzero(hit):
        t = max(0.0, float(t_in[k]))
        entry = p0 + t * (p1 - p0)
        ob = Obstruction(names[k], tuple(float(v) for v in entry), t * length)
        if names[k] not in found or ob.distance_m < found[names[k]].distance_m:
            found[names[k]] = ob
    return sorted(found.values(), key=lambda o: o.distance_m)


__all__ = ["Obstruction", "building_boxes", "buildings_on_segment"]
