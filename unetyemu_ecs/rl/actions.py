"""What an agent's action in [-1, 1] means at each action level: pure functions over N drones.

An agent flies a drone at one of four levels, from the lowest to the highest (each level hands its
command to the simulator's own layers below it, run at the physics rate):

=========== ============================================ ==============================================
level       action (each in [-1, 1])                     command
=========== ============================================ ==============================================
motors      4 motors FL, FR, BR, BL                      thrust of each motor, ``hover (1 + span a)``
                                                         of F_max (the rotors and the physics only)
rates       collective, roll rate, pitch rate, yaw rate  collective ``hover (1 + span a0)``; body rates
                                                         ``a * max_rate`` (FLU) -> rate loop -> mixer
attitude    collective, roll, pitch, yaw rate            collective as above; roll and pitch
                                                         ``a * max_tilt``, yaw rate ``a * lim_yaw_rate``
                                                         -> attitude layer -> mixer
velocity    east, north, up velocity, yaw rate           ``a * max_speed`` horizontally, ``a *
                                                         lim_climb`` (``lim_descent`` down), yaw rate
                                                         -> position, attitude layers -> mixer
=========== ============================================ ==============================================

``hover`` is the unloaded drone's hover thrust as a fraction of F_max (``m g / 4 F_max``), so the
zero action hovers at the motors, rates and attitude levels and holds position at the velocity level.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

ACTION_LEVELS = ("motors", "rates", "attitude", "velocity")
ACTION_SIZE = {"motors": 4, "rates": 4, "attitude": 4, "velocity": 4}
ACTION_LABELS = {
    "motors": ("motor_fl", "motor_fr", "motor_br", "motor_bl"),
    "rates": ("collective", "roll_rate", "pitch_rate", "yaw_rate"),
    "attitude": ("collective", "roll", "pitch", "yaw_rate"),
    "velocity": ("v_east", "v_north", "v_up", "yaw_rate"),
}


@dataclass(frozen=True)
class ActionScale:
    """How far a full action (+1) goes, per drone ((N,) arrays) or shared.

    hover_frac : unloaded hover thrust per motor, fraction of F_max
    thrust_span : +1 commands ``hover (1 + thrust_span)``, -1 ``hover (1 - thrust_span)`` [-]
    max_rate_rad_s : body rate of a full rates action [rad/s]
    max_tilt_rad : roll or pitch of a full attitude action [rad]
    lim_yaw_rate_rad_s : yaw rate of a full yaw action [rad/s]
    max_speed_m_s : horizontal speed of a full velocity action [m/s]
    lim_climb_m_s, lim_descent_m_s : vertical speed of a full up / down velocity action [m/s]
    """

    hover_frac: np.ndarray
    thrust_span: float
    max_rate_rad_s: np.ndarray
    max_tilt_rad: np.ndarray
    lim_yaw_rate_rad_s: np.ndarray
    max_speed_m_s: np.ndarray
    lim_climb_m_s: np.ndarray
    lim_descent_m_s: np.ndarray


def clean_action(action: np.ndarray, n: int, size: int = 4) -> np.ndarray:
    """The action as an (n, size) float array in [-1, 1]; NaN counts as 0. A wrong shape raises
    ``ValueError`` naming the shape expected."""
    a = np.asarray(action, dtype=float)
    if a.size != n * size:
        raise ValueError(f"an action must hold {n} x {size} numbers in [-1, 1], got shape {a.shape}")
    return np.clip(np.nan_to_num(a.reshape(n, size), nan=0.0), -1.0, 1.0)


def collective_frac(a: np.ndarray, scale: ActionScale) -> np.ndarray:
    """Collective thrust per motor, fraction of F_max (N,), from the action's first column."""
    return np.clip(scale.hover_frac * (1.0 + scale.thrust_span * a[:, 0]), 0.0, 1.0)


def motor_fracs(a: np.ndarray, scale: ActionScale) -> np.ndarray:
    """Each motor's thrust, fraction of F_max (N, 4), FL, FR, BR, BL."""
    hover = np.asarray(scale.hover_frac, dtype=float).reshape(-1, 1)
    return np.clip(hover * (1.0 + scale.thrust_span * a), 0.0, 1.0)


def body_rate_sp(a: np.ndarray, scale: ActionScale) -> np.ndarray:
    """Body-rate setpoints, FLU (N, 3) [rad/s]: roll, pitch and yaw rate from columns 1-3."""
    lim = np.stack(np.broadcast_arrays(scale.max_rate_rad_s, scale.max_rate_rad_s, scale.lim_yaw_rate_rad_s), axis=-1)
    return a[:, 1:4] * lim


def attitude_sp(a: np.ndarray, scale: ActionScale) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(roll_rad, pitch_rad, yaw_rate_rad_s)``, each (N,), from columns 1-3."""
    return a[:, 1] * scale.max_tilt_rad, a[:, 2] * scale.max_tilt_rad, a[:, 3] * scale.lim_yaw_rate_rad_s


def velocity_sp(a: np.ndarray, scale: ActionScale) -> tuple[np.ndarray, np.ndarray]:
    """``(vel_enu_m_s (N, 3), yaw_rate_rad_s (N,))``: east and north at up to ``max_speed`` (the pair
    clipped to the unit circle, so no diagonal is faster), up at ``lim_climb`` or down at ``lim_descent``."""
    horiz = a[:, :2]
    norm = np.maximum(np.hypot(horiz[:, 0], horiz[:, 1]), 1.0)
    vel = np.empty((a.shape[0], 3))
    vel[:, :2] = horiz / norm[:, None] * np.reshape(scale.max_speed_m_s, (-1, 1))
    vel[:, 2] = np.where(a[:, 2] >= 0.0, a[:, 2] * scale.lim_climb_m_s, a[:, 2] * scale.lim_descent_m_s)
    return vel, a[:, 3] * scale.lim_yaw_rate_rad_s


__all__ = ["ACTION_LABELS", "ACTION_LEVELS", "ACTION_SIZE", "ActionScale", "attitude_sp", "body_rate_sp",
           "clean_action", "collective_frac", "motor_fracs", "velocity_sp"]
