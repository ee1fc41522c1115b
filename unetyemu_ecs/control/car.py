"""Ground-vehicle laws, vectorised over a fleet of cars: steering geometry, drive and brake torque,
speed and course control, and the route speed profile.

Frames: world ENU; the car body is FLU (x forward, y left). Steering angle ``delta`` [rad] is the
bicycle-model front-wheel angle, positive = left (counter-clockwise turn, like yaw). No esper, no
PyBullet: every public function takes and returns arrays of N cars. Each law is written once for one
car and compiled (``*_of``, ``*_scalar_*``, ``ackermann_pair_rad``: what per-step kernels call); the
array functions are that code as a ufunc or a compiled loop over the cars (see ``compiled.py``).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import Annotated

import numpy as np

from ..config.schema import Ge, Gt, Le
from ..units import GRAVITY_M_S2, wrap_angle_of_rad
from .compiled import at, float_rows, gain_arg, jit, rows_arg, ufunc
from .layers import CarChassis, CarCommand, CarSetpoint, CarState

SPEED_FOR_STEER_SCALE_M_S = 50.0   # the steering limit falls linearly to its scale at this speed


@dataclass(frozen=True, kw_only=True)
class CarGuidanceParams:
    """Route following of a car (world-file key ``car_guidance``); ours."""

    # Ranges: accelerations within 5 g (50 m/s^2, beyond any tyre); look-ahead within 1 km or 60 s;
    # speeds within 100 m/s (beyond any road car)
    max_lat_accel_m_s2: Annotated[float, Gt(0.0), Le(50.0)] = 2.5   # corner speeds of a route: v = sqrt(a_lat R)
    max_decel_m_s2: Annotated[float, Gt(0.0), Le(50.0)] = 4.0       # the speed profile brakes for corners at 60 % of it
    lead_min_m: Annotated[float, Gt(0.0), Le(1_000.0)] = 3.0           # pure-pursuit look-ahead: max(lead_min, lead_time v)
    lead_time_s: Annotated[float, Ge(0.0), Le(60.0)] = 0.5
    arrival_radius_m: Annotated[float, Gt(0.0), Le(100.0)] = 1.0     # a route is done within this of its end, stopped
    cruise_speed_m_s: Annotated[float, Gt(0.0), Le(100.0)] = 8.0     # default speed of targets and routes


@dataclass(frozen=True, kw_only=True)
class SpeedSteerGains:
    """Gains of the built-in drive controller ``speed_pi_steer`` (``controller: {drive: {name:
    speed_pi_steer, params: {...}}}``); ours."""

    # Ranges: gains within 100 (defaults 0.3-1.2); accelerations within 5 g (50 m/s^2, beyond any tyre)
    gain_speed_p: Annotated[float, Gt(0.0), Le(100.0)] = 1.2         # [1/s] speed error -> acceleration
    gain_speed_i: Annotated[float, Ge(0.0), Le(100.0)] = 0.4         # [1/s^2]
    lim_speed_int_m_s2: Annotated[float, Ge(0.0), Le(50.0)] = 1.5   # clamp on the integral's acceleration
    gain_yaw_rate_p: Annotated[float, Ge(0.0), Le(100.0)] = 0.3      # [s] yaw-rate error -> extra steering [rad]
    max_accel_m_s2: Annotated[float, Gt(0.0), Le(50.0)] = 3.0       # comfort limits of the speed controller
    max_decel_m_s2: Annotated[float, Gt(0.0), Le(50.0)] = 4.0

    @cached_property
    def kernel_args(self) -> tuple:
        """The gains as the compiled laws take them (:func:`~.compiled.gain_arg`), in the order of the fields:
        worked out once per (frozen) object."""
        return (gain_arg(self.gain_speed_p), gain_arg(self.gain_speed_i), gain_arg(self.lim_speed_int_m_s2),
                gain_arg(self.gain_yaw_rate_p), gain_arg(self.max_accel_m_s2), gain_arg(self.max_decel_m_s2))


def _steer_limit(speed_m_s: float, max_steer_rad: float, scale_at_50_m_s: float) -> float:
    frac = min(abs(speed_m_s) / SPEED_FOR_STEER_SCALE_M_S, 1.0)
    return max_steer_rad * (1.0 - (1.0 - scale_at_50_m_s) * frac)


steer_limit_scalar_rad = jit(_steer_limit)
_steer_limit_ufunc = ufunc("f8(f8, f8, f8)")(_steer_limit)


def steer_limit_rad(speed_m_s: np.ndarray, max_steer_rad: np.ndarray, scale_at_50_m_s: np.ndarray) -> np.ndarray:
    """Steering limit (N,) [rad] at a speed: ``max_steer`` at rest, falling linearly to
    ``scale_at_50 * max_steer`` at 50 m/s and held there (the reference implementation's law).
    Compiled per car (:data:`steer_limit_scalar_rad` is the kernels' form)."""
    return _steer_limit_ufunc(speed_m_s, max_steer_rad, scale_at_50_m_s)


def _ackermann_pair(delta_rad: float, wheelbase_m: float, track_m: float) -> tuple[float, float]:
    if not abs(delta_rad) > 1e-9:                        # straight on (and NaN): both wheels straight
        return 0.0, 0.0
    sign = 1.0 if delta_rad > 0.0 else -1.0
    radius = wheelbase_m / np.tan(abs(delta_rad))
    return (sign * np.arctan(wheelbase_m / (radius - sign * track_m / 2.0)),
            sign * np.arctan(wheelbase_m / (radius + sign * track_m / 2.0)))


ackermann_pair_rad = jit(_ackermann_pair)


@jit
def _ackermann_rows(delta_rad, wheelbase_m, track_m, out):
    for k in range(out.shape[0]):
        out[k, 0], out[k, 1] = ackermann_pair_rad(delta_rad[k], wheelbase_m[k], track_m[k])


def ackermann_angles(delta_rad: np.ndarray, wheelbase_m: np.ndarray, track_m: np.ndarray) -> np.ndarray:
    """Left and right front-wheel angles (N, 2) [rad] for a bicycle-model angle ``delta``.

    Both wheels turn about the same centre on the rear-axle line, at radius ``R = L / tan(delta)``
    from the car's centre line: the inner wheel turns more (``atan(L / (R - t/2))``). Compiled per
    car (:data:`ackermann_pair_rad` is the kernels' form: one car's pair).
    """
    n = max(np.size(delta_rad), np.size(wheelbase_m), np.size(track_m))
    out = np.empty((n, 2))
    _ackermann_rows(*rows_arg(delta_rad, wheelbase_m, track_m, n=n), out)
    return out


def _bicycle_limit(wheel_limit_rad: float, wheelbase_m: float, track_m: float) -> float:
    return np.arctan(wheelbase_m / (wheelbase_m / np.tan(wheel_limit_rad) + track_m / 2.0))


bicycle_limit_scalar_rad = jit(_bicycle_limit)
_bicycle_limit_ufunc = ufunc("f8(f8, f8, f8)")(_bicycle_limit)


def bicycle_limit_rad(wheel_limit_rad: np.ndarray, wheelbase_m: np.ndarray, track_m: np.ndarray) -> np.ndarray:
    """The largest bicycle-model angle (N,) [rad] whose Ackermann *inner* wheel stays within
    ``wheel_limit`` (the inverse of :func:`ackermann_angles` for the inner wheel)."""
    return _bicycle_limit_ufunc(wheel_limit_rad, wheelbase_m, track_m)


def _drive_torque(throttle: float, speed_fwd_m_s: float, max_torque_n_m: float, top_speed_m_s: float) -> float:
    throttle = min(max(throttle, -1.0), 1.0)
    along = speed_fwd_m_s if throttle >= 0.0 else -speed_fwd_m_s          # speed in the driven direction
    fade = min(max(1.0 - along / top_speed_m_s, 0.0), 1.0)
    return throttle * max_torque_n_m * fade


drive_torque_scalar_n_m = jit(_drive_torque)
_drive_torque_ufunc = ufunc("f8(f8, f8, f8, f8)")(_drive_torque)


def drive_torque_n_m(throttle: np.ndarray, speed_fwd_m_s: np.ndarray, max_torque_n_m: np.ndarray,
                     top_speed_m_s: np.ndarray) -> np.ndarray:
    """Total drive torque at the rear axle (N,) [N m] for ``throttle`` in [-1, 1] (negative = reverse).

    The torque falls linearly with speed in the driven direction and vanishes at the top speed, so
    no input can drive the car faster than ``top_speed``; against the motion (``throttle`` opposing
    ``speed``) the full torque is available. Compiled per car (:data:`drive_torque_scalar_n_m`).
    """
    return _drive_torque_ufunc(throttle, speed_fwd_m_s, max_torque_n_m, top_speed_m_s)


@jit
def throttle_brake_of(speed_sp_m_s, speed_m_s, speed_int, dt_s, feedforward_n, mass_kg, wheel_radius_m,
                      max_drive_n_m, max_brake_n_m, top_speed_m_s, gain_speed_p, gain_speed_i, lim_speed_int_m_s2,
                      max_accel_m_s2, max_decel_m_s2):
    """:func:`speed_to_throttle_brake` of one car: ``(throttle, brake, new integral)``."""
    err = speed_sp_m_s - speed_m_s
    lim = lim_speed_int_m_s2 / max(gain_speed_i, 1e-12)
    trial = min(max(speed_int + err * dt_s, -lim), lim)
    acc = gain_speed_p * err + gain_speed_i * trial
    new_int = speed_int if (acc > max_accel_m_s2 or acc < -max_decel_m_s2) else trial
    acc = min(max(acc, -max_decel_m_s2), max_accel_m_s2)
    moving = abs(speed_m_s) > 0.3
    if moving:
        direction = 1.0 if speed_m_s > 0.0 else -1.0
    else:
        direction = -1.0 if speed_sp_m_s < 0.0 else 1.0
    force = mass_kg * acc + direction * feedforward_n                    # along the world-forward axis
    # drive: the torque that gives `force`, as a fraction of what the motor has at this speed
    available = max_drive_n_m * min(max(1.0 - direction * speed_m_s / top_speed_m_s, 0.05), 1.0)
    throttle = min(max(force * wheel_radius_m / available, -1.0), 1.0)
    if moving and force * direction < 0.0:                               # against the motion: brakes
        # all four wheels share the force
        return 0.0, min(abs(force) * wheel_radius_m / (4.0 * max_brake_n_m), 1.0), new_int
    if not moving and abs(speed_sp_m_s) < 0.05:                          # hold a stopped car
        return 0.0, 1.0, 0.0
    return throttle, 0.0, new_int


@jit
def _throttles_brakes(speed_sp_m_s, speed_m_s, speed_int, dt_s, feedforward_n, mass_kg, wheel_radius_m,
                      max_drive_n_m, max_brake_n_m, top_speed_m_s, gain_speed_p, gain_speed_i, lim_speed_int_m_s2,
                      max_accel_m_s2, max_decel_m_s2, out):
    for k in range(out.shape[0]):
        out[k, 0], out[k, 1], out[k, 2] = throttle_brake_of(
            speed_sp_m_s[k], speed_m_s[k], speed_int[k], dt_s, feedforward_n[k], mass_kg[k], wheel_radius_m[k],
            max_drive_n_m[k], max_brake_n_m[k], top_speed_m_s[k], at(gain_speed_p, k), at(gain_speed_i, k),
            at(lim_speed_int_m_s2, k), at(max_accel_m_s2, k), at(max_decel_m_s2, k))


def speed_to_throttle_brake(speed_sp_m_s: np.ndarray, speed_m_s: np.ndarray, speed_int: np.ndarray, dt_s: float,
                            feedforward_n: np.ndarray, mass_kg: np.ndarray, wheel_radius_m: np.ndarray,
                            max_drive_n_m: np.ndarray, max_brake_n_m: np.ndarray, top_speed_m_s: np.ndarray,
                            gains: SpeedSteerGains) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """PI speed control: return ``(throttle in [-1, 1], brake in [0, 1], new integral)``, each (N,).

    ``a = kp e + ki int(e)`` limited to ``[-max_decel, max_accel]`` [m/s^2]; the force
    ``m a + feedforward`` (rolling resistance) is produced by the motor when it pushes in the
    direction of travel (or the car is nearly stopped), by the brakes when it opposes the motion.
    Anti-windup: the integral is frozen while the output is limited. Compiled per car
    (:func:`throttle_brake_of`).
    """
    values = (speed_sp_m_s, speed_m_s, speed_int, feedforward_n, mass_kg, wheel_radius_m, max_drive_n_m,
              max_brake_n_m, top_speed_m_s)
    n = max(np.size(v) for v in values)
    sp, v, integral, ff, m, r, drive, brake, top = rows_arg(*values, n=n)
    out = np.empty((n, 3))
    _throttles_brakes(sp, v, integral, float(dt_s), ff, m, r, drive, brake, top, *gains.kernel_args[:2],
                      gains.kernel_args[2], gains.kernel_args[4], gains.kernel_args[5], out)
    return out[:, 0], out[:, 1], out[:, 2]


def _steer_for_yaw_rate(yaw_rate_sp_rad_s: float, yaw_rate_rad_s: float, speed_m_s: float, wheelbase_m: float,
                        gain_yaw_rate_p: float) -> float:
    v = speed_m_s
    if abs(speed_m_s) < 0.5:
        v = -0.5 if speed_m_s < 0.0 else 0.5
    return np.arctan(wheelbase_m * yaw_rate_sp_rad_s / v) + gain_yaw_rate_p * (yaw_rate_sp_rad_s - yaw_rate_rad_s)


steer_for_yaw_rate_rad = jit(_steer_for_yaw_rate)
_steer_for_yaw_rate_ufunc = ufunc("f8(f8, f8, f8, f8, f8)")(_steer_for_yaw_rate)


def yaw_rate_to_steer(yaw_rate_sp_rad_s: np.ndarray, yaw_rate_rad_s: np.ndarray, speed_m_s: np.ndarray,
                      wheelbase_m: np.ndarray, gains: SpeedSteerGains) -> np.ndarray:
    """Bicycle-model steering (N,) [rad] for a yaw rate: ``atan(L r / v)`` plus P on the rate error.

    Below 0.5 m/s the kinematic term uses 0.5 m/s (a car cannot turn on the spot). Compiled per car
    (:data:`steer_for_yaw_rate_rad`).
    """
    return _steer_for_yaw_rate_ufunc(yaw_rate_sp_rad_s, yaw_rate_rad_s, speed_m_s, wheelbase_m, gains.gain_yaw_rate_p)


@jit
def pursuit_steer_of(target_x_m, target_y_m, rear_axle_x_m, rear_axle_y_m, yaw_rad, wheelbase_m):
    """:func:`pure_pursuit_steer` of one car [rad]."""
    dx, dy = target_x_m - rear_axle_x_m, target_y_m - rear_axle_y_m
    dist = max(np.sqrt(dx * dx + dy * dy), 1e-6)
    alpha = wrap_angle_of_rad(np.arctan2(dy, dx) - yaw_rad)
    return np.arctan(wheelbase_m * 2.0 * np.sin(alpha) / dist)


@jit
def _pursuit_steers(target_enu_m, rear_axle_enu_m, yaw_rad, wheelbase_m, out):
    for k in range(out.shape[0]):
        out[k] = pursuit_steer_of(target_enu_m[k, 0], target_enu_m[k, 1], rear_axle_enu_m[k, 0], rear_axle_enu_m[k, 1],
                                  yaw_rad[k], wheelbase_m[k])


def pure_pursuit_steer(target_enu_m: np.ndarray, rear_axle_enu_m: np.ndarray, yaw_rad: np.ndarray,
                       wheelbase_m: np.ndarray) -> np.ndarray:
    """Classic pure pursuit (Coulter 1992): steer (N,) [rad] onto the arc through the target.

    The arc leaves the rear axle tangent to the heading and passes through the target: curvature
    ``2 sin(alpha) / l`` with ``alpha`` the bearing of the target off the heading and ``l`` its
    distance; ``delta = atan(L * curvature)``. Compiled per car (:func:`pursuit_steer_of`).
    """
    target, rear = float_rows(target_enu_m, 3), float_rows(rear_axle_enu_m, 3)
    n = target.shape[0]
    out = np.empty(n)
    _pursuit_steers(target, rear, *rows_arg(yaw_rad, wheelbase_m, n=n), out)
    return out


def corner_speeds_m_s(points_enu_m: np.ndarray, cruise_m_s: float, max_lat_accel_m_s2: float,
                      loop: bool) -> np.ndarray:
    """Speed limit (W,) [m/s] at each point of a route: ``sqrt(a_lat R)`` with ``R`` the radius of
    the circle through the point and its neighbours, capped at ``cruise``; 0 at the end of an open
    route (the car stops there)."""
    pts = np.asarray(points_enu_m, dtype=float)[:, :2]
    n = len(pts)
    speeds = np.full(n, float(cruise_m_s))
    for i in range(n):
        if loop:
            a, b, c = pts[(i - 1) % n], pts[i], pts[(i + 1) % n]
        elif 0 < i < n - 1:
            a, b, c = pts[i - 1], pts[i], pts[i + 1]
        else:
            continue
        ab, bc, ca = np.linalg.norm(b - a), np.linalg.norm(c - b), np.linalg.norm(a - c)
        cross = abs((b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]))
        if cross < 1e-9 or ab < 1e-9 or bc < 1e-9:
            continue                                            # straight on: no corner
        radius = ab * bc * ca / (2.0 * cross)
        speeds[i] = min(speeds[i], float(np.sqrt(max_lat_accel_m_s2 * radius)))
    if not loop:
        speeds[-1] = 0.0
    return speeds


@jit
def route_speed_of(s_along_m, cum_m, point_speeds_m_s, max_decel_m_s2):
    """:func:`route_speed_sp` of one car: ``cum_m`` and ``point_speeds_m_s`` (W,) its route's points."""
    best = np.inf
    for j in range(cum_m.shape[0]):
        if cum_m[j] >= s_along_m - 1e-9:
            best = min(best, np.sqrt(point_speeds_m_s[j] ** 2 + 2.0 * max_decel_m_s2 * max(cum_m[j] - s_along_m, 0.0)))
    return best


@jit
def _route_speeds(s_along_m, cum_m, point_speeds_m_s, max_decel_m_s2, out):
    for k in range(out.shape[0]):
        out[k] = route_speed_of(s_along_m[k], cum_m[k], point_speeds_m_s[k], at(max_decel_m_s2, k))


def route_speed_sp(s_along_m: np.ndarray, cum_m: np.ndarray, point_speeds_m_s: np.ndarray,
                   max_decel_m_s2: float | np.ndarray) -> np.ndarray:
    """Speed setpoint (N,) [m/s]: the lowest ``sqrt(v_i^2 + 2 a d_i)`` over route points ahead.

    s_along_m : (N,) [m] distance along the route; cum_m : (N, W) [m] distance of each point along
    it; point_speeds_m_s : (N, W) [m/s] limits at the points. Points behind contribute nothing.
    Compiled per car (:func:`route_speed_of`).
    """
    cum = np.asarray(cum_m, dtype=float)
    out = np.empty(cum.shape[0])
    _route_speeds(*rows_arg(s_along_m, n=cum.shape[0]), cum, np.asarray(point_speeds_m_s, dtype=float),
                  gain_arg(max_decel_m_s2), out)
    return out


__all__ = [
    "CarGuidanceParams",
    "SpeedSteerGains",
    "ackermann_angles",
    "ackermann_pair_rad",
    "bicycle_limit_rad",
    "bicycle_limit_scalar_rad",
    "corner_speeds_m_s",
    "drive_torque_n_m",
    "drive_torque_scalar_n_m",
    "pure_pursuit_steer",
    "pursuit_steer_of",
    "route_speed_of",
    "route_speed_sp",
    "speed_pi_steer_law",
    "speed_to_throttle_brake",
    "steer_for_yaw_rate_rad",
    "steer_limit_rad",
    "steer_limit_scalar_rad",
    "throttle_brake_of",
    "yaw_rate_to_steer",
]


def speed_pi_steer_law(sp: CarSetpoint, state: CarState, chassis: CarChassis, params: SpeedSteerGains,
                       memory: dict[str, np.ndarray], dt_s: float) -> tuple[CarCommand, dict[str, np.ndarray]]:
    """The built-in drive layer ``speed_pi_steer``: CarSetpoint -> CarCommand.

    Speed by :func:`speed_to_throttle_brake` (PI, memory ``speed_int``, with rolling resistance fed
    forward); steering: the route's angle where given, else :func:`yaw_rate_to_steer`. Bumpless:
    when the layer engages (memory ``engaged`` is 0, as after a reset) the integral starts at the
    value that reproduces the acceleration of the throttle and brake applied now, so taking over
    from manual driving or the parking brake causes no jerk. One compiled loop over the cars.
    """
    n = np.size(state.speed_m_s)
    out = np.empty((n, 4))                                   # throttle, brake, steer, new integral
    c = chassis
    _speed_pi_steer(*rows_arg(sp.speed_m_s, sp.steer_rad, sp.yaw_rate_rad_s, state.speed_m_s, state.yaw_rate_rad_s,
                              state.throttle, state.brake, c.mass_kg, c.wheelbase_m, c.wheel_radius_m,
                              c.max_drive_torque_n_m, c.max_brake_torque_n_m, c.top_speed_m_s,
                              c.rolling_resistance_coeff, memory["speed_int"], memory["engaged"], n=n),
                    float(dt_s), *params.kernel_args, out)
    return CarCommand(out[:, 0], out[:, 1], out[:, 2]), {"speed_int": out[:, 3], "engaged": np.ones(n)}


@jit
def _speed_pi_steer(speed_sp_m_s, steer_sp_rad, yaw_rate_sp_rad_s, speed_m_s, yaw_rate_rad_s, throttle_now,
                    brake_now, mass_kg, wheelbase_m, wheel_radius_m, max_drive_n_m, max_brake_n_m, top_speed_m_s,
                    rolling_coeff, speed_int, engaged, dt_s, gain_speed_p, gain_speed_i, lim_speed_int_m_s2,
                    gain_yaw_rate_p, max_accel_m_s2, max_decel_m_s2, out):
    for k in range(out.shape[0]):
        v = speed_m_s[k]
        kp, ki, lim_int = at(gain_speed_p, k), at(gain_speed_i, k), at(lim_speed_int_m_s2, k)
        integral = speed_int[k]
        if engaged[k] < 0.5:                                 # bumpless start: the acceleration applied now
            moving = abs(v) > 0.3
            direction = (1.0 if v > 0.0 else -1.0) if moving else 1.0
            drive_n = drive_torque_scalar_n_m(throttle_now[k], v, max_drive_n_m[k], top_speed_m_s[k]) / wheel_radius_m[k]
            brake_n = brake_now[k] * 4.0 * max_brake_n_m[k] / wheel_radius_m[k]
            acc_now = (drive_n - direction * brake_n * moving) / mass_kg[k]
            ki_pos = max(ki, 1e-9)
            lim = lim_int / ki_pos
            integral = min(max((acc_now - kp * (speed_sp_m_s[k] - v)) / ki_pos, -lim), lim) if ki > 0 else 0.0
        rolling_n = rolling_coeff[k] * mass_kg[k] * GRAVITY_M_S2
        out[k, 0], out[k, 1], out[k, 3] = throttle_brake_of(
            speed_sp_m_s[k], v, integral, dt_s, rolling_n, mass_kg[k], wheel_radius_m[k], max_drive_n_m[k],
            max_brake_n_m[k], top_speed_m_s[k], kp, ki, lim_int, at(max_accel_m_s2, k), at(max_decel_m_s2, k))
        steer = steer_sp_rad[k]
        out[k, 2] = steer if np.isfinite(steer) else steer_for_yaw_rate_rad(
            yaw_rate_sp_rad_s[k], yaw_rate_rad_s[k], v, wheelbase_m[k], at(gain_yaw_rate_p, k))
