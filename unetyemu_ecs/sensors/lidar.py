"""360° LiDAR on Open3D's RaycastingScene, published as ``sensor_msgs/PointCloud2``.

Geometry (world ENU): the static city is one RaycastingScene built once from the scene mesh.
Moving bodies (drones, cars, packages: their collision boxes at this step's poses) go into a small
second scene rebuilt on every LiDAR tick from ONE merged ``add_triangles`` call (Open3D cannot move
geometry after commit); both scenes are cast, and the nearer hit wins. Every LiDAR due in a tick is
cast in one batched call per scene.

Rays: ``horizontal_samples`` azimuths from -180° (behind) counter-clockwise, times ``channels``
elevations spread over ``vertical_fov_deg`` around ``vertical_center_deg`` (ring 0 lowest), in the
sensor frame (FLU: x forward, y left, z up), rotated into ENU by the full sensor attitude (body
attitude times mount), so the scan pattern is the same at any yaw, pitch and roll. Points are
``direction_sensor * range``: exact in the sensor frame. Hits only (``is_dense``), within
``[min range, max_range_m]``.

The vehicle never sees itself: a ray that passes through the vehicle's own collision box starts
where it leaves the box (computed exactly, slab method), and that distance is added back to the
range: the LiDAR sees through its own vehicle and nothing else is lost. (The static scene is cast
from 1 mm before that exit, the moving bodies from 1 mm after it, so neither the ground under a
landed drone nor the own box's face at the exit is missed or mistaken.) Wheels of cars are not
part of the moving geometry (their chassis box is).

Intensity: a per-class reflectivity (buildings, road, trees...) times the cosine of the incidence
angle, in [0, 1].
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated, Any

import esper
import numpy as np

from ..components.body import FleetSlot, RigidBody
from ..config.schema import Ge, Gt, Le, Lt
from ..frames import R_from_quat_xyzw
from ..phases import Phase
from ..scene.primitives import SceneClass
from ..world import StepContext
from .base import MountedSensor, SensorSpec, SensorSystemBase
from .messages import header, msg_type

# Reflectivity per scene class (ours: concrete/asphalt/vegetation orders of magnitude), and for bodies.
REFLECTIVITY = {SceneClass.GROUND: 0.3, SceneClass.ROAD: 0.15, SceneClass.SIDEWALK: 0.35,
                SceneClass.BUILDING: 0.6, SceneClass.TREE: 0.45, SceneClass.PAD: 0.8}
BODY_REFLECTIVITY = 0.5
EXIT_MARGIN_M = 0.001              # see the module docstring

POINT_DTYPE = np.dtype({"names": ["x", "y", "z", "intensity", "ring"],
                        "formats": ["<f4", "<f4", "<f4", "<f4", "<u2"],
                        "offsets": [0, 4, 8, 12, 16], "itemsize": 20})
FLOAT32, UINT16 = 7, 4             # sensor_msgs/PointField datatypes

_CUBE = np.array([[(k & 1) * 2 - 1, (k >> 1 & 1) * 2 - 1, (k >> 2 & 1) * 2 - 1] for k in range(8)], dtype=np.float64)
_CUBE_TRIS = np.array([[0, 2, 3], [0, 3, 1], [4, 5, 7], [4, 7, 6], [0, 1, 5], [0, 5, 4],
                       [2, 6, 7], [2, 7, 3], [0, 4, 6], [0, 6, 2], [1, 3, 7], [1, 7, 5]], dtype=np.int64)


@dataclass(frozen=True, kw_only=True)
class LidarSensor(SensorSpec):
    """World-file key ``lidar``."""

    rate_hz: Annotated[float, Gt(0.0)] = 10.0
    horizontal_samples: Annotated[int, Gt(0)] = 360
    channels: Annotated[int, Gt(0), Le(256)] = 16
    vertical_fov_deg: Annotated[float, Ge(0.0), Le(180.0)] = 45.0
    vertical_center_deg: Annotated[float, Ge(-90.0), Le(90.0)] = 0.0
    max_range_m: Annotated[float, Gt(0.0)] = 30.0
    min_range_m: Annotated[float, Ge(0.0), Lt(1000.0)] = 0.0     # hits nearer than this are dropped


def ray_directions_sensor(spec: LidarSensor) -> tuple[np.ndarray, np.ndarray]:
    """Unit directions (C*H, 3) in the sensor frame, ring-major, and the ring of each ray (C*H,)."""
    h = spec.horizontal_samples
    az = np.deg2rad(-180.0 + 360.0 * np.arange(h) / h)
    if spec.channels == 1:
        el = np.deg2rad(np.array([spec.vertical_center_deg]))
    else:
        el = np.deg2rad(spec.vertical_center_deg + spec.vertical_fov_deg * (np.arange(spec.channels) / (spec.channels - 1) - 0.5))
    ce, se = np.cos(el)[:, None], np.sin(el)[:, None]
    dirs = np.stack([ce * np.cos(az)[None, :], ce * np.sin(az)[None, :], np.broadcast_to(se, (len(el), h))], axis=-1)
    rings = np.repeat(np.arange(len(el), dtype=np.uint16), h)
    return dirs.reshape(-1, 3), rings


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


def box_triangles(centers_m: np.ndarray, quats_xyzw: np.ndarray, half_extents_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (8N, 3) and triangles (12N, 3) of N oriented boxes (outward CCW), world frame."""
    n = len(centers_m)
    R = R_from_quat_xyzw(quats_xyzw)
    local = _CUBE[None, :, :] * half_extents_m[:, None, :]                        # (N, 8, 3)
    verts = centers_m[:, None, :] + np.einsum("nij,nkj->nki", R, local)
    tris = (_CUBE_TRIS[None, :, :] + 8 * np.arange(n)[:, None, None]).reshape(-1, 3)
    return verts.reshape(-1, 3), tris


class SensorUnavailable(RuntimeError):
    """A sensor's library cannot be loaded on this machine (the message says what to install)."""


def import_open3d() -> Any:
    """Import Open3D, or explain what is missing (on Debian its import needs libusb-1.0-0)."""
    try:
        import open3d
    except ImportError as exc:
        hint = (" -- install the system package: apt-get install -y libusb-1.0-0" if "libusb" in str(exc) else
                " -- install it with: python3 -m pip install open3d-cpu==0.20.0")
        raise SensorUnavailable(f"the LiDAR needs Open3D, which does not import here ({exc}){hint}") from exc
    return open3d


class LidarScanner:
    """Casts LiDAR scans against the static scene mesh plus moving boxes (no esper: usable alone)."""

    def __init__(self, vertices_m: np.ndarray, triangles: np.ndarray, tri_cls: np.ndarray) -> None:
        o3d = import_open3d()
        self._o3d = o3d
        self.static = o3d.t.geometry.RaycastingScene()
        self.static.add_triangles(o3d.core.Tensor(np.asarray(vertices_m, dtype=np.float32)),
                                  o3d.core.Tensor(np.asarray(triangles, dtype=np.uint32)))
        table = np.zeros(max(int(c) for c in SceneClass) + 1, dtype=np.float32)
        for cls, refl in REFLECTIVITY.items():
            table[int(cls)] = refl
        self._tri_reflectivity = table[np.asarray(tri_cls, dtype=np.intp)]

    def cast(self, origins_m: np.ndarray, dirs_world: np.ndarray, start_static_m: np.ndarray, start_dynamic_m: np.ndarray,
             boxes: tuple[np.ndarray, np.ndarray, np.ndarray] | None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Cast rays (M,) from ``origins`` along unit ``dirs``, starting ``start_*`` metres along them in
        the static and the moving-body scene; return (distance from the origin [m] or inf,
        reflectivity, |cos incidence|). ``boxes`` = (centres, quats, half extents) of moving bodies."""
        o3d = self._o3d
        rays = np.hstack([origins_m + start_static_m[:, None] * dirs_world, dirs_world]).astype(np.float32)
        hit = self.static.cast_rays(o3d.core.Tensor(rays), nthreads=0)
        t = hit["t_hit"].numpy().astype(np.float64) + start_static_m
        normals = hit["primitive_normals"].numpy()
        prim = hit["primitive_ids"].numpy()
        found = np.isfinite(t)
        refl = np.zeros(len(t), dtype=np.float32)
        refl[found] = self._tri_reflectivity[prim[found]]
        if boxes is not None and len(boxes[0]):
            verts, tris = box_triangles(*boxes)
            dyn = o3d.t.geometry.RaycastingScene()
            dyn.add_triangles(o3d.core.Tensor(verts.astype(np.float32)), o3d.core.Tensor(tris.astype(np.uint32)))
            rays[:, :3] = origins_m + start_dynamic_m[:, None] * dirs_world
            dhit = dyn.cast_rays(o3d.core.Tensor(rays), nthreads=0)
            td = dhit["t_hit"].numpy().astype(np.float64) + start_dynamic_m
            nearer = td < t
            t = np.where(nearer, td, t)
            normals = np.where(nearer[:, None], dhit["primitive_normals"].numpy(), normals)
            refl = np.where(nearer, BODY_REFLECTIVITY, refl).astype(np.float32)
        cos = np.abs(np.einsum("ij,ij->i", normals.astype(np.float64), dirs_world))
        return t, refl, cos


def pointcloud2(points_sensor_m: np.ndarray, intensity: np.ndarray, rings: np.ndarray, time_s: float, frame_id: str) -> Any:
    """A PointCloud2 (x, y, z, intensity float32; ring uint16; 20-byte points) of hits."""
    arr = np.zeros(len(points_sensor_m), dtype=POINT_DTYPE)
    arr["x"], arr["y"], arr["z"] = points_sensor_m[:, 0], points_sensor_m[:, 1], points_sensor_m[:, 2]
    arr["intensity"], arr["ring"] = intensity, rings
    PointField = msg_type("sensor_msgs/msg/PointField")
    fields = [PointField(name=n, offset=o, datatype=FLOAT32, count=1)
              for n, o in (("x", 0), ("y", 4), ("z", 8), ("intensity", 12))]
    fields.append(PointField(name="ring", offset=16, datatype=UINT16, count=1))
    return msg_type("sensor_msgs/msg/PointCloud2")(
        header=header(time_s, frame_id), height=1, width=len(arr), fields=fields, is_bigendian=False,
        point_step=POINT_DTYPE.itemsize, row_step=POINT_DTYPE.itemsize * len(arr),
        data=np.frombuffer(arr.tobytes(), dtype=np.uint8), is_dense=True)


def read_points(msg: Any) -> np.ndarray:
    """The structured points (x, y, z, intensity, ring) of a PointCloud2 built by :func:`pointcloud2`."""
    return np.frombuffer(np.asarray(msg.data, dtype=np.uint8).tobytes(), dtype=POINT_DTYPE)


class LidarSystem(SensorSystemBase):
    """Every LiDAR that is due, cast in one batch. Phase: SENSORS. Reads: fleet poses, body boxes."""

    phase = Phase.SENSORS
    order = 50
    spec_type = LidarSensor
    key = "lidar"
    topic_suffix = "lidar/points"
    link = "lidar_link"

    def __init__(self) -> None:
        super().__init__()
        import_open3d()                     # fail when the simulation is built, not at the first scan
        self.scanner: LidarScanner | None = None
        self._patterns: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}   # entity -> (dirs, rings, own-hull exit)
        self._body_rows = np.empty(0, dtype=np.intp)
        self._body_half = np.empty((0, 3))

    def gather(self, ctx: StepContext) -> None:
        super().gather(ctx)
        if self.scanner is None:
            from ..scene.mesh import triangulate

            mesh = triangulate(ctx.services.layout)
            self.scanner = LidarScanner(mesh.vertices_m, mesh.triangles, mesh.cls)
        found = sorted((slot.row, body.half_extents_m) for _, (slot, body) in esper.get_components(FleetSlot, RigidBody))
        self._body_rows = np.array([r for r, _ in found], dtype=np.intp)
        self._body_half = np.array([h for _, h in found], dtype=float).reshape(-1, 3)
        self._patterns = {}
        for s in self.sensors:
            dirs_s, rings = ray_directions_sensor(s.spec)
            half = self._body_half[np.searchsorted(self._body_rows, s.row)]
            dirs_body = dirs_s @ R_from_quat_xyzw(s.spec.mount_quat_xyzw()).T
            exit_m = exit_distance_m(np.asarray(s.spec.mount_xyz_m, dtype=float), dirs_body, half)
            self._patterns[s.entity] = (dirs_s, rings, exit_m)

    def measure(self, ctx: StepContext, due: list[MountedSensor], time_s: float) -> None:
        f = ctx.fleet
        rows = np.array([s.row for s in due])
        R_body = R_from_quat_xyzw(f.quat_enu_flu_xyzw[rows])
        mounts = np.array([s.spec.mount_xyz_m for s in due], dtype=float)
        R_mount = R_from_quat_xyzw(np.array([s.spec.mount_quat_xyzw() for s in due]))
        R_sensor = np.einsum("nij,njk->nik", R_body, R_mount)
        pos_sensor = f.pos_enu_m[rows] + np.einsum("nij,nj->ni", R_body, mounts)
        origins, dirs_w, start_s, start_d, counts = [], [], [], [], []
        for k, s in enumerate(due):
            dirs_s, _, exit_m = self._patterns[s.entity]
            d_w = dirs_s @ R_sensor[k].T
            origins.append(np.broadcast_to(pos_sensor[k], d_w.shape))
            dirs_w.append(d_w)
            start_s.append(np.maximum(exit_m - EXIT_MARGIN_M, 0.0))
            start_d.append(np.where(exit_m > 0.0, exit_m + EXIT_MARGIN_M, 0.0))
            counts.append(len(dirs_s))
        boxes = (f.pos_enu_m[self._body_rows], f.quat_enu_flu_xyzw[self._body_rows], self._body_half)
        t, refl, cos = self.scanner.cast(np.vstack(origins), np.vstack(dirs_w), np.concatenate(start_s),
                                         np.concatenate(start_d), boxes)
        first = 0
        for k, s in enumerate(due):
            n = counts[k]
            dirs_s, rings, _ = self._patterns[s.entity]
            rng = t[first:first + n]
            keep = np.isfinite(rng) & (rng <= s.spec.max_range_m) & (rng >= s.spec.min_range_m)
            pts = dirs_s[keep] * rng[keep, None]
            intensity = (refl[first:first + n] * cos[first:first + n])[keep]
            self.publish(ctx, s, time_s, pointcloud2(pts, intensity, rings[keep], time_s, s.frame_id))
            first += n


__all__ = ["LidarScanner", "LidarSensor", "SensorUnavailable", "import_open3d", "LidarSystem", "box_triangles", "exit_distance_m", "pointcloud2",
           "ray_directions_sensor", "read_points"]
