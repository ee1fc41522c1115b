"""PX4's numbers on the wire: custom modes, stream rates, capabilities, health bits (PX4 v1.15)."""

from __future__ import annotations

from ...systems.flight_state import FlightMode, NavState

# px4_custom_mode.h: custom_mode = main << 16 | sub << 24
MAIN_MANUAL, MAIN_ALTCTL, MAIN_POSCTL, MAIN_AUTO, MAIN_ACRO, MAIN_OFFBOARD, MAIN_STABILIZED = 1, 2, 3, 4, 5, 6, 7
AUTO_READY, AUTO_TAKEOFF, AUTO_LOITER, AUTO_MISSION, AUTO_RTL, AUTO_LAND, AUTO_FOLLOW_TARGET = 1, 2, 3, 4, 5, 6, 8
POSCTL_POSCTL, POSCTL_ORBIT = 0, 1

NAV_TO_PX4: dict[int, tuple[int, int]] = {
    NavState.HOLD: (MAIN_AUTO, AUTO_LOITER),
    NavState.TAKEOFF: (MAIN_AUTO, AUTO_TAKEOFF),
    NavState.LAND: (MAIN_AUTO, AUTO_LAND),
    NavState.RTL: (MAIN_AUTO, AUTO_RTL),
    NavState.MISSION: (MAIN_AUTO, AUTO_MISSION),
    NavState.OFFBOARD: (MAIN_OFFBOARD, 0),
    NavState.POSCTL: (MAIN_POSCTL, POSCTL_POSCTL),
    NavState.MANUAL: (MAIN_MANUAL, 0),
    NavState.ORBIT: (MAIN_POSCTL, POSCTL_ORBIT),
    NavState.FOLLOW_TARGET: (MAIN_AUTO, AUTO_FOLLOW_TARGET),
    NavState.GOTO: (MAIN_AUTO, AUTO_LOITER),          # PX4 flies DO_REPOSITION in AUTO.LOITER
}

# What a GCS may ask for (SET_MODE, DO_SET_MODE). ALTCTL and STABILIZED are flown as POSCTL and
# MANUAL (the nearest modes we have); ORBIT and GOTO need their parameters (DO_ORBIT, DO_REPOSITION).
PX4_TO_NAV: dict[tuple[int, int], NavState] = {
    (MAIN_MANUAL, 0): NavState.MANUAL,
    (MAIN_STABILIZED, 0): NavState.MANUAL,
    (MAIN_ALTCTL, 0): NavState.POSCTL,
    (MAIN_POSCTL, POSCTL_POSCTL): NavState.POSCTL,
    (MAIN_OFFBOARD, 0): NavState.OFFBOARD,
    (MAIN_AUTO, AUTO_READY): NavState.HOLD,
    (MAIN_AUTO, AUTO_LOITER): NavState.HOLD,
    (MAIN_AUTO, AUTO_TAKEOFF): NavState.TAKEOFF,
    (MAIN_AUTO, AUTO_LAND): NavState.LAND,
    (MAIN_AUTO, AUTO_RTL): NavState.RTL,
    (MAIN_AUTO, AUTO_MISSION): NavState.MISSION,
    (MAIN_AUTO, AUTO_FOLLOW_TARGET): NavState.FOLLOW_TARGET,
}


def custom_mode(nav_state: int) -> int:
    main, sub = NAV_TO_PX4.get(int(nav_state), (MAIN_AUTO, AUTO_LOITER))
    return (main << 16) | (sub << 24)


def nav_state_of(custom: int) -> NavState | None:
    """NavState for a PX4 custom mode, None for a mode we do not fly."""
    main, sub = (custom >> 16) & 0xFF, (custom >> 24) & 0xFF
    if main in (MAIN_MANUAL, MAIN_STABILIZED, MAIN_ALTCTL, MAIN_OFFBOARD):
        sub = 0
    return PX4_TO_NAV.get((main, sub))


# MAV_MODE_FLAG
FLAG_CUSTOM, FLAG_AUTO, FLAG_GUIDED, FLAG_STABILIZE, FLAG_MANUAL, FLAG_ARMED = 1, 4, 8, 16, 64, 128


def base_mode(nav_state: int, armed: bool) -> int:
    """HEARTBEAT base_mode as PX4 fills it (commander: mode flags of the navigation state)."""
    main, _ = NAV_TO_PX4.get(int(nav_state), (MAIN_AUTO, AUTO_LOITER))
    flags = FLAG_CUSTOM | FLAG_STABILIZE
    if main in (MAIN_MANUAL, MAIN_ALTCTL, MAIN_POSCTL, MAIN_STABILIZED):
        flags |= FLAG_MANUAL
    if main == MAIN_AUTO:
        flags |= FLAG_AUTO | FLAG_GUIDED
    if main == MAIN_OFFBOARD or main == MAIN_POSCTL:
        flags |= FLAG_GUIDED
    if armed:
        flags |= FLAG_ARMED
    return flags


def is_armed(flight_mode: int) -> bool:
    return int(flight_mode) != FlightMode.DISARMED


# SYS_STATUS sensor bits (MAV_SYS_STATUS_SENSOR)
SENSORS_PRESENT = (0x1 | 0x2 | 0x4 | 0x8 | 0x20 | 0x8000 | 0x200000 | 0x2000000)   # gyro accel mag baro gps motors ahrs battery
SENSOR_PREARM = 0x10000000
SENSOR_BATTERY = 0x2000000

# AUTOPILOT_VERSION capabilities: MISSION_FLOAT | PARAM_FLOAT | MISSION_INT | COMMAND_INT |
# PARAM_ENCODE_BYTEWISE | SET_ATTITUDE_TARGET | SET_POSITION_TARGET_LOCAL_NED | MAVLINK2 | MISSION_FENCE | MISSION_RALLY
CAPABILITIES = 1 | 2 | 4 | 8 | 16 | 64 | 128 | 8192 | 16384 | 32768
FLIGHT_SW_VERSION = 0x010F00FF        # 1.15.0, FIRMWARE_VERSION_TYPE_OFFICIAL (PX4 encoding)

# Stream rates [Hz] per link (api = PX4 "onboard" mode, gcs = "normal" with SITL's raised rates),
# from PX4 mavlink_main.cpp. 0 = not streamed (still available through REQUEST_MESSAGE).
STREAM_RATES_HZ: dict[str, dict[int, tuple[float, float]]] = {
    "px4": {
        0: (1.0, 1.0),          # HEARTBEAT
        1: (5.0, 1.0),          # SYS_STATUS
        4: (1.0, 0.1),          # PING
        24: (5.0, 1.0),         # GPS_RAW_INT
        30: (100.0, 50.0),      # ATTITUDE
        31: (50.0, 50.0),       # ATTITUDE_QUATERNION
        32: (30.0, 50.0),       # LOCAL_POSITION_NED
        33: (50.0, 50.0),       # GLOBAL_POSITION_INT
        49: (1.0, 0.1),         # GPS_GLOBAL_ORIGIN
        74: (10.0, 4.0),        # VFR_HUD
        105: (50.0, 0.0),       # HIGHRES_IMU
        141: (10.0, 1.0),       # ALTITUDE
        147: (0.5, 0.5),        # BATTERY_STATUS
        242: (0.5, 0.5),        # HOME_POSITION
        245: (5.0, 1.0),        # EXTENDED_SYS_STATE
    },
}
STREAM_RATES_HZ["reduced"] = {**STREAM_RATES_HZ["px4"], 30: (20.0, 10.0), 31: (10.0, 0.0), 32: (10.0, 10.0),
                              33: (10.0, 10.0), 105: (10.0, 0.0)}

MAV_TYPE_QUADROTOR, MAV_AUTOPILOT_PX4 = 2, 12
MAV_STATE_STANDBY, MAV_STATE_ACTIVE = 3, 4
FORCE_ARM_MAGIC = 21196

# MAV_RESULT
ACCEPTED, TEMPORARILY_REJECTED, DENIED, UNSUPPORTED, FAILED = 0, 1, 2, 3, 4
