"""360° LiDAR on Open3D's RaycastingScene, published as ``sensor_msgs/PointCloud2``.

Rays: ``horizontal_samples`` azimuths from -180° (behind) counter-clockwise, times ``channels``
elevations spread over ``vertical_fov_deg`` around ``vertical_center_deg`` (ring 0 lowest), in the
sensor frame (FLU: x forward, y left, z up), rotated into ENU by the full sensor attitude (body
attitude times mount), so the scan pattern is the same at any yaw, pitch and roll. Every LiDAR due
in a tick is cast in one batch against the static city and the moving bodies
(:mod:`unetyemu_ecs.sensors.raycast`, which also keeps the vehicle from seeing itself). Points are
``direction_sensor * range``: exact in the sensor frame. Hits only (``is_dense``), within
``[min_range_m, max_range_m]``.

Intensity: a per-class reflectivity (buildings, road, trees...) times the cosine of the incidence
angle, in [0, 1].
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache, partial
from typing import Annotated, Any, ClassVar

import numpy as np

from ..config.limits import SensorRate
from ..config.schema import Ge, Gt, Le, Lt
from ..control.compiled import jit
from ..phases import Phase
from ..scene.primitives import SceneClass
from ..world import StepContext
from .base import MountedSensor, SensorSpec
from .messages import header, msg_type
from .raycast import MOVING_BODY
from .raycast_system import RaycastSensorSystem, per_sensor_set

# Reflectivity per scene class (ours: orders of magnitude of concrete, asphalt, vegetation), and bodies.
REFLECTIVITY = {SceneClass.GROUND: 0.3, SceneClass.ROAD: 0.15, SceneClass.SIDEWALK: 0.35,
                SceneClass.BUILDING: 0.6, SceneClass.TREE: 0.45, SceneClass.PAD: 0.8}
BODY_REFLECTIVITY = 0.5

POINT_DTYPE = np.dtype({"names": ["x", "y", "z", "intensity", "ring"],
                        "formats": ["<f4", "<f4", "<f4", "<f4", "<u2"],
                        "offsets": [0, 4, 8, 12, 16], "itemsize": 20})
FLOAT32, UINT16 = 7, 4             # sensor_msgs/PointField datatypes


@dataclass(frozen=True, kw_only=True)
class LidarSensor(SensorSpec):
    """World-file key ``lidar``."""

    LINK: ClassVar[str] = "lidar_link"

    rate_hz: SensorRate = 10.0                 # [Hz], config.limits
    horizontal_samples: Annotated[int, Gt(0), Le(4096)] = 360   # spinning LiDARs have 512-4096 columns
    channels: Annotated[int, Gt(0), Le(256)] = 16
    vertical_fov_deg: Annotated[float, Ge(0.0), Le(180.0)] = 45.0
    vertical_center_deg: Annotated[float, Ge(-90.0), Le(90.0)] = 0.0
    max_range_m: Annotated[float, Gt(0.0), Le(2_000.0)] = 30.0    # airborne survey LiDARs reach ~2 km
    min_range_m: Annotated[float, Ge(0.0), Lt(1000.0)] = 0.0     # hits nearer than this are dropped


def ray_directions_sensor(spec: LidarSensor) -> tuple[np.ndarray, np.ndarray]:
    """Unit directions (C*H, 3) in the sensor frame, ring-major, and the ring of each ray (C*H,)."""
    h = spec.horizontal_samples
    az = np.deg2rad(-180.0 + 360.0 * np.arange(h) / h)
    if spec.channels == 1:
        el = np.deg2rad(np.array([spec.vertical_center_deg]))
    else:
        el = np.deg2rad(spec.vertical_center_deg
                        + spec.vertical_fov_deg * (np.arange(spec.channels) / (spec.channels - 1) - 0.5))
    ce, se = np.cos(el)[:, None], np.sin(el)[:, None]
    dirs = np.stack([ce * np.cos(az)[None, :], ce * np.sin(az)[None, :], np.broadcast_to(se, (len(el), h))], axis=-1)
    rings = np.repeat(np.arange(len(el), dtype=np.uint16), h)
    return dirs.reshape(-1, 3), rings


def pointcloud2(points_sensor_m: np.ndarray, intensity: np.ndarray, rings: np.ndarray, time_s: float, frame_id: str) -> Any:
    """A PointCloud2 (x, y, z, intensity float32; ring uint16; 20-byte points) of hits."""
    arr = np.zeros(len(points_sensor_m), dtype=POINT_DTYPE)
    arr["x"], arr["y"], arr["z"] = points_sensor_m[:, 0], points_sensor_m[:, 1], points_sensor_m[:, 2]
    arr["intensity"], arr["ring"] = intensity, rings
    return pointcloud2_of_points(arr, time_s, frame_id)


@cache
def _point_fields() -> tuple[Any, ...]:
    """The PointFields of POINT_DTYPE (made once; messages share these immutable field descriptions)."""
    PointField = msg_type("sensor_msgs/msg/PointField")
    return (*(PointField(name=n, offset=o, datatype=FLOAT32, count=1)
              for n, o in (("x", 0), ("y", 4), ("z", 8), ("intensity", 12))),
            PointField(name="ring", offset=16, datatype=UINT16, count=1))


def pointcloud2_of_points(points: np.ndarray, time_s: float, frame_id: str) -> Any:
    """A PointCloud2 whose data are the bytes of ``points`` (a contiguous POINT_DTYPE array, not copied)."""
    return msg_type("sensor_msgs/msg/PointCloud2")(
        header=header(time_s, frame_id), height=1, width=len(points), fields=list(_point_fields()), is_bigendian=False,
        point_step=POINT_DTYPE.itemsize, row_step=POINT_DTYPE.itemsize * len(points),
        data=points.view(np.uint8), is_dense=True)          # the points' bytes, not a copy of them


def read_points(msg: Any) -> np.ndarray:
    """The structured points (x, y, z, intensity, ring) of a PointCloud2 built by :func:`pointcloud2`."""
    return np.frombuffer(np.asarray(msg.data, dtype=np.uint8).tobytes(), dtype=POINT_DTYPE)


class LidarSystem(RaycastSensorSystem):
    """Every LiDAR that is due, cast in one batch. Phase: SENSORS. Reads: fleet poses, body boxes."""

    phase = Phase.SENSORS
    order = 50
    spec_type = LidarSensor
    key = "lidar"
    topic_suffix = "lidar/points"

    def __init__(self) -> None:
        super().__init__()
        self._patterns: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}   # entity -> dirs, rings, exit
        table = np.zeros(256, dtype=np.float32)
        for cls, refl in REFLECTIVITY.items():
            table[int(cls)] = refl
        table[MOVING_BODY] = BODY_REFLECTIVITY
        self._reflectivity = table
        self._ray_limits: dict[tuple[int, ...], tuple[np.ndarray, np.ndarray, np.ndarray]] = {}

    def gather(self, ctx: StepContext) -> None:
        super().gather(ctx)
        self._patterns = {}
        self._ray_limits = {}
        for s in self.sensors:
            dirs_s, rings = ray_directions_sensor(s.spec)
            self._patterns[s.entity] = (dirs_s, rings, self.own_exit_m(s, dirs_s))

    def measure(self, ctx: StepContext, due: list[MountedSensor], time_s: float) -> None:
        rays = [(self._patterns[s.entity][0], self._patterns[s.entity][2]) for s in due]
        hits, cast, plan = self.cast_due(ctx, due, rays)
        rings, min_m, max_m = self._per_ray(due)
        # every sensor's points in one array, in sensor order (each cloud is a slice of it; room for every ray)
        counts = np.empty(len(due), dtype=np.intp)
        room = self.arrays.take(len(rings), POINT_DTYPE)       # reused once no cloud of it is held any more
        _write_points(hits.t, plan.dirs_sensor, hits.normal, cast, hits.cls, rings, plan.bounds, min_m, max_m,
                      self._reflectivity, room.view(np.float32).reshape(-1, 5), room.view(np.uint32).reshape(-1, 5),
                      counts)
        cloud = room[:int(counts.sum())]
        ends = np.cumsum(counts).tolist()
        for s, a, b in zip(due, [0, *ends[:-1]], ends):
            self.publish(ctx, s, time_s, build=partial(pointcloud2_of_points, cloud[a:b], time_s, s.frame_id))

    def _per_ray(self, due: list[MountedSensor]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Of ``due`` cast together: the ring of every ray as the point's last 4 bytes (uint32 little-endian: the
        uint16 ring, then 2 bytes of zero padding), and each sensor's kept range [min, max] (float32, m)."""
        def make() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
            return (np.concatenate([self._patterns[s.entity][1] for s in due]).astype("<u4"),
                    np.array([s.spec.min_range_m for s in due], dtype=np.float32),
                    np.array([s.spec.max_range_m for s in due], dtype=np.float32))

        return per_sensor_set(self._ray_limits, due, make)


@jit
def _write_points(t, dirs_sensor, normal, cast, cls, rings, bounds, min_m, max_m, reflectivity, columns, words,
                  counts):
    """The point of every ray that hit within its sensor's range [``min_m[j]``, ``max_m[j]``] (sensor j's rays:
    ``bounds[j]`` to ``bounds[j + 1]``), in ray order, as rows of ``columns`` (float32 x, y, z [m] in the sensor
    frame, intensity) and ``words`` (the same rows as uint32: the ring in the last word, its upper 2 bytes
    padding); ``counts[j]`` how many sensor j has. Intensity: the class's reflectivity times the cosine of
    incidence. A miss (inf) is never kept."""
    d, normals, rows = dirs_sensor.reshape(-1), normal.reshape(-1), cast.reshape(-1)   # flat: cheaper indexing
    out, out_words = columns.reshape(-1), words.reshape(-1)
    n = 0
    for j in range(bounds.shape[0] - 1):
        first, lo, hi = n, min_m[j], max_m[j]
        for i in range(bounds[j], bounds[j + 1]):
            ti = t[i]
            if not (ti <= hi and ti >= lo):
                continue
            out[5 * n], out[5 * n + 1], out[5 * n + 2] = d[3 * i] * ti, d[3 * i + 1] * ti, d[3 * i + 2] * ti
            cos_incidence = (normals[3 * i] * rows[6 * i + 3] + normals[3 * i + 1] * rows[6 * i + 4]
                             + normals[3 * i + 2] * rows[6 * i + 5])
            out[5 * n + 3] = reflectivity[cls[i]] * abs(cos_incidence)
            out_words[5 * n + 4] = rings[i]
            n += 1
        counts[j] = n - first


__all__ = ["LidarSensor", "LidarSystem", "pointcloud2", "pointcloud2_of_points", "ray_directions_sensor", "read_points"]
