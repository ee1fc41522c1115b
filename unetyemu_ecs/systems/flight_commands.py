"""COMMANDS phase, drones: turn commands into flight modes, routes, sticks and missions; scripted teleop."""

from __future__ import annotations

import math

import esper
import numpy as np

from ..components.body import FleetSlot, Identity
from ..components.flight import GuidanceLimits, TeleopScript
from ..components.mission import MissionRuntime
from ..navigation.state import NavRuntime
from ..phases import Phase
from ..transport.api import CommandStatus
from ..transport.bus import (Arm, ChangeSpeed, CmdVel, FollowTargetFix, Gripper, Land, LoadMission, ManualControl,
                             OffboardSetpoint, Orbit, PauseMission, ReturnToLaunch, SetFenceEnabled, SetGeofence,
                             SetHome, SetMissionCurrent, SetNavMode, SetParam, SetRallyPoints, SetTarget, StartMission,
                             StoreMission, Takeoff, Teleop, Terminate)
from ..world import StepContext
from .commands import Refusal, serve_commands, warn_if_obstructed
from .flight_state import (FlightMode, LandedState, MissionState, NavState, PayloadRequest, PayloadResult, Route,
                           set_route)
from .navigator import (arming_refusal, disarm, ensure_all_drones, ensure_nav, fly_manual, fly_offboard,
                        follow_fresh, hold, manual_fresh, offboard_fresh, start_follow, start_land, start_orbit,
                        start_rtl, start_takeoff)
from .row_counts import count_at_most


class FlightCommandSystem(esper.Processor):
    """Turn commands into modes, routes, sticks and missions.

    Phase: COMMANDS. Reads: the inbox, TeleopScript components, cmd_hold_until_s. Writes: flight_mode,
    stick, routes, cmd_hold_until_s (a streamed teleop/cmd_vel that lapses sends the drone to hover),
    MissionRuntime components. A live command ends the drone's TeleopScript.
    """

    phase = Phase.COMMANDS
    order = 10

    def __init__(self) -> None:
        self._script_next: dict[int, int] = {}      # entity -> index of the next keyframe to apply
        self._drones_seen: object = None            # the GuidanceLimits query ensure_all_drones last completed

    def process(self, ctx: StepContext) -> None:
        f = ctx.fleet
        # esper answers a query with the same list object until any entity gains, loses or replaces a
        # component: while it is the one seen after the last ensure_all_drones, every drone still has its
        # NavRuntime and FlightParams
        if esper.get_components(GuidanceLimits) is not self._drones_seen:
            ensure_all_drones()
            self._drones_seen = esper.get_components(GuidanceLimits)
        # no command pending and no streamed teleop/cmd_vel lapsing: serve_commands would do nothing
        if ctx.services.pending or count_at_most(f.cmd_hold_until_s, ctx.sim_time_s + 1e-9):
            serve_commands(ctx, GuidanceLimits, self._take, self._hold_after_lapse)
        for ent, (slot, script) in esper.get_components(FleetSlot, TeleopScript):
            k = self._script_next.get(ent, 0)
            frames = script.keyframes
            applied = False
            while k < len(frames) and frames[k].t_s <= ctx.sim_time_s + 1e-9:
                f.stick[slot.row] = frames[k].stick
                k += 1
                applied = True
            if applied:
                f.flight_mode[slot.row] = FlightMode.MANUAL
                f.nav_state[slot.row] = NavState.MANUAL
                _cancel_mission(ctx, ent, "teleop")
            self._script_next[ent] = k

    def _stop_script(self, ctx: StepContext, ent: int, msg: object) -> None:
        """A live command (API, ROS 2) takes the drone over from its world file's teleop_script for good."""
        script = esper.try_component(ent, TeleopScript)
        if script is not None and self._script_next.get(ent, 0) < len(script.keyframes):
            self._script_next[ent] = len(script.keyframes)
            ctx.services.note(ctx.sim_time_s, msg.vehicle, f"teleop_script stopped: a live {msg.kind} command "
                                                           "took over")

    def _take(self, ctx: StepContext, ent: int, msg: object) -> str:
        self._stop_script(ctx, ent, msg)
        return self._apply(ctx, ent, msg)

    def _hold_after_lapse(self, ctx: StepContext, ent: int, row: int) -> None:
        """No new teleop/cmd_vel within the command timeout: hover where the drone is."""
        f = ctx.fleet
        f.cmd_hold_until_s[row] = np.inf
        if f.flight_mode[row] not in (FlightMode.MANUAL, FlightMode.VELOCITY):
            return
        was = "teleop" if f.flight_mode[row] == FlightMode.MANUAL else "cmd_vel"
        _hold_position(f, row)
        f.nav_state[row] = NavState.HOLD
        name = esper.component_for_entity(ent, Identity).name
        ctx.services.note(ctx.sim_time_s, name, f"{was} timed out (no new command within the command timeout): "
                                                "holding position")

    def _apply(self, ctx: StepContext, ent: int, msg: object) -> str | Refusal:
        """Apply one command (values already checked by ``command_checks``); refuse it when the drone's
        state does not allow it. Returns "" (accepted), a Refusal, or why a value is invalid."""
        f = ctx.fleet
        row = esper.component_for_entity(ent, FleetSlot).row
        lim = esper.component_for_entity(ent, GuidanceLimits)
        handler = getattr(self, "_on_" + type(msg).__name__, None)
        if handler is not None:
            return handler(ctx, ent, row, msg)
        if isinstance(msg, SetTarget):
            pos = f.pos_enu_m[row].copy()
            cruise = msg.speed_m_s if msg.speed_m_s is not None else lim.cruise_speed_m_s
            sp = (cruise, lim.climb_speed_m_s, lim.descent_speed_m_s)
            yaw = np.nan if msg.yaw_rad is None else msg.yaw_rad
            _cancel_mission(ctx, ent, "set_target")
            _end_nav_mode(ent)
            f.flight_mode[row] = FlightMode.AUTO
            f.nav_state[row] = NavState.GOTO
            set_route(f, row, Route(np.array([pos, msg.pos_enu_m], dtype=float), np.array([sp, sp]), float(yaw)))
            ctx.services.note(ctx.sim_time_s, msg.vehicle, f"target set to {tuple(round(v, 2) for v in msg.pos_enu_m)}")
            warn_if_obstructed(ctx, ent, msg.vehicle, pos, np.asarray(msg.pos_enu_m, dtype=float))
            return ""
        if isinstance(msg, Teleop):
            f.stick[row] = msg.stick
            if f.flight_mode[row] != FlightMode.MANUAL:
                _cancel_mission(ctx, ent, "teleop")
                _end_nav_mode(ent)
                f.flight_mode[row] = FlightMode.MANUAL
            f.nav_state[row] = NavState.MANUAL
            return ""
        if isinstance(msg, CmdVel):
            f.vel_cmd_flu_m_s[row] = (msg.forward_m_s, msg.left_m_s, msg.up_m_s)
            f.yaw_rate_cmd_rad_s[row] = msg.yaw_rate_rad_s
            if f.flight_mode[row] != FlightMode.VELOCITY:
                _cancel_mission(ctx, ent, "cmd_vel")
                _end_nav_mode(ent)
                f.flight_mode[row] = FlightMode.VELOCITY    # the position layer restarts its memory
            f.nav_state[row] = NavState.OFFBOARD
            return ""
        if isinstance(msg, LoadMission):
            if esper.has_component(ent, MissionRuntime):
                esper.remove_component(ent, MissionRuntime)
            esper.add_component(ent, MissionRuntime(spec=msg.mission, stage_started_s=ctx.sim_time_s))
            _end_nav_mode(ent)
            f.nav_state[row] = NavState.MISSION
            f.mission_state[row] = MissionState.RUNNING
            ctx.services.note(ctx.sim_time_s, msg.vehicle, f"mission {msg.mission.name} loaded "
                                                           f"({len(msg.mission.steps)} steps)")
            return ""
        return Refusal(CommandStatus.REJECTED_INVALID, "unsupported",
                       f"a drone does not take {type(msg).__name__} commands yet")

    # -- arming ------------------------------------------------------------------------------
    def _on_Arm(self, ctx: StepContext, ent: int, row: int, msg: Arm) -> str | Refusal:
        f = ctx.fleet
        nav, params = ensure_nav(ent)
        armed = f.flight_mode[row] != FlightMode.DISARMED
        if msg.armed:
            if armed:
                return ""
            if not msg.force:
                why = arming_refusal(f, ent, row, nav, params)
                if why is not None:
                    return why
            if f.landed_state[row] in (LandedState.ON_GROUND, LandedState.UNDEFINED):
                f.home_enu_m[row] = f.pos_enu_m[row]
                f.home_set[row] = True
            nav.armed_s, nav.took_off = ctx.sim_time_s, False
            f.flight_mode[row] = FlightMode.AUTO
            if f.nav_state[row] == NavState.OFFBOARD and nav.offboard is not None:
                fly_offboard(ctx, ent, row, nav, ensure_nav(ent)[1], new=True)
            else:
                hold(ctx, ent, row)
            return ""
        if not armed:
            return ""
        if not msg.force and f.landed_state[row] not in (LandedState.ON_GROUND, LandedState.UNDEFINED):
            return Refusal(CommandStatus.REJECTED_STATE, "in_air",
                           "Disarming denied: the drone is in the air (land first, or force it)")
        _cancel_mission(ctx, ent, "disarm")
        disarm(ctx, ent, row, "commanded" + (" (forced)" if msg.force else ""))
        return ""

    def _on_Terminate(self, ctx: StepContext, ent: int, row: int, msg: Terminate) -> str | Refusal:
        _cancel_mission(ctx, ent, "flight termination")
        disarm(ctx, ent, row, "flight termination: motors off")
        return ""

    # -- navigation modes --------------------------------------------------------------------
    def _on_SetNavMode(self, ctx: StepContext, ent: int, row: int, msg: SetNavMode) -> str | Refusal:
        try:
            mode = NavState(msg.nav_state)
        except ValueError:
            return Refusal(CommandStatus.REJECTED_INVALID, "unknown_mode", f"unknown navigation mode {msg.nav_state!r}")
        if mode == NavState.HOLD:
            return self._to_hold(ctx, ent, row)
        if mode == NavState.TAKEOFF:
            return self._on_Takeoff(ctx, ent, row, Takeoff(msg.vehicle))
        if mode == NavState.LAND:
            return self._on_Land(ctx, ent, row, Land(msg.vehicle))
        if mode == NavState.RTL:
            return self._on_ReturnToLaunch(ctx, ent, row, ReturnToLaunch(msg.vehicle))
        if mode == NavState.MISSION:
            return _start_mission(ctx, ent, row, None)
        if mode == NavState.OFFBOARD:
            return self._to_offboard(ctx, ent, row)
        if mode in (NavState.POSCTL, NavState.MANUAL):
            return self._to_manual(ctx, ent, row, mode)
        if mode == NavState.FOLLOW_TARGET:
            return self._to_follow(ctx, ent, row)
        return Refusal(CommandStatus.REJECTED_INVALID, "unsupported",
                       f"navigation mode {mode.name} is not available through SetNavMode yet")

    def _to_offboard(self, ctx: StepContext, ent: int, row: int) -> str | Refusal:
        """OFFBOARD needs a setpoint from the last COM_OF_LOSS_T seconds (PX4: stream before switching)."""
        nav, params = ensure_nav(ent)
        if not offboard_fresh(nav, params, ctx.sim_time_s):
            return Refusal(CommandStatus.REJECTED_STATE, "no_setpoint_stream",
                           f"Offboard denied: no setpoint within COM_OF_LOSS_T = {params['COM_OF_LOSS_T']:g} s "
                           "(stream setpoints first)")
        _pause_mission(ctx, ent, "offboard")
        _end_nav_mode(ent)
        ctx.fleet.nav_state[row] = NavState.OFFBOARD
        fly_offboard(ctx, ent, row, nav, params, new=True)
        return ""

    def _on_OffboardSetpoint(self, ctx: StepContext, ent: int, row: int, msg: OffboardSetpoint) -> str | Refusal:
        """Keep the newest setpoint of the stream (checked by command_checks.check_offboard_setpoint); fly it
        when the drone is in OFFBOARD."""
        nav, params = ensure_nav(ent)
        nav.offboard, nav.offboard_s = msg, ctx.sim_time_s
        if ctx.fleet.nav_state[row] == NavState.OFFBOARD and not nav.mode:
            fly_offboard(ctx, ent, row, nav, params, new=True)
        return ""

    def _to_manual(self, ctx: StepContext, ent: int, row: int, mode: NavState) -> str | Refusal:
        """POSCTL / MANUAL need sticks (ManualControl) from the last COM_RC_LOSS_T seconds."""
        nav, params = ensure_nav(ent)
        if not manual_fresh(nav, params, ctx.sim_time_s):
            return Refusal(CommandStatus.REJECTED_STATE, "no_manual_control",
                           f"{mode.name} denied: no manual control within COM_RC_LOSS_T = "
                           f"{params['COM_RC_LOSS_T']:g} s")
        _pause_mission(ctx, ent, mode.name.lower())
        _end_nav_mode(ent)
        ctx.fleet.nav_state[row] = mode
        fly_manual(ctx, row, nav, params)
        return ""

    def _on_ManualControl(self, ctx: StepContext, ent: int, row: int, msg: ManualControl) -> str | Refusal:
        """Keep the newest sticks; fly them in POSCTL / MANUAL; sticks back after a loss restore the mode."""
        f = ctx.fleet
        nav, params = ensure_nav(ent)
        nav.manual, nav.manual_s = msg, ctx.sim_time_s
        if nav.mode == "rc_lost":
            f.nav_state[row] = int(nav.phase)
            _end_nav_mode(ent)
            ctx.services.note(ctx.sim_time_s, msg.vehicle, "manual control regained")
        if f.nav_state[row] in (NavState.POSCTL, NavState.MANUAL) and not nav.mode:
            fly_manual(ctx, row, nav, params)
        return ""

    def _on_Orbit(self, ctx: StepContext, ent: int, row: int, msg: Orbit) -> str | Refusal:
        f = ctx.fleet
        refusal = _airborne_refusal(f, row, "Orbit")
        if refusal is not None:
            return refusal
        _pause_mission(ctx, ent, "orbit")
        start_orbit(ctx, ent, row, msg)
        return ""

    def _on_FollowTargetFix(self, ctx: StepContext, ent: int, row: int, msg: FollowTargetFix) -> str | Refusal:
        nav, _ = ensure_nav(ent)
        nav.follow, nav.follow_s = msg, ctx.sim_time_s
        if msg.vel_enu_m_s is not None and math.hypot(msg.vel_enu_m_s[0], msg.vel_enu_m_s[1]) > 0.5:
            nav.follow_course_rad = math.atan2(msg.vel_enu_m_s[1], msg.vel_enu_m_s[0])
        return ""

    def _to_follow(self, ctx: StepContext, ent: int, row: int) -> str | Refusal:
        f = ctx.fleet
        nav, _ = ensure_nav(ent)
        refusal = _airborne_refusal(f, row, "Follow target")
        if refusal is not None:
            return refusal
        if not follow_fresh(nav, ctx.sim_time_s):
            return Refusal(CommandStatus.REJECTED_STATE, "no_target", "Follow target denied: no target fix received")
        _pause_mission(ctx, ent, "follow target")
        start_follow(ctx, ent, row)
        return ""

    def _on_SetGeofence(self, ctx: StepContext, ent: int, row: int, msg: SetGeofence) -> str | Refusal:
        nav, _ = ensure_nav(ent)
        nav.fence, nav.fence_ok = msg.fence, True
        ctx.services.note(ctx.sim_time_s, msg.vehicle, "geofence cleared" if msg.fence is None else "geofence set")
        return ""

    def _on_SetFenceEnabled(self, ctx: StepContext, ent: int, row: int, msg: SetFenceEnabled) -> str | Refusal:
        """Enable or disable the drone's geofence (PX4's MAV_CMD_DO_FENCE_ENABLE): disabled, a breach is
        neither acted on nor refuses arming; enabled again, a drone outside it gets GF_ACTION at once."""
        nav, _ = ensure_nav(ent)
        if nav.fence_enabled != msg.enabled:
            nav.fence_enabled, nav.fence_ok = msg.enabled, True
            ctx.services.note(ctx.sim_time_s, msg.vehicle, "geofence " + ("enabled" if msg.enabled else "disabled"))
        return ""

    def _to_hold(self, ctx: StepContext, ent: int, row: int) -> str | Refusal:
        _pause_mission(ctx, ent, "hold")
        hold(ctx, ent, row)
        return ""

    def _on_Takeoff(self, ctx: StepContext, ent: int, row: int, msg: Takeoff) -> str | Refusal:
        f = ctx.fleet
        if f.flight_mode[row] == FlightMode.DISARMED:
            return Refusal(CommandStatus.REJECTED_STATE, "not_armed", "Takeoff denied: arm the drone first")
        if msg.alt_enu_m is not None and msg.alt_enu_m <= f.pos_enu_m[row, 2]:
            if f.landed_state[row] != LandedState.ON_GROUND:
                return Refusal(CommandStatus.REJECTED_STATE, "in_air",
                               f"Takeoff denied: already above z = {msg.alt_enu_m:g} m")
            return f"takeoff altitude z = {msg.alt_enu_m:g} m is not above the drone (z = {f.pos_enu_m[row, 2]:.2f} m)"
        _pause_mission(ctx, ent, "takeoff")
        start_takeoff(ctx, ent, row, msg.alt_enu_m, msg.yaw_rad)
        return ""

    def _on_Land(self, ctx: StepContext, ent: int, row: int, msg: Land) -> str | Refusal:
        f = ctx.fleet
        if f.flight_mode[row] == FlightMode.DISARMED:
            return Refusal(CommandStatus.REJECTED_STATE, "not_armed", "Land denied: the drone is disarmed")
        if f.landed_state[row] == LandedState.ON_GROUND and msg.xy_enu_m is None:
            return Refusal(CommandStatus.REJECTED_STATE, "landed", "Land denied: already on the ground")
        _pause_mission(ctx, ent, "land")
        start_land(ctx, ent, row, None if msg.xy_enu_m is None else np.asarray(msg.xy_enu_m, dtype=float))
        return ""

    def _on_ReturnToLaunch(self, ctx: StepContext, ent: int, row: int, msg: ReturnToLaunch) -> str | Refusal:
        f = ctx.fleet
        refusal = _airborne_refusal(f, row, "RTL")
        if refusal is not None:
            return refusal
        _pause_mission(ctx, ent, "rtl")
        start_rtl(ctx, ent, row)
        return ""

    # -- missions ----------------------------------------------------------------------------
    def _on_StoreMission(self, ctx: StepContext, ent: int, row: int, msg: StoreMission) -> str | Refusal:
        f = ctx.fleet
        old = esper.try_component(ent, MissionRuntime)
        was_running = old is not None and old.state == "running"
        if old is not None:
            esper.remove_component(ent, MissionRuntime)
        if msg.mission is None:
            f.mission_state[row] = MissionState.NONE
            f.mission_step[row] = -1
            ctx.services.note(ctx.sim_time_s, msg.vehicle, "mission cleared")
        else:
            esper.add_component(ent, MissionRuntime(spec=msg.mission, state="stored", stage_started_s=ctx.sim_time_s))
            f.mission_state[row] = MissionState.STORED
            f.mission_step[row] = -1
            ctx.services.note(ctx.sim_time_s, msg.vehicle, f"mission {msg.mission.name} stored "
                                                           f"({len(msg.mission.steps)} steps)")
        if was_running:
            f.charging[row] = False
            hold(ctx, ent, row)
        return ""

    def _on_StartMission(self, ctx: StepContext, ent: int, row: int, msg: StartMission) -> str | Refusal:
        return _start_mission(ctx, ent, row, msg.first_step)

    def _on_SetMissionCurrent(self, ctx: StepContext, ent: int, row: int, msg: SetMissionCurrent) -> str | Refusal:
        rt = esper.try_component(ent, MissionRuntime)
        if rt is None:
            return Refusal(CommandStatus.REJECTED_STATE, "no_mission", "no mission to set the current step of")
        if not 0 <= msg.step < len(rt.spec.steps):
            return f"mission step {msg.step} does not exist (the mission has {len(rt.spec.steps)} steps)"
        rt.step_index = msg.step
        rt.stage, rt.stage_started_s, rt.scratch = "wait_before", ctx.sim_time_s, {}
        if rt.state == "completed":
            rt.state = "stored"
            ctx.fleet.mission_state[row] = MissionState.STORED
        ctx.services.note(ctx.sim_time_s, msg.vehicle, f"mission current step set to {msg.step}")
        return ""

    def _on_PauseMission(self, ctx: StepContext, ent: int, row: int, msg: PauseMission) -> str | Refusal:
        rt = esper.try_component(ent, MissionRuntime)
        if rt is None:
            return Refusal(CommandStatus.REJECTED_STATE, "no_mission", "no mission to pause or continue")
        if msg.resume:
            if rt.state != "paused":
                return Refusal(CommandStatus.REJECTED_STATE, "not_paused", f"the mission is {rt.state}, not paused")
            return _start_mission(ctx, ent, row, None)
        if rt.state != "running":
            return Refusal(CommandStatus.REJECTED_STATE, "not_running", f"the mission is {rt.state}, not running")
        return self._to_hold(ctx, ent, row)

    # -- parameters, home, speed, rally, gripper -----------------------------------------------
    def _on_SetParam(self, ctx: StepContext, ent: int, row: int, msg: SetParam) -> str | Refusal:
        _, params = ensure_nav(ent)
        error = params.set(msg.name, msg.value)
        if error:
            return Refusal(CommandStatus.REJECTED_INVALID, "unknown_param" if msg.name not in params.values
                           else "out_of_range", error)
        ctx.services.note(ctx.sim_time_s, msg.vehicle, f"parameter {msg.name} set to {params[msg.name]:g}")
        return ""

    def _on_SetHome(self, ctx: StepContext, ent: int, row: int, msg: SetHome) -> str | Refusal:
        f = ctx.fleet
        f.home_enu_m[row] = f.pos_enu_m[row] if msg.pos_enu_m is None else msg.pos_enu_m
        f.home_set[row] = True
        x, y, z = f.home_enu_m[row]
        ctx.services.note(ctx.sim_time_s, msg.vehicle, f"home set to ({x:.1f}, {y:.1f}, {z:.1f})")
        return ""

    def _on_ChangeSpeed(self, ctx: StepContext, ent: int, row: int, msg: ChangeSpeed) -> str | Refusal:
        f = ctx.fleet
        if msg.which not in _SPEED_COLUMN:
            return f"speed kind must be one of {sorted(_SPEED_COLUMN)}, got {msg.which!r}"
        nav, _ = ensure_nav(ent)
        nav.speeds[msg.which] = float(msg.speed_m_s)
        route = f.route[row]
        if route is not None and f.flight_mode[row] == FlightMode.AUTO:
            seg = int(f.route_segment[row])
            pts = np.vstack([f.pos_enu_m[row], route.points_enu_m[seg + 1:]])
            sps = np.vstack([route.speeds_m_s[seg + 1:seg + 2], route.speeds_m_s[seg + 1:]]).copy()
            sps[:, _SPEED_COLUMN[msg.which]] = msg.speed_m_s
            if pts.shape[0] >= 2:
                set_route(f, row, Route(pts, sps, route.yaw_sp_rad))
        ctx.services.note(ctx.sim_time_s, msg.vehicle, f"{msg.which} speed set to {msg.speed_m_s:g} m/s")
        return ""

    def _on_SetRallyPoints(self, ctx: StepContext, ent: int, row: int, msg: SetRallyPoints) -> str | Refusal:
        nav, _ = ensure_nav(ent)
        nav.rally_enu_m = tuple(tuple(float(v) for v in p) for p in msg.points_enu_m)
        return ""

    def _on_Gripper(self, ctx: StepContext, ent: int, row: int, msg: Gripper) -> str | Refusal:
        f = ctx.fleet
        if msg.grab:
            if f.payload_entity[row] >= 0:
                return Refusal(CommandStatus.REJECTED_STATE, "holding", "the gripper already holds a package")
            f.payload_package[row] = None
            f.payload_request[row] = PayloadRequest.ATTACH
        else:
            if f.payload_entity[row] < 0:
                return Refusal(CommandStatus.REJECTED_STATE, "empty", "the gripper holds nothing")
            f.payload_request[row] = PayloadRequest.RELEASE
        f.payload_result[row] = PayloadResult.NONE
        return ""


_SPEED_COLUMN = {"ground": 0, "climb": 1, "descent": 2}


def _airborne_refusal(f, row: int, what: str) -> Refusal | None:
    """Why ``what`` (an action for a flying drone: orbit, follow, land, RTL) cannot start now, or None."""
    if f.flight_mode[row] == FlightMode.DISARMED:
        return Refusal(CommandStatus.REJECTED_STATE, "not_armed", f"{what} denied: the drone is disarmed")
    if f.landed_state[row] == LandedState.ON_GROUND:
        return Refusal(CommandStatus.REJECTED_STATE, "landed", f"{what} denied: the drone is on the ground")
    return None


def _end_nav_mode(ent: int) -> None:
    nav = esper.try_component(ent, NavRuntime)
    if nav is not None:
        nav.mode, nav.phase, nav.goal_enu_m = "", "", None


def _pause_mission(ctx: StepContext, ent: int, why: str) -> None:
    """A mode switch away from MISSION pauses the mission (MISSION mode or PauseMission resumes it)."""
    rt = esper.try_component(ent, MissionRuntime)
    if rt is not None and rt.state == "running":
        rt.state, rt.reason = "paused", why
        row = ctx.fleet.row_of(ent)
        ctx.fleet.charging[row] = False
        ctx.fleet.mission_state[row] = MissionState.PAUSED
        ctx.services.note(ctx.sim_time_s, esper.component_for_entity(ent, Identity).name,
                          f"mission {rt.spec.name} paused at step {rt.step_index} by {why}")


def _start_mission(ctx: StepContext, ent: int, row: int, first_step: int | None) -> str | Refusal:
    """Run the drone's mission from ``first_step`` (None: resume a paused one at its current step, restart
    a finished one). On the ground it takes off first when the step flies somewhere (PX4's implicit takeoff)."""
    f = ctx.fleet
    rt = esper.try_component(ent, MissionRuntime)
    if rt is None:
        return Refusal(CommandStatus.REJECTED_STATE, "no_mission", "Mission denied: no mission uploaded")
    n = len(rt.spec.steps)
    if first_step is None:
        first_step = rt.step_index if rt.state in ("paused", "stored", "running") else 0
    if not 0 <= first_step < n:
        return f"mission step {first_step} does not exist (the mission has {n} steps)"
    _end_nav_mode(ent)
    rt.step_index, rt.state, rt.reason = first_step, "running", ""
    rt.stage, rt.stage_started_s, rt.scratch = "wait_before", ctx.sim_time_s, {}
    if f.landed_state[row] in (LandedState.ON_GROUND, LandedState.UNDEFINED) and \
            rt.spec.steps[first_step].type in ("cruise", "pickup", "return"):
        rt.scratch["takeoff_first"] = True
    f.nav_state[row] = NavState.MISSION
    f.mission_state[row] = MissionState.RUNNING
    name = esper.component_for_entity(ent, Identity).name
    ctx.services.note(ctx.sim_time_s, name, f"mission {rt.spec.name} started at step {first_step}")
    return ""


def _hold_position(f, row: int) -> None:
    """AUTO mode on a route that starts and ends where the drone is: hover (or stay) there."""
    f.flight_mode[row] = FlightMode.AUTO
    pos = f.pos_enu_m[row].copy()
    sp = np.ones(3)
    set_route(f, row, Route(np.array([pos, pos]), np.array([sp, sp]), np.nan))


def _cancel_mission(ctx: StepContext, ent: int, why: str) -> None:
    rt = esper.try_component(ent, MissionRuntime)
    if rt is not None and rt.state in ("running", "paused"):
        rt.state, rt.reason = "cancelled", why
        ctx.fleet.charging[ctx.fleet.row_of(ent)] = False
        ctx.fleet.mission_state[ctx.fleet.row_of(ent)] = MissionState.CANCELLED
        name = esper.component_for_entity(ent, Identity).name
        ctx.services.note(ctx.sim_time_s, name, f"mission {rt.spec.name} cancelled by {why}")
