"""PHYSICS phase: apply the accumulated external wrenches, then advance PyBullet by one step."""

from __future__ import annotations

import esper

from ..phases import Phase
from ..world import StepContext


class PhysicsStepSystem(esper.Processor):
    """Apply ``force_cmd_enu_n``/``torque_cmd_enu_n_m`` of every body, step PyBullet, clear them.

    Phase: PHYSICS. Reads: fleet.force_cmd_enu_n, fleet.torque_cmd_enu_n_m, fleet.pos_enu_m.
    Writes: the PyBullet world; clears the wrench accumulators.
    """

    phase = Phase.PHYSICS
    order = 0

    def __init__(self) -> None:
        self._seen_version = -1
        self._bodies: list[int] = []

    def process(self, ctx: StepContext) -> None:
        f = ctx.fleet
        if f.version != self._seen_version:              # rows allocated or freed: their body ids again
            self._bodies = f.body_id[f.rows].tolist()
            self._seen_version = f.version
        if self._bodies:
            r = f.active                                 # a slice when the rows are contiguous: views
            # the wrenches go to PyBullet as Python floats (tolist copies), so the arrays can be cleared after
            ctx.physics.apply_wrenches(self._bodies, f.pos_enu_m[r], f.force_cmd_enu_n[r], f.torque_cmd_enu_n_m[r])
            f.force_cmd_enu_n[r] = 0.0
            f.torque_cmd_enu_n_m[r] = 0.0
        ctx.physics.step()
