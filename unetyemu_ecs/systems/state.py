"""STATE phase: read every body's pose and velocity back from PyBullet into the fleet arrays, once."""

from __future__ import annotations

import esper
import numpy as np

from ..frames import R_from_quat_xyzw, row_norm
from ..phases import Phase
from ..world import StepContext


class StateReadbackSystem(esper.Processor):
    """Copy base pose/velocity of all active rows from PyBullet; derive body rates and acceleration.

    Phase: STATE. Reads: PyBullet. Writes: fleet.pos_enu_m, quat_enu_flu_xyzw, vel_enu_m_s,
    rate_enu_rad_s, rate_flu_rad_s, R_enu_flu, acc_enu_m_s2 (velocity difference over the step), odometer_m.

    Not a :class:`~unetyemu_ecs.systems.fleet_system.FleetSystem`: its rows are every body, whatever
    its components, and it needs nothing but their body ids, which change only when rows are
    allocated or freed, so ``fleet.version`` alone tells it when to look again.
    """

    phase = Phase.STATE
    order = 0

    def __init__(self) -> None:
        self._seen_version = -1
        self._bodies: list[int] = []

    def prime(self, ctx: StepContext) -> None:
        """Read the initial state (before the first step) so that phases before STATE see real poses."""
        self._read(ctx, first=True)

    def process(self, ctx: StepContext) -> None:
        self._read(ctx, first=False)

    def _read(self, ctx: StepContext, first: bool) -> None:
        f = ctx.fleet
        if f.version != self._seen_version:
            self._bodies = f.body_id[f.rows].tolist()
            self._seen_version = f.version
            first = True
        r = f.active                                     # the active rows (a slice when contiguous)
        if not self._bodies:
            return
        state = ctx.physics.read_states(self._bodies)                # (M, 13)
        pos, quat, vel, rate = state[:, 0:3], state[:, 3:7], state[:, 7:10], state[:, 10:13]
        if first:
            f.acc_enu_m_s2[r] = 0.0
        else:
            f.acc_enu_m_s2[r] = (vel - f.vel_enu_m_s[r]) / ctx.dt_s
            f.odometer_m[r] += row_norm(pos - f.pos_enu_m[r])
        f.pos_enu_m[r] = pos
        f.quat_enu_flu_xyzw[r] = quat
        f.vel_enu_m_s[r] = vel
        f.rate_enu_rad_s[r] = rate
        R_enu_flu = R_from_quat_xyzw(quat)                     # (M, 3, 3)
        f.R_enu_flu[r] = R_enu_flu
        f.rate_flu_rad_s[r] = np.einsum("mji,mj->mi", R_enu_flu, rate)   # R^T @ w_enu
