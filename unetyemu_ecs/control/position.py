"""Layer 3 (the paper's eq. 3): position -> velocity -> acceleration -> tilt, and heading -> yaw rate.

A cascade of P (position), PI (velocity) and a kinematic tilt mapping (Faessler et al. 2017,
Chovanova et al. 2014), vectorised over a fleet. World ENU; yaw 0 = east, counter-clockwise;
positive pitch = nose down (accelerates forward), positive roll = right side down (accelerates
right). Every gain may be a scalar or an (N,) array.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import Annotated

import numpy as np

from ..config.schema import Ge, Gt, Le
from ..frames import yaw_of_quat_xyzw
from ..units import GRAVITY_M_S2, wrap_angle_of_rad
from .compiled import at, float_rows, gain_arg, jit, rows_arg
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

    @cached_property
    def kernel_args(self) -> tuple:
        """The gains as the compiled laws take them (:func:`~.compiled.gain_arg`), in the order gain_pos_p,
        lim_decel_m_s2, gain_vel_p, gain_vel_i, lim_vel_int_m_s2, gain_yaw_p: worked out once per (frozen) object."""
        return (gain_arg(self.gain_pos_p), gain_arg(self.lim_decel_m_s2), gain_arg(self.gain_vel_p),
                gain_arg(self.gain_vel_i), gain_arg(self.lim_vel_int_m_s2), gain_arg(self.gain_yaw_p))


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
    a small sideways speed (no cross-track gain blow-up). Compiled, drone by drone
    (:func:`line_of_sight_velocity_into`).
    """
    pos_sp, pos = _vectors(pos_sp_enu_m, 3), _vectors(pos_enu_m, 3)
    n = pos.shape[0]
    out = np.empty((n, 3))
    limits = rows_arg(dist_to_go_m, lim_speed_h_m_s, lim_climb_m_s, lim_descent_m_s, n=n)
    _line_of_sight_velocities(pos_sp, pos, *limits, gain_arg(gains.gain_pos_p), gain_arg(gains.lim_decel_m_s2), out)
    return out


@jit
def line_of_sight_velocity_into(pos_sp_enu_m, pos_enu_m, dist_to_go_m, lim_speed_h_m_s, lim_climb_m_s,
                                lim_descent_m_s, gain_pos_p, lim_decel_m_s2, vel_sp_enu_m_s):
    """:func:`position_to_velocity_sp` of one drone, into ``vel_sp_enu_m_s`` (3,)."""
    dx, dy, dz = pos_sp_enu_m[0] - pos_enu_m[0], pos_sp_enu_m[1] - pos_enu_m[1], pos_sp_enu_m[2] - pos_enu_m[2]
    dist = np.sqrt(dx * dx + dy * dy + dz * dz)
    inv = 1.0 / dist if dist > 1e-9 else 0.0
    ux, uy, uz = dx * inv, dy * inv, dz * inv
    d_go = max(dist_to_go_m, dist)
    speed = min(gain_pos_p * d_go, np.sqrt(2.0 * lim_decel_m_s2 * d_go))
    v_lim = lim_climb_m_s if uz >= 0.0 else lim_descent_m_s
    speed = min(speed, _ratio_or_inf(lim_speed_h_m_s, np.hypot(ux, uy)))
    speed = min(speed, _ratio_or_inf(v_lim, abs(uz)))
    vel_sp_enu_m_s[0], vel_sp_enu_m_s[1], vel_sp_enu_m_s[2] = ux * speed, uy * speed, uz * speed


@jit
def _ratio_or_inf(num, den):
    """``num / den`` where ``den > 1e-9``, +inf elsewhere (no division by a vanishing denominator)."""
    return num / den if den > 1e-9 else np.inf


@jit
def _line_of_sight_velocities(pos_sp_enu_m, pos_enu_m, dist_to_go_m, lim_speed_h_m_s, lim_climb_m_s, lim_descent_m_s,
                              gain_pos_p, lim_decel_m_s2, out):
    for k in range(pos_enu_m.shape[0]):
        line_of_sight_velocity_into(pos_sp_enu_m[k], pos_enu_m[k], dist_to_go_m[k], lim_speed_h_m_s[k],
                                    lim_climb_m_s[k], lim_descent_m_s[k], at(gain_pos_p, k), at(lim_decel_m_s2, k),
                                    out[k])


def velocity_to_accel_sp(vel_sp_enu_m_s: np.ndarray, vel_enu_m_s: np.ndarray, vel_int: np.ndarray, dt_s: float,
                         lim_tilt_rad: np.ndarray, gains: GuidanceGains) -> tuple[np.ndarray, np.ndarray]:
    """Horizontal acceleration setpoint (N, 2) [m/s^2], ENU, and the new velocity integral (N, 2).

    PI on the horizontal velocity error, limited to ``g tan(lim_tilt)`` in magnitude (direction
    kept); the integral does not grow while the output is limited (anti-windup). Compiled, drone by
    drone (:func:`velocity_pi_into`).
    """
    vel_sp, vel = np.asarray(vel_sp_enu_m_s, dtype=float), np.asarray(vel_enu_m_s, dtype=float)
    integral = _vectors(vel_int, 2)
    n = integral.shape[0]
    acc, new_int = np.empty((n, 2)), np.empty((n, 2))
    lim_acc = GRAVITY_M_S2 * np.tan(rows_arg(lim_tilt_rad, n=n)[0])
    _velocity_pis(vel_sp, vel, integral, float(dt_s), lim_acc, *_pi_gains(gains), acc, new_int)
    return acc, new_int


@jit
def velocity_pi_into(vel_sp_enu_m_s, vel_enu_m_s, vel_int, dt_s, lim_acc_m_s2, gain_vel_p, gain_vel_i,
                     lim_vel_int_m_s2, acc_sp_h_enu_m_s2, vel_int_new):
    """:func:`velocity_to_accel_sp` of one drone given ``lim_acc_m_s2 = g tan(lim_tilt)``, into
    ``acc_sp_h_enu_m_s2`` (2,) and ``vel_int_new`` (2,)."""
    ex, ey = vel_sp_enu_m_s[0] - vel_enu_m_s[0], vel_sp_enu_m_s[1] - vel_enu_m_s[1]
    lim_int = lim_vel_int_m_s2 / max(gain_vel_i, 1e-12)
    tx, ty = vel_int[0] + ex * dt_s, vel_int[1] + ey * dt_s
    ratio = lim_int / max(np.sqrt(tx * tx + ty * ty), 1e-12)
    if ratio < 1.0:                                    # the integral's acceleration within its limit
        tx, ty = tx * ratio, ty * ratio
    ax, ay = gain_vel_p * ex + gain_vel_i * tx, gain_vel_p * ey + gain_vel_i * ty
    norm = np.sqrt(ax * ax + ay * ay)
    if norm > lim_acc_m_s2:                            # limited: direction kept, the integral frozen
        scale = lim_acc_m_s2 / max(norm, 1e-12)
        ax, ay = ax * scale, ay * scale
        tx, ty = vel_int[0], vel_int[1]
    acc_sp_h_enu_m_s2[0], acc_sp_h_enu_m_s2[1] = ax, ay
    vel_int_new[0], vel_int_new[1] = tx, ty


@jit
def _velocity_pis(vel_sp_enu_m_s, vel_enu_m_s, vel_int, dt_s, lim_acc_m_s2, gain_vel_p, gain_vel_i, lim_vel_int_m_s2,
                  acc, vel_int_new):
    for k in range(vel_int.shape[0]):
        velocity_pi_into(vel_sp_enu_m_s[k], vel_enu_m_s[k], vel_int[k], dt_s, lim_acc_m_s2[k], at(gain_vel_p, k),
                         at(gain_vel_i, k), at(lim_vel_int_m_s2, k), acc[k], vel_int_new[k])


def accel_to_tilt_sp(acc_sp_h_enu_m_s2: np.ndarray, yaw_rad: np.ndarray, lim_tilt_rad: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray]:
    """Roll and pitch setpoints (N,) [rad] that produce a horizontal acceleration in ENU.

    The acceleration is rotated into the heading frame (forward, left); ``pitch = atan(a_fwd / g)``
    and ``roll = atan(-a_left cos(pitch) / g)`` point the thrust axis exactly along
    ``(a_fwd, a_left, g)``, so the total tilt is ``atan(|a| / g)``: limiting ``|a|`` to
    ``g tan(lim_tilt)`` (direction kept) keeps the tilt within ``lim_tilt``. Compiled, drone by drone
    (:func:`tilt_of_accel`).
    """
    acc = _vectors(acc_sp_h_enu_m_s2, 2)
    yaw, lim_tilt = rows_arg(yaw_rad, lim_tilt_rad, n=acc.shape[0])
    return _tilts_of_accels(acc, yaw, GRAVITY_M_S2 * np.tan(lim_tilt))


@jit
def tilt_of_accel(ax_m_s2, ay_m_s2, yaw_rad, lim_acc_m_s2):
    """:func:`accel_to_tilt_sp` of one drone given ``lim_acc_m_s2 = g tan(lim_tilt)``: ``(roll, pitch)`` [rad]."""
    norm = np.sqrt(ax_m_s2 * ax_m_s2 + ay_m_s2 * ay_m_s2)
    if norm > lim_acc_m_s2:
        scale = lim_acc_m_s2 / max(norm, 1e-12)
        ax_m_s2, ay_m_s2 = ax_m_s2 * scale, ay_m_s2 * scale
    c, s = np.cos(yaw_rad), np.sin(yaw_rad)
    a_fwd = c * ax_m_s2 + s * ay_m_s2
    a_left = c * ay_m_s2 - s * ax_m_s2
    pitch = np.arctan(a_fwd / GRAVITY_M_S2)
    return np.arctan(-a_left * np.cos(pitch) / GRAVITY_M_S2), pitch


@jit
def _tilts_of_accels(acc, yaw_rad, lim_acc_m_s2):
    n = acc.shape[0]
    roll, pitch = np.empty(n), np.empty(n)
    for k in range(n):
        roll[k], pitch[k] = tilt_of_accel(acc[k, 0], acc[k, 1], yaw_rad[k], lim_acc_m_s2[k])
    return roll, pitch


def heading_to_yaw_rate_sp(yaw_sp_rad: np.ndarray, yaw_rad: np.ndarray, lim_yaw_rate_rad_s: np.ndarray,
                           gains: GuidanceGains) -> np.ndarray:
    """Yaw-rate setpoint (N,) [rad/s] turning the shortest way to ``yaw_sp`` (NaN or infinite = hold: 0).
    Compiled, drone by drone (:func:`yaw_rate_to_heading`)."""
    n = max(np.size(yaw_sp_rad), np.size(yaw_rad), np.size(lim_yaw_rate_rad_s))
    rate = _yaw_rates_to_headings(*rows_arg(yaw_sp_rad, yaw_rad, lim_yaw_rate_rad_s, n=n), gain_arg(gains.gain_yaw_p))
    return rate if np.ndim(yaw_sp_rad) or np.ndim(yaw_rad) or np.ndim(lim_yaw_rate_rad_s) else rate[0]


@jit
def yaw_rate_to_heading(yaw_sp_rad, yaw_rad, lim_yaw_rate_rad_s, gain_yaw_p):
    """:func:`heading_to_yaw_rate_sp` of one drone [rad/s]."""
    err = yaw_sp_rad - yaw_rad
    if not np.isfinite(err):
        err = 0.0
    err = wrap_angle_of_rad(err)
    return min(max(gain_yaw_p * err, -lim_yaw_rate_rad_s), lim_yaw_rate_rad_s)


@jit
def _yaw_rates_to_headings(yaw_sp_rad, yaw_rad, lim_yaw_rate_rad_s, gain_yaw_p):
    out = np.empty(yaw_rad.shape[0])
    for k in range(yaw_rad.shape[0]):
        out[k] = yaw_rate_to_heading(yaw_sp_rad[k], yaw_rad[k], lim_yaw_rate_rad_s[k], at(gain_yaw_p, k))
    return out


def _pi_gains(g: GuidanceGains) -> tuple:
    return g.kernel_args[2:5]


def _vectors(values: np.ndarray, k: int) -> np.ndarray:
    """(N, k) float rows."""
    return float_rows(values, k)


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
    yaw rate, within the yaw-rate limit. One compiled loop over the drones.
    """
    n = state.pos_enu_m.shape[0]
    out = np.empty((n, 4))
    vel_int = np.empty((n, 2))
    _cascade_pid(sp.pos_enu_m, sp.vel_enu_m_s, sp.speed_limit_m_s, sp.dist_to_go_m, sp.yaw_rad, sp.yaw_rate_rad_s,
                 state.pos_enu_m, state.vel_enu_m_s, state.quat_enu_flu_xyzw, airframe.max_tilt_rad,
                 airframe.lim_climb_m_s, airframe.lim_descent_m_s, airframe.lim_yaw_rate_rad_s,
                 _vectors(memory["vel_int_m_s"], 2), float(dt_s), *params.kernel_args, out, vel_int)
    return AttitudeSetpoint(out[:, 0], out[:, 1], out[:, 2], out[:, 3]), {"vel_int_m_s": vel_int}


@jit
def _cascade_pid(pos_sp_enu_m, vel_sp_enu_m_s, speed_limit_m_s, dist_to_go_m, yaw_sp_rad, yaw_rate_cmd_rad_s,
                 pos_enu_m, vel_enu_m_s, quat_enu_flu_xyzw, max_tilt_rad, lim_climb_m_s, lim_descent_m_s,
                 lim_yaw_rate_rad_s, vel_int, dt_s, gain_pos_p, lim_decel_m_s2, gain_vel_p, gain_vel_i,
                 lim_vel_int_m_s2, gain_yaw_p, out, vel_int_new):
    """``out`` (N, 4): vz, roll, pitch and yaw-rate setpoints; ``vel_int_new`` (N, 2)."""
    vel_sp = np.empty(3)
    acc = np.empty(2)
    for k in range(pos_enu_m.shape[0]):
        if np.isfinite(pos_sp_enu_m[k, 0]):                  # flies to a position
            line_of_sight_velocity_into(pos_sp_enu_m[k], pos_enu_m[k], dist_to_go_m[k], speed_limit_m_s[k, 0],
                                        min(speed_limit_m_s[k, 1], lim_climb_m_s[k]),
                                        min(speed_limit_m_s[k, 2], lim_descent_m_s[k]), at(gain_pos_p, k),
                                        at(lim_decel_m_s2, k), vel_sp)
        else:                                                 # flies its velocity
            vel_sp[:] = vel_sp_enu_m_s[k]
        lim_acc = GRAVITY_M_S2 * np.tan(max_tilt_rad[k])
        velocity_pi_into(vel_sp, vel_enu_m_s[k], vel_int[k], dt_s, lim_acc, at(gain_vel_p, k), at(gain_vel_i, k),
                         at(lim_vel_int_m_s2, k), acc, vel_int_new[k])
        yaw = yaw_of_quat_xyzw(quat_enu_flu_xyzw[k])
        roll, pitch = tilt_of_accel(acc[0], acc[1], yaw, lim_acc)
        lim_rate = lim_yaw_rate_rad_s[k]
        if np.isfinite(yaw_sp_rad[k]):                        # hold a heading
            yaw_rate = yaw_rate_to_heading(yaw_sp_rad[k], yaw, lim_rate, at(gain_yaw_p, k))
        else:
            yaw_rate = min(max(yaw_rate_cmd_rad_s[k], -lim_rate), lim_rate)
        out[k, 0], out[k, 1], out[k, 2], out[k, 3] = vel_sp[2], roll, pitch, yaw_rate
