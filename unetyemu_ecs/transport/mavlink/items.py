"""MAVLink mission items <-> our mission planner, geofence and rally points.

Items are kept exactly as received (:class:`MissionItem`) so a download returns what was uploaded;
:func:`build_mission`, :func:`build_geofence` and :func:`build_rally` validate a whole list and turn
it into what the simulation runs, or raise :class:`ItemError` with the ``MAV_MISSION_RESULT`` to
answer, the offending item and a reason. NED/degrees exist only here: everything produced is ENU
metres (z = height above the world's ground plane), yaw in ENU degrees.

Mission items (mission type 0) -> :class:`~unetyemu_ecs.mission.spec.MissionSpec` steps:

=====================================  ======================================================
MAV_CMD (id)                           step
=====================================  ======================================================
NAV_WAYPOINT (16)                      ``cruise`` waypoint; consecutive ones merge into one
                                       step; p1 hold time ends the step (``wait_after``);
                                       p4 yaw (NED deg, NaN = free) -> ``yaw_deg`` ENU;
                                       p2 acceptance radius is kept but not used
NAV_TAKEOFF (22)                       ``takeoff`` to the item's altitude (a waypoint when it
                                       gives lat/lon, else ``altitude_m`` above home)
NAV_LAND (21)                          ``land`` at lat/lon (where it is when lat/lon are 0/NaN)
NAV_RETURN_TO_LAUNCH (20)              ``return`` (flies home or to a rally point and lands)
NAV_LOITER_TIME (19)                   with lat/lon: a waypoint held p1 s; without: ``idle`` p1 s
NAV_DELAY (93)                         ``idle`` p1 s (p1 = -1, a time of day, is refused)
NAV_LOITER_UNLIM (17)                  ``idle`` for MAX_WAIT_S (a day)
DO_CHANGE_SPEED (178)                  speed of the waypoints that follow (p1 0/1 horizontal,
                                       2 climb, 3 descent; p2 m/s, -1 no change, -2 default)
DO_GRIPPER (211)                       p2 = 1 grab -> ``pickup``, p2 = 0 release -> ``deliver``,
                                       both at the position of the NAV item before it
camera / gimbal (203, 205, 206, 214,   accepted, no effect
530-532, 1000, 1001, 2000, 2001,
2500, 2501)
anything else (DO_JUMP 177 ...)        MAV_MISSION_UNSUPPORTED
=====================================  ======================================================

Frames: 3/6 (relative altitude) are heights above home, 0/5 are AMSL heights, taken as heights
above the world origin's ``alt_m``; terrain and local frames are MAV_MISSION_UNSUPPORTED_FRAME.
Items without a position (DO_*) may use any frame (MAVSDK and QGC send MAV_FRAME_MISSION 2).
Positions are fixed when the list is accepted: relative altitudes use the home known then
(the ground plane z = 0 before the drone has a home).

Fence items (type 1): NAV_FENCE_POLYGON_VERTEX_INCLUSION / _EXCLUSION (5001/5002, p1 = vertex
count, that many consecutive items, >= 3) and NAV_FENCE_CIRCLE_INCLUSION / _EXCLUSION (5003/5004,
p1 = radius m). Rally items (type 2): NAV_RALLY_POINT (5100).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Mapping, Sequence

import numpy as np
from pymavlink.dialects.v20 import common as mav

from ...config.limits import MAX_MISSION_STEPS, MAX_WAIT_S, MAX_WAYPOINTS, MAX_XY_M, MAX_Z_M, MIN_Z_M
from ...frames import yaw_ned_to_enu_rad
from ...geodesy import GeodeticOrigin, geodetic_to_enu
from ...mission import spec as mission_spec
from ...mission.spec import (MAX_CLIMB_SPEED_M_S, MAX_CRUISE_SPEED_M_S, MAX_DESCENT_SPEED_M_S, MissionSpec,
                             MissionStep, Waypoint)
from ...navigation.geofence import Geofence

# Most items one list (mission, fence or rally) may hold: a mission of 1000 steps already flies for hours.
MAX_ITEMS = MAX_MISSION_STEPS

GLOBAL_FRAMES = frozenset({mav.MAV_FRAME_GLOBAL, mav.MAV_FRAME_GLOBAL_INT})                  # AMSL altitude
RELATIVE_FRAMES = frozenset({mav.MAV_FRAME_GLOBAL_RELATIVE_ALT, mav.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT})
POSITION_FRAMES = GLOBAL_FRAMES | RELATIVE_FRAMES
# Frames whose x/y are latitude/longitude (scaled by 1e7 in the *_INT messages).
_LATLON_FRAMES = POSITION_FRAMES | frozenset({mav.MAV_FRAME_GLOBAL_TERRAIN_ALT, mav.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT})

NAV_WAYPOINT = mav.MAV_CMD_NAV_WAYPOINT                  # 16
NAV_LOITER_UNLIM = mav.MAV_CMD_NAV_LOITER_UNLIM          # 17
NAV_LOITER_TIME = mav.MAV_CMD_NAV_LOITER_TIME            # 19
NAV_RETURN_TO_LAUNCH = mav.MAV_CMD_NAV_RETURN_TO_LAUNCH  # 20
NAV_LAND = mav.MAV_CMD_NAV_LAND                          # 21
NAV_TAKEOFF = mav.MAV_CMD_NAV_TAKEOFF                    # 22
NAV_DELAY = mav.MAV_CMD_NAV_DELAY                        # 93
DO_CHANGE_SPEED = mav.MAV_CMD_DO_CHANGE_SPEED            # 178
DO_GRIPPER = mav.MAV_CMD_DO_GRIPPER                      # 211
FENCE_POLYGON_INCLUSION = mav.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION   # 5001
FENCE_POLYGON_EXCLUSION = mav.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_EXCLUSION   # 5002
FENCE_CIRCLE_INCLUSION = mav.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION            # 5003
FENCE_CIRCLE_EXCLUSION = mav.MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION            # 5004
RALLY_POINT = mav.MAV_CMD_NAV_RALLY_POINT                                  # 5100

# Camera and gimbal items: accepted and stored, no effect (we fly no camera payload in missions).
NOOP_COMMANDS = frozenset({203, 205, 206, 214, 530, 531, 532, 1000, 1001, 2000, 2001, 2500, 2501})
# Items the vehicle flies to or waits at: MISSION_ITEM_REACHED marks their completion.
NAV_COMMANDS = frozenset({NAV_WAYPOINT, NAV_LOITER_UNLIM, NAV_LOITER_TIME, NAV_RETURN_TO_LAUNCH, NAV_LAND,
                          NAV_TAKEOFF, NAV_DELAY})


class ItemError(ValueError):
    """A list refused as a whole: ``result`` is the MAV_MISSION_RESULT to answer, ``seq`` the item."""

    def __init__(self, result: int, seq: int, text: str) -> None:
        super().__init__(f"item {seq}: {text}")
        self.result = result
        self.seq = seq
        self.text = text


@dataclass(frozen=True)
class MissionItem:
    """One item as received (MISSION_ITEM_INT: ``int_xy`` True and x/y integers; MISSION_ITEM: floats)."""

    seq: int
    frame: int
    command: int
    current: int
    autocontinue: int
    param1: float
    param2: float
    param3: float
    param4: float
    x: float | int
    y: float | int
    z: float
    mission_type: int
    int_xy: bool

    @classmethod
    def from_msg(cls, msg: Any) -> MissionItem:
        """From a decoded MISSION_ITEM_INT (73) or MISSION_ITEM (39)."""
        int_xy = msg.get_msgId() == mav.MAVLINK_MSG_ID_MISSION_ITEM_INT
        return cls(seq=int(msg.seq), frame=int(msg.frame), command=int(msg.command), current=int(msg.current),
                   autocontinue=int(msg.autocontinue), param1=msg.param1, param2=msg.param2, param3=msg.param3,
                   param4=msg.param4, x=msg.x, y=msg.y, z=msg.z, mission_type=int(getattr(msg, "mission_type", 0)),
                   int_xy=int_xy)

    def xy(self, as_int: bool) -> tuple[float | int, float | int]:
        """x/y as the INT message (as_int) or the float one carries them."""
        if as_int == self.int_xy:
            return self.x, self.y
        scale = 1e7 if self.frame in _LATLON_FRAMES else 1.0
        if as_int:
            return _to_int32(self.x * scale), _to_int32(self.y * scale)
        return self.x / scale, self.y / scale

    def to_msg(self, as_int: bool, target_system: int, target_component: int) -> Any:
        """MISSION_ITEM_INT (as_int) or MISSION_ITEM for a download, fields as uploaded."""
        x, y = self.xy(as_int)
        cls = mav.MAVLink_mission_item_int_message if as_int else mav.MAVLink_mission_item_message
        return cls(target_system, target_component, self.seq, self.frame, self.command, self.current,
                   self.autocontinue, self.param1, self.param2, self.param3, self.param4, x, y, self.z,
                   self.mission_type)

    def latlon_deg(self) -> tuple[float, float] | None:
        """Latitude and longitude [deg], None when the item gives none (both 0, or NaN)."""
        lat, lon = (float(v) / 1e7 for v in (self.x, self.y)) if self.int_xy else (float(self.x), float(self.y))
        if math.isnan(lat) or math.isnan(lon) or (lat == 0.0 and lon == 0.0):
            return None
        return lat, lon


def _to_int32(v: float) -> int:
    if not math.isfinite(v):
        return 0
    return int(max(-(2 ** 31), min(2 ** 31 - 1, round(v))))


def _finite(v: float) -> bool:
    return math.isfinite(v)


def _position(item: MissionItem, origin: GeodeticOrigin, home_z_m: float, required: bool = True,
              use_z: bool = True) -> tuple[float, float, float] | None:
    """ENU position [m] of a positional item, checked against the world's extent (``use_z`` False:
    the altitude is ignored and z is 0, as for fence vertices)."""
    seq = item.seq
    if item.frame not in POSITION_FRAMES:
        raise ItemError(mav.MAV_MISSION_UNSUPPORTED_FRAME, seq,
                        f"frame {item.frame} not supported (use 0/5 AMSL or 3/6 relative altitude)")
    ll = item.latlon_deg()
    if ll is None:
        if required:
            raise ItemError(mav.MAV_MISSION_INVALID_PARAM5_X, seq, "latitude/longitude missing (0 or NaN)")
        return None
    lat, lon = ll
    if not -90.0 <= lat <= 90.0:
        raise ItemError(mav.MAV_MISSION_INVALID_PARAM5_X, seq, f"latitude {lat} outside [-90, 90]")
    if not -180.0 <= lon <= 180.0:
        raise ItemError(mav.MAV_MISSION_INVALID_PARAM6_Y, seq, f"longitude {lon} outside [-180, 180]")
    if not use_z:
        z = 0.0
    elif not _finite(item.z):
        raise ItemError(mav.MAV_MISSION_INVALID_PARAM7, seq, "altitude is NaN or infinite")
    else:
        z = home_z_m + float(item.z) if item.frame in RELATIVE_FRAMES else float(item.z) - origin.alt_m
    e, n, _ = geodetic_to_enu(lat, lon, origin.alt_m, origin)
    e, n = float(e), float(n)
    if abs(n) > MAX_XY_M:
        raise ItemError(mav.MAV_MISSION_INVALID_PARAM5_X, seq,
                        f"latitude {lat:.7f} is {n / 1000:.1f} km north of the world origin"
                        f" (limit {MAX_XY_M / 1000:g} km)")
    if abs(e) > MAX_XY_M:
        raise ItemError(mav.MAV_MISSION_INVALID_PARAM6_Y, seq,
                        f"longitude {lon:.7f} is {e / 1000:.1f} km east of the world origin"
                        f" (limit {MAX_XY_M / 1000:g} km)")
    if not MIN_Z_M <= z <= MAX_Z_M:
        raise ItemError(mav.MAV_MISSION_INVALID_PARAM7, seq,
                        f"altitude gives height {z:.1f} m, outside [{MIN_Z_M:g}, {MAX_Z_M:g}] m")
    return e, n, z


def _duration(item: MissionItem, what: str) -> float:
    p1 = item.param1
    if not _finite(p1) or not 0.0 <= p1 <= MAX_WAIT_S:
        raise ItemError(mav.MAV_MISSION_INVALID_PARAM1, item.seq, f"{what} {p1} s outside [0, {MAX_WAIT_S:g}] s")
    return float(p1)


@dataclass(frozen=True)
class StepSeqs:
    """Which items a mission step came from: ``first``..``last`` (inclusive; DO items belong to the step
    before them, leading ones to the first step) and its NAV items in order as (seq, ENU target or None)."""

    first: int
    last: int
    nav: tuple[tuple[int, tuple[float, float, float] | None], ...]


@dataclass(frozen=True)
class MissionPlan:
    """An accepted mission list: the MissionSpec (None when no item makes a step) and the step table."""

    spec: MissionSpec | None
    steps: tuple[StepSeqs, ...]
    count: int

    def step_of_seq(self, seq: int) -> int | None:
        """The step containing item ``seq`` (None for a seq out of range or a list without steps)."""
        for i, s in enumerate(self.steps):
            if s.first <= seq <= s.last:
                return i
        return None


def _speed(value: float, cap: float, item: MissionItem, what: str) -> float:
    if not 0.0 < value <= cap:
        raise ItemError(mav.MAV_MISSION_INVALID_PARAM2, item.seq, f"{what} speed {value} m/s outside (0, {cap:g}]")
    return float(value)


def _clamped_default(params: Mapping[str, float] | None, name: str, default: float, cap: float) -> float:
    v = (params or {}).get(name)
    if v is None or not math.isfinite(v) or v <= 0.0:
        return default
    return float(min(v, cap))


def build_mission(items: Sequence[MissionItem], origin: GeodeticOrigin, home_z_m: float = 0.0,
                  params: Mapping[str, float] | None = None) -> MissionPlan:
    """Validate a mission list and map it onto a MissionSpec (see the module docstring).

    home_z_m : height of home [m ENU] for relative-altitude frames
    params : flight parameters; MPC_XY_CRUISE / MPC_Z_V_AUTO_UP / MPC_Z_V_AUTO_DN give the mission's
        default speeds (capped by the mission schema)
    Raises ItemError.
    """
    if len(items) > MAX_ITEMS:
        raise ItemError(mav.MAV_MISSION_NO_SPACE, len(items) - 1, f"{len(items)} items, at most {MAX_ITEMS}")
    steps: list[MissionStep] = []
    starts: list[int] = []
    navs: list[list[tuple[int, tuple[float, float, float] | None]]] = []
    cruise: list[Waypoint] = []
    cruise_navs: list[tuple[int, tuple[float, float, float] | None]] = []
    cruise_first = -1
    speed = {"cruise": None, "climb": None, "descent": None}
    last_pos: tuple[float, float, float] | None = None

    def add(step: MissionStep, first: int, nav: list[tuple[int, tuple[float, float, float] | None]]) -> None:
        steps.append(step)
        starts.append(first)
        navs.append(nav)

    def flush_cruise(wait_after: float = 0.0) -> None:
        nonlocal cruise, cruise_navs, cruise_first
        if cruise:
            add(MissionStep(type="cruise", waypoints=list(cruise), wait_after=wait_after), cruise_first, cruise_navs)
        cruise, cruise_navs, cruise_first = [], [], -1

    for expected, it in enumerate(items):
        if it.seq != expected:
            raise ItemError(mav.MAV_MISSION_INVALID_SEQUENCE, it.seq, f"item {it.seq} where {expected} was expected")
        cmd = it.command
        if cmd in (NAV_WAYPOINT, NAV_LOITER_TIME):
            pos = _position(it, origin, home_z_m, required=cmd == NAV_WAYPOINT)
            hold = _duration(it, "hold time") if cmd == NAV_LOITER_TIME or _finite(it.param1) else 0.0
            if pos is None:                       # NAV_LOITER_TIME without a position: wait where it is
                flush_cruise()
                add(MissionStep(type="idle", duration_s=hold), it.seq, [(it.seq, None)])
                continue
            yaw_deg = None
            if cmd == NAV_WAYPOINT and _finite(it.param4):
                if not -360.0 <= it.param4 <= 360.0:
                    raise ItemError(mav.MAV_MISSION_INVALID_PARAM4, it.seq, f"yaw {it.param4} deg outside [-360, 360]")
                yaw_deg = math.degrees(float(yaw_ned_to_enu_rad(math.radians(it.param4))))
            if len(cruise) >= MAX_WAYPOINTS:
                flush_cruise()
            if not cruise:
                cruise_first = it.seq
            cruise.append(Waypoint(x=pos[0], y=pos[1], z=pos[2], yaw_deg=yaw_deg, cruise_speed=speed["cruise"],
                                   climb_speed=speed["climb"], descent_speed=speed["descent"]))
            cruise_navs.append((it.seq, pos))
            last_pos = pos
            if hold > 0.0:
                flush_cruise(wait_after=hold)
        elif cmd == NAV_TAKEOFF:
            flush_cruise()
            pos = _position(it, origin, home_z_m, required=False)
            if pos is not None:
                add(MissionStep(type="takeoff", waypoints=[Waypoint(x=pos[0], y=pos[1], z=pos[2])]), it.seq,
                    [(it.seq, pos)])
                last_pos = pos
            else:
                if not _finite(it.z):
                    raise ItemError(mav.MAV_MISSION_INVALID_PARAM7, it.seq, "takeoff altitude is NaN or infinite")
                height = float(it.z) if it.frame in RELATIVE_FRAMES else float(it.z) - origin.alt_m - home_z_m
                if not 0.0 < height <= MAX_Z_M:
                    raise ItemError(mav.MAV_MISSION_INVALID_PARAM7, it.seq,
                                    f"takeoff altitude gives {height:.1f} m above home, need (0, {MAX_Z_M:g}]")
                add(MissionStep(type="takeoff", altitude_m=height), it.seq, [(it.seq, None)])
        elif cmd == NAV_LAND:
            flush_cruise()
            pos = _position(it, origin, home_z_m, required=False)
            wps = [Waypoint(x=pos[0], y=pos[1], z=max(pos[2], last_pos[2] if last_pos else pos[2]))] if pos else []
            add(MissionStep(type="land", waypoints=wps), it.seq, [(it.seq, pos)])
            if pos is not None:
                last_pos = pos
        elif cmd == NAV_RETURN_TO_LAUNCH:
            if "return" not in mission_spec.STEP_TYPES:
                raise ItemError(mav.MAV_MISSION_UNSUPPORTED, it.seq,
                                "NAV_RETURN_TO_LAUNCH needs the mission 'return' step, not in this build")
            flush_cruise()
            add(MissionStep(type="return"), it.seq, [(it.seq, None)])
        elif cmd in (NAV_DELAY, NAV_LOITER_UNLIM):
            flush_cruise()
            if cmd == NAV_DELAY:
                if _finite(it.param1) and it.param1 < 0:
                    raise ItemError(mav.MAV_MISSION_INVALID_PARAM1, it.seq,
                                    "NAV_DELAY until a time of day (p1 = -1) is not supported")
                duration = _duration(it, "delay")
            else:
                duration = MAX_WAIT_S
            add(MissionStep(type="idle", duration_s=duration), it.seq, [(it.seq, None)])
        elif cmd == DO_CHANGE_SPEED:
            kind = it.param1
            which = {0.0: "cruise", 1.0: "cruise", 2.0: "climb", 3.0: "descent"}.get(kind) if _finite(kind) else None
            if which is None:
                raise ItemError(mav.MAV_MISSION_INVALID_PARAM1, it.seq,
                                f"speed type {kind} (expected 0/1 horizontal, 2 climb, 3 descent)")
            value = it.param2
            if not _finite(value) or value == -1.0:
                pass                                                   # no change (PX4: -1)
            elif value == -2.0:
                speed[which] = None                                    # back to the mission's default
            else:
                cap = {"cruise": MAX_CRUISE_SPEED_M_S, "climb": MAX_CLIMB_SPEED_M_S,
                       "descent": MAX_DESCENT_SPEED_M_S}[which]
                speed[which] = _speed(value, cap, it, which)
        elif cmd == DO_GRIPPER:
            action = it.param2
            if action not in (0.0, 1.0):
                raise ItemError(mav.MAV_MISSION_INVALID_PARAM2, it.seq,
                                f"gripper action {action} (expected 0 release, 1 grab)")
            flush_cruise()
            wps = [Waypoint(x=last_pos[0], y=last_pos[1], z=last_pos[2])] if last_pos is not None else []
            add(MissionStep(type="pickup" if action == 1.0 else "deliver", waypoints=wps), it.seq, [])
        elif cmd in NOOP_COMMANDS:
            pass
        else:
            name = mav.enums["MAV_CMD"][cmd].name if cmd in mav.enums["MAV_CMD"] else str(cmd)
            raise ItemError(mav.MAV_MISSION_UNSUPPORTED, it.seq, f"command {name} ({cmd}) not supported in missions")
        if len(steps) > MAX_MISSION_STEPS:
            raise ItemError(mav.MAV_MISSION_NO_SPACE, it.seq, f"more than {MAX_MISSION_STEPS} mission steps")
    flush_cruise()
    if not steps:
        return MissionPlan(spec=None, steps=(), count=len(items))
    starts[0] = 0
    table = tuple(StepSeqs(first=starts[i], last=(starts[i + 1] - 1 if i + 1 < len(steps) else len(items) - 1),
                           nav=tuple(navs[i])) for i in range(len(steps)))
    spec = MissionSpec(name="mavlink",
                       cruise_speed=_clamped_default(params, "MPC_XY_CRUISE", 5.0, MAX_CRUISE_SPEED_M_S),
                       climb_speed=_clamped_default(params, "MPC_Z_V_AUTO_UP", 3.0, MAX_CLIMB_SPEED_M_S),
                       descent_speed=_clamped_default(params, "MPC_Z_V_AUTO_DN", 1.5, MAX_DESCENT_SPEED_M_S),
                       steps=steps)
    return MissionPlan(spec=spec, steps=table, count=len(items))


def _check_sequence(items: Sequence[MissionItem]) -> None:
    if len(items) > MAX_ITEMS:
        raise ItemError(mav.MAV_MISSION_NO_SPACE, len(items) - 1, f"{len(items)} items, at most {MAX_ITEMS}")
    for expected, it in enumerate(items):
        if it.seq != expected:
            raise ItemError(mav.MAV_MISSION_INVALID_SEQUENCE, it.seq, f"item {it.seq} where {expected} was expected")


def build_geofence(items: Sequence[MissionItem], origin: GeodeticOrigin, home_z_m: float = 0.0) -> Geofence | None:
    """Validate fence items (5001–5004) and build the Geofence (None for an empty list). Raises ItemError."""
    _check_sequence(items)
    if not items:
        return None
    polys: dict[int, list[np.ndarray]] = {FENCE_POLYGON_INCLUSION: [], FENCE_POLYGON_EXCLUSION: []}
    circles: dict[int, list[tuple[float, float, float]]] = {FENCE_CIRCLE_INCLUSION: [], FENCE_CIRCLE_EXCLUSION: []}
    i = 0
    while i < len(items):
        it = items[i]
        if it.command in polys:
            n = it.param1
            if not _finite(n) or n != int(n) or n < 3:
                raise ItemError(mav.MAV_MISSION_INVALID_PARAM1, it.seq,
                                f"polygon vertex count {n} (need an integer >= 3)")
            n = int(n)
            run = items[i:i + n]
            if len(run) < n or any(v.command != it.command or v.param1 != it.param1 for v in run):
                bad = next((v.seq for v in run if v.command != it.command or v.param1 != it.param1),
                           items[-1].seq)
                raise ItemError(mav.MAV_MISSION_INVALID_PARAM1, bad,
                                f"polygon from item {it.seq} announces {n} vertices; fewer follow")
            verts = [_position(v, origin, home_z_m, use_z=False)[:2] for v in run]
            polys[it.command].append(np.array(verts, dtype=np.float64))
            i += n
        elif it.command in circles:
            r = it.param1
            if not _finite(r) or not 0.0 < r <= 2.0 * MAX_XY_M:
                raise ItemError(mav.MAV_MISSION_INVALID_PARAM1, it.seq,
                                f"circle radius {r} m outside (0, {2 * MAX_XY_M:g}]")
            x, y, _ = _position(it, origin, home_z_m, use_z=False)
            circles[it.command].append((x, y, float(r)))
            i += 1
        else:
            raise ItemError(mav.MAV_MISSION_UNSUPPORTED, it.seq,
                            f"command {it.command} is not a fence item (5001-5004)")
    return Geofence(inclusion_polygons=tuple(polys[FENCE_POLYGON_INCLUSION]),
                    exclusion_polygons=tuple(polys[FENCE_POLYGON_EXCLUSION]),
                    inclusion_circles=tuple(circles[FENCE_CIRCLE_INCLUSION]),
                    exclusion_circles=tuple(circles[FENCE_CIRCLE_EXCLUSION]))


def build_rally(items: Sequence[MissionItem], origin: GeodeticOrigin,
                home_z_m: float = 0.0) -> tuple[tuple[float, float, float], ...]:
    """Validate rally items (5100) and return their ENU positions [m]. Raises ItemError."""
    _check_sequence(items)
    points = []
    for it in items:
        if it.command != RALLY_POINT:
            raise ItemError(mav.MAV_MISSION_UNSUPPORTED, it.seq, f"command {it.command} is not a rally point (5100)")
        points.append(_position(it, origin, home_z_m))
    return tuple(points)


__all__ = ["MAX_ITEMS", "NAV_COMMANDS", "NOOP_COMMANDS", "ItemError", "MissionItem", "MissionPlan", "StepSeqs",
           "build_geofence", "build_mission", "build_rally"]
