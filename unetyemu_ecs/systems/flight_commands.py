"""COMMANDS phase, drones: turn commands into flight modes, routes, sticks and missions; scripted teleop."""

from __future__ import annotations

import math

import esper
import numpy as np

from ..components.body import FleetSlot, Identity
from ..components.flight import GuidanceLimits, TeleopScript
from ..components.mission import MissionRuntime
from ..phases import Phase
from ..transport.bus import Arm, CmdVel, LoadMission, SetTarget, Teleop
from ..world import StepContext
from .commands import serve_commands, warn_if_obstructed
from .flight_state import FlightMode, Route, set_route


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

    def process(self, ctx: StepContext) -> None:
        f = ctx.fleet
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
        name = esper.component_for_entity(ent, Identity).name
        ctx.services.note(ctx.sim_time_s, name, f"{was} timed out (no new command within the command timeout): "
                                                "holding position")

    def _apply(self, ctx: StepContext, ent: int, msg: object) -> str:
        f = ctx.fleet
        row = esper.component_for_entity(ent, FleetSlot).row
        lim = esper.component_for_entity(ent, GuidanceLimits)
        if isinstance(msg, SetTarget):
            values = [*msg.pos_enu_m, *(v for v in (msg.yaw_rad, msg.speed_m_s) if v is not None)]
            if not all(math.isfinite(v) for v in values):
                return "target values must be finite numbers"
            if msg.speed_m_s is not None and msg.speed_m_s <= 0.0:
                return f"speed must be > 0, got {msg.speed_m_s}"
            pos = f.pos_enu_m[row].copy()
            cruise = msg.speed_m_s if msg.speed_m_s is not None else lim.cruise_speed_m_s
            sp = (cruise, lim.climb_speed_m_s, lim.descent_speed_m_s)
            yaw = np.nan if msg.yaw_rad is None else msg.yaw_rad
            _cancel_mission(ctx, ent, "set_target")
            f.flight_mode[row] = FlightMode.AUTO
            set_route(f, row, Route(np.array([pos, msg.pos_enu_m], dtype=float), np.array([sp, sp]), float(yaw)))
            ctx.services.note(ctx.sim_time_s, msg.vehicle, f"target set to {tuple(round(v, 2) for v in msg.pos_enu_m)}")
            warn_if_obstructed(ctx, ent, msg.vehicle, pos, np.asarray(msg.pos_enu_m, dtype=float))
            return ""
        if isinstance(msg, Teleop):
            if len(msg.stick) != 4 or not all(math.isfinite(v) and -1.0 <= v <= 1.0 for v in msg.stick):
                return "teleop needs 4 finite values in [-1, 1]"
            f.stick[row] = msg.stick
            if f.flight_mode[row] != FlightMode.MANUAL:
                _cancel_mission(ctx, ent, "teleop")
                f.flight_mode[row] = FlightMode.MANUAL
            return ""
        if isinstance(msg, CmdVel):
            cmd = (msg.forward_m_s, msg.left_m_s, msg.up_m_s, msg.yaw_rate_rad_s)
            if not all(math.isfinite(v) for v in cmd):
                return "cmd_vel values must be finite numbers"
            f.vel_cmd_flu_m_s[row] = cmd[:3]
            f.yaw_rate_cmd_rad_s[row] = msg.yaw_rate_rad_s
            if f.flight_mode[row] != FlightMode.VELOCITY:
                _cancel_mission(ctx, ent, "cmd_vel")
                f.flight_mode[row] = FlightMode.VELOCITY    # the position layer restarts its memory
            return ""
        if isinstance(msg, LoadMission):
            if esper.has_component(ent, MissionRuntime):
                esper.remove_component(ent, MissionRuntime)
            esper.add_component(ent, MissionRuntime(spec=msg.mission, stage_started_s=ctx.sim_time_s))
            ctx.services.note(ctx.sim_time_s, msg.vehicle, f"mission {msg.mission.name} loaded "
                                                           f"({len(msg.mission.steps)} steps)")
            return ""
        if isinstance(msg, Arm):
            if msg.armed:
                if f.flight_mode[row] == FlightMode.DISARMED:
                    _hold_position(f, row)
            else:
                _cancel_mission(ctx, ent, "disarm")
                f.flight_mode[row] = FlightMode.DISARMED
                set_route(f, row, None)
            return ""
        return f"unsupported command {type(msg).__name__}"


def _hold_position(f, row: int) -> None:
    """AUTO mode on a route that starts and ends where the drone is: hover (or stay) there."""
    f.flight_mode[row] = FlightMode.AUTO
    pos = f.pos_enu_m[row].copy()
    sp = np.ones(3)
    set_route(f, row, Route(np.array([pos, pos]), np.array([sp, sp]), np.nan))


def _cancel_mission(ctx: StepContext, ent: int, why: str) -> None:
    rt = esper.try_component(ent, MissionRuntime)
    if rt is not None and rt.state == "running":
        rt.state, rt.reason = "cancelled", why
        ctx.fleet.charging[ctx.fleet.row_of(ent)] = False
        name = esper.component_for_entity(ent, Identity).name
        ctx.services.note(ctx.sim_time_s, name, f"mission {rt.spec.name} cancelled by {why}")
