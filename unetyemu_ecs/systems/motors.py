"""ACTUATE phase, layer 1: per-motor thrust of every quadrotor, applied at each motor's position.

The paper's §2.1.1: the mixer layer (``controller: {mixer: ...}``, default ``x_quad_priority``:
X configuration, attitude-priority desaturation) has turned the collective thrust and the
normalised roll/pitch/yaw commands into a fraction of F_max per motor; this system adds the
optional first-order motor lag; each force acts along the body z axis *at its motor's
position* (so roll and pitch torques arise from the lever arms), and yaw comes only from the rotor
reaction torques ``kappa * F_i`` with alternating spin directions.
"""

from __future__ import annotations

import numpy as np

from ..components.flight import QuadrotorMotors
from ..control.mixer import SPIN_REACTION_SIGN, motor_positions_flu_m
from ..frames import R_from_quat_xyzw
from ..phases import Phase
from ..world import StepContext
from .fleet_system import FleetSystem
from .flight_state import FlightMode


class MotorSystem(FleetSystem):
    """Lag and apply the mixer's motor thrusts for every quadrotor in one pass.

    Phase: ACTUATE (order 20, after the mixer layer). Reads: fleet.motor_frac_cmd, flight_mode,
    motors_enabled, pose. Writes: fleet.motor_thrust_cmd_n, motor_thrust_n, torque_cmd_enu_n_m (adds
    the reaction torque); applies one force per motor to PyBullet.
    """

    phase = Phase.ACTUATE
    order = 20
    requires = (QuadrotorMotors,)

    def gather(self, ctx: StepContext) -> None:
        (comps,) = self.components
        self._f_max = np.array([c.max_thrust_per_motor_n for c in comps])
        self._kappa = np.array([c.yaw_moment_coeff_m for c in comps])
        self._tau = np.array([c.motor_tau_s for c in comps])
        self._r_flu = motor_positions_flu_m(np.array([c.arm_length_m for c in comps]))   # (M, 4, 3)
        self._bodies4 = np.repeat(ctx.fleet.body_id[self.rows], 4)

    def update(self, ctx: StepContext) -> None:
        f = ctx.fleet
        r = self.rows
        live = (f.flight_mode[r] != FlightMode.DISARMED) & f.motors_enabled[r]
        cmd = f.motor_frac_cmd[r] * (self._f_max * live)[:, None]
        f.motor_thrust_cmd_n[r] = cmd
        alpha = np.where(self._tau > 0.0, 1.0 - np.exp(-ctx.dt_s / np.maximum(self._tau, 1e-12)), 1.0)
        thrust = f.motor_thrust_n[r] + alpha[:, None] * (cmd - f.motor_thrust_n[r])
        thrust = np.where(live[:, None], thrust, 0.0)        # a disabled motor stops at once
        f.motor_thrust_n[r] = thrust

        R_enu_flu = R_from_quat_xyzw(f.quat_enu_flu_xyzw[r])                          # (M, 3, 3)
        z_body_enu = R_enu_flu[:, :, 2]                                                # (M, 3)
        points = f.pos_enu_m[r][:, None, :] + np.einsum("mij,mkj->mki", R_enu_flu, self._r_flu)   # (M, 4, 3)
        forces = thrust[:, :, None] * z_body_enu[:, None, :]                           # (M, 4, 3)
        busy = thrust.reshape(-1) > 0.0
        if busy.any():
            ctx.physics.apply_point_forces(self._bodies4[busy], forces.reshape(-1, 3)[busy],
                                           points.reshape(-1, 3)[busy])
        yaw_torque_n_m = self._kappa * (thrust @ SPIN_REACTION_SIGN)                     # about body z
        f.torque_cmd_enu_n_m[r] += yaw_torque_n_m[:, None] * z_body_enu
