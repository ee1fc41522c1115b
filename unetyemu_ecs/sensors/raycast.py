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

from ..control.compiled import jit
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
    being convex, never meet again) is left out. Conservative: every ray that hits a body is kept.

    One sensor of :func:`moving_body_candidates_binned`, its rays in one cone that holds every direction."""
    m = len(dirs_world)
    every_direction = DirectionBins(np.arange(m), np.array([0, m]), np.array([[1.0, 0.0, 0.0]]), np.array([np.pi]))
    return moving_body_candidates_binned(np.asarray(origin_m, dtype=float).reshape(1, 3), np.eye(3)[None], dirs_world,
                                         every_direction, np.array([max_range_m]), centers_m, radii_m,
                                         np.array([exclude if 0 <= exclude < len(centers_m) else -1]))


@dataclass(frozen=True)
class DirectionBins:
    """A fixed ray pattern (sensor frame) cut into cones: the rays of bin ``b`` are
    ``order[starts[b]:starts[b + 1]]``, all within ``half_angle_rad[b]`` of the unit ``axis[b]``."""

    order: np.ndarray
    starts: np.ndarray
    axis: np.ndarray
    half_angle_rad: np.ndarray


def direction_bins(dirs_sensor: np.ndarray, n_azimuth: int = 36, n_elevation: int = 6) -> DirectionBins:
    """Cut unit directions (K, 3) into azimuth x elevation cells, each with the cone that holds its rays."""
    d = np.asarray(dirs_sensor, dtype=float)
    az = np.arctan2(d[:, 1], d[:, 0])
    el = np.arcsin(np.clip(d[:, 2], -1.0, 1.0))
    ia = np.minimum(((az + np.pi) / (2.0 * np.pi) * n_azimuth).astype(np.intp), n_azimuth - 1)
    lo, hi = el.min(), el.max()
    ie = np.minimum(((el - lo) / max(hi - lo, 1e-9) * n_elevation).astype(np.intp), n_elevation - 1)
    cell = ia * n_elevation + ie
    order = np.argsort(cell, kind="stable")
    _cells, starts = np.unique(cell[order], return_index=True)
    starts = np.append(starts, len(order))
    axis = np.array([d[order[a:b]].sum(axis=0) for a, b in zip(starts[:-1], starts[1:])]).reshape(-1, 3)
    axis /= np.maximum(np.linalg.norm(axis, axis=1, keepdims=True), 1e-12)
    half = np.array([np.arccos(np.clip(d[order[a:b]] @ axis[k], -1.0, 1.0)).max()
                     for k, (a, b) in enumerate(zip(starts[:-1], starts[1:]))])
    return DirectionBins(order, starts, axis, half + 1e-9)


def moving_body_candidates_binned(origins_m: np.ndarray, R_world_sensor: np.ndarray, dirs_world: np.ndarray,
                                  bins: DirectionBins, max_range_m: np.ndarray, centers_m: np.ndarray,
                                  radii_m: np.ndarray, exclude: np.ndarray) -> np.ndarray:
    """:func:`moving_body_candidates` of N sensors that share one ray pattern of K rays, at once.

    origins_m (N, 3) and R_world_sensor (N, 3, 3) are the sensors' poses, ``dirs_world`` (N * K, 3) their
    rays in the world (sensor n's are rows n K .. (n + 1) K - 1), ``bins`` the pattern's
    :func:`direction_bins`, ``max_range_m`` (N,), ``exclude`` (N,) each sensor's own body (-1: none).
    Returns indices into the N * K rays, ascending. A body's sphere (radius r at distance d) subtends the angle
    asin(r / d); only the bins whose cone comes that close to it are tested ray by ray (the same exact
    test as :func:`moving_body_candidates`), so the cost follows the rays near bodies, not all rays.
    """
    n = len(origins_m)
    k_rays = len(dirs_world) // max(n, 1)
    out = np.empty(n * k_rays, dtype=np.intp)
    count = _binned_candidates(np.asarray(origins_m, dtype=float).reshape(-1, 3),
                               np.asarray(R_world_sensor, dtype=float).reshape(-1, 3, 3), dirs_world,
                               bins.order, bins.starts, bins.axis, bins.half_angle_rad,
                               np.broadcast_to(np.asarray(max_range_m, dtype=float), (n,)),
                               np.asarray(centers_m, dtype=float).reshape(-1, 3), np.asarray(radii_m, dtype=float),
                               np.broadcast_to(np.asarray(exclude, dtype=np.intp), (n,)), k_rays,
                               np.zeros(k_rays, dtype=np.bool_), out)
    return out[:count].copy()


@jit
def _binned_candidates(origins, R, dirs_world, order, starts, axis, half_angle, max_range, centers, radii, exclude,
                       k_rays, seen, out):
    """:func:`moving_body_candidates_binned` as one pass over sensor-body pairs: for each body near sensor s
    (not its own), the bins whose cone comes within the body's angular radius, and in them each ray whose line
    passes within the body's sphere ahead of the sensor (``seen``, K, False on entry and on return); then the
    sensor's candidates in ray order into ``out``. A sensor inside a body's sphere keeps every ray. Returns how
    many were written."""
    count = 0
    for s in range(origins.shape[0]):
        first = s * k_rays
        whole, marked = False, False
        for b in range(centers.shape[0]):
            if b == exclude[s]:
                continue
            v0, v1, v2 = centers[b, 0] - origins[s, 0], centers[b, 1] - origins[s, 1], centers[b, 2] - origins[s, 2]
            d = np.sqrt(v0 * v0 + v1 * v1 + v2 * v2)
            r = radii[b]
            if not d - r <= max_range[s]:
                continue
            if d <= r:
                whole = True
                break
            u0 = (R[s, 0, 0] * v0 + R[s, 1, 0] * v1 + R[s, 2, 0] * v2) / d          # towards the body, sensor frame
            u1 = (R[s, 0, 1] * v0 + R[s, 1, 1] * v1 + R[s, 2, 1] * v2) / d
            u2 = (R[s, 0, 2] * v0 + R[s, 1, 2] * v1 + R[s, 2, 2] * v2) / d
            reach = np.arcsin(r / d)
            need = np.sqrt(d * d - r * r)                       # how far along the ray its closest approach must be
            for c in range(starts.shape[0] - 1):
                cos_axis = min(1.0, max(-1.0, u0 * axis[c, 0] + u1 * axis[c, 1] + u2 * axis[c, 2]))
                if np.arccos(cos_axis) > reach + half_angle[c]:
                    continue
                for q in range(starts[c], starts[c + 1]):
                    k = order[q]
                    i = first + k
                    if dirs_world[i, 0] * v0 + dirs_world[i, 1] * v1 + dirs_world[i, 2] * v2 >= need:
                        seen[k] = True
                        marked = True
        if whole:
            for k in range(k_rays):
                out[count] = first + k
                count += 1
                seen[k] = False
        elif marked:
            for k in range(k_rays):
                if seen[k]:
                    out[count] = first + k
                    count += 1
                    seen[k] = False
    return count


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
    """What M rays hit: ``t`` distance from the ray origin [m] (inf: nothing), unit ``normal`` (M, 3), both
    float32; ``cls`` the SceneClass of a static hit (MOVING_BODY, NO_HIT), ``box`` the moving body's index (-1)."""

    t: np.ndarray
    normal: np.ndarray
    cls: np.ndarray
    box: np.ndarray


class RaycastWorld:
    """The static scene mesh plus moving boxes, cast together (no esper: usable on its own)."""

    def __init__(self, vertices_m: np.ndarray, triangles: np.ndarray, tri_cls: np.ndarray, threads: int = 0) -> None:
        """``threads``: how many threads each cast may use (0: every core, Open3D's default)."""
        o3d = import_open3d()
        self._o3d = o3d
        self.threads = int(threads)
        self.static = o3d.t.geometry.RaycastingScene()
        self.static.add_triangles(o3d.core.Tensor(np.asarray(vertices_m, dtype=np.float32)),
                                  o3d.core.Tensor(np.asarray(triangles, dtype=np.uint32)))
        self._tri_cls = np.asarray(tri_cls, dtype=np.int16)
        self._cls_of_prim = np.append(self._tri_cls, np.int16(NO_HIT))   # index len(tri_cls): no triangle hit

    def cast(self, origins_m: np.ndarray, dirs_world: np.ndarray, start_static_m: np.ndarray,
             start_dynamic_m: np.ndarray, boxes: tuple[np.ndarray, np.ndarray, np.ndarray] | None,
             dynamic_rays: np.ndarray | None = None) -> RayHits:
        """Cast rays (M,) from ``origins`` (M, 3) along unit ``dirs``, starting ``start_*`` metres along them
        in the static and the moving-body scene. ``boxes`` = (centres, quats, half extents) of moving bodies;
        ``dynamic_rays`` (indices) limits the moving-body cast to the rays that can meet one
        (:func:`moving_body_candidates`; None: every ray)."""
        rays = np.empty((len(dirs_world), 6), dtype=np.float32)
        rays[:, :3] = origins_m + np.asarray(start_static_m, dtype=float)[:, None] * dirs_world
        rays[:, 3:] = dirs_world
        return self.cast_prepared(rays, start_static_m, start_dynamic_m, boxes, dynamic_rays)

    def cast_prepared(self, rays: np.ndarray, start_static_m: np.ndarray, start_dynamic_m: np.ndarray,
                      boxes: tuple[np.ndarray, np.ndarray, np.ndarray] | None,
                      dynamic_rays: np.ndarray | None = None) -> RayHits:
        """:meth:`cast` of rays already in Open3D's layout: ``rays`` (M, 6) float32 rows of (the point where
        the ray starts in the static scene, i.e. origin + start_static * direction; the unit direction).
        Distances are returned from the ray's origin. Distances and normals are float32 (Open3D's)."""
        o3d = self._o3d
        m = len(rays)
        start_static = np.asarray(start_static_m, dtype=np.float32)
        hit = self.static.cast_rays(o3d.core.Tensor.from_numpy(rays), nthreads=self.threads)
        t, normal = hit["t_hit"].numpy(), hit["primitive_normals"].numpy()
        cls, box = np.empty(m, dtype=np.int16), np.empty(m, dtype=np.int32)
        _static_hits(t, hit["primitive_ids"].numpy(), start_static, self._cls_of_prim, cls, box)
        idx = np.arange(m) if dynamic_rays is None else np.asarray(dynamic_rays, dtype=np.intp)
        if boxes is not None and len(boxes[0]) and idx.size:
            verts, tris = box_triangles(*boxes)
            dyn = o3d.t.geometry.RaycastingScene()
            dyn.add_triangles(o3d.core.Tensor(verts.astype(np.float32)), o3d.core.Tensor(tris.astype(np.uint32)))
            start = np.asarray(start_dynamic_m, dtype=np.float32)
            sub = np.empty((idx.size, 6), dtype=np.float32)
            _moving_body_rays(rays, idx, start_static, start, sub)
            dhit = dyn.cast_rays(o3d.core.Tensor.from_numpy(sub), nthreads=self.threads)
            _nearer_moving_hits(idx, dhit["t_hit"].numpy(), start, dhit["primitive_ids"].numpy(),
                                dhit["primitive_normals"].numpy(), t, normal, cls, box)
        return RayHits(t, normal, cls, box)


@jit
def _static_hits(t, prim_ids, start_static, cls_of_prim, cls, box):
    """The static cast's hits as :class:`RayHits` fields: ``t`` (M,) from the ray origin (the cast's distance plus
    where the ray started, in place; inf: no hit), ``cls`` the class of the triangle hit (NO_HIT for an invalid
    primitive id: the last entry of ``cls_of_prim``), ``box`` -1."""
    no_hit = cls_of_prim.shape[0] - 1
    for i in range(t.shape[0]):
        t[i] += start_static[i]
        cls[i] = cls_of_prim[min(prim_ids[i], no_hit)]
        box[i] = -1


@jit
def _moving_body_rays(rays, idx, start_static, start_dynamic, sub):
    """The rays ``idx`` of ``rays`` (start point in the static scene, direction) restarted at their moving-body
    start distance: ``sub`` (len(idx), 6) float32."""
    for k in range(idx.shape[0]):
        i = idx[k]
        shift = start_dynamic[i] - start_static[i]
        for c in range(3):
            sub[k, c] = rays[i, c] + shift * rays[i, 3 + c]
            sub[k, 3 + c] = rays[i, 3 + c]


@jit
def _nearer_moving_hits(idx, t_hit, start_dynamic, prim_ids, normals, t, normal, cls, box):
    """Where the moving-body cast of the rays ``idx`` hit nearer than the static scene, that hit wins: its
    distance, normal, MOVING_BODY and the box it hit (12 triangles per box)."""
    for k in range(idx.shape[0]):
        i = idx[k]
        td = t_hit[k] + start_dynamic[i]
        if td < t[i]:
            t[i] = td
            normal[i, 0], normal[i, 1], normal[i, 2] = normals[k, 0], normals[k, 1], normals[k, 2]
            cls[i] = MOVING_BODY
            box[i] = prim_ids[k] // 12


__all__ = ["EXIT_MARGIN_M", "MOVING_BODY", "NO_HIT", "DirectionBins", "RayHits", "RaycastWorld", "SensorUnavailable",
           "box_triangles", "direction_bins", "exit_distance_m", "import_open3d", "moving_body_candidates",
           "moving_body_candidates_binned", "ray_starts"]
