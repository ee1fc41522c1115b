"""PHYSICS phase: apply the accumulated external wrenches, then advance PyBullet by one step."""

from __future__ import annotations

import esper
import numpy as np

from ..phases import Phase
from ..world import StepContext


class PhysicsStepSystem(esper.Processor):
    """Apply ``force_cmd_enu_n``/``torque_cmd_enu_n_m`` of every body, step PyBullet, clear them.

    Phase: PHYSICS. Reads: fleet.force_cmd_enu_n, fleet.torque_cmd_enu_n_m, fleet.pos_enu_m.
    Writes: the PyBullet world; clears the wrench accumulators.
    """

    phase = Phase.PHYSICS
    order = 0

    def process(self, ctx: StepContext) -> None:
        f = ctx.fleet
        rows = f.rows
        if rows.size:
            force = f.force_cmd_enu_n[rows]
            torque = f.torque_cmd_enu_n_m[rows]
            busy = np.any(force != 0.0, axis=1) | np.any(torque != 0.0, axis=1)
            if busy.any():
                r = rows[busy]
                ctx.physics.apply_wrenches(f.body_id[r], f.pos_enu_m[r], force[busy], torque[busy])
                f.force_cmd_enu_n[r] = 0.0
                f.torque_cmd_enu_n_m[r] = 0.0
        ctx.physics.step()
