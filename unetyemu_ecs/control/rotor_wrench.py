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
    thrust = np.asarray(thrust_n, dtype=float)
    force = np.add.reduce(thrust, axis=1)[:, None] * R_enu_flu[:, :, 2]      # thrust.sum(axis=1), without the method's wrapper
    torque_flu = np.einsum("nkj,nj->nk", torque_matrix_flu, thrust)
    return force, np.einsum("nij,nj->ni", R_enu_flu, torque_flu)


__all__ = ["rotor_torque_matrix_flu", "rotor_wrench_enu"]
