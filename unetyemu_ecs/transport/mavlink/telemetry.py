"""Telemetry messages of one drone from one snapshot row (ENU/FLU -> NED/FRD here, and only here)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from pymavlink.dialects.v20 import common as mavlink2

from ...frames import enu_to_ned, euler_rpy_from_quat_xyzw, flu_to_frd, quat_enu_flu_to_ned_frd, quat_xyzw_to_wxyz
from ...geodesy import GeodeticOrigin, enu_to_geodetic
from ...systems.flight_state import ArmBlock
from ..api import Snapshot
from . import px4

UINT16_UNKNOWN = 65535
_HOME_CACHE: dict[tuple[float, ...], tuple[float, float, float]] = {}     # transport thread only


def _get(snap: Snapshot, name: str, row: int, default: Any) -> Any:
    arr = snap.arrays.get(name)
    return default if arr is None else arr[row]


class RowView:
    """The values of one drone in one snapshot, in MAVLink's frames and units."""

    def __init__(self, snap: Snapshot, row: int, origin: GeodeticOrigin, local_origin_enu_m: np.ndarray) -> None:
        self.snap = snap
        self.row = row
        self.t_s = snap.sim_time_s
        self.time_boot_ms = int(round(snap.sim_time_s * 1000.0)) & 0xFFFFFFFF
        self.time_usec = int(round(snap.sim_time_s * 1e6))
        pos = np.asarray(snap.arrays["pos_enu_m"][row], dtype=float)
        vel = np.asarray(_get(snap, "vel_enu_m_s", row, np.zeros(3)), dtype=float)
        self.pos_enu = pos
        self.vel_ned = enu_to_ned(vel)
        self.pos_local_ned = enu_to_ned(pos - local_origin_enu_m)
        q = np.asarray(_get(snap, "quat_enu_flu_xyzw", row, np.array([0.0, 0.0, 0.0, 1.0])), dtype=float)
        self.q_ned_frd_xyzw = quat_enu_flu_to_ned_frd(q)
        roll, pitch, yaw = euler_rpy_from_quat_xyzw(self.q_ned_frd_xyzw)
        self.roll, self.pitch, self.yaw = float(roll), float(pitch), float(yaw)
        self.rate_frd = flu_to_frd(np.asarray(_get(snap, "rate_flu_rad_s", row, np.zeros(3)), dtype=float))
        lat, lon, alt = enu_to_geodetic(pos, origin)
        self.lat_deg, self.lon_deg, self.alt_m = float(lat), float(lon), float(alt)
        self.home_set = bool(_get(snap, "home_set", row, False))
        self.home_enu = np.asarray(_get(snap, "home_enu_m", row, pos), dtype=float) if self.home_set else pos
        key = (origin.lat_deg, origin.lon_deg, origin.alt_m, *self.home_enu.tolist())
        if key not in _HOME_CACHE:                  # home rarely moves: one geodetic conversion per home
            if len(_HOME_CACHE) > 256:
                _HOME_CACHE.clear()
            hlat, hlon, halt = enu_to_geodetic(self.home_enu, origin)
            _HOME_CACHE[key] = (float(hlat), float(hlon), float(halt))
        self.home_lat, self.home_lon, self.home_alt = _HOME_CACHE[key]
        self.home_local_ned = enu_to_ned(self.home_enu - local_origin_enu_m)
        self.nav_state = int(_get(snap, "nav_state", row, 0))
        self.armed = px4.is_armed(_get(snap, "flight_mode", row, 0)) if "armed" not in snap.arrays \
            else bool(snap.arrays["armed"][row])
        self.landed_state = int(_get(snap, "landed_state", row, 0))
        self.soc = float(np.clip(_get(snap, "soc_frac", row, 1.0), 0.0, 1.0))
        self.power_w = float(_get(snap, "power_w", row, 0.0))
        self.energy_used_j = float(_get(snap, "energy_used_j", row, 0.0))
        self.remaining_time_s = float(_get(snap, "remaining_time_s", row, math.inf))
        self.low_battery = bool(_get(snap, "low_battery", row, False))
        self.arm_block = int(_get(snap, "arm_block", row, ArmBlock.LOW_BATTERY if self.low_battery else 0))
        self.voltage_v = float(_get(snap, "pack_voltage_v", row, 0.0))
        self.current_a = float(_get(snap, "pack_current_a", row, 0.0))

    @property
    def heading_cdeg(self) -> int:
        return int(round(math.degrees(self.yaw) % 360.0 * 100.0)) % 36000

    @property
    def relative_alt_m(self) -> float:
        return float(self.pos_enu[2] - self.home_enu[2])


def _i32(v: float) -> int:
    return int(max(-2**31, min(2**31 - 1, round(v))))


def _i16(v: float) -> int:
    return int(max(-32768, min(32767, round(v))))


def build(msgid: int, v: RowView, imu: Any | None) -> mavlink2.MAVLink_message | None:
    """The message ``msgid`` for this drone now (None: nothing to send, e.g. no IMU sample)."""
    if msgid == 0:
        return mavlink2.MAVLink_heartbeat_message(
            px4.MAV_TYPE_QUADROTOR, px4.MAV_AUTOPILOT_PX4, px4.base_mode(v.nav_state, v.armed),
            px4.custom_mode(v.nav_state), px4.MAV_STATE_ACTIVE if v.armed else px4.MAV_STATE_STANDBY, 3)
    if msgid == 1:
        health = px4.SENSORS_PRESENT
        if v.armed or v.arm_block == ArmBlock.NONE:       # PX4: pre-arm checks pass (and set while armed)
            health |= px4.SENSOR_PREARM
        if v.low_battery:
            health &= ~px4.SENSOR_BATTERY
        current_ca = _i16(v.current_a * 100.0) if v.voltage_v > 0 else -1
        return mavlink2.MAVLink_sys_status_message(
            px4.SENSORS_PRESENT | px4.SENSOR_PREARM, px4.SENSORS_PRESENT | px4.SENSOR_PREARM, health,
            100, min(int(v.voltage_v * 1000), UINT16_UNKNOWN - 1), current_ca, int(round(v.soc * 100)), 0, 0, 0, 0, 0, 0)
    if msgid == 24:
        return mavlink2.MAVLink_gps_raw_int_message(
            v.time_usec, 3, _i32(v.lat_deg * 1e7), _i32(v.lon_deg * 1e7), _i32(v.alt_m * 1000), 100, 100,
            int(min(65534, round(math.hypot(v.vel_ned[0], v.vel_ned[1]) * 100))),
            int(round(math.degrees(math.atan2(v.vel_ned[1], v.vel_ned[0])) % 360.0 * 100)) % 36000, 10)
    if msgid == 30:
        return mavlink2.MAVLink_attitude_message(v.time_boot_ms, v.roll, v.pitch, v.yaw, *map(float, v.rate_frd))
    if msgid == 31:
        w, x, y, z = map(float, quat_xyzw_to_wxyz(v.q_ned_frd_xyzw))
        return mavlink2.MAVLink_attitude_quaternion_message(v.time_boot_ms, w, x, y, z, *map(float, v.rate_frd))
    if msgid == 32:
        return mavlink2.MAVLink_local_position_ned_message(v.time_boot_ms, *map(float, v.pos_local_ned),
                                                           *map(float, v.vel_ned))
    if msgid == 33:
        return mavlink2.MAVLink_global_position_int_message(
            v.time_boot_ms, _i32(v.lat_deg * 1e7), _i32(v.lon_deg * 1e7), _i32(v.alt_m * 1000),
            _i32(v.relative_alt_m * 1000), *(_i16(c * 100) for c in v.vel_ned), v.heading_cdeg)
    if msgid == 49:
        return None                     # sent by the endpoint (it knows the local origin)
    if msgid == 74:
        ground = float(math.hypot(v.vel_ned[0], v.vel_ned[1]))
        throttle = int(round(min(100.0, max(0.0, v.power_w / 20.0)))) if v.armed else 0
        return mavlink2.MAVLink_vfr_hud_message(ground, ground, int(round(math.degrees(v.yaw) % 360.0)) % 360,
                                                throttle, v.alt_m, float(-v.vel_ned[2]))
    if msgid == 105:
        if imu is None:
            return None
        acc = flu_to_frd([imu.linear_acceleration.x, imu.linear_acceleration.y, imu.linear_acceleration.z])
        gyro = flu_to_frd([imu.angular_velocity.x, imu.angular_velocity.y, imu.angular_velocity.z])
        return mavlink2.MAVLink_highres_imu_message(
            v.time_usec, *map(float, acc), *map(float, gyro), 0.0, 0.0, 0.0, 1013.25, 0.0,
            float(v.alt_m), 20.0, 0x1FF)
    if msgid == 141:
        return mavlink2.MAVLink_altitude_message(
            v.time_usec, v.alt_m, v.alt_m, float(-v.pos_local_ned[2]), v.relative_alt_m, float(v.pos_enu[2]),
            float(v.pos_enu[2]))
    if msgid == 147:
        voltages = [min(int(v.voltage_v * 1000), UINT16_UNKNOWN - 1)] + [UINT16_UNKNOWN] * 9
        current_ca = _i16(v.current_a * 100.0) if v.voltage_v > 0 else -1
        used_mah = _i32(v.energy_used_j / 3.6 / v.voltage_v) if v.voltage_v > 0 else -1
        remaining = _i32(min(v.remaining_time_s, 2**31 - 1)) if math.isfinite(v.remaining_time_s) else 0
        charge_state = 4 if v.soc <= 0.0 else (2 if v.low_battery else 1)    # EMERGENCY / LOW / OK
        return mavlink2.MAVLink_battery_status_message(
            0, 0, 1, 32767, voltages, current_ca, used_mah, -1, int(round(v.soc * 100)), remaining, charge_state)
    if msgid == 242:
        w, x, y, z = 1.0, 0.0, 0.0, 0.0
        return mavlink2.MAVLink_home_position_message(
            _i32(v.home_lat * 1e7), _i32(v.home_lon * 1e7), _i32(v.home_alt * 1000), *map(float, v.home_local_ned),
            [w, x, y, z], 0.0, 0.0, 0.0, v.time_usec)
    if msgid == 245:
        return mavlink2.MAVLink_extended_sys_state_message(0, v.landed_state)
    return None


__all__ = ["RowView", "build"]
