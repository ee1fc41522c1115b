"""What an agent sees besides its task's state: the drone's own sensors, read from their ROS 2 messages.

Each part is measured by the simulator's sensor of that name, mounted on the drone in the world file
the environment builds (so noise, rates and ray casting are the simulator's own) and sampled at the
control rate; an agent sees exactly what a ROS 2 node subscribed to that topic would:

=========== ============ ===================================================================================
part        shape        contents
=========== ============ ===================================================================================
``imu``     (6,)         body rates FLU [rad/s], then specific force FLU [m/s^2] (+9.81 up at rest)
``gps``     (3,)         the fix as ENU metres from the copy's origin (WGS84 -> ENU of the world's origin)
``battery`` (2,)         state of charge [0-1], pack voltage / its full-charge voltage [-]
``lidar``   (sectors,)   nearest return per azimuth sector (sector 0 centred straight ahead, then
                         counter-clockwise) over every channel, as a fraction of the maximum range
                         (1: nothing within range)
``depth``   (H, W)       a small forward depth image [m], no return = the maximum range
=========== ============ ===================================================================================
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..config.limits import MAX_XY_M

SENSOR_PARTS = ("imu", "gps", "battery", "lidar", "depth")
OBSERVATION_PARTS = ("state", *SENSOR_PARTS)
SENSOR_KEY = {"imu": "imu", "gps": "gps", "battery": "battery", "lidar": "lidar", "depth": "depth_camera"}


@dataclass(frozen=True)
class SensorSetup:
    """The sensors' settings in an environment (each within the sensor's own world-file limits).

    lidar_sectors : azimuth sectors of the ``lidar`` part (the scan's 360 columns are binned into them)
    lidar_channels : vertical channels of the scan (spread over 30 deg about the horizon)
    lidar_range_m : the LiDAR's maximum range [m]
    depth_width, depth_height : the depth image [px]
    depth_hfov_deg : its horizontal field of view [deg]
    depth_range_m : its maximum range [m]
    """

    lidar_sectors: int = 36
    lidar_channels: int = 8
    lidar_range_m: float = 20.0
    depth_width: int = 32
    depth_height: int = 24
    depth_hfov_deg: float = 90.0
    depth_range_m: float = 30.0

    def __post_init__(self) -> None:
        if not (isinstance(self.lidar_sectors, int) and 1 <= self.lidar_sectors <= 360):
            raise ValueError(f"lidar_sectors must be an integer in [1, 360], got {self.lidar_sectors!r}")
        if not (isinstance(self.lidar_channels, int) and 1 <= self.lidar_channels <= 64):
            raise ValueError(f"lidar_channels must be an integer in [1, 64], got {self.lidar_channels!r}")
        for name, hi in (("lidar_range_m", 200.0), ("depth_range_m", 200.0)):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and 0.5 <= value <= hi):
                raise ValueError(f"{name} must be a range in [0.5, {hi:g}] m, got {value!r}")
        for name in ("depth_width", "depth_height"):
            value = getattr(self, name)
            if not (isinstance(value, int) and 1 <= value <= 256):
                raise ValueError(f"{name} must be an integer number of pixels in [1, 256], got {value!r}")
        if not (isinstance(self.depth_hfov_deg, (int, float)) and 10.0 <= self.depth_hfov_deg <= 170.0):
            raise ValueError(f"depth_hfov_deg must be in [10, 170] deg, got {self.depth_hfov_deg!r}")


MAX_OBS_SPEED_M_S = 60.0          # bounds of a speed in an observation [m/s]
MAX_OBS_RATE_RAD_S = 100.0        # of a body rate [rad/s]
FRACTION_LABELS = ("done_frac", "carrying", "soc")


def bounds_by_unit(labels: tuple[str, ...], max_distance_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Physically meaningful bounds (low, high) of each observation element, from its name's unit suffix:
    distances (``_m``) within ``max_distance_m``, speeds (``_m_s``) within :data:`MAX_OBS_SPEED_M_S`, rates
    (``_rad_s``) within :data:`MAX_OBS_RATE_RAD_S`, fractions and flags (:data:`FRACTION_LABELS`) in
    [0, 1], anything else (quaternion parts, cos and sin, actions) in [-1, 1]."""
    low, high = [], []
    for label in labels:
        if label.endswith("_rad_s"):
            lim = (-MAX_OBS_RATE_RAD_S, MAX_OBS_RATE_RAD_S)
        elif label.endswith("_m_s"):
            lim = (-MAX_OBS_SPEED_M_S, MAX_OBS_SPEED_M_S)
        elif label.endswith("_m"):
            lim = (-max_distance_m, max_distance_m)
        elif label in FRACTION_LABELS:
            lim = (0.0, 1.0)
        else:
            lim = (-1.0, 1.0)
        low.append(lim[0])
        high.append(lim[1])
    return np.array(low, dtype=np.float32), np.array(high, dtype=np.float32)


def check_parts(parts: Any) -> tuple[str, ...]:
    """The observation parts asked for, checked: a tuple from :data:`OBSERVATION_PARTS` holding ``state``."""
    if isinstance(parts, str):
        parts = (parts,)
    try:
        parts = tuple(parts)
    except TypeError:
        raise ValueError(f"observations must be a list of parts from {OBSERVATION_PARTS}, got {parts!r}") from None
    bad = [p for p in parts if p not in OBSERVATION_PARTS]
    if bad or "state" not in parts or len(set(parts)) != len(parts):
        raise ValueError(f"observations must name 'state' and any of {SENSOR_PARTS[0:]} once each, got {parts!r}"
                         + (f" ({', '.join(map(repr, bad))} unknown)" if bad else ""))
    return parts


def sensor_components(parts: tuple[str, ...], setup: SensorSetup, rate_hz: float) -> str:
    """The world-file ``components`` entries (YAML flow mappings) that mount the sensors of ``parts``,
    each sampled at ``rate_hz`` (the control rate: every observation is fresh)."""
    items = []
    if "imu" in parts:
        items.append(f"imu: {{rate_hz: {rate_hz:g}}}")
    if "gps" in parts:
        items.append(f"gps: {{rate_hz: {rate_hz:g}}}")
    if "battery" in parts:
        items.append(f"battery: {{rate_hz: {rate_hz:g}}}")
    if "lidar" in parts:
        items.append(f"lidar: {{rate_hz: {rate_hz:g}, horizontal_samples: 360, channels: {setup.lidar_channels}, "
                     f"vertical_fov_deg: 30.0, max_range_m: {setup.lidar_range_m:g}}}")
    if "depth" in parts:
        items.append(f"depth_camera: {{rate_hz: {rate_hz:g}, width: {setup.depth_width}, height: {setup.depth_height}, "
                     f"hfov_deg: {setup.depth_hfov_deg:g}, max_range_m: {setup.depth_range_m:g}}}")
    return ", ".join(items)


def part_bounds(part: str, setup: SensorSetup) -> tuple[tuple[int, ...], float, float]:
    """``(shape, low, high)`` of a sensor part's observation."""
    if part == "imu":                         # a gyro's and an accelerometer's full scale: 2000 deg/s, 16 g
        return (6,), -160.0, 160.0
    if part == "gps":
        return (3,), -MAX_XY_M, MAX_XY_M
    if part == "battery":
        return (2,), 0.0, 2.0
    if part == "lidar":
        return (setup.lidar_sectors,), 0.0, 1.0
    if part == "depth":
        return (setup.depth_height, setup.depth_width), 0.0, float(setup.depth_range_m)
    raise ValueError(f"unknown sensor part {part!r}")


def lidar_sectors(points_xyz_m: np.ndarray, sectors: int, range_m: float) -> np.ndarray:
    """Nearest return per azimuth sector as a fraction of ``range_m`` (sectors,), 1 where none.

    points_xyz_m : (P, 3) returns in the sensor frame (x forward, y left) [m]
    """
    out = np.ones(sectors)
    if len(points_xyz_m) == 0:
        return out
    pts = np.asarray(points_xyz_m, dtype=float)
    dist = np.linalg.norm(pts, axis=1) / range_m
    az = np.arctan2(pts[:, 1], pts[:, 0])                             # CCW from forward
    k = np.floor((az + np.pi / sectors) / (2.0 * np.pi / sectors)).astype(np.intp) % sectors
    np.minimum.at(out, k, np.minimum(dist, 1.0))
    return out


def read_part(sim: Any, vehicle: str, part: str, setup: SensorSetup, origin_enu_m: np.ndarray,
              full_voltage_v: float = 1.0) -> np.ndarray:
    """The newest sample of sensor ``part`` on ``vehicle`` as its observation (zeros before the first);
    ``origin_enu_m`` is the copy's origin (``gps``), ``full_voltage_v`` the pack's when full (``battery``)."""
    shape, _low, _high = part_bounds(part, setup)
    msg = sim.sensor(vehicle, SENSOR_KEY[part])
    if msg is None:
        return np.full(shape, 1.0 if part == "lidar" else (setup.depth_range_m if part == "depth" else 0.0))
    if part == "imu":
        w, a = msg.angular_velocity, msg.linear_acceleration
        return np.clip(np.array([w.x, w.y, w.z, a.x, a.y, a.z]), -160.0, 160.0)
    if part == "gps":
        from ..geodesy import geodetic_to_enu

        enu = geodetic_to_enu(msg.latitude, msg.longitude, msg.altitude, sim.services.origin)
        return np.clip(np.asarray(enu, dtype=float).reshape(3) - origin_enu_m, -MAX_XY_M, MAX_XY_M)
    if part == "battery":
        return np.array([float(msg.percentage), float(np.clip(float(msg.voltage) / max(full_voltage_v, 1e-9), 0.0, 2.0))])
    if part == "lidar":
        from ..sensors.lidar import read_points

        pts = read_points(msg)
        xyz = np.stack([pts["x"], pts["y"], pts["z"]], axis=1) if len(pts) else np.zeros((0, 3))
        return lidar_sectors(xyz, setup.lidar_sectors, setup.lidar_range_m)
    depth = np.frombuffer(np.asarray(msg.data, dtype=np.uint8).tobytes(), dtype=np.float32)
    depth = depth.reshape(msg.height, msg.width).astype(float)
    return np.minimum(np.where(np.isfinite(depth), depth, setup.depth_range_m), setup.depth_range_m)


__all__ = ["FRACTION_LABELS", "MAX_OBS_RATE_RAD_S", "MAX_OBS_SPEED_M_S", "OBSERVATION_PARTS", "bounds_by_unit", "SENSOR_PARTS", "SensorSetup", "check_parts", "lidar_sectors", "part_bounds",
           "read_part", "sensor_components"]
