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

import numpy as np

from ..components.body import RigidBody
from ..components.car import CarDynamics
from ..control.car import bicycle_limit_rad, steer_limit_rad
from ..control.layers import CarChassis, CarCommand, CarSetpoint, CarState
from ..phases import Phase
from ..world import StepContext
from .car_state import DRIVE_MANUAL, DRIVE_PARKED, DRIVE_ROUTE, DRIVE_VELOCITY
from .controllers import ControllerSystem, finite_or_zero
from .fleet_system import stack_params


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

        wheel_limit = steer_limit_rad(v, np.deg2rad(dyn.max_steer_deg), dyn.steer_scale_at_50_m_s)
        limit = bicycle_limit_rad(wheel_limit, dyn.wheelbase_m, dyn.track_m)     # inner wheel at the limit
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


DRIVE_REQUIRES = (CarDynamics, RigidBody)     # the components of a drive controller's rows, besides its params

__all__ = ["DRIVE_REQUIRES", "DriveControllerSystem"]
