"""MISSION phase: the mission state machine of every drone (the paper's §2.1.3, docs/architecture.md §5).

Steps: takeoff, cruise, land, pickup, deliver, recharge, idle, each wrapped in ``wait_before`` and
``wait_after``. A step turns into a route for the guidance layer, payload requests for the payload
system and charging for the energy model; the step ends on what the physics shows (arrived, slow,
touching the ground, package joined). This is event logic: one short Python check per drone with
a running mission per step, with all the flying done by the vectorised layers below.
"""

from __future__ import annotations

from typing import Any

import esper
import numpy as np

from ..components.body import FleetSlot, Identity, RigidBody
from ..components.flight import GuidanceLimits, QuadrotorMotors
from ..components.mission import MissionRuntime
from ..frames import yaw_rad_from_quat_xyzw
from ..navigation.params import FlightParams
from ..navigation.state import NavRuntime
from ..phases import Phase
from ..world import StepContext
from .flight_state import (MODE_DISARMED, NAV_MISSION, FlightMode, LandedState, MissionState, NavState,
                           PayloadRequest, PayloadResult, Route, set_route)
from .navigator import start_rtl

# MissionRuntime.state -> the number transports read (mission_state)
MISSION_STATES = {"stored": MissionState.STORED, "running": MissionState.RUNNING, "paused": MissionState.PAUSED,
                  "completed": MissionState.COMPLETED, "failed": MissionState.FAILED,
                  "cancelled": MissionState.CANCELLED}

SETTLED_SPEED_M_S = 0.5        # a step that ends "at" a point also needs the drone slower than this
GRAB_CLEARANCE_M = 0.10        # hover gap between the airframe's bottom and the package top when grabbing
GRAB_TOLERANCE_M = 0.12        # position error allowed before grabbing
PICKUP_SEARCH_RADIUS_M = 30.0
LAND_BELOW_M = 0.3             # land by aiming this far below the resting height (so touchdown happens)
STEP_TIMEOUT_S = 600.0
# A climb that makes no progress: the motors are held at (nearly) full collective thrust while the
# goal is still above and the drone has not risen CLIMB_PROGRESS_M in CLIMB_STALL_S -> the step fails
# with reason "insufficient_thrust" and the drone lands where it is.
CLIMB_STALL_S = 5.0
CLIMB_PROGRESS_M = 0.5
CLIMB_SATURATED_FRAC = 0.95    # total commanded thrust / (4 F_max) that counts as "full"


class MissionSystem(esper.Processor):
    """Advance every running mission by one step.

    Phase: MISSION. Reads: fleet pose/velocity, arrived, payload_result, payload_entity, low_battery, soc_frac.
    Writes: routes (via set_route), flight_mode, payload_request/payload_package, charging,
    mission_step; MissionRuntime components.
    """

    phase = Phase.MISSION
    order = 0

    def process(self, ctx: StepContext) -> None:
        f = ctx.fleet
        for ent, (ident, slot, rt) in esper.get_components(Identity, FleetSlot, MissionRuntime):
            row = slot.row
            f.mission_state[row] = MISSION_STATES[rt.state]
            if rt.state != "running":
                continue
            if f.nav_state[row] != NAV_MISSION and f.flight_mode[row] != MODE_DISARMED:     # plain ints: no enum
                f.nav_state[row] = NAV_MISSION
            if f.low_battery[row] and rt.spec.steps[rt.step_index].type not in ("land", "recharge"):
                self._fail(ctx, ident.name, row, rt, "low_battery")
                self._begin_emergency_landing(ctx, ent, row)
                continue
            self._advance(ctx, ent, ident.name, row, rt)
            f.mission_step[row] = rt.step_index if rt.state == "running" else -1
            f.mission_state[row] = MISSION_STATES[rt.state]
            if rt.state == "completed" and f.nav_state[row] == NAV_MISSION:
                f.nav_state[row] = NavState.HOLD

    # -- state machine -----------------------------------------------------------------------
    def _advance(self, ctx: StepContext, ent: int, name: str, row: int, rt: MissionRuntime) -> None:
        t = ctx.sim_time_s
        step = rt.spec.steps[rt.step_index]
        if rt.stage == "wait_before" and rt.scratch.get("takeoff_first"):
            self._takeoff_first(ctx, ent, name, row, rt, step)
            goal = rt.scratch.get("takeoff_goal")
            if goal is not None and _climb_stalled(ctx, ent, row, rt.scratch, float(goal[2])):
                self._fail_to_climb(ctx, ent, name, row, rt)
            return
        if rt.stage == "wait_before":
            if t - rt.stage_started_s >= step.wait_before - 1e-9:
                rt.stage, rt.stage_started_s, rt.scratch = "active", t, {}
                ctx.services.note(t, name, f"mission step {rt.step_index} ({step.type}) started")
                error = self._begin(ctx, ent, row, rt, step)
                if error:
                    self._fail(ctx, name, row, rt, error)
            return
        if rt.stage == "active":
            if t - rt.stage_started_s > STEP_TIMEOUT_S:
                self._fail(ctx, name, row, rt, f"{step.type}_timeout")
                return
            outcome = self._check(ctx, ent, row, rt, step)
            if outcome is None:
                return
            if outcome == "insufficient_thrust":
                self._fail_to_climb(ctx, ent, name, row, rt)
                return
            if outcome != "done":
                self._fail(ctx, name, row, rt, outcome)
                return
            rt.stage, rt.stage_started_s = "wait_after", t
            ctx.services.note(t, name, f"mission step {rt.step_index} ({step.type}) done")
        if rt.stage == "wait_after" and t - rt.stage_started_s >= step.wait_after - 1e-9:
            rt.step_index += 1
            if rt.step_index >= len(rt.spec.steps):
                rt.step_index = len(rt.spec.steps) - 1
                rt.state = "completed"
                ctx.services.note(t, name, f"mission {rt.spec.name} completed")
                return
            rt.stage, rt.stage_started_s, rt.scratch = "wait_before", t, {}

    def _takeoff_first(self, ctx: StepContext, ent: int, name: str, row: int, rt: MissionRuntime, step: Any) -> None:
        """PX4's implicit takeoff: a mission started on the ground whose step flies somewhere first climbs
        straight up to the higher of home + MIS_TAKEOFF_ALT and the step's first waypoint, at MPC_TKO_SPEED."""
        f = ctx.fleet
        s = rt.scratch
        if "takeoff_goal" not in s:
            params = esper.try_component(ent, FlightParams) or FlightParams()
            pos = f.pos_enu_m[row].copy()
            base = f.home_enu_m[row, 2] if f.home_set[row] else pos[2]
            z = base + params["MIS_TAKEOFF_ALT"]
            if step.waypoints:
                z = max(z, step.waypoints[0].z)
            goal = np.array([pos[0], pos[1], z])
            lim = esper.component_for_entity(ent, GuidanceLimits)
            sp = (rt.spec.cruise_speed, min(params["MPC_TKO_SPEED"], lim.lim_climb_m_s), lim.descent_speed_m_s)
            _arm(f, row)
            set_route(f, row, _route([pos, goal], [sp, sp], np.nan))
            s["takeoff_goal"] = goal
            ctx.services.note(ctx.sim_time_s, name, f"mission takeoff to z = {z:.1f} m before step {rt.step_index}")
            return
        if f.arrived[row] and abs(f.pos_enu_m[row, 2] - s["takeoff_goal"][2]) < 0.3:
            rt.scratch = {}
            rt.stage_started_s = ctx.sim_time_s

    def _fail_to_climb(self, ctx: StepContext, ent: int, name: str, row: int, rt: MissionRuntime) -> None:
        """The climb stalled at full thrust: fail with ``insufficient_thrust`` and land where it is."""
        f = ctx.fleet
        ctx.services.note(ctx.sim_time_s, name, f"climb stalled at z = {f.pos_enu_m[row, 2]:.2f} m with the motors at "
                                                f"{f.motor_thrust_cmd_n[row].sum():.1f} N for {CLIMB_STALL_S:g} s")
        self._fail(ctx, name, row, rt, "insufficient_thrust")
        f.nav_state[row] = NavState.LAND
        self._begin_emergency_landing(ctx, ent, row)

    def _fail(self, ctx: StepContext, name: str, row: int, rt: MissionRuntime, reason: str) -> None:
        rt.state, rt.reason = "failed", reason
        ctx.fleet.charging[row] = False
        ctx.fleet.mission_step[row] = -1
        ctx.fleet.mission_state[row] = MissionState.FAILED
        if ctx.fleet.nav_state[row] == NavState.MISSION:
            ctx.fleet.nav_state[row] = NavState.LAND if reason == "low_battery" else NavState.HOLD
        ctx.services.note(ctx.sim_time_s, name, f"mission {rt.spec.name} failed at step {rt.step_index}: {reason}")
        f = ctx.fleet
        if reason != "overweight" and f.flight_mode[row] == FlightMode.AUTO and f.motors_enabled[row]:
            _hold_here(f, row)

    # -- begin a step ------------------------------------------------------------------------
    def _begin(self, ctx: StepContext, ent: int, row: int, rt: MissionRuntime, step: Any) -> str:
        f = ctx.fleet
        lim = esper.component_for_entity(ent, GuidanceLimits)
        spec = rt.spec
        s = rt.scratch
        pos = f.pos_enu_m[row].copy()
        if step.type == "takeoff":
            if step.waypoints:
                wp = step.waypoints[0]
                goal = np.array([wp.x, wp.y, wp.z])
            else:
                alt = step.altitude_m if step.altitude_m is not None else lim.takeoff_altitude_m
                surface = ctx.services.layout.surface_height_m(pos[0], pos[1])
                goal = np.array([pos[0], pos[1], surface + alt])
            speed = _speeds(step.waypoints[0] if step.waypoints else None, spec, lim)
            _arm(f, row)
            set_route(f, row, _route([pos, goal], [speed, speed], _yaw(step.waypoints[0] if step.waypoints else None)))
            s["goal"] = goal
        elif step.type == "cruise":
            pts, speeds = [pos], []
            for wp in step.waypoints:
                pts.append(np.array([wp.x, wp.y, wp.z]))
                speeds.append(_speeds(wp, spec, lim))
            if step.pad is not None:
                pad = ctx.services.layout.pads[step.pad]
                pts.append(np.array([pad.center_enu_m[0], pad.center_enu_m[1], max(pos[2], pad.center_enu_m[2] + 5.0)]))
                speeds.append(_speeds(None, spec, lim))
            speeds.insert(0, speeds[0])
            _arm(f, row)
            set_route(f, row, _route(pts, speeds, _yaw(step.waypoints[-1] if step.waypoints else None)))
            s["goal"] = pts[-1]
        elif step.type in ("land", "deliver"):
            if step.type == "deliver" and f.payload_kg[row] <= 0.0:
                return "nothing_to_deliver"
            if _on_ground(ctx, row) and f.flight_mode[row] == FlightMode.DISARMED:
                s["landed"] = True
            else:
                self._begin_landing(ctx, ent, row, rt, step, lim)
        elif step.type == "pickup":
            return self._begin_pickup(ctx, ent, row, rt, step, lim)
        elif step.type == "recharge":
            s["soc_start"] = float(f.soc_frac[row])
            if f.flight_mode[row] != FlightMode.DISARMED:
                self._begin_landing(ctx, ent, row, rt, step, lim)
            if step.charge_power_w is not None:
                f.charge_power_w[row] = step.charge_power_w
        elif step.type == "idle":
            if f.flight_mode[row] != FlightMode.DISARMED and f.route[row] is None:
                _hold_here(f, row)     # otherwise keep converging on the last target
        elif step.type == "return":
            if f.landed_state[row] == LandedState.ON_GROUND:
                s["landed"] = True     # already down: nothing to return from
            else:
                start_rtl(ctx, ent, row, nav_state=NavState.MISSION)
        return ""

    def _begin_landing(self, ctx: StepContext, ent: int, row: int, rt: MissionRuntime, step: Any,
                       lim: GuidanceLimits) -> None:
        f = ctx.fleet
        pos = f.pos_enu_m[row].copy()
        if step.waypoints:
            xy = np.array([step.waypoints[-1].x, step.waypoints[-1].y])
        elif getattr(step, "pad", None) is not None:
            xy = np.array(ctx.services.layout.pads[step.pad].center_enu_m[:2])
        else:
            xy = pos[:2]
        body = esper.component_for_entity(ent, RigidBody)
        below = body.half_extents_m[2] + _carried_height(ctx, row)
        surface = ctx.services.layout.surface_height_m(xy[0], xy[1])
        touch_z = surface + below - LAND_BELOW_M
        speed = _speeds(step.waypoints[-1] if step.waypoints else None, rt.spec, lim)
        pts = [pos]
        if np.hypot(*(xy - pos[:2])) > 1.0:
            cruise_z = max(pos[2], surface + below + 2.0)
            pts.append(np.array([xy[0], xy[1], cruise_z]))
        pts.append(np.array([xy[0], xy[1], touch_z]))
        _arm(f, row)
        set_route(f, row, _route(pts, [speed] * len(pts), np.nan))
        rt.scratch["landing"] = True

    def _begin_pickup(self, ctx: StepContext, ent: int, row: int, rt: MissionRuntime, step: Any,
                      lim: GuidanceLimits) -> str:
        f = ctx.fleet
        pos = f.pos_enu_m[row].copy()
        centre = np.array([step.waypoints[0].x, step.waypoints[0].y]) if step.waypoints else pos[:2]
        best = None
        for pent, (pid, pslot, pbody) in esper.get_components(Identity, FleetSlot, RigidBody):
            if pid.kind != "package" or (step.package is not None and pid.name != step.package):
                continue
            d = float(np.hypot(*(f.pos_enu_m[pslot.row, :2] - centre)))
            if d <= PICKUP_SEARCH_RADIUS_M and (best is None or d < best[0]):
                best = (d, pid.name, pslot.row, pbody)
        if best is None:
            return "no_package_found" if step.package is None else f"package_not_found:{step.package}"
        _, pkg_name, pkg_row, pbody = best
        body = esper.component_for_entity(ent, RigidBody)
        pkg = f.pos_enu_m[pkg_row]
        grab_z = pkg[2] + pbody.half_extents_m[2] + GRAB_CLEARANCE_M + body.half_extents_m[2]
        grab = np.array([pkg[0], pkg[1], grab_z])
        speed = _speeds(step.waypoints[0] if step.waypoints else None, rt.spec, lim)
        pts = [pos]
        if np.hypot(*(grab[:2] - pos[:2])) > 0.3:
            pts.append(np.array([pos[0], pos[1], max(pos[2], grab_z + 1.0)]))
            pts.append(np.array([grab[0], grab[1], max(pos[2], grab_z + 1.0)]))
        pts.append(grab)
        slow = (min(speed[0], 1.0), min(speed[1], 1.0), min(speed[2], 0.5))
        _arm(f, row)
        set_route(f, row, _route(pts, [speed] * (len(pts) - 1) + [slow], np.nan))
        f.payload_package[row] = pkg_name
        rt.scratch.update(grab=grab, package=pkg_name, sub="approach")
        return ""

    def _begin_emergency_landing(self, ctx: StepContext, ent: int, row: int) -> None:
        f = ctx.fleet
        if f.flight_mode[row] == FlightMode.DISARMED:
            return
        lim = esper.component_for_entity(ent, GuidanceLimits)
        pos = f.pos_enu_m[row].copy()
        body = esper.component_for_entity(ent, RigidBody)
        surface = ctx.services.layout.surface_height_m(pos[0], pos[1])
        touch = np.array([pos[0], pos[1], surface + body.half_extents_m[2] + _carried_height(ctx, row) - LAND_BELOW_M])
        speed = (lim.cruise_speed_m_s, lim.climb_speed_m_s, lim.descent_speed_m_s)
        set_route(f, row, _route([pos, touch], [speed, speed], np.nan))
        esper.add_component(ent, _EmergencyLanding())

    # -- check a step ------------------------------------------------------------------------
    def _check(self, ctx: StepContext, ent: int, row: int, rt: MissionRuntime, step: Any) -> str | None:
        f = ctx.fleet
        s = rt.scratch
        speed = float(np.linalg.norm(f.vel_enu_m_s[row]))
        if step.type in ("takeoff", "cruise"):
            if f.arrived[row] and speed < SETTLED_SPEED_M_S:
                return "done"
            return "insufficient_thrust" if _climb_stalled(ctx, ent, row, s, float(s["goal"][2])) else None
        if step.type == "land":
            if s.get("landed") or _on_ground(ctx, row):
                f.flight_mode[row] = FlightMode.DISARMED
                set_route(f, row, None)
                return "done"
            return None
        if step.type == "deliver":
            sub = s.get("sub", "landing")
            if sub == "landing":
                if s.get("landed") or _on_ground(ctx, row):
                    f.flight_mode[row] = FlightMode.DISARMED
                    set_route(f, row, None)
                    f.payload_request[row] = PayloadRequest.RELEASE
                    f.payload_result[row] = PayloadResult.NONE
                    s["sub"] = "releasing"
                return None
            if f.payload_result[row] == PayloadResult.RELEASED:
                return "done"
            return None
        if step.type == "pickup":
            sub = s["sub"]
            if sub == "approach":
                err = f.pos_enu_m[row] - s["grab"]
                if np.linalg.norm(err) < GRAB_TOLERANCE_M and speed < 0.2:
                    f.payload_request[row] = PayloadRequest.ATTACH
                    f.payload_result[row] = PayloadResult.NONE
                    s["sub"] = "attaching"
                return None
            result = int(f.payload_result[row])
            if result == PayloadResult.NONE:
                return None
            f.payload_package[row] = None
            if result == PayloadResult.ATTACHED:
                _hold_here(f, row)
                return "done"
            if result == PayloadResult.OVERWEIGHT:
                f.flight_mode[row] = FlightMode.DISARMED
                set_route(f, row, None)
                return "overweight"
            return "no_package_in_reach"
        if step.type == "recharge":
            if s.get("landing") and not s.get("landed"):
                if _on_ground(ctx, row):
                    s["landed"] = True
                    f.flight_mode[row] = FlightMode.DISARMED
                    set_route(f, row, None)
                return None
            f.charging[row] = True
            elapsed = ctx.sim_time_s - s.setdefault("charge_start_s", ctx.sim_time_s)
            if f.soc_frac[row] >= step.target_soc_frac - 1e-9 or (step.duration_s is not None and elapsed >= step.duration_s):
                f.charging[row] = False
                return "done"
            return None
        if step.type == "return":
            nav = esper.try_component(ent, NavRuntime)
            if s.get("landed") or (nav is not None and nav.mode == "rtl" and nav.phase == "landed"):
                f.flight_mode[row] = FlightMode.DISARMED
                set_route(f, row, None)
                if nav is not None:
                    nav.mode, nav.phase = "", ""
                return "done"
            return None
        if step.type == "idle":
            return "done" if ctx.sim_time_s - rt.stage_started_s >= (step.duration_s or 0.0) - 1e-9 else None
        return f"unknown_step_type:{step.type}"


class _EmergencyLanding:
    """Marker: the drone is landing because its battery ran low (disarms on touchdown)."""


class EmergencyLandingSystem(esper.Processor):
    """Disarm drones that touched down after a low-battery landing.

    Phase: MISSION (order 10).
    """

    phase = Phase.MISSION
    order = 10

    def process(self, ctx: StepContext) -> None:
        for ent, (slot, _) in esper.get_components(FleetSlot, _EmergencyLanding):
            if _on_ground(ctx, slot.row):
                ctx.fleet.flight_mode[slot.row] = FlightMode.DISARMED
                set_route(ctx.fleet, slot.row, None)
                esper.remove_component(ent, _EmergencyLanding)


# -- helpers -----------------------------------------------------------------------------------
def _speeds(wp: Any, spec: Any, lim: GuidanceLimits) -> tuple[float, float, float]:
    """(cruise, climb, descent) speeds for a waypoint: its own, else the mission's, within the limits."""
    cruise = wp.cruise_speed if wp is not None and wp.cruise_speed is not None else spec.cruise_speed
    climb = wp.climb_speed if wp is not None and wp.climb_speed is not None else spec.climb_speed
    descent = wp.descent_speed if wp is not None and wp.descent_speed is not None else spec.descent_speed
    return cruise, min(climb, lim.lim_climb_m_s), min(descent, lim.lim_descent_m_s)


def _yaw(wp: Any) -> float:
    return np.deg2rad(wp.yaw_deg) if wp is not None and wp.yaw_deg is not None else np.nan


def _route(points: list[np.ndarray], speeds: list[tuple[float, float, float]], yaw_sp_rad: float) -> Route:
    return Route(np.array(points, dtype=float), np.array(speeds, dtype=float), float(yaw_sp_rad))


def _arm(f: Any, row: int) -> None:
    if f.flight_mode[row] != FlightMode.AUTO:
        f.flight_mode[row] = FlightMode.AUTO


def _hold_here(f: Any, row: int) -> None:
    """Hover where the drone is (a two-point route of zero length)."""
    pos = f.pos_enu_m[row].copy()
    yaw = float(yaw_rad_from_quat_xyzw(f.quat_enu_flu_xyzw[row]))
    sp = np.array([1.0, 1.0, 1.0])
    set_route(f, row, Route(np.array([pos, pos]), np.array([sp, sp]), yaw))


def _climb_stalled(ctx: StepContext, ent: int, row: int, scratch: dict[str, Any], goal_z_m: float) -> bool:
    """True once drone ``row`` has been climbing towards ``goal_z_m`` at full thrust for :data:`CLIMB_STALL_S`
    without rising :data:`CLIMB_PROGRESS_M` (its watch lives in the step's ``scratch``)."""
    f = ctx.fleet
    z = float(f.pos_enu_m[row, 2])
    f_max = esper.component_for_entity(ent, QuadrotorMotors).max_thrust_per_motor_n
    saturated = f.motor_thrust_cmd_n[row].sum() >= CLIMB_SATURATED_FRAC * 4.0 * f_max
    watch = scratch.get("climb_watch")             # (since_s, from_z_m)
    if not saturated or goal_z_m - z < CLIMB_PROGRESS_M or (watch is not None and z > watch[1] + CLIMB_PROGRESS_M):
        scratch.pop("climb_watch", None)
        return False
    if watch is None:
        scratch["climb_watch"] = (ctx.sim_time_s, z)
        return False
    return ctx.sim_time_s - watch[0] >= CLIMB_STALL_S


def _carried_height(ctx: StepContext, row: int) -> float:
    """Height of the package hanging under drone ``row`` (it adds to the landing height), 0 if none."""
    package = int(ctx.fleet.payload_entity[row])
    if package < 0:
        return 0.0
    return float(2.0 * esper.component_for_entity(package, RigidBody).half_extents_m[2])


def _on_ground(ctx: StepContext, row: int) -> bool:
    """The land detector (systems.navigator.LandDetectorSystem) says the drone rests on something: it, or the
    package it carries, touches it and moves and turns slower than the LNDMC_* thresholds, for 0.3 s."""
    return bool(ctx.fleet.landed_state[row] == LandedState.ON_GROUND)
