"""Geofence: where a drone may fly, as inclusion and exclusion zones in world ENU metres.

The MAVLink fence protocol (mission type 1, items ``MAV_CMD_NAV_FENCE_*`` 5001–5004) builds one
(:func:`unetyemu_ecs.transport.mavlink.items.build_geofence`); the navigator enforces it. The rule is
PX4's (``src/modules/navigator/geofence.cpp``, ``isInsidePolygonOrCircle``): a position is allowed
when it lies inside at least one inclusion zone (or there is none) and inside no exclusion zone.
Zones are horizontal only: like PX4, the altitude of fence vertices is ignored (vertical limits are
the ``GF_MAX_VER_DIST`` parameter's job).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike


def _points_in_polygon(xy: np.ndarray, poly: np.ndarray) -> np.ndarray:
    """Even-odd rule (ray casting towards +x), vectorised over points and edges.

    xy : (N, 2) float [m]; poly : (K, 2) float [m], K >= 3, not closed (last != first needed)
    Returns (N,) bool. Points exactly on an edge may fall either way.
    """
    a = poly                                   # (K, 2) edge starts
    b = np.roll(poly, -1, axis=0)              # (K, 2) edge ends
    px = xy[:, 0:1]                            # (N, 1)
    py = xy[:, 1:2]
    ay, by = a[None, :, 1], b[None, :, 1]      # (1, K)
    ax, bx = a[None, :, 0], b[None, :, 0]
    straddles = (ay > py) != (by > py)         # (N, K): the edge crosses the horizontal line through p
    with np.errstate(divide="ignore", invalid="ignore"):
        x_cross = ax + (py - ay) * (bx - ax) / (by - ay)
    crossings = straddles & (px < x_cross)
    return (np.count_nonzero(crossings, axis=1) % 2) == 1


@dataclass(frozen=True, eq=False)
class Geofence:
    """Inclusion and exclusion zones, ENU [m], horizontal (x east, y north).

    inclusion_polygons, exclusion_polygons : tuple of (K, 2) float64 arrays, K >= 3 vertices in order
    inclusion_circles, exclusion_circles : tuple of (x, y, radius_m), radius > 0
    """

    inclusion_polygons: tuple[np.ndarray, ...] = ()
    exclusion_polygons: tuple[np.ndarray, ...] = ()
    inclusion_circles: tuple[tuple[float, float, float], ...] = ()
    exclusion_circles: tuple[tuple[float, float, float], ...] = ()

    def __post_init__(self) -> None:
        for name in ("inclusion_polygons", "exclusion_polygons"):
            polys = []
            for i, p in enumerate(getattr(self, name)):
                arr = np.array(p, dtype=np.float64)
                if arr.ndim != 2 or arr.shape[1] != 2 or arr.shape[0] < 3:
                    raise ValueError(f"Geofence.{name}[{i}]: need (K >= 3, 2) vertices, got shape {arr.shape}")
                if not np.all(np.isfinite(arr)):
                    raise ValueError(f"Geofence.{name}[{i}]: vertices must be finite")
                arr.setflags(write=False)
                polys.append(arr)
            object.__setattr__(self, name, tuple(polys))
        for name in ("inclusion_circles", "exclusion_circles"):
            circles = []
            for i, c in enumerate(getattr(self, name)):
                x, y, r = (float(v) for v in c)
                if not (np.isfinite(x) and np.isfinite(y) and np.isfinite(r)) or r <= 0.0:
                    raise ValueError(f"Geofence.{name}[{i}]: need finite x, y and radius > 0, got {c}")
                circles.append((x, y, r))
            object.__setattr__(self, name, tuple(circles))

    @property
    def empty(self) -> bool:
        """True when the fence has no zone at all (everything is allowed)."""
        return not (self.inclusion_polygons or self.exclusion_polygons
                    or self.inclusion_circles or self.exclusion_circles)

    def contains(self, pos_enu_m: ArrayLike) -> np.ndarray | bool:
        """Whether positions are allowed by the fence.

        Parameters
        ----------
        pos_enu_m : (N, 2|3) or (2|3,) float [m], ENU (z is ignored)

        Returns
        -------
        (N,) bool array, or a bool for a single position
        """
        p = np.asarray(pos_enu_m, dtype=np.float64)
        single = p.ndim == 1
        xy = np.atleast_2d(p)[:, :2]
        n = xy.shape[0]
        has_inclusion = bool(self.inclusion_polygons or self.inclusion_circles)
        inside_incl = np.zeros(n, dtype=bool)
        for poly in self.inclusion_polygons:
            inside_incl |= _points_in_polygon(xy, poly)
        for x, y, r in self.inclusion_circles:
            inside_incl |= np.hypot(xy[:, 0] - x, xy[:, 1] - y) <= r
        inside_excl = np.zeros(n, dtype=bool)
        for poly in self.exclusion_polygons:
            inside_excl |= _points_in_polygon(xy, poly)
        for x, y, r in self.exclusion_circles:
            inside_excl |= np.hypot(xy[:, 0] - x, xy[:, 1] - y) < r
        ok = (inside_incl | (not has_inclusion)) & ~inside_excl
        return bool(ok[0]) if single else ok


__all__ = ["Geofence"]
