"""X-quadrotor motor mixing with attitude-priority desaturation, vectorised over a fleet.

The mix is the paper's eq. 2 (after Mueller & D'Andrea 2014)::

    FL = T - p + r - y     FR = T - p - r + y     BR = T + p - r - y     BL = T + p + r + y

in normalised units (fractions of F_max, the torque commands scaled by 1/2 so that a command of 1
at mid throttle drives one side to full and the other to zero). Unlike the reference
implementation, which let one motor reach 4 x F_max, every motor is kept in [0, 1] the way PX4's
mixer does it: roll/pitch first (scaled down only if their spread alone exceeds the range), then
the collective is shifted as little as needed, and yaw gives way first.

Body frame FLU, motor order FL, FR, BR, BL. Positive roll = right side down (more thrust on the
left motors), positive pitch = nose down (more thrust at the back), positive yaw = CCW (more thrust
on the motors whose reaction torque is +z: FR and BL, which spin clockwise).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .layers import Airframe, DroneState, MotorCommand, ThrustTorqueCommand

MOTOR_NAMES = ("FL", "FR", "BR", "BL")

# columns: roll, pitch, yaw (paper eq. 2 with r, p, y)
MIX_X = 0.5 * np.array([
    [+1.0, -1.0, -1.0],   # FL
    [-1.0, -1.0, +1.0],   # FR
    [-1.0, +1.0, -1.0],   # BR
    [+1.0, +1.0, +1.0],   # BL
])

# reaction torque on the body about +z per unit thrust (FL, BR spin CCW seen from above; FR, BL CW)
SPIN_REACTION_SIGN = np.array([-1.0, +1.0, -1.0, +1.0])

# the mix's two parts as :func:`mix_x_quad` uses them (kept, not rebuilt each step)
_MIX_RP_T = MIX_X[:, :2].T          # (2, 4) roll/pitch -> motors (a view of MIX_X, as before)
_MIX_YAW_ROW = MIX_X[:, 2][None, :]  # (1, 4) yaw -> motors

_MOTOR_DIRS_FLU = np.array([[+1.0, +1.0], [+1.0, -1.0], [-1.0, -1.0], [-1.0, +1.0]]) / np.sqrt(2.0)


def motor_positions_flu_m(arm_length_m: np.ndarray) -> np.ndarray:
    """Motor hub positions w.r.t. the centre of mass, FLU [m]: (N, 4, 3) for arm lengths (N,)."""
    arm = np.asarray(arm_length_m, dtype=float).reshape(-1)
    out = np.zeros((arm.size, 4, 3))
    out[:, :, :2] = arm[:, None, None] * _MOTOR_DIRS_FLU[None]
    return out


def torque_per_unit_cmd_flu_n_m(max_thrust_per_motor_n: np.ndarray, arm_length_m: np.ndarray,
                                yaw_moment_coeff_m: np.ndarray) -> np.ndarray:
    """Torque (N, 3) [N m] about FLU x, y, z that a normalised torque command of 1 stands for.

    The convention of :class:`~unetyemu_ecs.control.layers.ThrustTorqueCommand`, which every mixer
    honours: a roll or pitch command of 1 at mid collective puts one side's two motors at F_max and
    the other side's at 0, each at ``arm / sqrt 2`` from the axis: ``sqrt 2 F_max arm``; a yaw
    command of 1 puts the two motors of one spin direction at F_max and the others at 0, reaction
    torque ``kappa F`` each: ``2 kappa F_max``.
    """
    f_max = np.asarray(max_thrust_per_motor_n, dtype=float).reshape(-1)
    rp = np.sqrt(2.0) * f_max * np.asarray(arm_length_m, dtype=float).reshape(-1)
    return np.stack([rp, rp, 2.0 * np.asarray(yaw_moment_coeff_m, dtype=float).reshape(-1) * f_max], axis=1)


def mix_x_quad(thrust_frac: np.ndarray, torque_cmd: np.ndarray) -> np.ndarray:
    """Return motor thrust fractions (N, 4) in [0, 1] (FL, FR, BR, BL).

    Parameters
    ----------
    thrust_frac : (N,) collective thrust as a fraction of 4 F_max (clipped to [0, 1])
    torque_cmd : (N, 3) normalised [roll, pitch, yaw] commands

    A NaN in a drone's inputs zeroes that drone's command (motors off) rather than reaching the
    motors.
    """
    thrust = np.asarray(thrust_frac, dtype=float).reshape(-1)
    torque = np.asarray(torque_cmd, dtype=float).reshape(-1, 3)
    if np.count_nonzero(np.isfinite(thrust)) + np.count_nonzero(np.isfinite(torque)) != thrust.size + torque.size:
        bad = ~np.isfinite(thrust) | ~np.all(np.isfinite(torque), axis=1)
        thrust, torque = np.where(bad, 0.0, thrust), np.where(bad[:, None], 0.0, torque)
    torque = np.minimum(np.maximum(torque, -1e6), 1e6)
    thrust = np.minimum(np.maximum(thrust, 0.0), 1.0)

    rp = torque[:, :2] @ _MIX_RP_T                            # (N, 4) roll/pitch differential
    yw = torque[:, 2:3] * _MIX_YAW_ROW                        # (N, 4) yaw differential

    # 1. roll/pitch alone must fit in the [0, 1] range: scale down uniformly if their spread is > 1
    rp_max, rp_min = np.maximum.reduce(rp, axis=1), np.minimum.reduce(rp, axis=1)
    spread = rp_max - rp_min
    if np.count_nonzero(spread > 1.0):
        shrink = np.where(spread > 1.0, 1.0 / np.maximum(spread, 1e-12), 1.0)
        rp = rp * shrink[:, None]
        rp_max, rp_min = rp_max * shrink, rp_min * shrink
    # 2. shift the collective as little as needed so that thrust + rp lies in [0, 1]
    thrust = np.minimum(np.maximum(thrust, -rp_min), 1.0 - rp_max)   # between the lowest and highest admissible
    base = thrust[:, None] + rp                                # (N, 4) in [0, 1]
    # 3. yaw with the largest scale in [0, 1] that keeps every motor in [0, 1]: per motor, the room
    #    left in the direction its yaw share pushes, over that share (inf where the share is below 1e-12)
    room = np.empty_like(base)
    room.fill(np.inf)
    np.divide(np.where(yw > 0.0, 1.0 - base, -base), yw, out=room, where=np.abs(yw) > 1e-12)
    scale = np.minimum(np.maximum(np.minimum.reduce(room, axis=1), 0.0), 1.0)
    out = base + scale[:, None] * yw
    # 4. numerical safety only
    return np.minimum(np.maximum(out, 0.0), 1.0)


@dataclass(frozen=True, kw_only=True)
class XQuadMixer:
    """The built-in mixer ``x_quad_priority`` has no parameters (world file: ``controller: {mixer:
    x_quad_priority}``)."""


def x_quad_priority_law(cmd: ThrustTorqueCommand, state: DroneState, airframe: Airframe, params: XQuadMixer,
                        memory: dict[str, np.ndarray], dt_s: float) -> tuple[MotorCommand, dict[str, np.ndarray]]:
    """The built-in mixer layer ``x_quad_priority``: ThrustTorqueCommand -> MotorCommand by :func:`mix_x_quad`."""
    return MotorCommand(mix_x_quad(cmd.thrust_frac, cmd.torque_cmd)), {}
