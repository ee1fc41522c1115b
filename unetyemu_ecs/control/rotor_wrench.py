"""The resultant of a quadrotor's four rotor forces and reaction torques, about its centre of mass.

Each motor ``i`` pushes ``f_i`` [N] along the body z axis at its hub ``r_i`` (FLU, from the centre
of mass) and its rotor twists the body by ``kappa s_i f_i`` about z (``s_i`` the spin sign). For a
rigid body these four forces are, exactly, one force at the centre of mass and one torque::

    F = (0, 0, sum f_i)            tau = sum r_i x (0, 0, f_i) + (0, 0, kappa sum s_i f_i)
                                       = (sum y_i f_i, -sum x_i f_i, kappa sum s_i f_i)

which is what the motor system hands to the physics (two calls per drone instead of five); the
per-motor thrusts, lag and energy stay per motor. ``tests/unit/test_rotor_wrench.py`` checks the
formula against the cross products and PyBullet's response to both against each other.
"""

from __future__ import annotations

import numpy as np

from .compiled import jit
from .mixer import SPIN_REACTION_SIGN


def rotor_torque_matrix_flu(motor_pos_flu_m: np.ndarray, yaw_moment_coeff_m: np.ndarray) -> np.ndarray:
    """(N, 3, 4) matrix ``L`` with ``tau_flu = L @ thrust_n`` for hubs (N, 4, 3) [m] and kappa (N,) [m]."""
    r = np.asarray(motor_pos_flu_m, dtype=float).reshape(-1, 4, 3)
    kappa = np.asarray(yaw_moment_coeff_m, dtype=float).reshape(-1)
    out = np.empty((r.shape[0], 3, 4))
    out[:, 0, :] = r[:, :, 1]                                  # roll: y_i f_i
    out[:, 1, :] = -r[:, :, 0]                                 # pitch: -x_i f_i
    out[:, 2, :] = kappa[:, None] * SPIN_REACTION_SIGN[None]   # yaw: rotor reaction
    return out


def rotor_wrench_enu(thrust_n: np.ndarray, R_enu_flu: np.ndarray, torque_matrix_flu: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray]:
    """Resultant force (N, 3) [N] and torque about the centre of mass (N, 3) [N m], both ENU, of the
    four motor thrusts ``thrust_n`` (N, 4) of bodies with attitude ``R_enu_flu`` (N, 3, 3), for the
    matrices of :func:`rotor_torque_matrix_flu`."""
    thrust = np.ascontiguousarray(thrust_n, dtype=float)
    force, torque = np.zeros((thrust.shape[0], 3)), np.zeros((thrust.shape[0], 3))
    _add_rotor_wrenches_enu(thrust, np.ascontiguousarray(R_enu_flu, dtype=float),
                            np.ascontiguousarray(torque_matrix_flu, dtype=float), force, torque)
    return force, torque


@jit
def add_rotor_wrench_enu(thrust_n, R_enu_flu, torque_matrix_flu, force_enu_n, torque_enu_n_m):
    """Add to ``force_enu_n`` (3,) and ``torque_enu_n_m`` (3,) the resultant of one body's four thrusts
    ``thrust_n`` (4,): ``F = R (0, 0, sum f_i)``, ``tau = R L f`` (kernels call this; :func:`rotor_wrench_enu`
    for arrays)."""
    L = torque_matrix_flu
    f0, f1, f2, f3 = thrust_n[0], thrust_n[1], thrust_n[2], thrust_n[3]
    tau_x = L[0, 0] * f0 + L[0, 1] * f1 + L[0, 2] * f2 + L[0, 3] * f3           # body FLU
    tau_y = L[1, 0] * f0 + L[1, 1] * f1 + L[1, 2] * f2 + L[1, 3] * f3
    tau_z = L[2, 0] * f0 + L[2, 1] * f1 + L[2, 2] * f2 + L[2, 3] * f3
    total = f0 + f1 + f2 + f3
    for i in range(3):
        force_enu_n[i] += total * R_enu_flu[i, 2]
        torque_enu_n_m[i] += R_enu_flu[i, 0] * tau_x + R_enu_flu[i, 1] * tau_y + R_enu_flu[i, 2] * tau_z


@jit
def _add_rotor_wrenches_enu(thrust_n, R_enu_flu, torque_matrix_flu, force_enu_n, torque_enu_n_m):
    for k in range(thrust_n.shape[0]):
        add_rotor_wrench_enu(thrust_n[k], R_enu_flu[k], torque_matrix_flu[k], force_enu_n[k], torque_enu_n_m[k])


__all__ = ["add_rotor_wrench_enu", "rotor_torque_matrix_flu", "rotor_wrench_enu"]
