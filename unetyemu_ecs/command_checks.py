"""The physical range of every value a command carries, checked in one place for every transport.

Each ``check_*`` function takes a command's raw values as a caller hands them over (Python API,
ROS 2 message, MAVLink message), and returns them as floats in our units and frames (SI, ENU, yaw
counter-clockwise from East) or raises ``ValueError`` naming the command, the vehicle, the field,
its range and the value received. Nothing here looks up a vehicle or touches the simulation: the
caller checks that the vehicle exists and is of the right kind, then queues the checked values.

Ranges and why (frames: docs/architecture.md §3; the ROS 2 command topics: §6):

- ``hold_s`` (teleop, drive, cmd_vel): ``None`` (held until the next command) or (0, 3600] s. The
  vehicle holds the command that long, then a drone hovers and a car brakes; a stream's timeout is
  a fraction of a second, an hour is already far beyond any scripted manoeuvre.
- ``set_target``: x and y inside the world's extent (``SceneLayout.extent_min_m/extent_max_m``):
  beyond it there is no ground to land or drive on. A drone's z in [0, ``MAX_Z_M``] m, height above
  the ground plane (10 km is above every drone's service ceiling); a car ignores z and yaw. ``speed``
  in (0, ``MAX_CRUISE_SPEED_M_S``] m/s, the same cap as a mission's cruise speed (§5).
  ``yaw_deg`` within one turn either way, [-360, 360] deg [ENU, 0 = east, counter-clockwise].
- ``teleop`` (drone sticks): throttle, pitch, roll, yaw normalised to [-1, 1].
- ``drive`` (car pedals and wheel): throttle [-1, 1] (negative = reverse), brake [0, 1], steering
  [-1, 1] (+1 = full left).
- ``cmd_vel`` (body frame FLU): forward, left and up speeds within +-``MAX_CRUISE_SPEED_M_S`` m/s,
  yaw rate within +-``MAX_YAW_RATE_RAD_S`` rad/s (a turn a second). The controllers clamp further
  to each vehicle's own limits.
- ``drive_route``: one to ``MAX_WAYPOINTS`` (x, y) waypoints of numbers [m, ENU], each inside the
  world; a loop needs at least 3; ``speed`` in (0, ``MAX_CRUISE_SPEED_M_S``] m/s like a target's;
  ``loop`` True or False; ``laps`` an integer in [0, ``MAX_LAPS``] (0 = forever), only with ``loop``.
- ``arm``: ``True`` or ``False`` (numbers and strings are refused: ``"False"`` is truthy).

Booleans are not numbers here (``True`` is not a speed), numpy scalars are.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np

from .config.limits import MAX_WAYPOINTS, MAX_Z_M
from .mission.spec import MAX_CRUISE_SPEED_M_S
from .scene.primitives import SceneLayout

MAX_HOLD_S = 3600.0               # longest hold of a teleop/drive/cmd_vel command [s]
MAX_YAW_RATE_RAD_S = 2 * math.pi  # a turn a second: beyond any drone's or car's yaw-rate limit
# Laps of a looping car route (0 = forever): 10 000 laps of a 100 m loop at 30 m/s take 9 h of sim
# time; a larger number is a typo for 0.
MAX_YAW_DEG = 360.0               # a heading: one turn either way is every heading there is
MAX_ATTITUDE_DEG = 80.0           # an OFFBOARD roll or pitch: near 90 deg ZYX Euler angles degenerate
MAX_LAPS = 10_000


def is_real(v: object) -> bool:
    """A real number (Python or numpy), not a bool."""
    return isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, (bool, np.bool_))


def finite_floats(what: str, values: Iterable[float]) -> list[float]:
    """``values`` as floats, all finite, else ``ValueError("<what> must be finite numbers, got [...]")``."""
    out = [float(v) for v in values]
    if not all(math.isfinite(v) for v in out):
        raise ValueError(f"{what} must be finite numbers, got {out}")
    return out


def check_hold_s(what: str, hold_s: float | None) -> float | None:
    """A command's hold time [s]: None (held until the next command) or a number in (0, MAX_HOLD_S]."""
    if hold_s is None:
        return None
    if not (is_real(hold_s) and 0.0 < hold_s <= MAX_HOLD_S):
        raise ValueError(f"{what}: hold_s must be None or a number of seconds in (0, {MAX_HOLD_S:g}], "
                         f"got {hold_s!r}")
    return float(hold_s)


def check_in_world(what: str, layout: SceneLayout, points_xy: Iterable[tuple[float, float]]) -> None:
    """ENU (x, y) points [m] must lie on the world's ground (its extent), where there is something to fly over."""
    for x, y in points_xy:
        if not layout.contains_xy(x, y):
            raise ValueError(f"{what}: ({x:g}, {y:g}) is outside the world, which spans "
                             f"{layout.extent_text()} (ENU)")


def check_set_target(vehicle: str, kind: str, layout: SceneLayout, x: float, y: float, z: float = 0.0,
                     yaw_deg: float | None = None, speed: float | None = None
                     ) -> tuple[tuple[float, float, float], float | None, float | None]:
    """Check a go-to command of ``vehicle`` (``kind`` ``quadrotor`` or ``car``).

    Returns ``(pos_enu_m, yaw_rad, speed_m_s)``: the target (x, y, z) [m, ENU], the yaw [rad, ENU]
    or None (keep), the speed [m/s] or None (the vehicle's default).
    """
    what = f"set_target({vehicle!r})"
    values = [x, y, z, *(v for v in (yaw_deg, speed) if v is not None)]
    if not all(is_real(v) and math.isfinite(v) for v in values):
        raise ValueError(f"{what}: values must be finite numbers, got {values}")
    if speed is not None and not 0 < speed <= MAX_CRUISE_SPEED_M_S:
        raise ValueError(f"{what}: speed must be in (0, {MAX_CRUISE_SPEED_M_S:g}] m/s, got {speed}")
    if yaw_deg is not None and not -MAX_YAW_DEG <= yaw_deg <= MAX_YAW_DEG:
        raise ValueError(f"{what}: yaw_deg must be in [-{MAX_YAW_DEG:g}, {MAX_YAW_DEG:g}] deg (ENU, 0 = east, "
                         f"counter-clockwise), got {yaw_deg}")
    check_in_world(what, layout, [(x, y)])
    if kind == "quadrotor" and not 0.0 <= z <= MAX_Z_M:
        raise ValueError(f"{what}: z must be in [0, {MAX_Z_M:g}] m (ENU height above "
                         f"the ground plane), got {z}")
    yaw_rad = None if yaw_deg is None else math.radians(yaw_deg)
    return (float(x), float(y), float(z)), yaw_rad, None if speed is None else float(speed)


def check_teleop(vehicle: str, throttle: float, pitch: float, roll: float, yaw: float,
                 hold_s: float | None = None) -> tuple[tuple[float, float, float, float], float | None]:
    """Check a drone's sticks (each in [-1, 1]) and hold time; return ``(sticks, hold_s)``."""
    what = f"teleop({vehicle!r})"
    stick = (throttle, pitch, roll, yaw)
    if not all(is_real(v) and math.isfinite(v) and -1.0 <= v <= 1.0 for v in stick):
        raise ValueError(f"{what}: sticks must be finite numbers in [-1, 1], got {stick}")
    return (float(throttle), float(pitch), float(roll), float(yaw)), check_hold_s(what, hold_s)


def check_armed(vehicle: str, armed: object) -> bool:
    """Check an arm/disarm request: ``True`` or ``False`` (numpy bools too)."""
    if not isinstance(armed, (bool, np.bool_)):
        raise ValueError(f"arm({vehicle!r}): armed must be True or False, got {armed!r}")
    return bool(armed)


def check_drive(vehicle: str, throttle: float, brake: float, steering: float,
                hold_s: float | None = None) -> tuple[float, float, float, float | None]:
    """Check a car's manual controls; return ``(throttle, brake, steering, hold_s)``."""
    what = f"drive({vehicle!r})"
    cmd = (throttle, brake, steering)
    if not (all(is_real(v) and math.isfinite(v) for v in cmd)
            and -1 <= throttle <= 1 and 0 <= brake <= 1 and -1 <= steering <= 1):
        raise ValueError(f"{what}: need throttle in [-1, 1], brake in [0, 1], steering in [-1, 1], got {cmd}")
    return float(throttle), float(brake), float(steering), check_hold_s(what, hold_s)


def check_cmd_vel(vehicle: str, forward_m_s: float, yaw_rate_rad_s: float, left_m_s: float = 0.0,
                  up_m_s: float = 0.0, hold_s: float | None = None
                  ) -> tuple[float, float, float, float, float | None]:
    """Check a body-frame (FLU) velocity command; return ``(forward_m_s, yaw_rate_rad_s, left_m_s,
    up_m_s, hold_s)``."""
    what = f"cmd_vel({vehicle!r})"
    values = (forward_m_s, yaw_rate_rad_s, left_m_s, up_m_s)
    if not all(is_real(v) and math.isfinite(v) for v in values):
        raise ValueError(f"{what}: values must be finite numbers, got {values}")
    if max(abs(forward_m_s), abs(left_m_s), abs(up_m_s)) > MAX_CRUISE_SPEED_M_S \
            or abs(yaw_rate_rad_s) > MAX_YAW_RATE_RAD_S:
        raise ValueError(f"{what}: speeds must be within +-{MAX_CRUISE_SPEED_M_S:g} m/s and the yaw "
                         f"rate within +-{MAX_YAW_RATE_RAD_S:g} rad/s, got {values}")
    return (float(forward_m_s), float(yaw_rate_rad_s), float(left_m_s), float(up_m_s),
            check_hold_s(what, hold_s))


def check_drive_route(vehicle: str, layout: SceneLayout, waypoints: Sequence[tuple[float, float]],
                      speed: float | None = None, loop: bool = False, laps: int = 0
                      ) -> tuple[tuple[tuple[float, float], ...], float | None, bool, int]:
    """Check a car route; return ``(waypoints_enu_m, speed_m_s, loop, laps)`` (waypoints as (x, y)
    float pairs [m, ENU], speed None = the car's default)."""
    what = f"drive_route({vehicle!r})"
    try:
        pairs = [tuple(p) for p in waypoints]
    except TypeError:
        raise ValueError(f"{what}: waypoints must be (x, y) pairs of numbers") from None
    if not all(len(p) == 2 and all(is_real(v) for v in p) for p in pairs):
        raise ValueError(f"{what}: waypoints must be (x, y) pairs of numbers")
    if len(pairs) > MAX_WAYPOINTS:
        raise ValueError(f"{what}: at most {MAX_WAYPOINTS} waypoints, got {len(pairs)}")
    wp = tuple((float(x), float(y)) for x, y in pairs)
    if not wp or not all(math.isfinite(v) for xy in wp for v in xy):
        raise ValueError(f"{what}: need at least one finite (x, y) waypoint")
    check_in_world(what, layout, wp)
    if speed is not None and not (is_real(speed) and 0 < speed <= MAX_CRUISE_SPEED_M_S):
        raise ValueError(f"{what}: speed must be a number in (0, {MAX_CRUISE_SPEED_M_S:g}] m/s, got {speed!r}")
    if not isinstance(loop, (bool, np.bool_)):
        raise ValueError(f"{what}: loop must be True or False, got {loop!r}")
    if loop and len(wp) < 3:
        raise ValueError(f"{what}: a loop needs at least 3 waypoints, got {len(wp)}")
    if not isinstance(laps, (int, np.integer)) or isinstance(laps, bool) or not 0 <= laps <= MAX_LAPS \
            or (laps and not loop):
        raise ValueError(f"{what}: laps must be an integer in [0, {MAX_LAPS}] and needs loop=True, got {laps!r}")
    return wp, None if speed is None else float(speed), bool(loop), int(laps)


__all__ = ["MAX_HOLD_S", "MAX_LAPS", "MAX_YAW_RATE_RAD_S", "check_armed", "check_cmd_vel", "check_drive",
           "check_drive_route", "check_hold_s", "check_in_world", "check_set_target", "check_teleop",
           "finite_floats", "is_real"]


# -- PX4-style navigation commands (navigation.commands_api, MAVLink, ROS 2) ------------------------
# Ranges and why: heights within [0, MAX_Z_M] like a target's z; speeds of ChangeSpeed within the
# mission caps (cruise MAX_CRUISE_SPEED_M_S, climb MAX_CLIMB_SPEED_M_S, descent MAX_DESCENT_SPEED_M_S,
# docs/architecture.md §5); a mission step index within [0, MAX_MISSION_STEPS); parameters within
# their PX4 ranges (navigation.params); at most MAX_WAYPOINTS rally points, each inside the world.

NAV_SPEED_KINDS = ("ground", "climb", "descent")


def check_nav_mode(vehicle: str, mode: object) -> int:
    """A navigation mode: a ``NavState`` or its name (``"HOLD"``, ``"rtl"`` ...); returns its number."""
    from .systems.flight_state import NavState

    what = f"set_nav_mode({vehicle!r})"
    if isinstance(mode, str):
        try:
            return int(NavState[mode.strip().upper()])
        except KeyError:
            pass
    elif isinstance(mode, (int, np.integer)) and not isinstance(mode, bool) and mode in NavState._value2member_map_:
        return int(mode)
    raise ValueError(f"{what}: mode must be one of {', '.join(m.name for m in NavState)}, got {mode!r}")


def check_takeoff(vehicle: str, alt_enu_m: float | None = None, yaw_deg: float | None = None
                  ) -> tuple[float | None, float | None]:
    """A takeoff altitude (world z [m] in (0, MAX_Z_M]; None: home + MIS_TAKEOFF_ALT) and heading [deg ENU]
    (None: keep); returns ``(alt_enu_m, yaw_rad)``."""
    what = f"takeoff({vehicle!r})"
    if alt_enu_m is not None and not (is_real(alt_enu_m) and math.isfinite(alt_enu_m) and 0.0 < alt_enu_m <= MAX_Z_M):
        raise ValueError(f"{what}: alt_m must be None or a number in (0, {MAX_Z_M:g}] m (ENU z), got {alt_enu_m!r}")
    if yaw_deg is not None and not (is_real(yaw_deg) and math.isfinite(yaw_deg) and abs(yaw_deg) <= MAX_YAW_DEG):
        raise ValueError(f"{what}: yaw_deg must be None or a number in [-{MAX_YAW_DEG:g}, {MAX_YAW_DEG:g}] deg, "
                         f"got {yaw_deg!r}")
    return (None if alt_enu_m is None else float(alt_enu_m)), (None if yaw_deg is None else math.radians(yaw_deg))


def check_land_xy(vehicle: str, layout: SceneLayout, xy: Sequence[float] | None) -> tuple[float, float] | None:
    """Where to land: None (straight below) or an ENU (x, y) [m] inside the world."""
    what = f"land({vehicle!r})"
    if xy is None:
        return None
    try:
        x, y = xy
    except (TypeError, ValueError):
        raise ValueError(f"{what}: xy must be None or an (x, y) pair of numbers, got {xy!r}") from None
    if not all(is_real(v) and math.isfinite(v) for v in (x, y)):
        raise ValueError(f"{what}: xy must be finite numbers, got {xy!r}")
    check_in_world(what, layout, [(x, y)])
    return float(x), float(y)


def check_position(what: str, layout: SceneLayout, pos: Sequence[float]) -> tuple[float, float, float]:
    """An ENU position (x, y, z) [m]: x, y inside the world, z in [0, MAX_Z_M]."""
    try:
        x, y, z = pos
    except (TypeError, ValueError):
        raise ValueError(f"{what}: expected an (x, y, z) position, got {pos!r}") from None
    if not all(is_real(v) and math.isfinite(v) for v in (x, y, z)):
        raise ValueError(f"{what}: position must be finite numbers, got {pos!r}")
    check_in_world(what, layout, [(x, y)])
    if not 0.0 <= z <= MAX_Z_M:
        raise ValueError(f"{what}: z must be in [0, {MAX_Z_M:g}] m, got {z!r}")
    return float(x), float(y), float(z)


def check_param(vehicle: str, name: object, value: object) -> tuple[str, float]:
    """A flight parameter and its new value (``navigation.params``: known name, PX4 range)."""
    from .navigation.params import check_param as param_error

    what = f"set_param({vehicle!r})"
    if not isinstance(name, str):
        raise ValueError(f"{what}: the parameter name must be a string, got {name!r}")
    error = param_error(name, value)    # type: ignore[arg-type]
    if error:
        raise ValueError(f"{what}: {error}")
    return name, float(value)           # type: ignore[arg-type]


def check_change_speed(vehicle: str, which: object, speed_m_s: object) -> tuple[str, float]:
    """ChangeSpeed: ``which`` in NAV_SPEED_KINDS, the speed within that kind's mission cap."""
    from .mission.spec import MAX_CLIMB_SPEED_M_S, MAX_DESCENT_SPEED_M_S

    what = f"change_speed({vehicle!r})"
    caps = {"ground": MAX_CRUISE_SPEED_M_S, "climb": MAX_CLIMB_SPEED_M_S, "descent": MAX_DESCENT_SPEED_M_S}
    if which not in caps:
        raise ValueError(f"{what}: which must be one of {', '.join(NAV_SPEED_KINDS)}, got {which!r}")
    ok = is_real(speed_m_s) and math.isfinite(speed_m_s) and 0.0 < speed_m_s <= caps[which]  # type: ignore[operator]
    if not ok:
        raise ValueError(f"{what}: {which} speed must be in (0, {caps[which]:g}] m/s, got {speed_m_s!r}")
    return str(which), float(speed_m_s)  # type: ignore[arg-type]


def check_mission_step(vehicle: str, step: object) -> int:
    """A mission step index: an integer in [0, MAX_MISSION_STEPS) (the mission's own length is checked when applied)."""
    from .config.limits import MAX_MISSION_STEPS

    if not isinstance(step, (int, np.integer)) or isinstance(step, bool) or not 0 <= step < MAX_MISSION_STEPS:
        raise ValueError(f"mission step of {vehicle!r} must be an integer in [0, {MAX_MISSION_STEPS}), got {step!r}")
    return int(step)


def check_flag(what: str, flag: object) -> bool:
    """True or False (numpy bools too); numbers and strings are refused."""
    if not isinstance(flag, (bool, np.bool_)):
        raise ValueError(f"{what} must be True or False, got {flag!r}")
    return bool(flag)


def check_rally_points(vehicle: str, layout: SceneLayout, points: Iterable[Sequence[float]]
                       ) -> tuple[tuple[float, float, float], ...]:
    """Rally points: at most MAX_WAYPOINTS ENU positions, each as check_position."""
    what = f"set_rally_points({vehicle!r})"
    pts = tuple(check_position(what, layout, p) for p in points)
    if len(pts) > MAX_WAYPOINTS:
        raise ValueError(f"{what}: at most {MAX_WAYPOINTS} rally points, got {len(pts)}")
    return pts


def check_offboard_setpoint(vehicle: str, layout: SceneLayout, pos: Sequence[float] | None = None,
                            vel_enu: Sequence[float] | None = None, vel_flu: Sequence[float] | None = None,
                            yaw_deg: float | None = None, yaw_rate_rad_s: float | None = None
                            ) -> tuple[tuple[float, float, float] | None, tuple[float, float, float] | None,
                                       tuple[float, float, float] | None, float | None, float | None]:
    """One OFFBOARD setpoint: a position (as check_position) or a velocity, ENU or body FLU (each part within
    +-MAX_CRUISE_SPEED_M_S m/s), never both; a heading (deg ENU, one turn either way) or a yaw rate
    (+-MAX_YAW_RATE_RAD_S), with a velocity not both. Returns ``(pos, vel_enu, vel_flu, yaw_rad,
    yaw_rate_rad_s)`` as the OffboardSetpoint fields."""
    what = f"offboard_setpoint({vehicle!r})"
    if pos is not None and (vel_enu is not None or vel_flu is not None):
        raise ValueError(f"{what}: give a position or a velocity, not both")
    if vel_enu is not None and vel_flu is not None:
        raise ValueError(f"{what}: give an ENU or a body (FLU) velocity, not both")
    if pos is None and vel_enu is None and vel_flu is None and yaw_deg is None and yaw_rate_rad_s is None:
        raise ValueError(f"{what}: give a position, a velocity, a yaw or a yaw rate")
    if pos is None and yaw_deg is not None and yaw_rate_rad_s is not None:
        raise ValueError(f"{what}: give a yaw or a yaw rate, not both")

    def velocity(name: str, v: Sequence[float] | None) -> tuple[float, float, float] | None:
        if v is None:
            return None
        vals = tuple(v)
        if len(vals) != 3 or not all(is_real(x) and math.isfinite(x) and abs(x) <= MAX_CRUISE_SPEED_M_S for x in vals):
            raise ValueError(f"{what}: {name} must be 3 finite numbers within +-{MAX_CRUISE_SPEED_M_S:g} m/s, "
                             f"got {v!r}")
        return float(vals[0]), float(vals[1]), float(vals[2])

    checked_pos = None if pos is None else check_position(what, layout, pos)
    return (checked_pos, velocity("vel_enu", vel_enu), velocity("vel_flu", vel_flu),
            *_heading_or_rate(what, yaw_deg, yaw_rate_rad_s))


def _heading_or_rate(what: str, yaw_deg: float | None, yaw_rate_rad_s: float | None
                     ) -> tuple[float | None, float | None]:
    """A setpoint's heading (deg ENU, one turn either way) and yaw rate (+-MAX_YAW_RATE_RAD_S), each
    optional, as ``(yaw_rad, yaw_rate_rad_s)``."""
    if yaw_deg is not None and not (is_real(yaw_deg) and math.isfinite(yaw_deg) and abs(yaw_deg) <= MAX_YAW_DEG):
        raise ValueError(f"{what}: yaw_deg must be a number in [-{MAX_YAW_DEG:g}, {MAX_YAW_DEG:g}], got {yaw_deg!r}")
    if yaw_rate_rad_s is not None and not (is_real(yaw_rate_rad_s) and math.isfinite(yaw_rate_rad_s)
                                           and abs(yaw_rate_rad_s) <= MAX_YAW_RATE_RAD_S):
        raise ValueError(f"{what}: yaw_rate_rad_s must be within +-{MAX_YAW_RATE_RAD_S:g} rad/s, "
                         f"got {yaw_rate_rad_s!r}")
    return (None if yaw_deg is None else math.radians(yaw_deg),
            None if yaw_rate_rad_s is None else float(yaw_rate_rad_s))


def check_offboard_attitude(vehicle: str, roll_deg: float, pitch_deg: float, thrust: float,
                            yaw_deg: float | None = None, yaw_rate_rad_s: float | None = None
                            ) -> tuple[float | None, float | None, tuple[float, float], float]:
    """One OFFBOARD attitude setpoint: roll and pitch [deg] of the body (FLU) in ENU, ZYX Euler, right side
    down and nose down positive, each within +-``MAX_ATTITUDE_DEG`` (beyond it the Euler angles of a
    multirotor stop meaning a tilt); collective ``thrust`` in [0, 1], a fraction of the four motors'
    maximum; a heading (deg ENU, one turn either way) or a yaw rate (+-MAX_YAW_RATE_RAD_S), not both
    (neither: no turn). Returns ``(yaw_rad, yaw_rate_rad_s, (roll_rad, pitch_rad), thrust)``."""
    what = f"offboard_attitude({vehicle!r})"
    for name, value in (("roll_deg", roll_deg), ("pitch_deg", pitch_deg)):
        if not (is_real(value) and math.isfinite(value) and abs(value) <= MAX_ATTITUDE_DEG):
            raise ValueError(f"{what}: {name} must be a number in [-{MAX_ATTITUDE_DEG:g}, {MAX_ATTITUDE_DEG:g}], "
                             f"got {value!r}")
    if not (is_real(thrust) and 0.0 <= thrust <= 1.0):
        raise ValueError(f"{what}: thrust must be a number in [0, 1] (fraction of full collective thrust), "
                         f"got {thrust!r}")
    if yaw_deg is not None and yaw_rate_rad_s is not None:
        raise ValueError(f"{what}: give a yaw or a yaw rate, not both")
    return (*_heading_or_rate(what, yaw_deg, yaw_rate_rad_s), (math.radians(roll_deg), math.radians(pitch_deg)),
            float(thrust))


MAX_ORBIT_RADIUS_M = 1000.0       # a 1 km circle is already far beyond a multicopter orbit
ORBIT_YAW_BEHAVIOURS = (0, 1, 2, 3, 5)   # MAVLink ORBIT_YAW_BEHAVIOUR values the navigator flies


def check_manual_control(vehicle: str, pitch: float, roll: float, throttle: float, yaw: float
                         ) -> tuple[float, float, float, float]:
    """Sticks of a transmitter: pitch, roll, yaw in [-1, 1], throttle in [0, 1] (0.5 = centre)."""
    values = (pitch, roll, throttle, yaw)
    if not (all(is_real(v) and math.isfinite(v) for v in values) and -1 <= pitch <= 1 and -1 <= roll <= 1
            and 0 <= throttle <= 1 and -1 <= yaw <= 1):
        raise ValueError(f"manual_control({vehicle!r}): need pitch, roll, yaw in [-1, 1] and throttle in [0, 1], "
                         f"got {values}")
    return float(pitch), float(roll), float(throttle), float(yaw)


def check_orbit(vehicle: str, layout: SceneLayout, center: Sequence[float], radius_m: float, speed_m_s: float,
                yaw_behaviour: int = 0) -> tuple[tuple[float, float, float], float, float, int]:
    """An orbit: centre as check_position; 0 < |radius| <= MAX_ORBIT_RADIUS_M (sign = direction); speed in
    (0, MAX_CRUISE_SPEED_M_S]; yaw_behaviour one of ORBIT_YAW_BEHAVIOURS."""
    what = f"orbit({vehicle!r})"
    c = check_position(what, layout, center)
    if not (is_real(radius_m) and math.isfinite(radius_m) and 0 < abs(radius_m) <= MAX_ORBIT_RADIUS_M):
        raise ValueError(f"{what}: radius_m must be non-zero within +-{MAX_ORBIT_RADIUS_M:g} m, got {radius_m!r}")
    if not (is_real(speed_m_s) and math.isfinite(speed_m_s) and 0 < speed_m_s <= MAX_CRUISE_SPEED_M_S):
        raise ValueError(f"{what}: speed_m_s must be in (0, {MAX_CRUISE_SPEED_M_S:g}] m/s, got {speed_m_s!r}")
    if yaw_behaviour not in ORBIT_YAW_BEHAVIOURS or isinstance(yaw_behaviour, bool):
        raise ValueError(f"{what}: yaw_behaviour must be one of {ORBIT_YAW_BEHAVIOURS}, got {yaw_behaviour!r}")
    return c, float(radius_m), float(speed_m_s), int(yaw_behaviour)


def check_follow_target(vehicle: str, layout: SceneLayout, pos: Sequence[float], vel: Sequence[float] | None = None
                        ) -> tuple[tuple[float, float, float], tuple[float, float, float] | None]:
    """A target fix: position as check_position, velocity None or 3 numbers within +-MAX_CRUISE_SPEED_M_S."""
    what = f"follow_target({vehicle!r})"
    p = check_position(what, layout, pos)
    if vel is None:
        return p, None
    v = tuple(vel)
    if len(v) != 3 or not all(is_real(x) and math.isfinite(x) and abs(x) <= MAX_CRUISE_SPEED_M_S for x in v):
        raise ValueError(f"{what}: vel must be 3 finite numbers within +-{MAX_CRUISE_SPEED_M_S:g} m/s, got {vel!r}")
    return p, (float(v[0]), float(v[1]), float(v[2]))


def check_mission(vehicle: str, what: str, layout: SceneLayout, package_names: Sequence[str], mission: object) -> Any:
    """A mission for drone ``vehicle``: JSON text (ours or the paper's format) or a ``MissionSpec``,
    whose pads and packages exist; returns the MissionSpec. A bad mission raises ``ConfigError``
    naming the step and field; something that is not a mission, ``ValueError`` (``what`` names the call)."""
    from .config.schema import ConfigError, Issue
    from .mission import MissionSpec, mission_reference_issues, parse_mission

    if isinstance(mission, (str, bytes, bytearray)):
        spec = parse_mission(mission, source=f"mission for {vehicle}")
    elif isinstance(mission, MissionSpec):
        spec = mission
    else:
        raise ValueError(f"{what}({vehicle!r}): expected mission text (JSON) or a MissionSpec, got "
                         f"{type(mission).__name__}")
    problems = mission_reference_issues(spec, layout, package_names)
    if problems:
        raise ConfigError([Issue(f"mission for {vehicle}", None, path, msg) for path, msg in problems])
    return spec
