"""PX4-style navigation on the flight stack: land detector, home, TAKEOFF / LAND / RTL, auto-disarm
(docs/architecture.md §7).

Two systems:

- :class:`LandDetectorSystem` (STATE) writes ``landed_state`` from the physics, as PX4's multicopter
  land detector does: ON_GROUND once the drone (or the package it carries) touches something and moves
  slower than LNDMC_Z_VEL_MAX vertically, LNDMC_XY_VEL_MAX horizontally and turns slower than
  LNDMC_ROT_MAX, held for :data:`LAND_TRIGGER_S`; otherwise IN_AIR, reported as TAKEOFF or LANDING while
  the navigator (or the mission step) is taking off or landing.
- :class:`NavigatorSystem` (MISSION, after the mission) sets home at the first position fix, advances
  TAKEOFF, LAND and RTL, and disarms a drone COM_DISARM_LAND seconds after it landed, or
  COM_DISARM_PRFLT seconds after arming when it never took off (not while a mission runs: a mission
  arms and disarms the drone itself).

The modes are started by commands (:mod:`.flight_commands`) and by the mission's ``return`` step through
:func:`start_takeoff`, :func:`start_land` and :func:`start_rtl`; each turns the mode into a route flown
by the AUTO path, with PX4's parameters (:mod:`unetyemu_ecs.navigation.params`) for speeds and heights.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from itertools import compress
from typing import Any

import esper
import numpy as np

from ..components.body import FleetSlot, Identity, RigidBody
from ..components.flight import EnergyModel, GuidanceLimits, PayloadBay
from ..components.mission import MissionRuntime
from ..control.compiled import jit
from ..navigation.params import FlightParams, FlightParamsSpec, params_from_spec
from ..navigation.state import NavRuntime
from ..phases import Phase
from ..transport.api import CommandStatus
from ..world import StepContext
from .commands import Refusal
from .fleet_system import FleetSystem
from .flight_state import (LANDED_IN_AIR, LANDED_ON_GROUND, LANDED_UNDEFINED, MISSION_RUNNING, MODE_DISARMED,
                           NAV_MANUAL, NAV_MISSION, NAV_OFFBOARD, NAV_POSCTL, NAV_TAKEOFF, ArmBlock, FlightMode,
                           LandedState, MissionState, NavState, Route, set_route)
from .row_counts import count_true

_NOTHING: frozenset[int] = frozenset()
# by nav_state (int8 in FLIGHT_ARRAYS, read as uint8): flown from a stream or sticks (OFFBOARD, POSCTL, MANUAL)
_STREAM_OR_STICKS = np.zeros(256, dtype=bool)
_STREAM_OR_STICKS[[NAV_OFFBOARD, NAV_POSCTL, NAV_MANUAL]] = True
LAND_TRIGGER_S = 0.3        # the land-detector conditions must hold this long (PX4 LandDetector trigger time)
LAND_BELOW_M = 0.3          # a landing aims this far below the resting height, so touchdown happens
TAKEOFF_DONE_M = 0.3        # TAKEOFF is done within this height of its altitude
GOAL_DONE_M = 1.0           # an RTL leg is done within this distance of its end
BRAKE_ACC_M_S2 = 3.0        # HOLD stops where braking at this deceleration ends (PX4 MPC_ACC_HOR default)


# -- components ------------------------------------------------------------------------------
def ensure_nav(ent: int) -> tuple[NavRuntime, FlightParams]:
    """The drone's navigator state and flight parameters (created with the defaults on first use)."""
    nav = esper.try_component(ent, NavRuntime)
    if nav is None:
        nav = NavRuntime()
        esper.add_component(ent, nav)
    params = esper.try_component(ent, FlightParams)
    if params is None:
        params = params_from_spec(esper.try_component(ent, FlightParamsSpec))
        esper.add_component(ent, params)
    return nav, params


def ensure_all_drones() -> None:
    """Give every drone (every entity with GuidanceLimits) its NavRuntime and FlightParams."""
    missing = [ent for ent, _ in esper.get_components(GuidanceLimits)
               if not (esper.has_component(ent, NavRuntime) and esper.has_component(ent, FlightParams))]
    for ent in missing:
        ensure_nav(ent)


# -- mode starts (called by the command system and the mission) -------------------------------
def _speeds(ent: int, params: FlightParams, nav: NavRuntime, *, climb: float | None = None,
            descent: float | None = None) -> tuple[float, float, float]:
    """(cruise, climb, descent) of an automatic leg: MPC_XY_CRUISE, MPC_Z_V_AUTO_UP/DN (or the given
    ones), ChangeSpeed overrides, within the drone's guidance limits."""
    lim = esper.component_for_entity(ent, GuidanceLimits)
    cruise = nav.speeds.get("ground", params["MPC_XY_CRUISE"])
    up = climb if climb is not None else nav.speeds.get("climb", params["MPC_Z_V_AUTO_UP"])
    down = descent if descent is not None else nav.speeds.get("descent", params["MPC_Z_V_AUTO_DN"])
    return float(cruise), float(min(up, lim.lim_climb_m_s)), float(min(down, lim.lim_descent_m_s))


def _route(points: list[np.ndarray], speeds: list[tuple[float, float, float]], yaw: float = math.nan) -> Route:
    return Route(np.array(points, dtype=float), np.array(speeds, dtype=float), float(yaw))


def _set_mode(nav: NavRuntime, mode: str, phase: str, t: float, goal: np.ndarray | None) -> None:
    nav.mode, nav.phase, nav.phase_started_s, nav.goal_enu_m = mode, phase, t, goal


def hold(ctx: StepContext, ent: int, row: int) -> None:
    """HOLD: brake and hover where the drone is (stay put on the ground); ends any navigator mode."""
    f = ctx.fleet
    nav, _ = ensure_nav(ent)
    _set_mode(nav, "", "", ctx.sim_time_s, None)
    f.nav_state[row] = NavState.HOLD
    if f.flight_mode[row] == FlightMode.DISARMED:
        return
    brake_and_hold(f, row)


def brake_and_hold(f: Any, row: int) -> None:
    """AUTO on a route from here to where braking at BRAKE_ACC_M_S2 stops the drone: it stops and stays there."""
    f.flight_mode[row] = FlightMode.AUTO
    pos = f.pos_enu_m[row].copy()
    vel = f.vel_enu_m_s[row]
    stop = pos + np.array([*(vel[:2] * np.hypot(vel[0], vel[1]) / (2.0 * BRAKE_ACC_M_S2)), 0.0])
    sp = (1.0, 1.0, 1.0)
    set_route(f, row, _route([pos, stop], [sp, sp]))


def start_takeoff(ctx: StepContext, ent: int, row: int, alt_enu_m: float | None, yaw_rad: float | None) -> None:
    """TAKEOFF: climb straight up at MPC_TKO_SPEED to ``alt_enu_m`` (None: home + MIS_TAKEOFF_ALT), then HOLD."""
    f = ctx.fleet
    nav, params = ensure_nav(ent)
    pos = f.pos_enu_m[row].copy()
    if alt_enu_m is None:
        base = f.home_enu_m[row, 2] if f.home_set[row] else pos[2]
        alt_enu_m = float(base + params["MIS_TAKEOFF_ALT"])
    goal = np.array([pos[0], pos[1], alt_enu_m])
    sp = _speeds(ent, params, nav, climb=params["MPC_TKO_SPEED"])
    f.flight_mode[row] = FlightMode.AUTO
    set_route(f, row, _route([pos, goal], [sp, sp], math.nan if yaw_rad is None else yaw_rad))
    _set_mode(nav, "takeoff", "climb", ctx.sim_time_s, goal)
    f.nav_state[row] = NavState.TAKEOFF
    ctx.services.note(ctx.sim_time_s, _name(ent), f"takeoff to z = {alt_enu_m:.1f} m")


def _touchdown_z(ctx: StepContext, ent: int, row: int, x: float, y: float) -> tuple[float, float]:
    """(surface height under (x, y), the resting height of the drone's centre there) [m]."""
    body = esper.component_for_entity(ent, RigidBody)
    below = float(body.half_extents_m[2]) + _carried_height(ctx, row)
    surface = float(ctx.services.layout.surface_height_m(x, y))
    return surface, surface + below


def land_route(ctx: StepContext, ent: int, row: int, xy: np.ndarray | None) -> tuple[Route, np.ndarray]:
    """A landing at ``xy`` (None: straight below): there at cruise, down at MPC_Z_V_AUTO_DN to MPC_LAND_ALT2
    above the surface, then at MPC_LAND_SPEED to a point LAND_BELOW_M under the resting height."""
    f = ctx.fleet
    nav, params = ensure_nav(ent)
    pos = f.pos_enu_m[row].copy()
    xy = pos[:2].copy() if xy is None else np.asarray(xy, dtype=float)
    surface, rest = _touchdown_z(ctx, ent, row, float(xy[0]), float(xy[1]))
    fast = _speeds(ent, params, nav)
    slow = _speeds(ent, params, nav, descent=params["MPC_LAND_SPEED"])
    pts, sps = [pos], [fast]
    if np.hypot(*(xy - pos[:2])) > GOAL_DONE_M:
        pts.append(np.array([xy[0], xy[1], max(pos[2], rest + 2.0)]))
        sps.append(fast)
    slow_z = rest + params["MPC_LAND_ALT2"]
    if pts[-1][2] > slow_z + 0.2:
        # speeds are interpolated between route points: a 5 cm step makes the change at MPC_LAND_ALT2 sharp
        pts += [np.array([xy[0], xy[1], slow_z]), np.array([xy[0], xy[1], slow_z - 0.05])]
        sps += [fast, slow]
    goal = np.array([xy[0], xy[1], rest - LAND_BELOW_M])
    pts.append(goal)
    sps.append(slow)
    sps[0] = sps[1]
    return _route(pts, sps), goal


def start_land(ctx: StepContext, ent: int, row: int, xy: np.ndarray | None, *, mode: str = "land") -> None:
    """LAND at ``xy`` (None: here); touchdown is the land detector's ON_GROUND; disarm after COM_DISARM_LAND."""
    f = ctx.fleet
    nav, _ = ensure_nav(ent)
    route, goal = land_route(ctx, ent, row, xy)
    f.flight_mode[row] = FlightMode.AUTO
    set_route(f, row, route)
    _set_mode(nav, mode, "land", ctx.sim_time_s, goal)
    if mode == "land":
        f.nav_state[row] = NavState.LAND
    ctx.services.note(ctx.sim_time_s, _name(ent), f"landing at ({goal[0]:.1f}, {goal[1]:.1f})")


def rtl_destination(f: Any, row: int, nav: NavRuntime) -> np.ndarray:
    """RTL_TYPE 0: the closest of home and the rally points (horizontal distance)."""
    home = f.home_enu_m[row].copy() if f.home_set[row] else f.pos_enu_m[row].copy()
    best = home
    here = f.pos_enu_m[row, :2]
    for p in nav.rally_enu_m:
        p = np.asarray(p, dtype=float)
        if np.hypot(*(p[:2] - here)) < np.hypot(*(best[:2] - here)):
            best = p
    return best


def start_rtl(ctx: StepContext, ent: int, row: int, *, nav_state: int = NavState.RTL) -> None:
    """RTL: climb to RTL_RETURN_ALT above the destination (or stay higher), fly there at MPC_XY_CRUISE,
    descend to RTL_DESCEND_ALT, wait RTL_LAND_DELAY (-1: hover there), land."""
    f = ctx.fleet
    nav, params = ensure_nav(ent)
    dest = rtl_destination(f, row, nav)
    pos = f.pos_enu_m[row].copy()
    return_z = max(pos[2], dest[2] + params["RTL_RETURN_ALT"])
    descend_z = min(return_z, dest[2] + params["RTL_DESCEND_ALT"])
    sp = _speeds(ent, params, nav)
    pts = [pos]
    if return_z > pos[2] + 0.1:
        pts.append(np.array([pos[0], pos[1], return_z]))
    if np.hypot(*(dest[:2] - pos[:2])) > GOAL_DONE_M:
        pts.append(np.array([dest[0], dest[1], return_z]))
    end = np.array([dest[0], dest[1], descend_z])
    if np.linalg.norm(end - pts[-1]) > 0.1 or len(pts) == 1:
        pts.append(end)
    f.flight_mode[row] = FlightMode.AUTO
    set_route(f, row, _route(pts, [sp] * len(pts)))
    _set_mode(nav, "rtl", "return", ctx.sim_time_s, pts[-1])
    f.nav_state[row] = nav_state
    ctx.services.note(ctx.sim_time_s, _name(ent),
                      f"returning to ({dest[0]:.1f}, {dest[1]:.1f}) at z = {return_z:.1f} m")


def disarm(ctx: StepContext, ent: int, row: int, why: str) -> None:
    """Motors off (flight_mode DISARMED), route cleared, HOLD; ``why`` goes to the event log."""
    f = ctx.fleet
    nav, _ = ensure_nav(ent)
    f.flight_mode[row] = FlightMode.DISARMED
    set_route(f, row, None)
    f.nav_state[row] = NavState.HOLD
    _set_mode(nav, "", "", ctx.sim_time_s, None)
    nav.armed_s, nav.took_off = math.nan, False
    ctx.services.note(ctx.sim_time_s, _name(ent), f"disarmed: {why}")


def _name(ent: int) -> str:
    return esper.component_for_entity(ent, Identity).name


def _carried_height(ctx: StepContext, row: int) -> float:
    package = int(ctx.fleet.payload_entity[row])
    if package < 0:
        return 0.0
    return float(2.0 * esper.component_for_entity(package, RigidBody).half_extents_m[2])


def _mission_step_type(ent: int) -> str:
    rt = esper.try_component(ent, MissionRuntime)
    if rt is None or rt.state != "running":
        return ""
    return rt.spec.steps[rt.step_index].type


# -- OFFBOARD ----------------------------------------------------------------------------------
OFFBOARD_YAW_GAIN = 2.0     # [1/s] heading error -> yaw rate while an OFFBOARD setpoint holds a heading


def offboard_fresh(nav: NavRuntime, params: FlightParams, t: float) -> bool:
    """An OFFBOARD setpoint arrived within the last COM_OF_LOSS_T seconds."""
    return nav.offboard is not None and t - nav.offboard_s <= params["COM_OF_LOSS_T"] + 1e-9


def fly_offboard(ctx: StepContext, ent: int, row: int, nav: NavRuntime, params: FlightParams, new: bool) -> None:
    """Fly the newest OFFBOARD setpoint: a position on the AUTO path (re-planned when a new one arrives), a
    velocity (ENU, turned into body FLU with the heading every step, or body FLU) on the VELOCITY path,
    an attitude with a collective thrust on the ATTITUDE path (straight to the attitude layer); a heading
    through a yaw-rate loop, or a yaw rate."""
    from ..frames import yaw_rad_from_quat_xyzw

    f = ctx.fleet
    sp = nav.offboard
    if f.flight_mode[row] == FlightMode.DISARMED or sp is None:
        return
    yaw = float(yaw_rad_from_quat_xyzw(f.quat_enu_flu_xyzw[row]))
    if sp.attitude_rp_rad is not None:
        if f.flight_mode[row] != FlightMode.ATTITUDE:
            f.flight_mode[row] = FlightMode.ATTITUDE
            set_route(f, row, None)
        f.roll_sp_rad[row], f.pitch_sp_rad[row] = sp.attitude_rp_rad
        f.thrust_cmd_frac[row] = sp.thrust_frac
        if sp.yaw_rate_rad_s is not None:
            f.yaw_rate_sp_rad_s[row] = sp.yaw_rate_rad_s
        elif sp.yaw_rad is not None:
            f.yaw_rate_sp_rad_s[row] = _yaw_rate_to(sp.yaw_rad, yaw, params)
        else:
            f.yaw_rate_sp_rad_s[row] = 0.0
        return
    if sp.pos_enu_m is not None:
        if new or f.flight_mode[row] != FlightMode.AUTO:
            lim = esper.component_for_entity(ent, GuidanceLimits)
            speeds = (params["MPC_XY_VEL_MAX"] or lim.cruise_speed_m_s,
                      min(params["MPC_Z_V_AUTO_UP"], lim.lim_climb_m_s),
                      min(params["MPC_Z_V_AUTO_DN"], lim.lim_descent_m_s))
            pos = f.pos_enu_m[row].copy()
            yaw_sp = sp.yaw_rad if sp.yaw_rad is not None else math.nan
            f.flight_mode[row] = FlightMode.AUTO
            set_route(f, row, _route([pos, np.asarray(sp.pos_enu_m, dtype=float)], [speeds, speeds], yaw_sp))
        return
    if f.flight_mode[row] != FlightMode.VELOCITY:
        f.flight_mode[row] = FlightMode.VELOCITY
        set_route(f, row, None)
    if sp.vel_flu_m_s is not None:
        f.vel_cmd_flu_m_s[row] = sp.vel_flu_m_s
    elif sp.vel_enu_m_s is not None:
        ve, vn, vu = sp.vel_enu_m_s
        c, s_ = math.cos(yaw), math.sin(yaw)
        f.vel_cmd_flu_m_s[row] = (c * ve + s_ * vn, -s_ * ve + c * vn, vu)
    else:
        f.vel_cmd_flu_m_s[row] = 0.0
    max_rate = math.radians(params["MPC_YAWRAUTO_MAX"])
    if sp.yaw_rate_rad_s is not None:
        f.yaw_rate_cmd_rad_s[row] = sp.yaw_rate_rad_s
    elif sp.yaw_rad is not None:
        err = (sp.yaw_rad - yaw + math.pi) % (2 * math.pi) - math.pi
        f.yaw_rate_cmd_rad_s[row] = float(np.clip(OFFBOARD_YAW_GAIN * err, -max_rate, max_rate))
    else:
        f.yaw_rate_cmd_rad_s[row] = 0.0


def failsafe_action(ctx: StepContext, ent: int, row: int, what: str, why: str) -> None:
    """Carry out a failsafe: ``what`` is "return" (RTL), "land", "terminate" or "disarm" (motors off,
    ``why`` in the event), or "hold"."""
    if what == "return":
        start_rtl(ctx, ent, row)
    elif what == "land":
        start_land(ctx, ent, row, None)
    elif what in ("terminate", "disarm"):
        disarm(ctx, ent, row, f"{why} ({what})")
    else:
        hold(ctx, ent, row)


def offboard_lost(ctx: StepContext, ent: int, row: int, nav: NavRuntime, params: FlightParams) -> None:
    """The OFFBOARD stream lapsed (COM_OF_LOSS_T): COM_OBL_RC_ACT's failsafe (0, 1, 2, 5 hold; 3 return;
    4 land; 6 terminate; 7 disarm, when on the ground, else hold)."""
    f = ctx.fleet
    action = int(params["COM_OBL_RC_ACT"])
    nav.offboard = None
    name = _name(ent)
    on_ground = f.landed_state[row] == LandedState.ON_GROUND
    what = {3: "return", 4: "land", 6: "terminate", 7: "disarm"}.get(action, "hold")
    if what == "disarm" and not on_ground:
        what = "hold"
    if what == "return" and on_ground:
        what = "hold"
    ctx.services.note(ctx.sim_time_s, name, f"failsafe: offboard setpoints lost for {params['COM_OF_LOSS_T']:g} s "
                                            f"(COM_OF_LOSS_T): {what} (COM_OBL_RC_ACT {action})")
    failsafe_action(ctx, ent, row, what, "offboard loss failsafe")


# -- POSCTL / MANUAL from ManualControl sticks ------------------------------------------------------
STICK_DEADZONE = 0.05       # sticks within this of centre are centred (POSCTL then holds position)


def manual_fresh(nav: NavRuntime, params: FlightParams, t: float) -> bool:
    """Sticks (ManualControl) arrived within the last COM_RC_LOSS_T seconds."""
    return nav.manual is not None and t - nav.manual_s <= params["COM_RC_LOSS_T"] + 1e-9


def _set_flu_velocity(f: Any, row: int, v_enu: np.ndarray) -> float:
    """VELOCITY path: world velocity ``v_enu`` turned into body FLU with the current heading; returns the heading."""
    from ..frames import yaw_rad_from_quat_xyzw

    yaw = float(yaw_rad_from_quat_xyzw(f.quat_enu_flu_xyzw[row]))
    c, s_ = math.cos(yaw), math.sin(yaw)
    f.vel_cmd_flu_m_s[row] = (c * v_enu[0] + s_ * v_enu[1], -s_ * v_enu[0] + c * v_enu[1], v_enu[2])
    if f.flight_mode[row] != FlightMode.VELOCITY:
        f.flight_mode[row] = FlightMode.VELOCITY
        set_route(f, row, None)
    return yaw


def _yaw_rate_to(yaw_sp: float, yaw: float, params: FlightParams) -> float:
    err = (yaw_sp - yaw + math.pi) % (2 * math.pi) - math.pi
    max_rate = math.radians(params["MPC_YAWRAUTO_MAX"])
    return float(np.clip(OFFBOARD_YAW_GAIN * err, -max_rate, max_rate))


def fly_manual(ctx: StepContext, row: int, nav: NavRuntime, params: FlightParams) -> None:
    """MANUAL: the sticks are the stabilizer's (throttle = climb rate, pitch/roll = tilt, yaw = turn rate).
    POSCTL: pitch/roll command horizontal speed up to MPC_XY_VEL_MAX, throttle climb/descent at
    MPC_Z_V_AUTO_UP/DN, yaw turn rate up to MPC_YAWRAUTO_MAX; centred sticks brake and hold position."""
    f = ctx.fleet
    mc = nav.manual
    if f.flight_mode[row] == FlightMode.DISARMED or mc is None:
        return
    thr = 2.0 * mc.throttle - 1.0
    if f.nav_state[row] == NavState.MANUAL:
        f.flight_mode[row] = FlightMode.MANUAL
        f.stick[row] = (thr, mc.pitch, mc.roll, -mc.yaw)
        return
    if max(abs(thr), abs(mc.pitch), abs(mc.roll), abs(mc.yaw)) < STICK_DEADZONE:
        if f.flight_mode[row] != FlightMode.AUTO:
            brake_and_hold(f, row)
        return
    vmax = params["MPC_XY_VEL_MAX"]
    up = thr * (params["MPC_Z_V_AUTO_UP"] if thr >= 0.0 else params["MPC_Z_V_AUTO_DN"])
    _set_flu_velocity(f, row, np.zeros(3))
    f.vel_cmd_flu_m_s[row] = (mc.pitch * vmax, -mc.roll * vmax, up)
    f.yaw_rate_cmd_rad_s[row] = -mc.yaw * math.radians(params["MPC_YAWRAUTO_MAX"])


def manual_lost(ctx: StepContext, ent: int, row: int, nav: NavRuntime, params: FlightParams) -> None:
    """Sticks lost for COM_RC_LOSS_T: HOLD now; NAV_RCL_ACT after COM_FAIL_ACT_T more (PX4's order)."""
    f = ctx.fleet
    was = int(f.nav_state[row])
    ctx.services.note(ctx.sim_time_s, _name(ent), f"failsafe: manual control lost for {params['COM_RC_LOSS_T']:g} s "
                                                  f"(COM_RC_LOSS_T): holding, NAV_RCL_ACT in "
                                                  f"{params['COM_FAIL_ACT_T']:g} s")
    hold(ctx, ent, row)
    _set_mode(nav, "rc_lost", str(was), ctx.sim_time_s, None)


def _rc_lost_action(ctx: StepContext, ent: int, row: int, nav: NavRuntime, params: FlightParams) -> None:
    f = ctx.fleet
    action = int(params["NAV_RCL_ACT"])
    on_ground = f.landed_state[row] == LandedState.ON_GROUND
    what = {2: "return", 3: "land", 5: "terminate", 6: "disarm"}.get(action, "hold")
    if on_ground and what in ("return", "land"):
        what = "hold"
    ctx.services.note(ctx.sim_time_s, _name(ent), f"failsafe: manual control still lost: {what} "
                                                  f"(NAV_RCL_ACT {action})")
    _set_mode(nav, "", "", ctx.sim_time_s, None)
    if what != "hold":              # holding already since the sticks were lost
        failsafe_action(ctx, ent, row, what, "manual control loss failsafe")


# -- ORBIT -------------------------------------------------------------------------------------
ORBIT_RADIAL_GAIN = 1.0     # [1/s] radius error -> radial speed
Z_GAIN = 1.0                # [1/s] height error -> climb speed (orbit, follow target)


def start_orbit(ctx: StepContext, ent: int, row: int, orbit: Any) -> None:
    """ORBIT: circle ``orbit.center_enu_m`` at |radius| (> 0 clockwise seen from above) at ``speed_m_s``."""
    from ..frames import yaw_rad_from_quat_xyzw

    nav, _ = ensure_nav(ent)
    nav.orbit = orbit
    yaw0 = float(yaw_rad_from_quat_xyzw(ctx.fleet.quat_enu_flu_xyzw[row]))
    _set_mode(nav, "orbit", "circle", ctx.sim_time_s, np.array([*orbit.center_enu_m[:2], yaw0]))
    ctx.fleet.nav_state[row] = NavState.ORBIT
    c = orbit.center_enu_m
    ctx.services.note(ctx.sim_time_s, _name(ent), f"orbit around ({c[0]:.1f}, {c[1]:.1f}) at r = {orbit.radius_m:g} m")


def fly_orbit(ctx: StepContext, row: int, nav: NavRuntime, params: FlightParams) -> None:
    f = ctx.fleet
    o = nav.orbit
    c = np.asarray(o.center_enu_m, dtype=float)
    pos = f.pos_enu_m[row]
    rel = pos[:2] - c[:2]
    r = float(np.hypot(*rel))
    u = rel / r if r > 1e-3 else np.array([1.0, 0.0])
    tangent = np.array([u[1], -u[0]]) if o.radius_m > 0 else np.array([-u[1], u[0]])
    v_xy = o.speed_m_s * tangent + ORBIT_RADIAL_GAIN * (abs(o.radius_m) - r) * u
    vz = float(np.clip(Z_GAIN * (c[2] - pos[2]), -params["MPC_Z_V_AUTO_DN"], params["MPC_Z_V_AUTO_UP"]))
    yaw = _set_flu_velocity(f, row, np.array([v_xy[0], v_xy[1], vz]))
    behaviour = int(o.yaw_behaviour)
    if behaviour == 0:
        f.yaw_rate_cmd_rad_s[row] = _yaw_rate_to(math.atan2(-u[1], -u[0]), yaw, params)
    elif behaviour == 3:
        f.yaw_rate_cmd_rad_s[row] = _yaw_rate_to(math.atan2(tangent[1], tangent[0]), yaw, params)
    elif behaviour == 1:
        f.yaw_rate_cmd_rad_s[row] = _yaw_rate_to(float(nav.goal_enu_m[2]), yaw, params)
    else:
        f.yaw_rate_cmd_rad_s[row] = 0.0


# -- FOLLOW_TARGET -----------------------------------------------------------------------------
FOLLOW_LOST_S = 2.0         # no target fix for this long: hold (a documented choice; PX4 keeps its estimate)
FOLLOW_POS_GAIN = 0.8       # [1/s] follow-point error -> speed on top of the target's velocity


def follow_fresh(nav: NavRuntime, t: float) -> bool:
    return nav.follow is not None and t - nav.follow_s <= FOLLOW_LOST_S + 1e-9


def start_follow(ctx: StepContext, ent: int, row: int) -> None:
    nav, _ = ensure_nav(ent)
    _set_mode(nav, "follow", "follow", ctx.sim_time_s, None)
    nav.follow_sp_enu_m = None
    ctx.fleet.nav_state[row] = NavState.FOLLOW_TARGET
    ctx.services.note(ctx.sim_time_s, _name(ent), "following the target")


def fly_follow(ctx: StepContext, row: int, nav: NavRuntime, params: FlightParams) -> None:
    """Hold FLW_TGT_DST behind (FLW_TGT_FA clockwise from the target's course) at FLW_TGT_HT above home
    (FLW_TGT_ALT_M 2: above the target), filtered by FLW_TGT_RS, at most FLW_TGT_MAX_VEL faster than the
    target, facing it."""
    f = ctx.fleet
    t = ctx.sim_time_s
    fix = nav.follow
    tv = np.zeros(3) if fix.vel_enu_m_s is None else np.asarray(fix.vel_enu_m_s, dtype=float)
    tp = np.asarray(fix.pos_enu_m, dtype=float) + tv * (t - nav.follow_s)
    ang = nav.follow_course_rad - math.radians(params["FLW_TGT_FA"])
    base_z = tp[2] if int(params["FLW_TGT_ALT_M"]) == 2 else (f.home_enu_m[row, 2] if f.home_set[row] else 0.0)
    sp = np.array([tp[0] + params["FLW_TGT_DST"] * math.cos(ang), tp[1] + params["FLW_TGT_DST"] * math.sin(ang),
                   base_z + params["FLW_TGT_HT"]])
    if nav.follow_sp_enu_m is None:
        nav.follow_sp_enu_m = sp
    else:
        alpha = 1.0 - params["FLW_TGT_RS"] ** (ctx.dt_s / 0.1)
        nav.follow_sp_enu_m = nav.follow_sp_enu_m + alpha * (sp - nav.follow_sp_enu_m)
    pos = f.pos_enu_m[row]
    err = nav.follow_sp_enu_m - pos
    extra = FOLLOW_POS_GAIN * err[:2]
    norm = float(np.hypot(*extra))
    if norm > params["FLW_TGT_MAX_VEL"] > 0.0:
        extra *= params["FLW_TGT_MAX_VEL"] / norm
    vz = float(np.clip(Z_GAIN * err[2], -params["MPC_Z_V_AUTO_DN"], params["MPC_Z_V_AUTO_UP"]))
    yaw = _set_flu_velocity(f, row, np.array([tv[0] + extra[0], tv[1] + extra[1], vz]))
    to_target = tp[:2] - pos[:2]
    if np.hypot(*to_target) > 0.5:
        f.yaw_rate_cmd_rad_s[row] = _yaw_rate_to(math.atan2(to_target[1], to_target[0]), yaw, params)
    else:
        f.yaw_rate_cmd_rad_s[row] = 0.0


# -- geofence ----------------------------------------------------------------------------------
def fence_breach(f: Any, row: int, nav: NavRuntime, params: FlightParams) -> str:
    """Why the drone is outside its geofence (zones, GF_MAX_HOR_DIST, GF_MAX_VER_DIST from home), "" if inside
    or if the fence is disabled (MAV_CMD_DO_FENCE_ENABLE 0)."""
    if not nav.fence_enabled:
        return ""
    pos = f.pos_enu_m[row]
    if nav.fence is not None and not nav.fence.empty and not nav.fence.contains(pos):
        return "outside the fence zones"
    if f.home_set[row]:
        home = f.home_enu_m[row]
        hor, ver = params["GF_MAX_HOR_DIST"], params["GF_MAX_VER_DIST"]
        if hor > 0.0 and math.hypot(pos[0] - home[0], pos[1] - home[1]) > hor:
            return f"more than GF_MAX_HOR_DIST = {hor:g} m from home"
        if ver > 0.0 and pos[2] - home[2] > ver:
            return f"more than GF_MAX_VER_DIST = {ver:g} m above home"
    return ""


def enforce_fence(ctx: StepContext, ent: int, row: int, nav: NavRuntime, params: FlightParams) -> None:
    """On entering a breach: GF_ACTION (0 none, 1 warning, 2 hold, 3 return, 4 terminate, 5 land) and an event."""
    f = ctx.fleet
    why = fence_breach(f, row, nav, params)
    if not why:
        nav.fence_ok = True
        return
    if not nav.fence_ok:
        return
    nav.fence_ok = False
    action = int(params["GF_ACTION"])
    if action == 0:
        return
    what = {1: "warning", 2: "hold", 3: "return", 4: "terminate", 5: "land"}[action]
    ctx.services.note(ctx.sim_time_s, _name(ent), f"geofence breached ({why}): {what} (GF_ACTION {action})")
    if what == "warning":           # PX4: warn only, the flight goes on as it was
        return
    _pause_running_mission(ctx, ent, row, "geofence")
    failsafe_action(ctx, ent, row, what, "geofence breach")


def _pause_running_mission(ctx: StepContext, ent: int, row: int, why: str) -> None:
    rt = esper.try_component(ent, MissionRuntime)
    if rt is not None and rt.state == "running":
        rt.state, rt.reason = "paused", why
        ctx.fleet.charging[row] = False
        ctx.fleet.mission_state[row] = MissionState.PAUSED


# -- arming checks ---------------------------------------------------------------------------
def arming_refusal(f: Any, ent: int, row: int, nav: NavRuntime, params: FlightParams) -> Refusal | None:
    """Why drone ``row`` may not arm now (PX4's pre-arm checks that apply here), or None. The one place
    these checks live: the Arm command refuses with it, the navigator writes its code to ``arm_block``
    every step (MAVLink's SYS_STATUS pre-arm health and MAV_CMD_RUN_PREARM_CHECKS read that)."""
    energy = esper.try_component(ent, EnergyModel)
    if energy is not None and (f.low_battery[row] or f.soc_frac[row] < energy.low_battery_land_frac):
        return Refusal(CommandStatus.REJECTED_STATE, "low_battery",
                       f"Arming denied: battery at {100 * f.soc_frac[row]:.0f} % (below "
                       f"{100 * energy.low_battery_land_frac:.0f} %)")
    if not f.motors_enabled[row]:
        bay = esper.try_component(ent, PayloadBay)
        if bay is not None and f.payload_kg[row] > bay.max_payload_kg:
            return Refusal(CommandStatus.REJECTED_STATE, "overweight",
                           f"Arming denied: payload {f.payload_kg[row]:.2f} kg exceeds {bay.max_payload_kg:g} kg")
        return Refusal(CommandStatus.REJECTED_STATE, "motors_disabled", "Arming denied: motors disabled")
    why = fence_breach(f, row, nav, params)
    if why:
        return Refusal(CommandStatus.REJECTED_STATE, "outside_fence", f"Arming denied: {why}")
    if f.landed_state[row] not in (LandedState.ON_GROUND, LandedState.UNDEFINED):
        return Refusal(CommandStatus.REJECTED_STATE, "in_air",
                       "Arming denied: not on the ground (force it to arm in the air)")
    return None


def arm_block(f: Any, ent: int, row: int, nav: NavRuntime, params: FlightParams) -> int:
    """The :class:`ArmBlock` code of :func:`arming_refusal` (0: the drone would arm now)."""
    why = arming_refusal(f, ent, row, nav, params)
    return ArmBlock.NONE if why is None else ArmBlock[why.reason.upper()]


def fence_active(nav: NavRuntime, params: FlightParams) -> bool:
    """The drone's geofence can be breached: enabled, with a zone or a GF_MAX_* distance limit."""
    return fences_active([nav], [params])[0]


def fences_active(navs: list[NavRuntime], params_of: list[FlightParams]) -> list[bool]:
    """:func:`fence_active` of each drone, the test written out once for the fleet (a call per drone costs more
    than the test)."""
    return [nav.fence_enabled and ((nav.fence is not None and not nav.fence.empty)
                                   or params.values["GF_MAX_HOR_DIST"] > 0.0 or params.values["GF_MAX_VER_DIST"] > 0.0)
            for nav, params in zip(navs, params_of)]


def arming_limits(f: Any) -> tuple[np.ndarray, np.ndarray]:
    """Per fleet row: the battery fraction below which arming is refused (-inf: no battery) and the
    payload bay's limit [kg] (inf: no bay), from the EnergyModel and PayloadBay components."""
    n = f.soc_frac.shape[0]
    low_frac, max_payload = np.full(n, -np.inf), np.full(n, np.inf)     # no battery: never low; no bay: no limit
    for _, (slot, energy) in esper.get_components(FleetSlot, EnergyModel):
        low_frac[slot.row] = energy.low_battery_land_frac
    for _, (slot, bay) in esper.get_components(FleetSlot, PayloadBay):
        max_payload[slot.row] = bay.max_payload_kg
    return low_frac, max_payload


def arm_blocks(f: Any, rows: np.ndarray, fence_why: list[str],
               limits: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """:func:`arm_block` of the drones in ``rows`` at once (int8 ArmBlock codes), with the checks in the same
    order; ``fence_why`` holds :func:`fence_breach` of each row ("" inside, or no fence to breach);
    ``limits`` are :func:`arming_limits` when the caller keeps them (they change only with the ECS)."""
    low_frac, max_payload = arming_limits(f) if limits is None else limits
    outside = np.array([bool(w) for w in fence_why], dtype=bool)
    return _arm_codes(f, rows, _RowLimits(low_frac[rows], max_payload[rows]), outside)


class _RowLimits:
    """:func:`arming_limits` of some rows (kept with the rows: they change only with the ECS)."""

    __slots__ = ("low_frac", "max_payload")

    def __init__(self, low_frac: np.ndarray, max_payload: np.ndarray) -> None:
        self.low_frac = low_frac
        self.max_payload = max_payload


_CODE_IN_AIR, _CODE_OUTSIDE = int(ArmBlock.IN_AIR), int(ArmBlock.OUTSIDE_FENCE)
_CODE_MOTORS = int(ArmBlock.MOTORS_DISABLED)
_CODE_OVERWEIGHT, _CODE_LOW = int(ArmBlock.OVERWEIGHT), int(ArmBlock.LOW_BATTERY)


def _arm_codes(f: Any, sel: slice | np.ndarray, lim: _RowLimits, outside: np.ndarray | None) -> np.ndarray:
    """The ArmBlock codes (int8) of the rows ``sel`` selects: the first failing check in the order low battery,
    overweight, motors disabled, outside the fence (``outside``; None: nowhere), in the air; NONE if none fails."""
    landed = f.landed_state[sel]
    codes = np.empty(landed.shape[0], dtype=np.int8)
    _arm_codes_into(landed, f.motors_enabled[sel], f.payload_kg[sel], f.low_battery[sel], f.soc_frac[sel],
                    lim.low_frac, lim.max_payload, outside, codes)
    return codes


@jit
def _arm_code(landed_state, motors_enabled, payload_kg, low_battery, soc_frac, low_frac, max_payload_kg, outside):
    """The ArmBlock code of one drone, each check's code written over the lower-priority ones (a drone without a
    battery has low_frac -inf and is never low; one without a bay max_payload_kg inf and is never overweight)."""
    code = 0
    if landed_state != LANDED_ON_GROUND and landed_state != LANDED_UNDEFINED:
        code = _CODE_IN_AIR
    if outside:
        code = _CODE_OUTSIDE
    if not motors_enabled:
        code = _CODE_OVERWEIGHT if payload_kg > max_payload_kg else _CODE_MOTORS
    if (low_battery or soc_frac < low_frac) and np.isfinite(low_frac):
        code = _CODE_LOW
    return code


@jit
def _arm_codes_into(landed_state, motors_enabled, payload_kg, low_battery, soc_frac, low_frac, max_payload, outside,
                    codes):
    """:func:`_arm_codes` row by row (``outside`` None: nowhere)."""
    for k in range(codes.shape[0]):
        codes[k] = _arm_code(landed_state[k], motors_enabled[k], payload_kg[k], low_battery[k], soc_frac[k],
                             low_frac[k], max_payload[k], outside is not None and outside[k])


@jit
def _navigator_screen(landed_state, motors_enabled, payload_kg, low_battery, soc_frac, low_frac, max_payload, outside,
                      flight_mode, nav_state, stream_or_sticks, arm_block, busy):
    """One pass of the navigator over its rows: ``arm_block`` (N,) the arming verdicts (:func:`_arm_codes`) and
    ``busy`` (N,) bool the rows disarmed, on the ground, or flown from a stream or sticks (``stream_or_sticks`` by
    nav_state); returns how many are busy."""
    n = 0
    for k in range(busy.shape[0]):
        arm_block[k] = _arm_code(landed_state[k], motors_enabled[k], payload_kg[k], low_battery[k], soc_frac[k],
                                 low_frac[k], max_payload[k], outside is not None and outside[k])
        b = (flight_mode[k] == MODE_DISARMED or landed_state[k] == LANDED_ON_GROUND
             or stream_or_sticks[np.uint8(nav_state[k])])
        busy[k] = b
        n += b
    return n


@jit
def _land_screen(payload_entity, flight_mode, nav_state, carrying, taking_off_or_mission):
    """One pass of the land detector over its rows: ``carrying`` (N,) bool the rows carrying a package
    (``payload_entity`` >= 0), ``taking_off_or_mission`` (N,) bool those whose nav state is TAKEOFF or MISSION;
    returns how many carry, how many are armed and how many take off or fly a mission."""
    n_carrying = n_armed = n_special = 0
    for k in range(carrying.shape[0]):
        c = payload_entity[k] >= 0
        t = nav_state[k] == NAV_TAKEOFF or nav_state[k] == NAV_MISSION
        carrying[k], taking_off_or_mission[k] = c, t
        n_carrying += c
        n_armed += flight_mode[k] != MODE_DISARMED
        n_special += t
    return n_carrying, n_armed, n_special


# -- land detector ---------------------------------------------------------------------------
class LandDetectorSystem(FleetSystem):
    """Landed state of every drone from contact and motion (PX4's multicopter land detector).

    Phase: STATE (after the read-back). Reads: pose, velocity, body rates, payload_entity, nav_state,
    contacts. Writes: landed_state; NavRuntime contact/ground timers and ``took_off``.
    """

    phase = Phase.STATE
    order = 30
    requires = (RigidBody, NavRuntime, FlightParams)

    def gather(self, ctx: StepContext) -> None:
        bodies = [body.body_id for body in self.components[0]]
        self._body_ids = bodies
        k_of_body = {body: k for k, body in enumerate(bodies)}
        self._k_of_body = k_of_body if len(k_of_body) == len(bodies) else None     # None: a body id twice
        self._ents = self.entities.tolist()
        self._carrying = np.zeros(self.rows.size, dtype=bool)
        self._special = np.zeros(self.rows.size, dtype=bool)
        self._states = np.empty(self.rows.size, dtype=np.int8)

    def update(self, ctx: StepContext) -> None:
        f = ctx.fleet
        t = ctx.sim_time_s + ctx.dt_s           # the state read back is the state at the end of this step
        contact = ctx.physics.contact_map()     # one query for the whole world
        sel = self.sel
        navs = self.components[1]
        m = len(navs)
        # Only a drone whose body touches something, or that carries a package (which may), can be still on
        # something: those rows get the whole test (_check_rows). Every other row touches nothing, so it is
        # in the air this step, which is what that test would find: its timers are cleared, took_off is set
        # when armed, and its state is the airborne one.
        k_of_body = self._k_of_body
        if k_of_body is None:
            check = [k for k, body in enumerate(self._body_ids) if body in contact]
        else:
            check = [k_of_body[body] for body in contact if body in k_of_body]
        nan = math.nan
        modes, nav_states = f.flight_mode[sel], f.nav_state[sel]
        carrying, special = self._carrying, self._special
        n_carrying, n_armed, n_special = _land_screen(f.payload_entity[sel], modes, nav_states, carrying, special)
        if n_carrying:
            check = sorted(set(check).union(carrying.nonzero()[0].tolist()))
        else:
            check.sort()
        states = self._states                                  # the new landed states, written back at once
        states.fill(LANDED_IN_AIR)
        if check:
            self._check_rows(ctx, t, contact, check, states)
            free_mask = np.ones(m, dtype=bool)
            free_mask[check] = False
            free_list = free_mask.tolist()
            free = list(compress(navs, free_list))
            armed = list(compress((modes != MODE_DISARMED).tolist(), free_list))
        else:
            free_mask = None
            free = navs
            armed = None
        if armed is None and n_armed == m:
            for nav in free:
                nav.contact_since_s = nan
                nav.ground_since_s = nan
                nav.took_off = True
        else:
            for nav in free:
                nav.contact_since_s = nan
                nav.ground_since_s = nan
            for nav in compress(free, (modes != MODE_DISARMED).tolist() if armed is None else armed):
                nav.took_off = True
        # the airborne state is IN_AIR but while taking off or landing: a TAKEOFF or MISSION nav state, or a
        # navigator mode (_airborne_state's first test)
        moded = [k for k, nav in enumerate(navs) if nav.mode]
        if n_special or moded:
            special[moded] = True
            if free_mask is not None:
                special &= free_mask
            ents, nav_state_list = self._ents, nav_states.tolist()
            for k in special.nonzero()[0].tolist():
                states[k] = int(self._airborne_state(ents[k], nav_state_list[k], navs[k]))
        f.landed_state[sel] = states

    def _check_rows(self, ctx: StepContext, t: float, contact: dict, check: list[int],
                    states: np.ndarray) -> None:
        """The land detector's test on the rows ``check`` (positions in ``rows``, ascending), one by one; their
        new landed states go to ``states``."""
        f = ctx.fleet
        rows = self.rows
        vel = f.vel_enu_m_s[rows]
        speed_z = np.abs(vel[:, 2]).tolist()
        speed_xy = np.hypot(vel[:, 0], vel[:, 1]).tolist()
        rate = np.linalg.norm(f.rate_flu_rad_s[rows], axis=1).tolist()
        packages = f.payload_entity[rows].tolist()
        landed = f.landed_state[rows].tolist()
        modes, nav_states = f.flight_mode[rows].tolist(), f.nav_state[rows].tolist()
        ents, (bodies, navs, params_of) = self._ents, self.components
        for k in check:
            ent, body, nav, params = ents[k], bodies[k], navs[k], params_of[k]
            touching = contact.get(body.body_id, _NOTHING)
            if packages[k] >= 0:
                carried = esper.component_for_entity(packages[k], RigidBody).body_id
                touching = (touching | contact.get(carried, _NOTHING)) - {body.body_id, carried}
            still = (bool(touching) and speed_z[k] < params["LNDMC_Z_VEL_MAX"]
                     and speed_xy[k] < params["LNDMC_XY_VEL_MAX"]
                     and rate[k] < math.radians(params["LNDMC_ROT_MAX"]))
            prev = landed[k]
            if still:
                if math.isnan(nav.contact_since_s):
                    nav.contact_since_s = t
                on_ground = (prev in (LANDED_UNDEFINED, LANDED_ON_GROUND)
                             or t - nav.contact_since_s >= LAND_TRIGGER_S - 1e-9)
            else:
                nav.contact_since_s = math.nan
                on_ground = False
            if on_ground:
                if prev != LANDED_ON_GROUND:
                    nav.ground_since_s = t
                    states[k] = LANDED_ON_GROUND
                else:
                    states[k] = prev
                continue
            nav.ground_since_s = math.nan
            if modes[k] != MODE_DISARMED:
                nav.took_off = True
            states[k] = int(self._airborne_state(ent, nav_states[k], nav))

    @staticmethod
    def _airborne_state(ent: int, nav_state: int, nav: NavRuntime) -> int:
        if nav_state != NAV_TAKEOFF and nav_state != NAV_MISSION and not nav.mode:
            return LANDED_IN_AIR                # the common case first, in plain ints
        if nav_state == NavState.TAKEOFF:
            return LandedState.TAKEOFF
        if nav.mode in ("land", "rtl") and nav.phase == "land":
            return LandedState.LANDING
        if nav_state == NavState.MISSION:
            step = _mission_step_type(ent)
            if step == "takeoff":
                return LandedState.TAKEOFF
            if step in ("land", "deliver", "recharge"):
                return LandedState.LANDING
        return LandedState.IN_AIR


# -- navigator -------------------------------------------------------------------------------
class NavigatorSystem(FleetSystem):
    """Home, the navigator-flown modes (TAKEOFF, LAND, RTL) and auto-disarm.

    Phase: MISSION (after the mission and emergency landing). Reads: pose, arrived, landed_state,
    mission_state, battery, payload, FlightParams. Writes: home_enu_m/home_set, routes and flight_mode
    (mode changes, disarm), nav_state, arm_block (the arming checks' verdict at the start of the step); NavRuntime.
    """

    phase = Phase.MISSION
    order = 20
    requires = (NavRuntime, FlightParams)

    def gather(self, ctx: StepContext) -> None:
        self._limits = low_frac, max_payload = arming_limits(ctx.fleet)     # from the battery and bay components
        rows = self.rows
        self._row_limits = _RowLimits(low_frac[rows], max_payload[rows])    # kept with the rows
        self._rows_list, self._ents = rows.tolist(), self.entities.tolist()
        self._busy = np.zeros(rows.size, dtype=bool)
        self._arm_block = np.zeros(rows.size, dtype=np.int8)

    def update(self, ctx: StepContext) -> None:
        f = ctx.fleet
        sel = self.sel
        navs, params_of = self.components
        m = len(navs)
        home_set = f.home_set[sel]
        if count_true(home_set) != m:
            unset = self.rows[~home_set]
            f.home_enu_m[unset] = f.pos_enu_m[unset]
            f.home_set[unset] = True
        fenced = fences_active(navs, params_of)
        any_fenced = any(fenced)
        outside = None
        if any_fenced:
            outside = np.array([bool(fence_breach(f, row, nav, params)) if on else False
                                for on, row, nav, params in zip(fenced, self._rows_list, navs, params_of)], dtype=bool)
        # The arming verdicts, and the rows with something to do one by one: disarmed, on the ground
        # (auto-disarm), in a navigator mode, flying a stream or sticks (OFFBOARD, POSCTL, MANUAL), or with a fence
        # to enforce. Every other drone flies on with nothing to breach: only its fence_ok is set (what the loop
        # below would do).
        landed, busy, lim = f.landed_state[sel], self._busy, self._row_limits
        arm_block = f.arm_block[sel] if isinstance(sel, slice) else self._arm_block     # a view: written in place
        n_busy = _navigator_screen(landed, f.motors_enabled[sel], f.payload_kg[sel], f.low_battery[sel],
                                   f.soc_frac[sel], lim.low_frac, lim.max_payload, outside, f.flight_mode[sel],
                                   f.nav_state[sel], _STREAM_OR_STICKS, arm_block, busy)
        if arm_block is self._arm_block:
            f.arm_block[sel] = arm_block
        moded = [k for k, nav in enumerate(navs) if nav.mode]
        if moded or any_fenced:
            busy[moded] = True
            if any_fenced:
                busy |= np.array(fenced, dtype=bool)
            n_busy = count_true(busy)
        if n_busy == 0:
            for nav in navs:
                nav.fence_ok = True
            return
        if n_busy < m:
            for nav in compress(navs, (~busy).tolist()):
                nav.fence_ok = True
        self._busy_rows(ctx, np.flatnonzero(busy).tolist(), fenced, (landed == LANDED_ON_GROUND).tolist())

    def _busy_rows(self, ctx: StepContext, busy: Iterable[int], fenced: list[bool], grounded: list[bool]) -> None:
        """One step of the navigator for the drones at positions ``busy`` of ``rows``, one by one in row order;
        ``grounded``: landed_state is ON_GROUND, by position (only the land detector writes it)."""
        f = ctx.fleet
        t = ctx.sim_time_s
        sel = self.sel
        rows, ents, (navs, params_of) = self._rows_list, self._ents, self.components
        modes, nav_states = f.flight_mode[sel].tolist(), f.nav_state[sel].tolist()
        for k in busy:
            row, ent, nav, params = rows[k], ents[k], navs[k], params_of[k]
            if modes[k] == MODE_DISARMED:
                if nav.mode:
                    _set_mode(nav, "", "", t, None)
                nav.took_off, nav.armed_s = False, math.nan
                continue
            if nav.mode:
                self._advance(ctx, ent, row, nav, params)
            elif nav_states[k] == NAV_OFFBOARD and nav.offboard is not None:
                if offboard_fresh(nav, params, t):
                    fly_offboard(ctx, ent, row, nav, params, new=False)
                else:
                    offboard_lost(ctx, ent, row, nav, params)
            elif nav_states[k] in (NAV_POSCTL, NAV_MANUAL) and nav.manual is not None:
                if manual_fresh(nav, params, t):
                    fly_manual(ctx, row, nav, params)
                else:
                    manual_lost(ctx, ent, row, nav, params)
            on_ground = grounded[k]
            if not on_ground and int(f.flight_mode[row]) != MODE_DISARMED:
                if fenced[k]:
                    enforce_fence(ctx, ent, row, nav, params)
                else:
                    nav.fence_ok = True            # nothing to breach (what enforce_fence would find)
            if on_ground:
                self._auto_disarm(ctx, ent, row, nav, params)

    def _advance(self, ctx: StepContext, ent: int, row: int, nav: NavRuntime, params: FlightParams) -> None:
        f = ctx.fleet
        t = ctx.sim_time_s
        name = _name(ent)
        if nav.mode == "orbit":
            fly_orbit(ctx, row, nav, params)
            return
        if nav.mode == "follow":
            if follow_fresh(nav, t):
                fly_follow(ctx, row, nav, params)
            else:
                ctx.services.note(t, name, f"follow target: no target fix for {FOLLOW_LOST_S:g} s: holding")
                hold(ctx, ent, row)
            return
        if nav.mode == "rc_lost":
            if t - nav.phase_started_s >= params["COM_FAIL_ACT_T"] - 1e-9:
                _rc_lost_action(ctx, ent, row, nav, params)
            return
        if nav.mode == "takeoff":
            if f.arrived[row] and abs(f.pos_enu_m[row, 2] - nav.goal_enu_m[2]) < TAKEOFF_DONE_M:
                _set_mode(nav, "", "", t, None)
                f.nav_state[row] = NavState.HOLD
                ctx.services.note(t, name, f"takeoff complete at z = {f.pos_enu_m[row, 2]:.1f} m: holding")
            return
        if nav.phase == "land":
            if f.landed_state[row] == LandedState.ON_GROUND:
                nav.phase, nav.phase_started_s = "landed", t
                ctx.services.note(t, name, "landed")
            return
        if nav.mode == "rtl" and nav.phase == "return":
            if f.arrived[row] and np.linalg.norm(f.pos_enu_m[row] - nav.goal_enu_m) < GOAL_DONE_M:
                nav.phase, nav.phase_started_s = "delay", t
            return
        if nav.mode == "rtl" and nav.phase == "delay":
            delay = params["RTL_LAND_DELAY"]
            if delay >= 0.0 and t - nav.phase_started_s >= delay - 1e-9:
                start_land(ctx, ent, row, nav.goal_enu_m[:2].copy(), mode="rtl")

    def _auto_disarm(self, ctx: StepContext, ent: int, row: int, nav: NavRuntime, params: FlightParams) -> None:
        f = ctx.fleet
        if int(f.landed_state[row]) != LANDED_ON_GROUND or int(f.mission_state[row]) == MISSION_RUNNING:
            return
        t = ctx.sim_time_s
        if nav.took_off:
            delay = params["COM_DISARM_LAND"]
            if delay >= 0.0 and not math.isnan(nav.ground_since_s) and t - nav.ground_since_s >= delay - 1e-9:
                disarm(ctx, ent, row, f"landed {delay:g} s ago (COM_DISARM_LAND)")
        else:
            delay = params["COM_DISARM_PRFLT"]
            if delay >= 0.0 and not math.isnan(nav.armed_s) and t - nav.armed_s >= delay - 1e-9:
                disarm(ctx, ent, row, f"armed {delay:g} s without taking off (COM_DISARM_PRFLT)")


__all__ = ["LandDetectorSystem", "NavigatorSystem", "arm_block", "arm_blocks", "arming_refusal", "brake_and_hold",
           "disarm", "enforce_fence", "ensure_all_drones", "ensure_nav", "fence_active", "fence_breach",
           "fences_active", "fly_follow", "fly_manual", "fly_offboard", "fly_orbit", "follow_fresh", "hold",
           "land_route", "manual_fresh", "offboard_fresh", "offboard_lost", "rtl_destination", "start_follow",
           "start_land", "start_orbit", "start_rtl", "start_takeoff"]
