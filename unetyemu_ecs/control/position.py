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


def _all(mask: np.ndarray) -> bool:
    """``mask.all()`` for a bool array (a quarter of its cost on a few rows)."""
    return np.count_nonzero(mask) == mask.size


def _ratio_or_inf(num: np.ndarray, den: np.ndarray, tiny: float = 1e-9) -> np.ndarray:
    """``num / den`` where ``den > tiny``, +inf elsewhere (no division by a vanishing denominator)."""
    if type(num) is not np.ndarray or type(den) is not np.ndarray or num.shape != den.shape \
            or num.dtype != np.float64 or den.dtype != np.float64 or not den.ndim:
        num, den = np.broadcast_arrays(np.asarray(num, dtype=float), np.asarray(den, dtype=float))
    ok = den > tiny
    if np.count_nonzero(ok) == ok.size and den.ndim:
        return num / den
    return np.divide(num, den, out=np.full(den.shape, np.inf), where=ok)


def _per_row(gain: float | np.ndarray) -> float | np.ndarray:
    """A gain that multiplies (N, k) vectors: scalars as they are, (N,) arrays as an (N, 1) column."""
    if type(gain) is not np.ndarray or gain.dtype != np.float64:
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
    ok = dist > 1e-9
    inv = 1.0 / dist if np.count_nonzero(ok) == ok.size else np.divide(1.0, dist, out=np.zeros_like(dist), where=ok)
    unit = delta * inv[:, None]
    d_go = np.maximum(dist_to_go_m, dist)
    speed = np.minimum(gains.gain_pos_p * d_go, np.sqrt(2.0 * gains.lim_decel_m_s2 * d_go))
    uz = unit[:, 2]
    h = np.hypot(unit[:, 0], unit[:, 1])
    up = uz >= 0.0
    n_up = np.count_nonzero(up)
    if n_up == up.size and getattr(lim_climb_m_s, "shape", None) == up.shape:
        v_lim = lim_climb_m_s
    elif n_up == 0 and getattr(lim_descent_m_s, "shape", None) == up.shape:
        v_lim = lim_descent_m_s
    else:
        v_lim = np.where(up, lim_climb_m_s, lim_descent_m_s)
    speed = np.minimum(speed, _ratio_or_inf(lim_speed_h_m_s, h))
    speed = np.minimum(speed, _ratio_or_inf(v_lim, np.abs(uz)))
    return unit * speed[:, None]


def _velocity_to_accel(vel_sp_enu_m_s: np.ndarray, vel_enu_m_s: np.ndarray, vel_int: np.ndarray, dt_s: float,
                       lim_acc: np.ndarray, gains: GuidanceGains) -> tuple[np.ndarray, np.ndarray, bool]:
    """:func:`velocity_to_accel_sp` given ``lim_acc = g tan(lim_tilt)``; also whether a row was limited."""
    if vel_sp_enu_m_s.shape == vel_enu_m_s.shape:       # the same differences, contiguous (cheaper from here on)
        err = np.ascontiguousarray((vel_sp_enu_m_s - vel_enu_m_s)[:, :2])
    else:
        err = vel_sp_enu_m_s[:, :2] - vel_enu_m_s[:, :2]
    lim_int = gains.lim_vel_int_m_s2 / np.maximum(gains.gain_vel_i, 1e-12)
    trial = vel_int + err * dt_s
    ratio = lim_int / np.maximum(row_norm(trial), 1e-12)
    if np.count_nonzero(ratio >= 1.0) != ratio.size:     # else min(1, ratio) is 1 and leaves trial as it is
        trial *= np.minimum(1.0, ratio)[:, None]
    acc = _per_row(gains.gain_vel_p) * err + _per_row(gains.gain_vel_i) * trial
    norm = row_norm(acc)
    limited = norm > lim_acc
    if np.count_nonzero(limited):
        acc *= np.where(limited, lim_acc / np.maximum(norm, 1e-12), 1.0)[:, None]
        return acc, np.where(limited[:, None], vel_int, trial), True
    return acc, trial, False


def velocity_to_accel_sp(vel_sp_enu_m_s: np.ndarray, vel_enu_m_s: np.ndarray, vel_int: np.ndarray, dt_s: float,
                         lim_tilt_rad: np.ndarray, gains: GuidanceGains) -> tuple[np.ndarray, np.ndarray]:
    """Horizontal acceleration setpoint (N, 2) [m/s^2], ENU, and the new velocity integral (N, 2).

    PI on the horizontal velocity error, limited to ``g tan(lim_tilt)`` in magnitude (direction
    kept); the integral does not grow while the output is limited (anti-windup).
    """
    acc, trial, _ = _velocity_to_accel(vel_sp_enu_m_s, vel_enu_m_s, vel_int, dt_s,
                                       GRAVITY_M_S2 * np.tan(lim_tilt_rad), gains)
    return acc, trial


def _accel_to_tilt(acc: np.ndarray, yaw_rad: np.ndarray, lim_acc: np.ndarray | None
                   ) -> tuple[np.ndarray, np.ndarray]:
    """:func:`accel_to_tilt_sp` of float (N, 2) accelerations given ``lim_acc = g tan(lim_tilt)``; None: none of
    them is above it (they come from :func:`_velocity_to_accel`, which limited none)."""
    if lim_acc is not None:
        norm = row_norm(acc)
        if np.count_nonzero(norm > lim_acc):
            acc = acc * np.where(norm > lim_acc, lim_acc / np.maximum(norm, 1e-12), 1.0)[:, None]
    c, s = np.cos(yaw_rad), np.sin(yaw_rad)
    ax, ay = acc[:, 0], acc[:, 1]
    a_fwd = c * ax + s * ay
    a_left = c * ay - s * ax                                      # == -s a_x + c a_y exactly
    pitch = np.arctan(a_fwd / GRAVITY_M_S2)
    roll = np.arctan(-a_left * np.cos(pitch) / GRAVITY_M_S2)
    return roll, pitch


def accel_to_tilt_sp(acc_sp_h_enu_m_s2: np.ndarray, yaw_rad: np.ndarray, lim_tilt_rad: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray]:
    """Roll and pitch setpoints (N,) [rad] that produce a horizontal acceleration in ENU.

    The acceleration is rotated into the heading frame (forward, left); ``pitch = atan(a_fwd / g)``
    and ``roll = atan(-a_left cos(pitch) / g)`` point the thrust axis exactly along
    ``(a_fwd, a_left, g)``, so the total tilt is ``atan(|a| / g)``: limiting ``|a|`` to
    ``g tan(lim_tilt)`` (direction kept) keeps the tilt within ``lim_tilt``.
    """
    return _accel_to_tilt(np.asarray(acc_sp_h_enu_m_s2, dtype=float), yaw_rad, GRAVITY_M_S2 * np.tan(lim_tilt_rad))


def heading_to_yaw_rate_sp(yaw_sp_rad: np.ndarray, yaw_rad: np.ndarray, lim_yaw_rate_rad_s: np.ndarray,
                           gains: GuidanceGains) -> np.ndarray:
    """Yaw-rate setpoint (N,) [rad/s] turning the shortest way to ``yaw_sp`` (NaN or infinite = hold: 0)."""
    err = yaw_sp_rad - yaw_rad
    finite = np.isfinite(err)
    err = wrap_angle_rad(err if _all(finite) else np.where(finite, err, 0.0))
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
    east, north = c * fwd - s * left, s * fwd + c * left
    vertical = np.minimum(np.maximum(up, -lim_descent_m_s), lim_climb_m_s)          # np.clip, at a third of its cost
    if east.shape != vertical.shape or east.ndim != 1:
        return np.stack([east, north, vertical], axis=1)
    out = np.empty((east.shape[0], 3), dtype=np.result_type(east, north, vertical))   # np.stack, at a third of its cost
    out[:, 0] = east
    out[:, 1] = north
    out[:, 2] = vertical
    return out


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
    n_to_pos = np.count_nonzero(to_pos)
    pos = state.pos_enu_m
    if n_to_pos == 0:                             # every row flies its velocity
        vel_sp = np.array(sp.vel_enu_m_s, dtype=float)
    else:                                         # (when every row flies to a position, no np.where is needed)
        every = n_to_pos == to_pos.size
        target = sp.pos_enu_m if every else np.where(to_pos[:, None], sp.pos_enu_m, pos)
        dist_to_go = sp.dist_to_go_m if every else np.where(to_pos, sp.dist_to_go_m, 0.0)
        vel_sp = position_to_velocity_sp(target, pos, dist_to_go, sp.speed_limit_m_s[:, 0],
                                         np.minimum(sp.speed_limit_m_s[:, 1], airframe.lim_climb_m_s),
                                         np.minimum(sp.speed_limit_m_s[:, 2], airframe.lim_descent_m_s), params)
        if not every:
            vel_sp = np.where(to_pos[:, None], vel_sp, sp.vel_enu_m_s)
    lim_acc = GRAVITY_M_S2 * np.tan(airframe.max_tilt_rad)
    acc_h, vel_int, limited = _velocity_to_accel(vel_sp, state.vel_enu_m_s, memory["vel_int_m_s"], dt_s, lim_acc,
                                                 params)
    yaw = yaw_rad_from_quat_xyzw(state.quat_enu_flu_xyzw)
    roll_sp, pitch_sp = _accel_to_tilt(acc_h, yaw, lim_acc if limited else None)
    hold_heading = np.isfinite(sp.yaw_rad)
    lim_rate = airframe.lim_yaw_rate_rad_s
    if _all(hold_heading):
        yaw_rate = heading_to_yaw_rate_sp(sp.yaw_rad, yaw, lim_rate, params)
    else:
        yaw_rate = np.where(hold_heading,
                            heading_to_yaw_rate_sp(np.where(hold_heading, sp.yaw_rad, yaw), yaw, lim_rate, params),
                            np.minimum(np.maximum(sp.yaw_rate_rad_s, -lim_rate), lim_rate))
    return AttitudeSetpoint(vel_sp[:, 2], roll_sp, pitch_sp, yaw_rate), {"vel_int_m_s": vel_int}
