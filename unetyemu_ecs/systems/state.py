"""STATE phase: read every body's pose and velocity back from PyBullet into the fleet arrays, once."""

from __future__ import annotations

import esper
import numpy as np

from ..control.compiled import jit
from ..frames import set_R_from_quat_xyzw
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
        self._rows = np.empty(0, dtype=np.intp)

    def prime(self, ctx: StepContext) -> None:
        """Read the initial state (before the first step) so that phases before STATE see real poses."""
        self._read(ctx, first=True)

    def process(self, ctx: StepContext) -> None:
        self._read(ctx, first=False)

    def _read(self, ctx: StepContext, first: bool) -> None:
        f = ctx.fleet
        if f.version != self._seen_version:
            self._rows = f.rows
            self._bodies = f.body_id[self._rows].tolist()
            self._seen_version = f.version
            first = True
        if not self._bodies:
            return
        store_body_states(self._rows, ctx.physics.read_states(self._bodies), ctx.dt_s, first, f.pos_enu_m,
                          f.quat_enu_flu_xyzw, f.vel_enu_m_s, f.rate_enu_rad_s, f.rate_flu_rad_s, f.R_enu_flu,
                          f.acc_enu_m_s2, f.odometer_m)


@jit
def store_body_states(rows, state, dt_s, first, pos_enu_m, quat_enu_flu_xyzw, vel_enu_m_s, rate_enu_rad_s,
                      rate_flu_rad_s, R_enu_flu, acc_enu_m_s2, odometer_m):
    """Write the PyBullet ``state`` (M, 13) of the bodies in fleet ``rows`` (position, quaternion xyzw,
    velocity, angular velocity, world frame) into the fleet arrays, with the attitude also as a rotation
    matrix, the angular velocity in body FLU (``R^T w``), the acceleration as the velocity's difference over
    ``dt_s`` (0 when ``first``) and the distance moved added to the odometer (not when ``first``)."""
    for k in range(rows.shape[0]):
        r = rows[k]
        s = state[k]
        if first:
            acc_enu_m_s2[r] = 0.0
        else:
            for i in range(3):
                acc_enu_m_s2[r, i] = (s[7 + i] - vel_enu_m_s[r, i]) / dt_s
            dx, dy, dz = s[0] - pos_enu_m[r, 0], s[1] - pos_enu_m[r, 1], s[2] - pos_enu_m[r, 2]
            odometer_m[r] += np.sqrt(dx * dx + dy * dy + dz * dz)
        pos_enu_m[r] = s[0:3]
        quat_enu_flu_xyzw[r] = s[3:7]
        vel_enu_m_s[r] = s[7:10]
        rate_enu_rad_s[r] = s[10:13]
        R = R_enu_flu[r]
        set_R_from_quat_xyzw(s[3:7], R)
        for j in range(3):                                   # R^T w
            rate_flu_rad_s[r, j] = R[0, j] * s[10] + R[1, j] * s[11] + R[2, j] * s[12]
