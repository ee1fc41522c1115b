"""What the page is sent each frame, built from either source (live snapshots, a recording).

:func:`state_message` turns per-vehicle rows (:class:`VehicleRow`) into the ``state`` message;
:func:`lidar_message` and :func:`image_message` build the binary LiDAR and camera messages from
``sensor_msgs/PointCloud2`` and ``sensor_msgs/Image`` messages, after :func:`cloud_points_enu`
moved the points from the sensor frame into the world (ENU) with the vehicle's pose and the
sensor's mount. :class:`LazyFrame` holds what a message is built from, so that it is built only
when a page asks for it, and at most once.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..frames import R_from_quat_xyzw
from . import wire

POINTFIELD_FLOAT32 = 7
DEPTH_FAR_M = 60.0            # depth images: this far and beyond is black, 0 m white


@dataclass(frozen=True, slots=True)
class VehicleRow:
    """One vehicle in a ``state`` message.

    pos_enu_m : position [m] ENU · quat_enu_flu_xyzw : attitude · speed_m_s : ground-truth speed ·
    alt_m : height above the ground plane z = 0 [m] · battery_frac : state of charge in [0, 1] (None:
    no battery) · mode : what it is doing, as text · mission : the mission step, as text
    """

    name: str
    pos_enu_m: Sequence[float]
    quat_enu_flu_xyzw: Sequence[float]
    speed_m_s: float
    alt_m: float
    battery_frac: float | None
    mode: str
    mission: str


def _r(x: float, digits: int) -> float | None:
    x = float(x)
    return round(x, digits) if math.isfinite(x) else None


def state_message(sim_time_s: float, rtf: float | None, rows: Sequence[VehicleRow],
                  events: Sequence[tuple[float, str, str]] = (), replay: Mapping[str, Any] | None = None) -> str:
    """The ``state`` text message (positions to the millimetre, quaternions to 1e-4)."""
    vehicles = [{"name": r.name, "p": [_r(v, 3) for v in r.pos_enu_m], "q": [_r(v, 4) for v in r.quat_enu_flu_xyzw],
                 "speed": _r(r.speed_m_s, 2), "alt": _r(r.alt_m, 2),
                 "battery": None if r.battery_frac is None else _r(r.battery_frac, 4),
                 "mode": r.mode, "mission": r.mission} for r in rows]
    msg: dict[str, Any] = {"type": "state", "t": _r(sim_time_s, 4), "rtf": None if rtf is None else _r(rtf, 3),
                           "vehicles": vehicles, "events": [[_r(t, 2), v, text] for t, v, text in events]}
    if replay is not None:
        msg["replay"] = dict(replay)
    return wire.text(msg)


def mission_text(status: Mapping[str, Any] | None) -> str:
    """A mission status (``MissionRuntime.status()``, or the JSON of ``/<v>/mission/status``) as one
    short line: ``3/8 cruise (wait_before)``, ``completed``, ``idle``; "" without a status."""
    if not status:
        return ""
    state = str(status.get("state", ""))
    if status.get("mission") is None:
        return state or "idle"
    if state == "running":
        step, steps = status.get("step"), status.get("steps")
        where = f"{int(step) + 1}/{int(steps)} " if isinstance(step, int) and isinstance(steps, int) else ""
        stage = status.get("stage")
        return f"{where}{status.get('step_type', '')}" + (f" ({stage})" if stage else "")
    reason = status.get("reason")
    return f"{state}: {reason}" if reason else state


# -- LiDAR -------------------------------------------------------------------------------------
def cloud_xyz(msg: Any) -> np.ndarray:
    """The x, y, z of a ``sensor_msgs/PointCloud2`` in its own frame, float32 (N, 3), non-finite points
    dropped; (0, 3) for a cloud without float32 x, y, z fields."""
    fields = {f.name: f for f in msg.fields}
    if any(k not in fields or fields[k].datatype != POINTFIELD_FLOAT32 for k in "xyz") or msg.is_bigendian:
        return np.zeros((0, 3), np.float32)
    n = int(msg.width) * int(msg.height)
    step = int(msg.point_step)
    dtype = np.dtype({"names": ["x", "y", "z"], "formats": ["<f4"] * 3,
                      "offsets": [int(fields[k].offset) for k in "xyz"], "itemsize": step})
    data = np.asarray(msg.data, dtype=np.uint8)
    if n == 0 or data.size < n * step:
        return np.zeros((0, 3), np.float32)
    pts = np.frombuffer(np.ascontiguousarray(data[:n * step]), dtype=dtype)
    xyz = np.stack([pts["x"], pts["y"], pts["z"]], axis=1)
    return xyz[np.isfinite(xyz).all(axis=1)]


def cloud_points_enu(xyz_sensor_m: np.ndarray, pos_enu_m: Sequence[float], quat_enu_flu_xyzw: Sequence[float],
                     mount_xyz_m: Sequence[float] = (0.0, 0.0, 0.0),
                     mount_quat_xyzw: Sequence[float] = (0.0, 0.0, 0.0, 1.0)) -> np.ndarray:
    """Points (N, 3) of a sensor mounted at ``mount_*`` on base_link (FLU), the body at ``pos_enu_m`` with
    attitude ``quat_enu_flu_xyzw``, in the world: ENU [m], float32 (N, 3)."""
    R_body = R_from_quat_xyzw(np.asarray(quat_enu_flu_xyzw, dtype=float))
    R = R_body @ R_from_quat_xyzw(np.asarray(mount_quat_xyzw, dtype=float))
    t = np.asarray(pos_enu_m, dtype=float) + R_body @ np.asarray(mount_xyz_m, dtype=float)
    out = xyz_sensor_m.astype(np.float32) @ R.T.astype(np.float32)
    out += t.astype(np.float32)
    return out


def decimate(points: np.ndarray, cap: int) -> np.ndarray:
    """At most ``cap`` rows of ``points``, evenly strided (the scan pattern stays even)."""
    n = len(points)
    return points if n <= cap else points[:: math.ceil(n / cap)]


def lidar_message(vehicle: str, t_s: float, points_enu_m: np.ndarray) -> bytes:
    """The binary ``lidar`` message of a cloud already in ENU (decimated to ``MAX_LIDAR_POINTS``)."""
    pts = np.ascontiguousarray(decimate(points_enu_m, wire.MAX_LIDAR_POINTS), dtype="<f4")
    return wire.binary({"type": "lidar", "vehicle": vehicle, "t": t_s, "points": len(pts)}, pts.tobytes())


# -- cameras -----------------------------------------------------------------------------------
def image_rgb8(msg: Any) -> np.ndarray | None:
    """A ``sensor_msgs/Image`` as rgb8 (H, W, 3) uint8: colour encodings as they are, depth (32FC1 in
    metres, 16UC1 in millimetres) as a grey scale, near bright; None for another encoding."""
    h, w, step = int(msg.height), int(msg.width), int(msg.step)
    enc = str(msg.encoding).lower()
    data = np.asarray(msg.data, dtype=np.uint8)
    if h <= 0 or w <= 0 or data.size < h * step:
        return None
    rows = data[:h * step].reshape(h, step)
    if enc in ("rgb8", "bgr8", "rgba8", "bgra8"):
        ch = 4 if enc.endswith("a8") else 3
        if step < w * ch:
            return None
        px = rows[:, :w * ch].reshape(h, w, ch)[:, :, :3]
        return np.ascontiguousarray(px[:, :, ::-1] if enc.startswith("bgr") else px)
    if enc == "mono8":
        return np.repeat(rows[:, :w, None], 3, axis=2)
    if enc in ("32fc1", "16uc1"):
        dt = np.dtype("<f4" if enc == "32fc1" else "<u2").newbyteorder(">" if msg.is_bigendian else "<")
        if step < w * dt.itemsize:
            return None
        depth_m = rows[:, :w * dt.itemsize].copy().view(dt).astype(np.float32)
        if enc == "16uc1":
            depth_m = np.where(depth_m > 0, depth_m / 1000.0, np.inf)
        grey = np.where(np.isfinite(depth_m), 255.0 * (1.0 - np.clip(depth_m / DEPTH_FAR_M, 0.0, 1.0)), 0.0)
        return np.repeat(grey.astype(np.uint8)[:, :, None], 3, axis=2)
    return None


def image_message(vehicle: str, sensor: str, t_s: float, rgb: np.ndarray) -> bytes:
    """The binary ``image`` message of an rgb8 image (decimated to at most ``MAX_IMAGE_PIXELS``)."""
    h, w = rgb.shape[:2]
    k = max(1, math.ceil(math.sqrt(h * w / wire.MAX_IMAGE_PIXELS)))
    if k > 1:
        rgb = rgb[::k, ::k]
        h, w = rgb.shape[:2]
    return wire.binary({"type": "image", "vehicle": vehicle, "sensor": sensor, "t": t_s, "width": w, "height": h},
                       np.ascontiguousarray(rgb, dtype=np.uint8).tobytes())


class LazyFrame:
    """A message built the first time it is asked for (on the server's thread), then kept.

    ``seq`` orders frames of one channel (a vehicle's LiDAR, its camera): a page is sent a frame only
    when its ``seq`` is newer than the last it got. A build that fails yields None (counted by the
    server), never an exception.
    """

    __slots__ = ("seq", "t_s", "_build", "_value", "_lock")

    def __init__(self, seq: int, t_s: float, build: Callable[[], bytes | None]) -> None:
        self.seq, self.t_s = seq, t_s
        self._build: Callable[[], bytes | None] | None = build
        self._value: bytes | None = None
        self._lock = threading.Lock()

    def get(self) -> bytes | None:
        with self._lock:
            if self._build is not None:
                build, self._build = self._build, None
                try:
                    self._value = build()
                except Exception:       # a malformed message (a recording): nothing to send
                    self._value = None
            return self._value


__all__ = ["DEPTH_FAR_M", "LazyFrame", "VehicleRow", "cloud_points_enu", "cloud_xyz", "decimate", "image_message",
           "image_rgb8", "lidar_message", "mission_text", "state_message"]
