"""Ground-vehicle laws, vectorised over a fleet of cars: steering geometry, drive and brake torque,
speed and course control, and the route speed profile.

Frames: world ENU; the car body is FLU (x forward, y left). Steering angle ``delta`` [rad] is the
bicycle-model front-wheel angle, positive = left (counter-clockwise turn, like yaw). No esper, no
PyBullet: every function takes and returns arrays of N cars.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated

import numpy as np

from ..config.schema import Ge, Gt, Le
from ..units import GRAVITY_M_S2, wrap_angle_rad
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


def steer_limit_rad(speed_m_s: np.ndarray, max_steer_rad: np.ndarray, scale_at_50_m_s: np.ndarray) -> np.ndarray:
    """Steering limit (N,) [rad] at a speed: ``max_steer`` at rest, falling linearly to
    ``scale_at_50 * max_steer`` at 50 m/s and held there (the reference implementation's law)."""
    frac = np.clip(np.abs(speed_m_s) / SPEED_FOR_STEER_SCALE_M_S, 0.0, 1.0)
    return max_steer_rad * (1.0 - (1.0 - scale_at_50_m_s) * frac)


def ackermann_angles(delta_rad: np.ndarray, wheelbase_m: np.ndarray, track_m: np.ndarray) -> np.ndarray:
    """Left and right front-wheel angles (N, 2) [rad] for a bicycle-model angle ``delta``.

    Both wheels turn about the same centre on the rear-axle line, at radius ``R = L / tan(delta)``
    from the car's centre line: the inner wheel turns more (``atan(L / (R - t/2))``).
    """
    delta = np.asarray(delta_rad, dtype=float)
    turning = np.abs(delta) > 1e-9
    radius = wheelbase_m / np.tan(np.where(turning, np.abs(delta), 1.0))
    sign = np.sign(delta)
    left = sign * np.arctan(wheelbase_m / (radius - sign * track_m / 2.0))
    right = sign * np.arctan(wheelbase_m / (radius + sign * track_m / 2.0))
    return np.where(turning[:, None], np.stack([left, right], axis=1), 0.0)


def bicycle_limit_rad(wheel_limit_rad: np.ndarray, wheelbase_m: np.ndarray, track_m: np.ndarray) -> np.ndarray:
    """The largest bicycle-model angle (N,) [rad] whose Ackermann *inner* wheel stays within
    ``wheel_limit`` (the inverse of :func:`ackermann_angles` for the inner wheel)."""
    return np.arctan(wheelbase_m / (wheelbase_m / np.tan(wheel_limit_rad) + track_m / 2.0))


def drive_torque_n_m(throttle: np.ndarray, speed_fwd_m_s: np.ndarray, max_torque_n_m: np.ndarray,
                     top_speed_m_s: np.ndarray) -> np.ndarray:
    """Total drive torque at the rear axle (N,) [N m] for ``throttle`` in [-1, 1] (negative = reverse).

    The torque falls linearly with speed in the driven direction and vanishes at the top speed, so
    no input can drive the car faster than ``top_speed``; against the motion (``throttle`` opposing
    ``speed``) the full torque is available.
    """
    throttle = np.clip(throttle, -1.0, 1.0)
    along = np.where(throttle >= 0.0, speed_fwd_m_s, -speed_fwd_m_s)          # speed in the driven direction
    fade = np.clip(1.0 - along / top_speed_m_s, 0.0, 1.0)
    return throttle * max_torque_n_m * fade


def speed_to_throttle_brake(speed_sp_m_s: np.ndarray, speed_m_s: np.ndarray, speed_int: np.ndarray, dt_s: float,
                            feedforward_n: np.ndarray, mass_kg: np.ndarray, wheel_radius_m: np.ndarray,
                            max_drive_n_m: np.ndarray, max_brake_n_m: np.ndarray, top_speed_m_s: np.ndarray,
                            gains: SpeedSteerGains) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """PI speed control: return ``(throttle in [-1, 1], brake in [0, 1], new integral)``, each (N,).

    ``a = kp e + ki int(e)`` limited to ``[-max_decel, max_accel]`` [m/s^2]; the force
    ``m a + feedforward`` (rolling resistance) is produced by the motor when it pushes in the
    direction of travel (or the car is nearly stopped), by the brakes when it opposes the motion.
    Anti-windup: the integral is frozen while the output is limited.
    """
    err = speed_sp_m_s - speed_m_s
    lim = gains.lim_speed_int_m_s2 / np.maximum(gains.gain_speed_i, 1e-12)
    trial = np.clip(speed_int + err * dt_s, -lim, lim)
    acc = gains.gain_speed_p * err + gains.gain_speed_i * trial
    limited = (acc > gains.max_accel_m_s2) | (acc < -gains.max_decel_m_s2)
    new_int = np.where(limited, speed_int, trial)
    acc = np.clip(acc, -gains.max_decel_m_s2, gains.max_accel_m_s2)
    moving = np.abs(speed_m_s) > 0.3
    direction = np.where(moving, np.sign(speed_m_s), np.where(speed_sp_m_s < 0.0, -1.0, 1.0))
    force = mass_kg * acc + direction * feedforward_n                        # along the world-forward axis
    wants_brake = moving & (force * direction < 0.0)
    # drive: the torque that gives `force`, as a fraction of what the motor has at this speed
    along = direction * speed_m_s
    available = max_drive_n_m * np.clip(1.0 - along / top_speed_m_s, 0.05, 1.0)
    throttle = np.clip(force * wheel_radius_m / available, -1.0, 1.0)
    # brake: all four wheels share the force
    brake = np.clip(np.abs(force) * wheel_radius_m / (4.0 * max_brake_n_m), 0.0, 1.0)
    stop_hold = (~moving) & (np.abs(speed_sp_m_s) < 0.05)                    # hold a stopped car
    throttle = np.where(wants_brake | stop_hold, 0.0, throttle)
    brake = np.where(wants_brake, brake, np.where(stop_hold, 1.0, 0.0))
    new_int = np.where(stop_hold, 0.0, new_int)
    return throttle, brake, new_int


def yaw_rate_to_steer(yaw_rate_sp_rad_s: np.ndarray, yaw_rate_rad_s: np.ndarray, speed_m_s: np.ndarray,
                      wheelbase_m: np.ndarray, gains: SpeedSteerGains) -> np.ndarray:
    """Bicycle-model steering (N,) [rad] for a yaw rate: ``atan(L r / v)`` plus P on the rate error.

    Below 0.5 m/s the kinematic term uses 0.5 m/s (a car cannot turn on the spot).
    """
    v = np.where(np.abs(speed_m_s) < 0.5, np.where(speed_m_s < 0.0, -0.5, 0.5), speed_m_s)
    return np.arctan(wheelbase_m * yaw_rate_sp_rad_s / v) + gains.gain_yaw_rate_p * (yaw_rate_sp_rad_s - yaw_rate_rad_s)


def pure_pursuit_steer(target_enu_m: np.ndarray, rear_axle_enu_m: np.ndarray, yaw_rad: np.ndarray,
                       wheelbase_m: np.ndarray) -> np.ndarray:
    """Classic pure pursuit (Coulter 1992): steer (N,) [rad] onto the arc through the target.

    The arc leaves the rear axle tangent to the heading and passes through the target: curvature
    ``2 sin(alpha) / l`` with ``alpha`` the bearing of the target off the heading and ``l`` its
    distance; ``delta = atan(L * curvature)``.
    """
    d = target_enu_m[:, :2] - rear_axle_enu_m[:, :2]
    dist = np.maximum(np.linalg.norm(d, axis=1), 1e-6)
    alpha = wrap_angle_rad(np.arctan2(d[:, 1], d[:, 0]) - yaw_rad)
    return np.arctan(wheelbase_m * 2.0 * np.sin(alpha) / dist)


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


def route_speed_sp(s_along_m: np.ndarray, cum_m: np.ndarray, point_speeds_m_s: np.ndarray,
                   max_decel_m_s2: float | np.ndarray) -> np.ndarray:
    """Speed setpoint (N,) [m/s]: the lowest ``sqrt(v_i^2 + 2 a d_i)`` over route points ahead.

    s_along_m : (N,) [m] distance along the route; cum_m : (N, W) [m] distance of each point along
    it; point_speeds_m_s : (N, W) [m/s] limits at the points. Points behind contribute nothing.
    """
    ahead = np.maximum(cum_m - s_along_m[:, None], 0.0)
    decel = np.asarray(max_decel_m_s2, dtype=float)
    decel = decel[:, None] if decel.ndim else decel
    reach = np.sqrt(point_speeds_m_s ** 2 + 2.0 * decel * ahead)
    reach = np.where(cum_m >= s_along_m[:, None] - 1e-9, reach, np.inf)
    return np.min(reach, axis=1)


__all__ = [
    "CarGuidanceParams",
    "SpeedSteerGains",
    "ackermann_angles",
    "bicycle_limit_rad",
    "corner_speeds_m_s",
    "drive_torque_n_m",
    "pure_pursuit_steer",
    "route_speed_sp",
    "speed_pi_steer_law",
    "speed_to_throttle_brake",
    "steer_limit_rad",
    "yaw_rate_to_steer",
]


def speed_pi_steer_law(sp: CarSetpoint, state: CarState, chassis: CarChassis, params: SpeedSteerGains,
                       memory: dict[str, np.ndarray], dt_s: float) -> tuple[CarCommand, dict[str, np.ndarray]]:
    """The built-in drive layer ``speed_pi_steer``: CarSetpoint -> CarCommand.

    Speed by :func:`speed_to_throttle_brake` (PI, memory ``speed_int``, with rolling resistance fed
    forward); steering: the route's angle where given, else :func:`yaw_rate_to_steer`. Bumpless:
    when the layer engages (memory ``engaged`` is 0, as after a reset) the integral starts at the
    value that reproduces the acceleration of the throttle and brake applied now, so taking over
    from manual driving or the parking brake causes no jerk.
    """
    v = state.speed_m_s
    integral = memory["speed_int"].copy()
    fresh = memory["engaged"] < 0.5
    if fresh.any():
        direction = np.where(np.abs(v) > 0.3, np.sign(v), 1.0)
        drive_n = drive_torque_n_m(state.throttle, v, chassis.max_drive_torque_n_m,
                                   chassis.top_speed_m_s) / chassis.wheel_radius_m
        brake_n = state.brake * 4.0 * chassis.max_brake_torque_n_m / chassis.wheel_radius_m
        acc_now = (drive_n - direction * brake_n * (np.abs(v) > 0.3)) / chassis.mass_kg
        ki = np.maximum(params.gain_speed_i, 1e-9)
        start = (acc_now - params.gain_speed_p * (sp.speed_m_s - v)) / ki
        lim = params.lim_speed_int_m_s2 / ki
        start = np.where(params.gain_speed_i > 0, np.clip(start, -lim, lim), 0.0)
        integral = np.where(fresh, start, integral)
    rolling_n = chassis.rolling_resistance_coeff * chassis.mass_kg * GRAVITY_M_S2
    throttle, brake, integral = speed_to_throttle_brake(
        sp.speed_m_s, v, integral, dt_s, rolling_n, chassis.mass_kg, chassis.wheel_radius_m,
        chassis.max_drive_torque_n_m, chassis.max_brake_torque_n_m, chassis.top_speed_m_s, params)
    by_rate = yaw_rate_to_steer(sp.yaw_rate_rad_s, state.yaw_rate_rad_s, v, chassis.wheelbase_m, params)
    steer = np.where(np.isfinite(sp.steer_rad), sp.steer_rad, by_rate)
    return CarCommand(throttle, brake, steer), {"speed_int": integral, "engaged": np.ones_like(integral)}
