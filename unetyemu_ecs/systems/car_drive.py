"""STABILIZE phase for cars: the drive layer (speed and steering) of every car, by its chosen controller.

The paper's layer 2 for cars, framework part: PARKED holds
the brakes, MANUAL passes the teleop through (steering scaled by the speed-dependent limit), and
the ROUTE and VELOCITY rows are handed to the car's drive controller (``controller: {drive: ...}``,
default ``speed_pi_steer``) as a :class:`~unetyemu_ecs.control.layers.CarSetpoint`. Whatever the
source, the steering angle is then limited so that the inner front wheel stays within
``max_steer_deg`` at rest, less at speed (falling linearly to ``steer_scale_at_50_m_s`` of it at
50 m/s), and slewed at ``max_steer_rate_deg_s``.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..components.body import RigidBody
from ..components.car import CarDynamics
from ..control.car import bicycle_limit_scalar_rad, steer_limit_scalar_rad
from ..control.compiled import jit
from ..control.layers import CarChassis, CarCommand, CarSetpoint, CarState
from ..phases import Phase
from ..world import StepContext
from .car_state import DRIVE_MANUAL, DRIVE_PARKED, DRIVE_ROUTE, DRIVE_VELOCITY
from .controllers import ControllerSystem
from .fleet_system import stack_params


@jit
def _drive_screen(rows, R_enu_flu, vel_enu_m_s, drive_mode, car_speed_m_s, controlled):
    """Each car's forward speed (``car_speed_m_s`` at ``rows``: the velocity along the body x axis) and
    ``controlled`` (per row): ROUTE or VELOCITY, the modes the drive controller serves; returns how many."""
    n = 0
    for k in range(rows.shape[0]):
        r = rows[k]
        car_speed_m_s[r] = (R_enu_flu[r, 0, 0] * vel_enu_m_s[r, 0] + R_enu_flu[r, 1, 0] * vel_enu_m_s[r, 1]
                            + R_enu_flu[r, 2, 0] * vel_enu_m_s[r, 2])
        c = drive_mode[r] == DRIVE_ROUTE or drive_mode[r] == DRIVE_VELOCITY
        controlled[k] = c
        n += c
    return n


@jit
def _law_inputs(rows, drive_mode, car_speed_sp_m_s, car_steer_sp_rad, cmd_vel, car_speed_m_s, rate_flu_rad_s,
                car_steer_rad, car_throttle, car_brake, out):
    """``out`` (8, M) for the cars at ``rows``: their CarSetpoint (speed, steer, yaw rate: the route's in ROUTE,
    cmd_vel's otherwise, steer NaN) then their CarState (speed, yaw rate, steer, throttle, brake)."""
    for k in range(rows.shape[0]):
        r = rows[k]
        if drive_mode[r] == DRIVE_ROUTE:
            out[0, k], out[1, k], out[2, k] = car_speed_sp_m_s[r], car_steer_sp_rad[r], 0.0
        else:
            out[0, k], out[1, k], out[2, k] = cmd_vel[r, 0], np.nan, cmd_vel[r, 1]
        out[3, k], out[4, k], out[5, k] = car_speed_m_s[r], rate_flu_rad_s[r, 2], car_steer_rad[r]
        out[6, k], out[7, k] = car_throttle[r], car_brake[r]


@jit
def _finite(value):
    return value if np.isfinite(value) else 0.0


@jit
def _apply_drive(rows, controlled, throttle, brake, steer, drive_mode, drive_cmd, car_speed_m_s, max_steer_rad,
                 steer_scale_at_50_m_s, wheelbase_m, track_m, max_steer_rate_rad_s, dt_s, car_steer_rad,
                 car_throttle, car_brake):
    """Throttle, brake and steering of every car at ``rows``: the controller's (``throttle``, ``brake``,
    ``steer`` for the ``controlled`` rows in order; NaN and infinities 0, throttle and brake clamped), the
    teleop's in MANUAL (steering scaled by the limit), full brake when PARKED, nothing otherwise; the
    steering then limited so the inner wheel stays within its speed-dependent limit, and slewed at
    ``max_steer_rate_rad_s`` over the step ``dt_s``."""
    j = 0
    for k in range(rows.shape[0]):
        r = rows[k]
        mode = drive_mode[r]
        limit = bicycle_limit_scalar_rad(steer_limit_scalar_rad(car_speed_m_s[r], max_steer_rad[k],
                                                                steer_scale_at_50_m_s[k]), wheelbase_m[k], track_m[k])
        th, br, st = 0.0, 0.0, 0.0
        if controlled[k]:
            th = min(max(_finite(throttle[j]), -1.0), 1.0)
            br = min(max(_finite(brake[j]), 0.0), 1.0)
            st = _finite(steer[j])
            j += 1
        if mode == DRIVE_MANUAL:
            th, br, st = drive_cmd[r, 0], drive_cmd[r, 1], drive_cmd[r, 2] * limit
        elif mode == DRIVE_PARKED:
            th, br = 0.0, 1.0
        st = min(max(st, -limit), limit)
        prev = car_steer_rad[r]
        step = max_steer_rate_rad_s[k] * dt_s
        car_steer_rad[r] = prev + min(max(st - prev, -step), step)
        car_throttle[r] = th
        car_brake[r] = br


def _law_rows(values: Any, n: int) -> np.ndarray:
    """A law's output (N,) as the float array the kernel reads (a scalar is every row's)."""
    if type(values) is np.ndarray and values.dtype == np.float64 and values.shape == (n,):
        return values
    return np.ascontiguousarray(np.broadcast_to(np.asarray(values, dtype=float), (n,)))


class DriveControllerSystem(ControllerSystem):
    """Drive layer: throttle, brake and steering for every car that chose this controller.

    Phase: STABILIZE (order 20). Reads: drive_mode, car_speed_sp_m_s and car_steer_sp_rad (ROUTE),
    cmd_vel (VELOCITY), drive_cmd (MANUAL), pose, velocity. Writes: car_speed_m_s, car_throttle,
    car_brake, car_steer_rad. The controller's memory is reset when the car enters ROUTE or VELOCITY.
    """

    phase = Phase.STABILIZE
    order = 20
    mode_array = "drive_mode"

    def gather(self, ctx: StepContext) -> None:
        super().gather(ctx)
        _, dyns, bodies = self.components
        dyn = stack_params(dyns, CarDynamics)
        self.dyn = dyn
        self.chassis = CarChassis(
            mass_kg=np.array([b.mass_kg for b in bodies], dtype=float), wheelbase_m=dyn.wheelbase_m,
            track_m=dyn.track_m, wheel_radius_m=dyn.wheel_radius_m, max_drive_torque_n_m=dyn.max_drive_torque_n_m,
            max_brake_torque_n_m=dyn.max_brake_torque_n_m, top_speed_m_s=dyn.top_speed_m_s,
            rolling_resistance_coeff=dyn.rolling_resistance_coeff)
        self._max_steer_rad = np.deg2rad(dyn.max_steer_deg)
        self._max_steer_rate_rad_s = np.deg2rad(dyn.max_steer_rate_deg_s)
        self._controlled = np.zeros(self.rows.size, dtype=bool)
        self._inputs = np.empty((8, self.rows.size))
        self._no_output = np.empty(0)

    def update(self, ctx: StepContext) -> None:
        f = ctx.fleet
        r, controlled, dyn = self.rows, self._controlled, self.dyn
        n = _drive_screen(r, f.R_enu_flu, f.vel_enu_m_s, f.drive_mode, f.car_speed_m_s, controlled)
        self.restart_on_entry(ctx, f.drive_mode[self.sel], controlled)
        throttle = brake = steer = self._no_output
        if n:
            k = controlled.nonzero()[0]
            rk = r[k]
            inputs = self._inputs[:, :n]
            _law_inputs(rk, f.drive_mode, f.car_speed_sp_m_s, f.car_steer_sp_rad, f.cmd_vel, f.car_speed_m_s,
                        f.rate_flu_rad_s, f.car_steer_rad, f.car_throttle, f.car_brake, inputs)
            params, chassis = self.take_rows(k, self.params, self.chassis)
            out: CarCommand = self.call_law(ctx, CarSetpoint(*inputs[:3]), CarState(*inputs[3:]), chassis, params, rk)
            throttle, brake, steer = _law_rows(out.throttle, n), _law_rows(out.brake, n), _law_rows(out.steer_rad, n)
        _apply_drive(r, controlled, throttle, brake, steer, f.drive_mode, f.drive_cmd, f.car_speed_m_s,
                     self._max_steer_rad, dyn.steer_scale_at_50_m_s, dyn.wheelbase_m, dyn.track_m,
                     self._max_steer_rate_rad_s, ctx.dt_s, f.car_steer_rad, f.car_throttle, f.car_brake)


DRIVE_REQUIRES = (CarDynamics, RigidBody)     # the components of a drive controller's rows, besides its params

__all__ = ["DRIVE_REQUIRES", "DriveControllerSystem"]
