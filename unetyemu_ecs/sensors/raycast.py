"""Ray casting against the world for the LiDAR and the cameras (Open3D RaycastingScene).

The static city is one RaycastingScene built once from the scene mesh. Moving bodies (their
collision boxes at this step's poses) go into a small second scene rebuilt for each cast from ONE
merged ``add_triangles`` call (Open3D cannot move geometry after commit); both are cast and the
nearer hit wins (the fastest exact approach we measured).

A sensor never sees its own vehicle: a ray that crosses the vehicle's own box starts where it
leaves it (:func:`exit_distance_m`, exact) and that distance is added back. The static scene is cast
from 1 mm before that exit and the moving bodies from 1 mm after it, so neither the ground under a
landed drone nor the own box's face at the exit is missed or mistaken. Cars' wheels are not part of
the moving geometry (their chassis box is).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..frames import R_from_quat_xyzw

EXIT_MARGIN_M = 0.001
NO_HIT = -1            # RayHits.cls for rays that hit nothing
MOVING_BODY = 255      # RayHits.cls for rays that hit a moving body (RayHits.box says which)

_CUBE = np.array([[(k & 1) * 2 - 1, (k >> 1 & 1) * 2 - 1, (k >> 2 & 1) * 2 - 1] for k in range(8)], dtype=np.float64)
_CUBE_TRIS = np.array([[0, 2, 3], [0, 3, 1], [4, 5, 7], [4, 7, 6], [0, 1, 5], [0, 5, 4],
                       [2, 6, 7], [2, 7, 3], [0, 4, 6], [0, 6, 2], [1, 3, 7], [1, 7, 5]], dtype=np.int64)


class SensorUnavailable(RuntimeError):
    """A sensor's library cannot be loaded on this machine (the message says what to install)."""


# system libraries Open3D's wheel links against -> the Debian/Ubuntu package that provides each
_OPEN3D_SYSTEM_LIBS = {"libusb-1.0": "libusb-1.0-0", "libGL.so": "libgl1", "libEGL.so": "libegl1"}


def open3d_import_hint(error: str) -> str:
    """What to install when ``import open3d`` failed with ``error``: a system library, or Open3D itself."""
    missing = [pkg for lib, pkg in _OPEN3D_SYSTEM_LIBS.items() if lib in error]
    if missing:
        return f"install the system package{'s' if len(missing) > 1 else ''}: apt-get install -y {' '.join(missing)}"
    if "No module named" in error:
        return "install it into the simulator's environment: .venv/bin/pip install open3d-cpu==0.20.0"
    return "it needs the system libraries libusb-1.0-0, libgl1 and libegl1 (apt-get install -y ...)"


def import_open3d() -> Any:
    """Import Open3D, or explain what is missing (a fresh Debian needs libusb-1.0-0, libgl1, libegl1)."""
    try:
        import open3d
    except ImportError as exc:
        raise SensorUnavailable(f"LiDAR and cameras need Open3D, which does not import here ({exc}) -- "
                                f"{open3d_import_hint(str(exc))}") from exc
    return open3d


def exit_distance_m(origin_m: np.ndarray, dirs: np.ndarray, half_extents_m: np.ndarray) -> np.ndarray:
    """Distance (M,) along each ray from ``origin`` (3,) to where it leaves an axis-aligned box of
    ``half_extents`` centred at the frame origin (0 for rays that never cross the box). Slab method."""
    with np.errstate(divide="ignore", invalid="ignore"):
        t1 = (-half_extents_m - origin_m) / dirs
        t2 = (half_extents_m - origin_m) / dirs
    inside_slab = np.abs(origin_m) <= half_extents_m                      # per axis, for rays parallel to it
    t_lo = np.where(dirs == 0.0, np.where(inside_slab, -np.inf, np.inf), np.minimum(t1, t2))
    t_hi = np.where(dirs == 0.0, np.where(inside_slab, np.inf, -np.inf), np.maximum(t1, t2))
    t_near, t_far = t_lo.max(axis=1), t_hi.min(axis=1)
    crosses = (t_far >= np.maximum(t_near, 0.0)) & np.isfinite(t_far)
    return np.where(crosses, np.maximum(t_far, 0.0), 0.0)


def ray_starts(exit_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Start distances (static scene, moving bodies) for rays leaving the own hull at ``exit_m``."""
    return np.maximum(exit_m - EXIT_MARGIN_M, 0.0), np.where(exit_m > 0.0, exit_m + EXIT_MARGIN_M, 0.0)


def moving_body_candidates(origin_m: np.ndarray, dirs_world: np.ndarray, max_range_m: float, centers_m: np.ndarray,
                           radii_m: np.ndarray, exclude: int = -1) -> np.ndarray:
    """Indices of the rays (from ``origin_m`` along unit ``dirs_world`` (M, 3)) that can meet a moving body
    within ``max_range_m``: those whose line passes within a body's bounding sphere (centres (B, 3),
    radii (B,)) ahead of the origin. Body ``exclude`` (the sensor's own vehicle, which its rays leave and,
    being convex, never meet again) is left out. Conservative: every ray that hits a body is kept."""
    v = centers_m - origin_m                                              # (B, 3)
    dist = np.linalg.norm(v, axis=1)
    near = dist - radii_m <= max_range_m
    if 0 <= exclude < len(near):
        near[exclude] = False
    if not near.any():
        return np.empty(0, dtype=np.intp)
    v, r, dist = v[near], radii_m[near], dist[near]
    if np.any(dist <= r):                                                # inside a body's sphere: every ray
        return np.arange(len(dirs_world))
    # a ray from outside a sphere meets it iff its angle to the centre is at most asin(r / dist), i.e. its
    # projection on the centre's direction reaches the tangent point: along >= sqrt(dist^2 - r^2)
    along = dirs_world @ v.T                                              # (M, K)
    return np.flatnonzero((along >= np.sqrt(dist ** 2 - r ** 2)).any(axis=1))


def box_triangles(centers_m: np.ndarray, quats_xyzw: np.ndarray, half_extents_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (8N, 3) and triangles (12N, 3) of N oriented boxes (outward CCW), world frame."""
    n = len(centers_m)
    R = R_from_quat_xyzw(quats_xyzw)
    local = _CUBE[None, :, :] * half_extents_m[:, None, :]                        # (N, 8, 3)
    verts = centers_m[:, None, :] + np.einsum("nij,nkj->nki", R, local)
    tris = (_CUBE_TRIS[None, :, :] + 8 * np.arange(n)[:, None, None]).reshape(-1, 3)
    return verts.reshape(-1, 3), tris


@dataclass(frozen=True)
class RayHits:
    """What M rays hit: ``t`` distance from the ray origin [m] (inf: nothing), unit ``normal`` (M, 3),
    ``cls`` the SceneClass of a static hit (MOVING_BODY, NO_HIT), ``box`` the moving body's index (-1)."""

    t: np.ndarray
    normal: np.ndarray
    cls: np.ndarray
    box: np.ndarray


class RaycastWorld:
    """The static scene mesh plus moving boxes, cast together (no esper: usable on its own)."""

    def __init__(self, vertices_m: np.ndarray, triangles: np.ndarray, tri_cls: np.ndarray) -> None:
        o3d = import_open3d()
        self._o3d = o3d
        self.static = o3d.t.geometry.RaycastingScene()
        self.static.add_triangles(o3d.core.Tensor(np.asarray(vertices_m, dtype=np.float32)),
                                  o3d.core.Tensor(np.asarray(triangles, dtype=np.uint32)))
        self._tri_cls = np.asarray(tri_cls, dtype=np.int16)

    def cast(self, origins_m: np.ndarray, dirs_world: np.ndarray, start_static_m: np.ndarray,
             start_dynamic_m: np.ndarray, boxes: tuple[np.ndarray, np.ndarray, np.ndarray] | None,
             dynamic_rays: np.ndarray | None = None) -> RayHits:
        """Cast rays (M,) from ``origins`` along unit ``dirs``, starting ``start_*`` metres along them in
        the static and the moving-body scene. ``boxes`` = (centres, quats, half extents) of moving bodies;
        ``dynamic_rays`` (indices) limits the moving-body cast to the rays that can meet one
        (:func:`moving_body_candidates`; None: every ray)."""
        o3d = self._o3d
        rays = np.empty((len(dirs_world), 6), dtype=np.float32)             # Open3D's (origin, direction) rows
        rays[:, :3] = origins_m + start_static_m[:, None] * dirs_world
        rays[:, 3:] = dirs_world
        hit = self.static.cast_rays(o3d.core.Tensor(rays), nthreads=0)
        t = hit["t_hit"].numpy().astype(np.float64) + start_static_m
        normal = hit["primitive_normals"].numpy().astype(np.float64)
        prim = hit["primitive_ids"].numpy()
        found = np.isfinite(t)
        cls = np.full(len(t), NO_HIT, dtype=np.int16)
        cls[found] = self._tri_cls[prim[found]]
        box = np.full(len(t), -1, dtype=np.int64)
        idx = np.arange(len(t)) if dynamic_rays is None else np.asarray(dynamic_rays, dtype=np.intp)
        if boxes is not None and len(boxes[0]) and idx.size:
            verts, tris = box_triangles(*boxes)
            dyn = o3d.t.geometry.RaycastingScene()
            dyn.add_triangles(o3d.core.Tensor(verts.astype(np.float32)), o3d.core.Tensor(tris.astype(np.uint32)))
            start = start_dynamic_m[idx]
            d = dirs_world[idx]
            sub = np.empty((len(idx), 6), dtype=np.float32)
            sub[:, :3] = origins_m[idx] + start[:, None] * d
            sub[:, 3:] = d
            dhit = dyn.cast_rays(o3d.core.Tensor(sub), nthreads=0)
            td = dhit["t_hit"].numpy().astype(np.float64) + start
            nearer = td < t[idx]
            k = idx[nearer]
            t[k] = td[nearer]
            normal[k] = dhit["primitive_normals"].numpy()[nearer]
            cls[k] = MOVING_BODY
            box[k] = dhit["primitive_ids"].numpy().astype(np.int64)[nearer] // 12
        return RayHits(t, normal, cls, box)


__all__ = ["EXIT_MARGIN_M", "MOVING_BODY", "NO_HIT", "RayHits", "RaycastWorld", "SensorUnavailable", "box_triangles",
           "exit_distance_m", "import_open3d", "moving_body_candidates", "ray_starts"]
