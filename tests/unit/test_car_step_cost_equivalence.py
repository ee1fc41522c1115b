"""The cars' compiled per-step forms give what the plain numpy formulas gave, to rounding: each law of
``control/car.py`` (steering limits, Ackermann angles, drive torque, PI speed control, yaw-rate steering and the
``speed_pi_steer`` law with its bumpless start), the drive layer's system over steps of changing modes and rows, and
the wheel commands of the actuation system (drive and brake torques, wheel angles, when a parked car falls asleep).

The reference functions below are the code as it was before those changes, copied verbatim."""

from __future__ import annotations

import dataclasses
from types import SimpleNamespace

import esper
import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from unetyemu_ecs.builtin import SPEED_PI_STEER
from unetyemu_ecs.components.car import CarDynamics
from unetyemu_ecs.control.car import (SPEED_FOR_STEER_SCALE_M_S, SpeedSteerGains, ackermann_angles,
                                      bicycle_limit_rad, drive_torque_n_m, speed_pi_steer_law, speed_to_throttle_brake,
                                      steer_limit_rad, yaw_rate_to_steer)
from unetyemu_ecs.control.layers import CarChassis, CarCommand, CarSetpoint, CarState
from unetyemu_ecs.fleet import FleetState
from unetyemu_ecs.components.body import Identity
from unetyemu_ecs.control.car import CarGuidanceParams
from unetyemu_ecs.control.pursuit import pure_pursuit
from unetyemu_ecs.frames import R_from_quat_xyzw
from unetyemu_ecs.systems.car import (ASLEEP_AFTER_S, ROUTE_FOLLOWING_HZ, STILL_M_S, STOPPED_SPEED_M_S, CarGuidanceSystem,
                                      _enter_mode, _wheel_commands)
from unetyemu_ecs.systems.car_state import CarPath, DriveMode
from unetyemu_ecs.systems.car_state import (DRIVE_MANUAL, DRIVE_PARKED, DRIVE_ROUTE, DRIVE_VELOCITY,
                                            declare_car_arrays)
from unetyemu_ecs.systems.controllers import controller_system, finite_or_zero
from unetyemu_ecs.units import GRAVITY_M_S2, wrap_angle_rad
from unetyemu_ecs.world import StepContext

RNG = np.random.default_rng(23)
MODES = [DRIVE_PARKED, DRIVE_ROUTE, DRIVE_VELOCITY, DRIVE_MANUAL]


def assert_same_to_rounding(got, want, err_msg=""):
    """Equal to the last bits: compiled code takes atan and tan from the C library, which differs from numpy's
    vectorised ones by an ulp now and then, and sums a dot product in its own order."""
    assert_allclose(got, want, rtol=1e-12, atol=1e-14, err_msg=err_msg)


# -- the code before the change (references) -------------------------------------------------------------------------
def steer_limit_rad_ref(speed_m_s: np.ndarray, max_steer_rad: np.ndarray, scale_at_50_m_s: np.ndarray) -> np.ndarray:
    """Steering limit (N,) [rad] at a speed: ``max_steer`` at rest, falling linearly to
    ``scale_at_50 * max_steer`` at 50 m/s and held there (the reference implementation's law)."""
    frac = np.clip(np.abs(speed_m_s) / SPEED_FOR_STEER_SCALE_M_S, 0.0, 1.0)
    return max_steer_rad * (1.0 - (1.0 - scale_at_50_m_s) * frac)


def ackermann_angles_ref(delta_rad: np.ndarray, wheelbase_m: np.ndarray, track_m: np.ndarray) -> np.ndarray:
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


def bicycle_limit_rad_ref(wheel_limit_rad: np.ndarray, wheelbase_m: np.ndarray, track_m: np.ndarray) -> np.ndarray:
    """The largest bicycle-model angle (N,) [rad] whose Ackermann *inner* wheel stays within
    ``wheel_limit`` (the inverse of :func:`ackermann_angles_ref` for the inner wheel)."""
    return np.arctan(wheelbase_m / (wheelbase_m / np.tan(wheel_limit_rad) + track_m / 2.0))


def drive_torque_n_m_ref(throttle: np.ndarray, speed_fwd_m_s: np.ndarray, max_torque_n_m: np.ndarray,
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


def speed_to_throttle_brake_ref(speed_sp_m_s: np.ndarray, speed_m_s: np.ndarray, speed_int: np.ndarray, dt_s: float,
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


def yaw_rate_to_steer_ref(yaw_rate_sp_rad_s: np.ndarray, yaw_rate_rad_s: np.ndarray, speed_m_s: np.ndarray,
                      wheelbase_m: np.ndarray, gains: SpeedSteerGains) -> np.ndarray:
    """Bicycle-model steering (N,) [rad] for a yaw rate: ``atan(L r / v)`` plus P on the rate error.

    Below 0.5 m/s the kinematic term uses 0.5 m/s (a car cannot turn on the spot).
    """
    v = np.where(np.abs(speed_m_s) < 0.5, np.where(speed_m_s < 0.0, -0.5, 0.5), speed_m_s)
    return np.arctan(wheelbase_m * yaw_rate_sp_rad_s / v) + gains.gain_yaw_rate_p * (yaw_rate_sp_rad_s - yaw_rate_rad_s)


def speed_pi_steer_law_ref(sp: CarSetpoint, state: CarState, chassis: CarChassis, params: SpeedSteerGains,
                       memory: dict[str, np.ndarray], dt_s: float) -> tuple[CarCommand, dict[str, np.ndarray]]:
    """The built-in drive layer ``speed_pi_steer``: CarSetpoint -> CarCommand.

    Speed by :func:`speed_to_throttle_brake_ref` (PI, memory ``speed_int``, with rolling resistance fed
    forward); steering: the route's angle where given, else :func:`yaw_rate_to_steer_ref`. Bumpless:
    when the layer engages (memory ``engaged`` is 0, as after a reset) the integral starts at the
    value that reproduces the acceleration of the throttle and brake applied now, so taking over
    from manual driving or the parking brake causes no jerk.
    """
    v = state.speed_m_s
    integral = memory["speed_int"].copy()
    fresh = memory["engaged"] < 0.5
    if fresh.any():
        direction = np.where(np.abs(v) > 0.3, np.sign(v), 1.0)
        drive_n = drive_torque_n_m_ref(state.throttle, v, chassis.max_drive_torque_n_m,
                                   chassis.top_speed_m_s) / chassis.wheel_radius_m
        brake_n = state.brake * 4.0 * chassis.max_brake_torque_n_m / chassis.wheel_radius_m
        acc_now = (drive_n - direction * brake_n * (np.abs(v) > 0.3)) / chassis.mass_kg
        ki = np.maximum(params.gain_speed_i, 1e-9)
        start = (acc_now - params.gain_speed_p * (sp.speed_m_s - v)) / ki
        lim = params.lim_speed_int_m_s2 / ki
        start = np.where(params.gain_speed_i > 0, np.clip(start, -lim, lim), 0.0)
        integral = np.where(fresh, start, integral)
    rolling_n = chassis.rolling_resistance_coeff * chassis.mass_kg * GRAVITY_M_S2
    throttle, brake, integral = speed_to_throttle_brake_ref(
        sp.speed_m_s, v, integral, dt_s, rolling_n, chassis.mass_kg, chassis.wheel_radius_m,
        chassis.max_drive_torque_n_m, chassis.max_brake_torque_n_m, chassis.top_speed_m_s, params)
    by_rate = yaw_rate_to_steer_ref(sp.yaw_rate_rad_s, state.yaw_rate_rad_s, v, chassis.wheelbase_m, params)
    steer = np.where(np.isfinite(sp.steer_rad), sp.steer_rad, by_rate)
    return CarCommand(throttle, brake, steer), {"speed_int": integral, "engaged": np.ones_like(integral)}


def _heading_ref(quat_xyzw: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Forward unit vectors (N, 3) and yaw (N,) [rad] from ENU/FLU quaternions."""
    fwd = R_from_quat_xyzw(quat_xyzw)[:, :, 0]
    return fwd, np.arctan2(fwd[:, 1], fwd[:, 0])


def pure_pursuit_steer_ref(target_enu_m: np.ndarray, rear_axle_enu_m: np.ndarray, yaw_rad: np.ndarray,
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


def route_speed_sp_ref(s_along_m: np.ndarray, cum_m: np.ndarray, point_speeds_m_s: np.ndarray,
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


def _pack_paths_ref(paths: list[CarPath]) -> tuple:
    """Padded (N, W, 3) points, (N, W) speeds, point counts, cumulative lengths and cruise speeds."""
    width = max(len(p.points_enu_m) for p in paths)
    route = np.empty((len(paths), width, 3))
    speeds = np.zeros((len(paths), width))
    n_points = np.array([len(p.points_enu_m) for p in paths])
    for k, p in enumerate(paths):
        n = len(p.points_enu_m)
        route[k, :n], route[k, n:] = p.points_enu_m, p.points_enu_m[-1]
        speeds[k, :n], speeds[k, n:] = p.speeds_m_s, p.speeds_m_s[-1]
    seg_lengths = np.linalg.norm(np.diff(route, axis=1), axis=2)
    cum = np.concatenate([np.zeros((len(paths), 1)), np.cumsum(seg_lengths, axis=1)], axis=1)
    cruise = np.array([p.cruise_m_s for p in paths])
    return paths, route, np.repeat(speeds[:, :, None], 3, axis=2), n_points, cum, cruise


def _along_ref(pos: np.ndarray, route: np.ndarray, seg: np.ndarray) -> np.ndarray:
    """Distance (N,) [m] of each car's projection along its active segment."""
    m = np.arange(len(seg))
    a, b = route[m, seg], route[m, seg + 1]
    d = b - a
    length = np.linalg.norm(d, axis=1)
    t = np.clip(np.einsum("ni,ni->n", pos - a, d) / np.maximum(length, 1e-9) ** 2, 0.0, 1.0)
    return t * length


class CarGuidanceRef:
    """The route following's update as it was."""

    def update(self, ctx: StepContext) -> None:
        f, c = ctx.fleet, self
        sel = np.flatnonzero(f.drive_mode[c.rows] == DRIVE_ROUTE)
        if sel.size == 0:
            return
        r = c.rows[sel]
        key = (tuple(r.tolist()), tuple(f.path_stamp[r].tolist()))
        decimation = max(1, round(1.0 / (ROUTE_FOLLOWING_HZ * ctx.dt_s)))
        if key == self._key and ctx.step % decimation:
            return
        if key != self._key:                       # routes changed: rebuild the padded arrays once
            self._key = key
            self._packed = _pack_paths_ref([f.car_path[i] for i in r])
        paths, route, speeds, n_points, cum, cruise = self._packed
        pos = f.pos_enu_m[r].copy()
        pos[:, 2] = 0.0
        fwd, yaw = _heading_ref(f.quat_enu_flu_xyzw[r])
        v = f.car_speed_m_s[r]
        gains = c.gains
        lead = np.maximum(gains.lead_min_m[sel], gains.lead_time_s[sel] * np.abs(v))
        res = pure_pursuit(pos, route, n_points, f.path_segment[r], speeds, lead, np.zeros(len(r)))
        seg = res.segment.copy()
        for k, p in enumerate(paths):
            laps = int(f.path_laps[r[k]])
            if p.period and seg[k] >= p.wrap_from:
                seg[k] -= p.period
                laps += 1
            elif p.lap_ends:
                laps = max(laps, p.laps_done(int(seg[k])))
            if laps != f.path_laps[r[k]]:
                f.path_laps[r[k]] = laps
                name = esper.component_for_entity(int(c.entities[sel[k]]), Identity).name
                ctx.services.note(ctx.sim_time_s, name, f"route lap {laps} done")
        f.path_segment[r] = seg

        s_along = cum[np.arange(len(r)), res.segment] + _along_ref(pos, route, res.segment)
        speed_sp = np.minimum(cruise, route_speed_sp_ref(s_along, cum, speeds[:, :, 0], gains.max_decel_m_s2[sel] * 0.6))
        wheelbase = c.dyn.wheelbase_m[sel]
        rear_axle = pos - fwd * (wheelbase / 2.0)[:, None]
        steer = pure_pursuit_steer_ref(res.target_enu_m, rear_axle, yaw, wheelbase)

        # the end of the route: on the last segment, within the arrival radius along the route
        # (a car that rolled a little past the end counts), and stopped
        on_last = (res.segment == n_points - 2) & np.array([p.period == 0 for p in paths])
        along_left = res.dist_to_go_m - res.cross_track_m
        at_end = on_last & (along_left < gains.arrival_radius_m[sel]) & \
            (res.dist_to_final_m < 3.0 * gains.arrival_radius_m[sel])
        done = at_end & (np.abs(v) < STOPPED_SPEED_M_S)
        speed_sp = np.where(at_end, 0.0, speed_sp)
        f.car_speed_sp_m_s[r] = speed_sp
        f.car_steer_sp_rad[r] = np.where(at_end, f.car_steer_rad[r], steer)
        for k in np.flatnonzero(done):
            ent = int(c.entities[sel[k]])
            name = esper.component_for_entity(ent, Identity).name
            laps = len(paths[k].lap_ends)
            if laps:
                ctx.services.note(ctx.sim_time_s, name, f"route lap {laps} done")
            ctx.services.note(ctx.sim_time_s, name, "route done")
            _enter_mode(ctx, ent, int(r[k]), DriveMode.PARKED)
            f.path_done[r[k]] = True                   # after parking (which clears the path)
            f.path_laps[r[k]] = laps


class DriveControllerRef:
    """The drive layer's update as it was (mixed into a system made like the simulation's)."""

    def update(self, ctx: StepContext) -> None:
        f = ctx.fleet
        r = self.rows
        dyn = self.dyn
        fwd = f.R_enu_flu[r, :, 0]
        v = np.einsum("ni,ni->n", f.vel_enu_m_s[r], fwd)
        f.car_speed_m_s[r] = v
        mode = f.drive_mode[r]
        controlled = (mode == DRIVE_VELOCITY) | (mode == DRIVE_ROUTE)
        self.restart_on_entry(ctx, mode, controlled)

        throttle = np.zeros(r.size)
        brake = np.zeros(r.size)
        steer_sp = np.zeros(r.size)
        k = np.flatnonzero(controlled)
        if k.size:
            rk = r[k]
            route = f.drive_mode[rk] == DRIVE_ROUTE
            sp = CarSetpoint(np.where(route, f.car_speed_sp_m_s[rk], f.cmd_vel[rk, 0]),
                             np.where(route, f.car_steer_sp_rad[rk], np.nan),
                             np.where(route, 0.0, f.cmd_vel[rk, 1]))
            state = CarState(v[k], f.rate_flu_rad_s[rk, 2], f.car_steer_rad[rk], f.car_throttle[rk], f.car_brake[rk])
            params, chassis = self.take_rows(k, self.params, self.chassis)
            out: CarCommand = self.call_law(ctx, sp, state, chassis, params, rk)
            throttle[k] = np.clip(finite_or_zero(out.throttle), -1.0, 1.0)
            brake[k] = np.clip(finite_or_zero(out.brake), 0.0, 1.0)
            steer_sp[k] = finite_or_zero(out.steer_rad)

        wheel_limit = steer_limit_rad_ref(v, np.deg2rad(dyn.max_steer_deg), dyn.steer_scale_at_50_m_s)
        limit = bicycle_limit_rad_ref(wheel_limit, dyn.wheelbase_m, dyn.track_m)     # inner wheel at the limit
        manual = mode == DRIVE_MANUAL
        cmd = f.drive_cmd[r]
        throttle = np.where(manual, cmd[:, 0], throttle)
        brake = np.where(manual, cmd[:, 1], brake)
        steer_sp = np.where(manual, cmd[:, 2] * limit, steer_sp)
        parked = mode == DRIVE_PARKED
        throttle = np.where(parked, 0.0, throttle)
        brake = np.where(parked, 1.0, brake)

        steer_sp = np.clip(steer_sp, -limit, limit)
        slew = np.deg2rad(dyn.max_steer_rate_deg_s) * ctx.dt_s
        prev = f.car_steer_rad[r]
        f.car_steer_rad[r] = prev + np.clip(steer_sp - prev, -slew, slew)
        f.car_throttle[r] = throttle
        f.car_brake[r] = brake


# -- the laws --------------------------------------------------------------------------------------------------------
def _gains(n: int, scalar: bool = False) -> SpeedSteerGains:
    if scalar:
        return SpeedSteerGains(gain_speed_p=1.1, gain_speed_i=0.5, lim_speed_int_m_s2=1.2, gain_yaw_rate_p=0.4,
                               max_accel_m_s2=2.5, max_decel_m_s2=5.0)
    return SpeedSteerGains(gain_speed_p=RNG.uniform(0.2, 3.0, n),
                           gain_speed_i=np.where(RNG.random(n) < 0.25, 0.0, RNG.uniform(0.0, 1.0, n)),
                           lim_speed_int_m_s2=np.where(RNG.random(n) < 0.2, 0.0, RNG.uniform(0.0, 3.0, n)),
                           gain_yaw_rate_p=RNG.uniform(0.0, 1.0, n), max_accel_m_s2=RNG.uniform(0.5, 5.0, n),
                           max_decel_m_s2=RNG.uniform(0.5, 8.0, n))


def _speeds(n: int) -> np.ndarray:
    """Speeds [m/s] across the thresholds of the laws (0.3 moving, 0.5 steering, 50 limit scale) and at them."""
    v = RNG.normal(0.0, 12.0, n) * RNG.choice([0.01, 0.05, 1.0, 5.0], n)
    v[RNG.random(n) < 0.2] = RNG.choice([0.0, -0.0, 0.3, -0.3, 0.5, -0.5, 50.0, -50.0, 80.0], 1)[0]
    return v


def _chassis(n: int) -> CarChassis:
    return CarChassis(mass_kg=RNG.uniform(800.0, 12000.0, n), wheelbase_m=RNG.uniform(2.0, 6.0, n),
                      track_m=RNG.uniform(1.2, 2.4, n), wheel_radius_m=RNG.uniform(0.25, 0.6, n),
                      max_drive_torque_n_m=RNG.uniform(500.0, 20000.0, n),
                      max_brake_torque_n_m=RNG.uniform(500.0, 20000.0, n), top_speed_m_s=RNG.uniform(10.0, 45.0, n),
                      rolling_resistance_coeff=RNG.uniform(0.0, 0.03, n))


@pytest.mark.parametrize("n", [1, 3, 50])
def test_steering_geometry_and_drive_torque_are_what_they_were(n):
    for _ in range(20):
        delta = RNG.normal(0.0, 0.4, n) * RNG.choice([0.0, 1e-10, 1e-3, 1.0], n)
        L, T = RNG.uniform(2.0, 6.0, n), RNG.uniform(1.2, 2.4, n)
        assert_same_to_rounding(ackermann_angles(delta, L, T), ackermann_angles_ref(delta, L, T))
        lim = RNG.uniform(0.05, 1.0, n)
        assert_same_to_rounding(bicycle_limit_rad(lim, L, T), bicycle_limit_rad_ref(lim, L, T))
        v, scale = _speeds(n), RNG.uniform(0.1, 1.0, n)
        assert_same_to_rounding(steer_limit_rad(v, lim, scale), steer_limit_rad_ref(v, lim, scale))
        assert_same_to_rounding(steer_limit_rad(v, 0.5, 0.3), steer_limit_rad_ref(v, 0.5, 0.3))
        throttle = RNG.uniform(-1.5, 1.5, n)
        top, tq = RNG.uniform(10.0, 40.0, n), RNG.uniform(100.0, 5000.0, n)
        assert_same_to_rounding(drive_torque_n_m(throttle, v, tq, top), drive_torque_n_m_ref(throttle, v, tq, top))


@pytest.mark.parametrize("n", [1, 4, 60])
@pytest.mark.parametrize("scalar_gains", [False, True])
def test_speed_control_and_yaw_rate_steering_are_what_they_were(n, scalar_gains):
    for _ in range(30):
        g, c = _gains(n, scalar_gains), _chassis(n)
        v = _speeds(n)
        sp = np.where(RNG.random(n) < 0.2, RNG.choice([0.0, 0.04, -0.04], n), v + RNG.normal(0.0, 4.0, n))
        integral = RNG.normal(0.0, 3.0, n)
        ff = c.rolling_resistance_coeff * c.mass_kg * GRAVITY_M_S2
        got = speed_to_throttle_brake(sp, v, integral, 1 / 240, ff, c.mass_kg, c.wheel_radius_m,
                                      c.max_drive_torque_n_m, c.max_brake_torque_n_m, c.top_speed_m_s, g)
        want = speed_to_throttle_brake_ref(sp, v, integral, 1 / 240, ff, c.mass_kg, c.wheel_radius_m,
                                           c.max_drive_torque_n_m, c.max_brake_torque_n_m, c.top_speed_m_s, g)
        for name, a, b in zip(("throttle", "brake", "integral"), got, want):
            assert_same_to_rounding(a, b, err_msg=name)
        rate_sp, rate = RNG.normal(0.0, 0.5, n), RNG.normal(0.0, 0.5, n)
        assert_same_to_rounding(yaw_rate_to_steer(rate_sp, rate, v, c.wheelbase_m, g),
                                yaw_rate_to_steer_ref(rate_sp, rate, v, c.wheelbase_m, g))


@pytest.mark.parametrize("n", [1, 2, 9, 64])
@pytest.mark.parametrize("scalar_gains", [False, True])
def test_speed_pi_steer_law_is_what_it_was_engaging_or_engaged(n, scalar_gains):
    for trial in range(40):
        v = _speeds(n)
        steer_sp = np.where(RNG.random(n) < 0.5, np.nan, RNG.normal(0.0, 0.3, n))
        sp = CarSetpoint(v + RNG.normal(0.0, 3.0, n) * RNG.choice([0.0, 1.0], n), steer_sp, RNG.normal(0.0, 0.5, n))
        state = CarState(v, RNG.normal(0.0, 0.5, n), RNG.normal(0.0, 0.3, n), RNG.uniform(-1.0, 1.0, n),
                         RNG.uniform(0.0, 1.0, n) * RNG.choice([0.0, 1.0], n))
        memory = {"speed_int": RNG.normal(0.0, 2.0, n), "engaged": RNG.choice([0.0, 1.0], n)}
        c, g = _chassis(n), _gains(n, scalar_gains)
        out, mem = speed_pi_steer_law(sp, state, c, g, {k: m.copy() for k, m in memory.items()}, 1 / 240)
        ref, mem_ref = speed_pi_steer_law_ref(sp, state, c, g, {k: m.copy() for k, m in memory.items()}, 1 / 240)
        for name in ("throttle", "brake", "steer_rad"):
            assert_same_to_rounding(getattr(out, name), getattr(ref, name), err_msg=f"{name}, trial {trial}")
        for name in ("speed_int", "engaged"):
            assert_same_to_rounding(mem[name], mem_ref[name], err_msg=f"{name}, trial {trial}")


# -- the drive layer's system ----------------------------------------------------------------------------------------
def _dynamics(i: int) -> CarDynamics:
    return CarDynamics(wheelbase_m=2.5 + 0.4 * i, track_m=1.5 + 0.05 * i, wheel_radius_m=0.35 + 0.02 * i,
                       wheel_width_m=0.25, wheel_mass_kg=20.0, max_drive_torque_n_m=2500.0 + 300.0 * i,
                       max_brake_torque_n_m=1500.0 + 200.0 * i, rolling_resistance_coeff=0.015,
                       top_speed_m_s=25.0 + i, max_steer_deg=30.0 + i, steer_scale_at_50_m_s=0.3 + 0.05 * i,
                       max_steer_rate_deg_s=200.0 + 20.0 * i, suspension_stiffness_n_m=40000.0,
                       suspension_damping_n_s_m=3000.0, suspension_travel_m=0.15, tyre_friction=1.0)


def _drive_system(cls_name: str, rows: np.ndarray, fleet: FleetState, gains: list[SpeedSteerGains], law):
    plugin = dataclasses.replace(SPEED_PI_STEER, law=law)
    system = controller_system("speed_pi_steer", plugin)
    if cls_name == "ref":
        system.__class__ = type("DriveRef", (DriveControllerRef, type(system)), {})
    from unetyemu_ecs.fleet import row_selector
    system.rows, system.sel = rows, row_selector(rows)
    system.components = (gains, [_dynamics(i) for i in range(rows.size)],
                         [SimpleNamespace(mass_kg=900.0 + 500.0 * i) for i in range(rows.size)])
    system.gather(SimpleNamespace(fleet=fleet))
    return system


def _fleet(n: int) -> FleetState:
    f = FleetState(n)
    for e in range(n):
        f.allocate(100 + e, e)
    declare_car_arrays(f)
    return f


def _car_arrays(f: FleetState) -> dict[str, np.ndarray]:
    return {name: getattr(f, name) for name in ("car_speed_m_s", "car_throttle", "car_brake", "car_steer_rad",
                                                "ctl_SpeedSteerGains_speed_int", "ctl_SpeedSteerGains_engaged")}


@pytest.mark.parametrize("rows", [np.arange(1), np.arange(4), np.array([0, 2, 3, 6]), np.array([1, 4, 5, 7, 9])])
def test_drive_system_writes_what_it_wrote_over_steps_of_changing_modes(rows):
    # GIVEN the same cars twice, one driven by the system as it was and one by the system as it is
    n = 10
    f_ref, f_new = _fleet(n), _fleet(n)
    gains = [_gains(1, scalar=True) if i % 2 else SpeedSteerGains() for i in range(rows.size)]
    ref = _drive_system("ref", rows, f_ref, gains, speed_pi_steer_law_ref)
    new = _drive_system("new", rows, f_new, gains, speed_pi_steer_law)
    for step in range(80):
        # WHEN the cars move and turn, get new setpoints and teleop, and now and then change mode
        quat = RNG.normal(size=(n, 4))
        quat /= np.linalg.norm(quat, axis=1, keepdims=True)
        inputs = {"vel_enu_m_s": RNG.normal(0.0, 6.0, (n, 3)) * RNG.choice([0.01, 1.0], (n, 1)),
                  "rate_flu_rad_s": RNG.normal(0.0, 0.4, (n, 3)), "car_speed_sp_m_s": RNG.uniform(-2.0, 15.0, n),
                  "car_steer_sp_rad": RNG.normal(0.0, 0.5, n), "cmd_vel": RNG.normal(0.0, 3.0, (n, 2)),
                  "drive_cmd": np.column_stack([RNG.uniform(-1.0, 1.0, n), RNG.uniform(0.0, 1.0, n),
                                                RNG.uniform(-1.0, 1.0, n)])}
        R = np.array([_rotation(q) for q in quat])
        if step % 9 == 0:
            modes = RNG.choice(MODES, n).astype(np.int8)
            if step == 27:
                modes[:] = DRIVE_ROUTE
            if step == 45:
                modes[:] = DRIVE_PARKED
        for f in (f_ref, f_new):
            f.R_enu_flu[:n] = R
            for name, values in inputs.items():
                getattr(f, name)[:n] = values
            f.drive_mode[:n] = modes
        ctx_ref = SimpleNamespace(fleet=f_ref, dt_s=1 / 240, sim_time_s=step / 240)
        ctx_new = SimpleNamespace(fleet=f_new, dt_s=1 / 240, sim_time_s=step / 240)
        ref.update(ctx_ref)
        new.update(ctx_new)
        # THEN every array it writes is the same, to rounding
        for name, values in _car_arrays(f_ref).items():
            assert_same_to_rounding(_car_arrays(f_new)[name], values, err_msg=f"{name} at step {step}")


def _rotation(q: np.ndarray) -> np.ndarray:
    from unetyemu_ecs.frames import R_from_quat_xyzw
    return R_from_quat_xyzw(q[None])[0]


def test_a_law_that_returns_nan_or_a_scalar_is_read_as_before():
    def odd_law(sp, state, chassis, params, memory, dt_s):
        n = state.speed_m_s.shape[0]
        return CarCommand(np.full(n, np.nan), 0.7, np.where(np.arange(n) % 2, np.inf, 0.2)), memory
    n, rows = 5, np.arange(5)
    f_ref, f_new = _fleet(n), _fleet(n)
    ref = _drive_system("ref", rows, f_ref, [SpeedSteerGains()] * n, odd_law)
    new = _drive_system("new", rows, f_new, [SpeedSteerGains()] * n, odd_law)
    for f in (f_ref, f_new):
        f.drive_mode[:n] = [DRIVE_ROUTE, DRIVE_VELOCITY, DRIVE_ROUTE, DRIVE_PARKED, DRIVE_VELOCITY]
        f.R_enu_flu[:n] = np.eye(3)
    for step in range(3):
        ref.update(SimpleNamespace(fleet=f_ref, dt_s=1 / 240, sim_time_s=step / 240))
        new.update(SimpleNamespace(fleet=f_new, dt_s=1 / 240, sim_time_s=step / 240))
    for name, values in _car_arrays(f_ref).items():
        assert_array_equal(_car_arrays(f_new)[name], values, err_msg=name)
    assert_array_equal(f_new.car_throttle[:n], [0.0, 0.0, 0.0, 0.0, 0.0])      # NaN throttle: none
    assert_array_equal(f_new.car_brake[:n], [0.7, 0.7, 0.7, 1.0, 0.7])          # parked: full brake


# -- the actuation system's wheel commands ---------------------------------------------------------------------------
def _wheel_commands_ref(r, f, dyn, mass, was_parked, still_s, dt_s):
    """The numpy lines of CarActuationSystem.update as they were (its PyBullet calls aside)."""
    parked = f.drive_mode[r] == DRIVE_PARKED
    changed = was_parked != parked
    still = parked & (np.linalg.norm(f.vel_enu_m_s[r], axis=1) < STILL_M_S) & \
        (np.linalg.norm(f.rate_enu_rad_s[r], axis=1) < STILL_M_S)
    still_s = np.where(still, still_s + dt_s, 0.0)
    asleep = still_s > ASLEEP_AFTER_S
    drive = drive_torque_n_m_ref(f.car_throttle[r], f.car_speed_m_s[r], dyn.max_drive_torque_n_m, dyn.top_speed_m_s)
    corner_weight_n = mass * GRAVITY_M_S2 / 4.0
    rolling = dyn.rolling_resistance_coeff * corner_weight_n * dyn.wheel_radius_m
    brake = f.car_brake[r] * dyn.max_brake_torque_n_m + rolling
    steer = ackermann_angles_ref(f.car_steer_rad[r], dyn.wheelbase_m, dyn.track_m)
    return changed, parked, still_s, asleep, drive, brake, steer


@pytest.mark.parametrize("rows", [np.arange(3), np.array([1, 4, 6, 7])])
def test_wheel_commands_are_what_they_were_and_a_still_parked_car_falls_asleep(rows):
    from unetyemu_ecs.systems.fleet_system import stack_params
    n, m = 8, rows.size
    f = _fleet(n)
    dyn = stack_params([_dynamics(i) for i in range(m)], CarDynamics)
    mass = 900.0 + 500.0 * np.arange(m)
    rolling = dyn.rolling_resistance_coeff * mass * GRAVITY_M_S2 / 4.0 * dyn.wheel_radius_m
    was_parked, still_s = np.ones(m, bool), np.zeros(m)
    was_ref, still_ref = was_parked.copy(), still_s.copy()
    changed, out = np.zeros(m, bool), np.empty((m, 5))
    slept = np.zeros(m, bool)
    for step in range(1200):
        # every third row parked and still but for a shake now and then, the others driving; then modes at random
        parked = np.arange(n) % 3 == 0
        f.drive_mode[:n] = np.where(parked, DRIVE_PARKED, DRIVE_ROUTE) if step < 1000 else RNG.choice(MODES, n)
        shaken = RNG.random(n) < (0.05 if step < 150 else 0.0)
        f.vel_enu_m_s[:n] = RNG.normal(0.0, 0.001, (n, 3)) + (shaken | ~parked)[:, None] * 0.5
        f.rate_enu_rad_s[:n] = RNG.normal(0.0, 0.001, (n, 3))
        f.car_throttle[:n] = RNG.uniform(-1.2, 1.2, n)
        f.car_speed_m_s[:n] = RNG.normal(0.0, 10.0, n)
        f.car_brake[:n] = RNG.uniform(0.0, 1.0, n)
        f.car_steer_rad[:n] = RNG.normal(0.0, 0.3, n) * RNG.choice([0.0, 1.0], n)
        count = _wheel_commands(rows, f.drive_mode, f.vel_enu_m_s, f.rate_enu_rad_s, f.car_throttle, f.car_speed_m_s,
                                f.car_brake, f.car_steer_rad, 1 / 240, dyn.max_drive_torque_n_m, dyn.top_speed_m_s,
                                dyn.max_brake_torque_n_m, rolling, dyn.wheelbase_m, dyn.track_m, was_parked, still_s,
                                changed, out)
        ch_ref, was_ref, still_ref, asleep, drive, brake, steer = _wheel_commands_ref(rows, f, dyn, mass, was_ref,
                                                                                      still_ref, 1 / 240)
        assert_array_equal(changed, ch_ref)
        assert count == ch_ref.sum()
        assert_array_equal(was_parked, was_ref)
        assert_same_to_rounding(still_s, still_ref)
        assert_array_equal(out[:, 0] == 0.0, asleep)
        assert_same_to_rounding(out[:, 1], drive)
        assert_same_to_rounding(out[:, 2], brake)
        assert_same_to_rounding(out[:, 3:], steer)
        slept |= asleep
    # the parked cars (every third row) were still for more than 3 s and fell asleep; the others never
    assert_array_equal(slept, rows % 3 == 0)


# -- route following -------------------------------------------------------------------------------------------------
@pytest.fixture
def esper_world():
    esper.switch_world("car-equivalence")
    yield
    esper.switch_world("default")
    esper.delete_world("car-equivalence")


def _guidance_system(cls, rows: np.ndarray, entities: list[int]):
    from unetyemu_ecs.fleet import row_selector
    from unetyemu_ecs.systems.fleet_system import stack_params
    system = cls()
    system.rows, system.sel, system.entities = rows, row_selector(rows), np.array(entities, dtype=np.int64)
    system.dyn = stack_params([_dynamics(i) for i in range(rows.size)], CarDynamics)
    system.gains = stack_params([CarGuidanceParams(lead_min_m=2.0 + i, lead_time_s=0.3 + 0.1 * i,
                                                   max_decel_m_s2=3.0 + i, arrival_radius_m=1.0 + 0.5 * i)
                                 for i in range(rows.size)], CarGuidanceParams)
    return system


def _paths() -> list[CarPath]:
    square = np.array([[40.0, 0.0], [40.0, 40.0], [0.0, 40.0], [0.0, 0.0]])
    return [CarPath.build(np.zeros(3), square, 8.0, 2.5, loop=False, laps=0),
            CarPath.build(np.zeros(3), square, 10.0, 2.5, loop=True, laps=0),
            CarPath.build(np.zeros(3), square, 6.0, 2.5, loop=True, laps=2),
            CarPath.build(np.zeros(3), square[:1], 5.0, 2.5, loop=False, laps=0)]


@pytest.mark.parametrize("rows", [np.arange(4), np.array([0, 2, 5, 6]), np.array([1, 3, 4, 7, 8, 9])])
def test_route_following_of_cars_writes_what_it_wrote_along_open_routes_and_loops(rows, esper_world):
    # GIVEN cars on an open route, a never-ending loop, a two-lap loop and a one-point route, followed twice
    n = 10
    entities = [esper.create_entity(Identity(name=f"car{i}", kind="car", preset=None, index=i))
                for i in range(rows.size)]
    notes = {"ref": [], "new": []}
    fleets, systems, ctxs = {}, {}, {}
    for which, cls in (("ref", type("GuidanceRef", (CarGuidanceRef, CarGuidanceSystem), {})),
                       ("new", CarGuidanceSystem)):
        f = _fleet(n)
        f.car_path = np.full(f.capacity, None, dtype=object)
        for k, row in enumerate(rows.tolist()):
            f.car_path[row] = _paths()[k % 4]
            f.path_stamp[row] = 1
            f.drive_mode[row] = DRIVE_ROUTE
        fleets[which], systems[which] = f, _guidance_system(cls, rows, entities)
        services = SimpleNamespace(note=lambda t, name, text, out=notes[which]: out.append((t, name, text)))
        ctxs[which] = SimpleNamespace(fleet=f, dt_s=1 / 240, services=services)
    # WHEN the cars go round at their own pace, a little off the route, for 2.5 laps and then slow to a crawl
    s_along = np.zeros(rows.size)
    for step in range(1500):
        s_along += np.where(step < 1300, RNG.uniform(0.2, 0.6, rows.size), 0.0)
        for k, row in enumerate(rows.tolist()):
            path = fleets["ref"].car_path[row]
            pts = path.points_enu_m if path is not None else np.zeros((2, 3))
            seg_len = np.linalg.norm(np.diff(pts, axis=0), axis=1)
            cum = np.concatenate([[0.0], np.cumsum(seg_len)])
            s = min(s_along[k], cum[-1])
            j = min(np.searchsorted(cum, s, side="right") - 1, len(seg_len) - 1)
            u = (s - cum[j]) / seg_len[j] if seg_len[j] > 0 else 0.0
            pos = pts[j] + u * (pts[j + 1] - pts[j]) + np.append(RNG.normal(0.0, 0.3, 2), 0.5)
            yaw = RNG.normal(np.arctan2(*(pts[j + 1] - pts[j])[1::-1]), 0.2)
            q = np.array([0.0, 0.0, np.sin(yaw / 2), np.cos(yaw / 2)])
            for f in fleets.values():
                f.pos_enu_m[row] = pos
                f.quat_enu_flu_xyzw[row] = q
                f.R_enu_flu[row] = R_from_quat_xyzw(q[None])[0]
                f.car_speed_m_s[row] = 6.0 if step < 1300 else STOPPED_SPEED_M_S + 0.05
                f.car_steer_rad[row] = 0.1 * np.sin(step / 50.0)
        for which in ("ref", "new"):
            ctxs[which].step, ctxs[which].sim_time_s = step, step / 240
            systems[which].update(ctxs[which])
        # THEN the setpoints are the same to rounding, the segments, laps and notes exactly
        for name in ("car_speed_sp_m_s", "car_steer_sp_rad"):
            assert_same_to_rounding(getattr(fleets["new"], name), getattr(fleets["ref"], name),
                                    err_msg=f"{name} at step {step}")
        for name in ("path_segment", "path_laps", "drive_mode"):
            assert_array_equal(getattr(fleets["new"], name), getattr(fleets["ref"], name),
                               err_msg=f"{name} at step {step}")
        assert notes["new"] == notes["ref"]
    # the two-lap loop was driven to its end, the never-ending loop wrapped, and the open route's car at its end
    # is held (speed setpoint 0) but not done: it still rolls
    assert any("route lap 1 done" in text for _, _, text in notes["new"])
    assert fleets["new"].car_speed_sp_m_s[rows[0]] == 0.0
