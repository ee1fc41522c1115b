"""COMMANDS phase: route queued commands (API, ROS 2, MAVLink, teleop) to the vehicles' command systems.

Commands arrive as frozen messages in the inbox. :class:`InboxSystem` drains it once per step
(keeping of the streamed kinds only the newest per vehicle and kind) into ``services.pending``; each vehicle type's
command system takes the messages addressed to its vehicles (:func:`claim`); whatever nobody took
(an unknown vehicle, a drone command sent to a car) is rejected by :class:`UnclaimedCommandSystem`
with a note in the event log. The drone's system is :mod:`.flight_commands`, the car's :mod:`.car`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import esper
import numpy as np

from ..components.body import Identity, RigidBody
from ..phases import Phase
from ..scene.obstacles import buildings_on_segment
from ..transport.api import CommandStatus
from ..transport.bus import Rejected
from ..world import StepContext


class InboxSystem(esper.Processor):
    """Drain the inbox into ``services.pending`` (streamed kinds coalesced, every other command in
    order: :meth:`Inbox.drain`); samples a transport could not turn into a command
    (:class:`~unetyemu_ecs.transport.bus.Rejected`) get their REJECTED_INVALID result here.
    Phase: COMMANDS, first. Always present."""

    phase = Phase.COMMANDS
    order = 0

    def process(self, ctx: StepContext) -> None:
        pending = ctx.services.inbox.drain()
        if pending and any(type(m) is Rejected for m in pending):
            for m in pending:
                if type(m) is Rejected:
                    ctx.services.report(ctx.sim_time_s, m, CommandStatus.REJECTED_INVALID, "invalid", m.text)
            pending = [m for m in pending if type(m) is not Rejected]
        ctx.services.pending = pending


class UnclaimedCommandSystem(esper.Processor):
    """Reject the commands no vehicle system took, naming why. Phase: COMMANDS, last. Always present."""

    phase = Phase.COMMANDS
    order = 99

    def process(self, ctx: StepContext) -> None:
        for msg in ctx.services.pending:
            ent = ctx.services.entities.get(msg.vehicle)
            if ent is None:
                reason, why = "unknown_vehicle", f"unknown vehicle {msg.vehicle!r}"
            else:
                kind = esper.component_for_entity(ent, Identity).kind
                reason, why = "unsupported", f"a {kind} does not take {type(msg).__name__} commands"
            ctx.services.report(ctx.sim_time_s, msg, CommandStatus.REJECTED_INVALID, reason, why)
        ctx.services.pending = []


def claim(ctx: StepContext, has: type, types: tuple[type, ...] | None = None) -> list[tuple[int, object]]:
    """Take from ``services.pending`` the commands for entities carrying component ``has`` (only those
    of the command classes ``types``, when given).

    Returns ``(entity, message)`` pairs in arrival order; the rest stay pending.
    """
    mine, rest = [], []
    for msg in ctx.services.pending:
        ent = ctx.services.entities.get(msg.vehicle)
        if ent is not None and esper.has_component(ent, has) and (types is None or isinstance(msg, types)):
            mine.append((ent, msg))
        else:
            rest.append(msg)
    ctx.services.pending = rest
    return mine


def hold_until_s(ctx: StepContext, msg: object) -> float:
    """Sim time [s] at which an accepted command lapses: now + its ``hold_s`` for a streamed teleop or
    cmd_vel, never (inf) for anything else."""
    hold = getattr(msg, "hold_s", None)
    return ctx.sim_time_s + hold if hold else np.inf


def lapsed_rows(ctx: StepContext) -> np.ndarray:
    """Rows whose streamed teleop/cmd_vel command has lapsed this step (``cmd_hold_until_s`` passed)."""
    return np.flatnonzero(ctx.fleet.cmd_hold_until_s <= ctx.sim_time_s + 1e-9)


@dataclass(frozen=True, slots=True)
class Refusal:
    """Why a command system did not apply a command: ``status`` (REJECTED_INVALID, REJECTED_STATE or
    FAILED), a machine-readable ``reason`` (``not_armed``, ``in_air`` ...) and ``text`` for people."""

    status: CommandStatus
    reason: str
    text: str


def serve_commands(ctx: StepContext, has: type, apply: Callable[[StepContext, int, object], str | Refusal],
                   on_lapse: Callable[[StepContext, int, int], None],
                   types: tuple[type, ...] | None = None) -> None:
    """One vehicle type's commands for this step: claim those for entities carrying ``has`` (of the
    classes ``types`` when given), apply each and report its result (``services.report``):
    ``apply(ctx, entity, msg)`` returns "" when it applied it (ACCEPTED; the row's ``cmd_hold_until_s``
    is set), a :class:`Refusal`, or a plain string (an invalid value: REJECTED_INVALID with that text).
    Then call ``on_lapse(ctx, entity, row)`` for each such entity whose streamed teleop/cmd_vel lapsed
    this step."""
    f = ctx.fleet
    for ent, msg in claim(ctx, has, types):
        outcome = apply(ctx, ent, msg)
        if isinstance(outcome, Refusal):
            ctx.services.report(ctx.sim_time_s, msg, outcome.status, outcome.reason, outcome.text)
        elif outcome:
            ctx.services.report(ctx.sim_time_s, msg, CommandStatus.REJECTED_INVALID, "invalid", outcome)
        else:
            ctx.services.report(ctx.sim_time_s, msg, CommandStatus.ACCEPTED)
            f.cmd_hold_until_s[f.row_of(ent)] = hold_until_s(ctx, msg)
    for row in lapsed_rows(ctx):
        ent = int(f.entity[row])
        if esper.has_component(ent, has):
            on_lapse(ctx, ent, int(row))


def warn_if_obstructed(ctx: StepContext, ent: int, vehicle: str, start_enu_m: np.ndarray,
                       end_enu_m: np.ndarray) -> None:
    """Say so (a warning event) when the straight line from ``start`` to a commanded target runs
    through a building; the command is still flown, as commanded."""
    half = esper.component_for_entity(ent, RigidBody).half_extents_m
    hits = buildings_on_segment(ctx.services.layout, start_enu_m, end_enu_m, clearance_m=float(np.max(half[:2])))
    if hits:
        x, y, z = hits[0].entry_enu_m
        ctx.services.note(ctx.sim_time_s, vehicle, f"warning: the straight path to the target crosses "
                                                   f"{hits[0].name} at ENU ({x:.1f}, {y:.1f}, {z:.1f}) m, "
                                                   f"{hits[0].distance_m:.0f} m ahead")
