"""ACTUATE phase, layer 1: per-motor thrust of every quadrotor, and its resultant on the body.

The paper's §2.1.1: the mixer layer (``controller: {mixer: ...}``, default ``x_quad_priority``:
X configuration, attitude-priority desaturation) has turned the collective thrust and the
normalised roll/pitch/yaw commands into a fraction of F_max per motor; this system adds the
optional first-order motor lag. Each motor's force acts along the body z axis at its motor's
position (roll and pitch torques arise from the lever arms) and yaw comes only from the rotor
reaction torques ``kappa * F_i`` with alternating spin directions; for the rigid body these are
exactly one force at the centre of mass and one torque (:mod:`..control.rotor_wrench`), which is
what goes to PyBullet, added to the body's ``force_cmd_enu_n`` / ``torque_cmd_enu_n_m``.
"""

from __future__ import annotations

import numpy as np

from ..components.flight import QuadrotorMotors
from ..control.mixer import motor_positions_flu_m
from ..control.rotor_wrench import rotor_torque_matrix_flu, rotor_wrench_enu
from ..phases import Phase
from ..world import StepContext
from .fleet_system import FleetSystem
from .flight_state import MODE_DISARMED


class MotorSystem(FleetSystem):
    """Lag and apply the mixer's motor thrusts for every quadrotor in one pass.

    Phase: ACTUATE (order 20, after the mixer layer). Reads: fleet.motor_frac_cmd, flight_mode,
    motors_enabled, R_enu_flu. Writes: fleet.motor_thrust_cmd_n, motor_thrust_n; adds the rotors'
    resultant force and torque to force_cmd_enu_n and torque_cmd_enu_n_m (applied in PHYSICS).
    """

    phase = Phase.ACTUATE
    order = 20
    requires = (QuadrotorMotors,)

    def gather(self, ctx: StepContext) -> None:
        (comps,) = self.components
        self._f_max = np.array([c.max_thrust_per_motor_n for c in comps])
        self._kappa = np.array([c.yaw_moment_coeff_m for c in comps])
        tau = np.array([c.motor_tau_s for c in comps], dtype=float)
        self._alpha = np.where(tau > 0.0, 1.0 - np.exp(-ctx.dt_s / np.maximum(tau, 1e-12)), 1.0)   # lag per step
        self._torque_matrix = rotor_torque_matrix_flu(motor_positions_flu_m(np.array([c.arm_length_m for c in comps])),
                                                      self._kappa)                    # (M, 3, 4)

    def update(self, ctx: StepContext) -> None:
        f = ctx.fleet
        r = self.sel
        live = (f.flight_mode[r] != MODE_DISARMED) & f.motors_enabled[r]
        cmd = f.motor_frac_cmd[r] * (self._f_max * live)[:, None]
        f.motor_thrust_cmd_n[r] = cmd
        lagged = f.motor_thrust_n[r]
        # a disabled motor stops at once
        thrust = np.where(live[:, None], lagged + self._alpha[:, None] * (cmd - lagged), 0.0)
        f.motor_thrust_n[r] = thrust
        force, torque = rotor_wrench_enu(thrust, f.R_enu_flu[r], self._torque_matrix)
        f.force_cmd_enu_n[r] += force
        f.torque_cmd_enu_n_m[r] += torque
