"""Layer 3 (the paper's eq. 3): position -> velocity -> acceleration -> tilt, and heading -> yaw rate.

A cascade of P (position), PI (velocity) and a kinematic tilt mapping (Faessler et al. 2017,
Chovanova et al. 2014), vectorised over a fleet. World ENU; yaw 0 = east, counter-clockwise;
positive pitch = nose down (accelerates forward), positive roll = right side down (accelerates
right). Every gain may be a scalar or an (N,) array.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated

import numpy as np

from ..config.schema import Ge, Gt, Le
from ..frames import row_norm, yaw_rad_from_quat_xyzw
from ..units import GRAVITY_M_S2, wrap_angle_rad
from .layers import Airframe, AttitudeSetpoint, DroneState, PositionSetpoint


@dataclass(frozen=True, kw_only=True)
class GuidanceGains:
    """Gains of the built-in position controller ``cascade_pid`` (``controller: {position: {name: cascade_pid,
    params: {...}}}``); ours, tuned at 240 Hz for the presets."""

    # Ranges: gains within 1000 (defaults 0.3-2); accelerations within 10 g (100 m/s^2)
    gain_pos_p: Annotated[float, Gt(0.0), Le(1_000.0)] = 1.0          # [1/s] position error -> velocity
    gain_vel_p: Annotated[float, Gt(0.0), Le(1_000.0)] = 2.0          # [1/s] velocity error -> acceleration
    gain_vel_i: Annotated[float, Ge(0.0), Le(1_000.0)] = 0.3          # [1/s^2]
    lim_vel_int_m_s2: Annotated[float, Ge(0.0), Le(100.0)] = 2.0    # clamp on the integral's acceleration
    gain_yaw_p: Annotated[float, Gt(0.0), Le(1_000.0)] = 2.0          # [1/s] heading error -> yaw rate
    lim_decel_m_s2: Annotated[float, Gt(0.0), Le(100.0)] = 2.5      # braking that sizes the approach speed


def _ratio_or_inf(num: np.ndarray, den: np.ndarray, tiny: float = 1e-9) -> np.ndarray:
    """``num / den`` where ``den > tiny``, +inf elsewhere (no division by a vanishing denominator)."""
    num, den = np.broadcast_arrays(np.asarray(num, dtype=float), np.asarray(den, dtype=float))
    return np.divide(num, den, out=np.full(den.shape, np.inf), where=den > tiny)


def _per_row(gain: float | np.ndarray) -> float | np.ndarray:
    """A gain that multiplies (N, k) vectors: scalars as they are, (N,) arrays as an (N, 1) column."""
    gain = np.asarray(gain, dtype=float)
    return gain[..., None] if gain.ndim else float(gain)


def position_to_velocity_sp(pos_sp_enu_m: np.ndarray, pos_enu_m: np.ndarray, dist_to_go_m: np.ndarray,
                            lim_speed_h_m_s: np.ndarray, lim_climb_m_s: np.ndarray, lim_descent_m_s: np.ndarray,
                            gains: GuidanceGains) -> np.ndarray:
    """Velocity setpoint (N, 3) [m/s], ENU, along the line of sight to ``pos_sp``.

    The direction is ``pos_sp - pos`` (for pure pursuit, the virtual target a lead distance ahead);
    the speed is ``min(gain_pos_p d, sqrt(2 lim_decel d))`` with ``d = dist_to_go`` the distance
    still to fly to the final point (so a nearby virtual target does not cap the cruise speed, and
    the square-root profile brakes for the end without overshoot), then scaled down so that the
    horizontal part stays within ``lim_speed_h`` and the vertical part within the climb/descent
    limits. Because the whole vector is scaled, a climb leg with a small sideways error asks for
    a small sideways speed (no cross-track gain blow-up).
    """
    delta = pos_sp_enu_m - pos_enu_m
    dist = row_norm(delta)
    unit = delta * np.divide(1.0, dist, out=np.zeros_like(dist), where=dist > 1e-9)[:, None]
    d_go = np.maximum(dist_to_go_m, dist)
    speed = np.minimum(gains.gain_pos_p * d_go, np.sqrt(2.0 * gains.lim_decel_m_s2 * d_go))
    h = np.hypot(unit[:, 0], unit[:, 1])
    v_lim = np.where(unit[:, 2] >= 0.0, lim_climb_m_s, lim_descent_m_s)
    speed = np.minimum(speed, _ratio_or_inf(lim_speed_h_m_s, h))
    speed = np.minimum(speed, _ratio_or_inf(v_lim, np.abs(unit[:, 2])))
    return unit * speed[:, None]


def velocity_to_accel_sp(vel_sp_enu_m_s: np.ndarray, vel_enu_m_s: np.ndarray, vel_int: np.ndarray, dt_s: float,
                         lim_tilt_rad: np.ndarray, gains: GuidanceGains) -> tuple[np.ndarray, np.ndarray]:
    """Horizontal acceleration setpoint (N, 2) [m/s^2], ENU, and the new velocity integral (N, 2).

    PI on the horizontal velocity error, limited to ``g tan(lim_tilt)`` in magnitude (direction
    kept); the integral does not grow while the output is limited (anti-windup).
    """
    err = vel_sp_enu_m_s[:, :2] - vel_enu_m_s[:, :2]
    lim_int = gains.lim_vel_int_m_s2 / np.maximum(gains.gain_vel_i, 1e-12)
    trial = vel_int + err * dt_s
    trial *= np.minimum(1.0, lim_int / np.maximum(row_norm(trial), 1e-12))[:, None]
    acc = _per_row(gains.gain_vel_p) * err + _per_row(gains.gain_vel_i) * trial
    lim_acc = GRAVITY_M_S2 * np.tan(lim_tilt_rad)
    norm = row_norm(acc)
    limited = norm > lim_acc
    if limited.any():
        acc *= np.where(limited, lim_acc / np.maximum(norm, 1e-12), 1.0)[:, None]
        return acc, np.where(limited[:, None], vel_int, trial)
    return acc, trial


def accel_to_tilt_sp(acc_sp_h_enu_m_s2: np.ndarray, yaw_rad: np.ndarray, lim_tilt_rad: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray]:
    """Roll and pitch setpoints (N,) [rad] that produce a horizontal acceleration in ENU.

    The acceleration is rotated into the heading frame (forward, left); ``pitch = atan(a_fwd / g)``
    and ``roll = atan(-a_left cos(pitch) / g)`` point the thrust axis exactly along
    ``(a_fwd, a_left, g)``, so the total tilt is ``atan(|a| / g)``: limiting ``|a|`` to
    ``g tan(lim_tilt)`` (direction kept) keeps the tilt within ``lim_tilt``.
    """
    acc = np.asarray(acc_sp_h_enu_m_s2, dtype=float)
    norm = row_norm(acc)
    lim_acc = GRAVITY_M_S2 * np.tan(lim_tilt_rad)
    if (norm > lim_acc).any():
        acc = acc * np.where(norm > lim_acc, lim_acc / np.maximum(norm, 1e-12), 1.0)[:, None]
    c, s = np.cos(yaw_rad), np.sin(yaw_rad)
    a_fwd = c * acc[:, 0] + s * acc[:, 1]
    a_left = -s * acc[:, 0] + c * acc[:, 1]
    pitch = np.arctan(a_fwd / GRAVITY_M_S2)
    roll = np.arctan(-a_left * np.cos(pitch) / GRAVITY_M_S2)
    return roll, pitch


def heading_to_yaw_rate_sp(yaw_sp_rad: np.ndarray, yaw_rad: np.ndarray, lim_yaw_rate_rad_s: np.ndarray,
                           gains: GuidanceGains) -> np.ndarray:
    """Yaw-rate setpoint (N,) [rad/s] turning the shortest way to ``yaw_sp`` (NaN or infinite = hold: 0)."""
    err = yaw_sp_rad - yaw_rad
    err = wrap_angle_rad(np.where(np.isfinite(err), err, 0.0))
    return np.minimum(np.maximum(gains.gain_yaw_p * err, -lim_yaw_rate_rad_s), lim_yaw_rate_rad_s)


def body_velocity_to_enu_sp(vel_flu_m_s: np.ndarray, yaw_rad: np.ndarray, lim_climb_m_s: np.ndarray,
                            lim_descent_m_s: np.ndarray) -> np.ndarray:
    """Velocity setpoint (N, 3) [m/s], ENU, of a body-frame command (N, 3) [forward, left, up] [m/s].

    ROS ``cmd_vel`` semantics for a multirotor: the horizontal part turns with the current heading
    ``yaw_rad`` (N,), so a constant command with a yaw rate flies a circle; the vertical part is
    clamped to the climb/descent limits. The horizontal speed is left to the tilt limit downstream.
    """
    c, s = np.cos(yaw_rad), np.sin(yaw_rad)
    fwd, left, up = vel_flu_m_s[:, 0], vel_flu_m_s[:, 1], vel_flu_m_s[:, 2]
    return np.stack([c * fwd - s * left, s * fwd + c * left, np.clip(up, -lim_descent_m_s, lim_climb_m_s)], axis=1)


def cascade_pid_law(sp: PositionSetpoint, state: DroneState, airframe: Airframe, params: GuidanceGains,
                    memory: dict[str, np.ndarray], dt_s: float) -> tuple[AttitudeSetpoint, dict[str, np.ndarray]]:
    """The built-in position layer ``cascade_pid``: PositionSetpoint -> AttitudeSetpoint.

    Rows flying to a position: line-of-sight velocity (:func:`position_to_velocity_sp`) within the
    leg's speed limits and the airframe's climb/descent limits; rows flying a velocity take it as
    given. Then the velocity PI (:func:`velocity_to_accel_sp`, memory ``vel_int_m_s``) and the tilt
    mapping (:func:`accel_to_tilt_sp`); heading P (:func:`heading_to_yaw_rate_sp`) or the commanded
    yaw rate, within the yaw-rate limit.
    """
    to_pos = sp.flies_to_position
    pos = state.pos_enu_m
    target = np.where(to_pos[:, None], sp.pos_enu_m, pos)
    vel_to_pos = position_to_velocity_sp(target, pos, np.where(to_pos, sp.dist_to_go_m, 0.0), sp.speed_limit_m_s[:, 0],
                                         np.minimum(sp.speed_limit_m_s[:, 1], airframe.lim_climb_m_s),
                                         np.minimum(sp.speed_limit_m_s[:, 2], airframe.lim_descent_m_s), params)
    vel_sp = np.where(to_pos[:, None], vel_to_pos, sp.vel_enu_m_s)
    acc_h, vel_int = velocity_to_accel_sp(vel_sp, state.vel_enu_m_s, memory["vel_int_m_s"], dt_s,
                                          airframe.max_tilt_rad, params)
    yaw = yaw_rad_from_quat_xyzw(state.quat_enu_flu_xyzw)
    roll_sp, pitch_sp = accel_to_tilt_sp(acc_h, yaw, airframe.max_tilt_rad)
    hold_heading = np.isfinite(sp.yaw_rad)
    lim_rate = airframe.lim_yaw_rate_rad_s
    if hold_heading.all():
        yaw_rate = heading_to_yaw_rate_sp(sp.yaw_rad, yaw, lim_rate, params)
    else:
        yaw_rate = np.where(hold_heading,
                            heading_to_yaw_rate_sp(np.where(hold_heading, sp.yaw_rad, yaw), yaw, lim_rate, params),
                            np.minimum(np.maximum(sp.yaw_rate_rad_s, -lim_rate), lim_rate))
    return AttitudeSetpoint(vel_sp[:, 2], roll_sp, pitch_sp, yaw_rate), {"vel_int_m_s": vel_int}
