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

from .compiled import float_rows, jit
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
    motors. Compiled, drone by drone (:func:`mix_x_quad_into`).
    """
    thrust = float_rows(thrust_frac)
    torque = float_rows(torque_cmd, 3)
    return _mix_x_quads(thrust, torque)


@jit
def mix_x_quad_into(thrust_frac, roll_cmd, pitch_cmd, yaw_cmd, motor_frac):
    """:func:`mix_x_quad` of one drone, into ``motor_frac`` (4,). Every clamp ``min(hi, max(lo, x))`` and running
    maximum or minimum is ordered as numpy's ``minimum(maximum(x, lo), hi)`` and ``.reduce``, so that the result is
    numpy's to the sign of a zero."""
    if not (np.isfinite(thrust_frac) and np.isfinite(roll_cmd) and np.isfinite(pitch_cmd) and np.isfinite(yaw_cmd)):
        thrust_frac = roll_cmd = pitch_cmd = yaw_cmd = 0.0
    roll_cmd, pitch_cmd, yaw_cmd = (min(1e6, max(-1e6, roll_cmd)), min(1e6, max(-1e6, pitch_cmd)),
                                    min(1e6, max(-1e6, yaw_cmd)))
    thrust = min(1.0, max(0.0, thrust_frac))
    rp = np.empty(4)                                           # roll/pitch differential
    yw = np.empty(4)                                           # yaw differential
    for j in range(4):
        rp[j] = roll_cmd * MIX_X[j, 0] + pitch_cmd * MIX_X[j, 1]
        yw[j] = yaw_cmd * MIX_X[j, 2]
    rp_max, rp_min = rp[0], rp[0]
    for j in range(1, 4):
        rp_max, rp_min = max(rp[j], rp_max), min(rp[j], rp_min)
    # 1. roll/pitch alone must fit in the [0, 1] range: scale down uniformly if their spread is > 1
    spread = rp_max - rp_min
    if spread > 1.0:
        shrink = 1.0 / max(1e-12, spread)
        for j in range(4):
            rp[j] *= shrink
        rp_max, rp_min = rp_max * shrink, rp_min * shrink
    # 2. shift the collective as little as needed so that thrust + rp lies in [0, 1]
    thrust = min(1.0 - rp_max, max(-rp_min, thrust))           # between the lowest and highest admissible
    # 3. yaw with the largest scale in [0, 1] that keeps every motor in [0, 1]: per motor, the room
    #    left in the direction its yaw share pushes, over that share (none where the share is below 1e-12)
    room = np.inf
    for j in range(4):
        base = thrust + rp[j]
        share_room = (((1.0 - base) if yw[j] > 0.0 else -base) / yw[j]) if abs(yw[j]) > 1e-12 else np.inf
        room = share_room if j == 0 else min(share_room, room)
    scale = min(1.0, max(0.0, room))
    for j in range(4):
        motor_frac[j] = min(1.0, max(0.0, thrust + rp[j] + scale * yw[j]))    # 4. numerical safety only


@jit
def _mix_x_quads(thrust_frac, torque_cmd):
    out = np.empty((thrust_frac.shape[0], 4))
    for k in range(thrust_frac.shape[0]):
        mix_x_quad_into(thrust_frac[k], torque_cmd[k, 0], torque_cmd[k, 1], torque_cmd[k, 2], out[k])
    return out


@dataclass(frozen=True, kw_only=True)
class XQuadMixer:
    """The built-in mixer ``x_quad_priority`` has no parameters (world file: ``controller: {mixer:
    x_quad_priority}``)."""


def x_quad_priority_law(cmd: ThrustTorqueCommand, state: DroneState, airframe: Airframe, params: XQuadMixer,
                        memory: dict[str, np.ndarray], dt_s: float) -> tuple[MotorCommand, dict[str, np.ndarray]]:
    """The built-in mixer layer ``x_quad_priority``: ThrustTorqueCommand -> MotorCommand by :func:`mix_x_quad`."""
    return MotorCommand(mix_x_quad(cmd.thrust_frac, cmd.torque_cmd)), {}
