"""GUIDANCE phase, layer 3: route -> virtual target -> velocity -> acceleration -> tilt, yaw rate.

The paper's §2.1.3 and eq. 3: pure pursuit places a virtual target on the route; a cascade of
position -> velocity -> acceleration loops turns it into vertical-speed, roll, pitch and yaw-rate
setpoints for the stabilizer.
"""

from __future__ import annotations

import esper
import numpy as np

from ..components.flight import GuidanceLimits
from ..control.position import (GuidanceGains, accel_to_tilt_sp, body_velocity_to_enu_sp, heading_to_yaw_rate_sp,
                                position_to_velocity_sp, velocity_to_accel_sp)
from ..control.pursuit import pure_pursuit
from ..frames import yaw_rad_from_quat_xyzw
from ..phases import Phase
from ..world import StepContext
from .flight_state import FlightMode, declare_flight_arrays
from .rows import gather_rows, stack_params, take_params


class GuidanceSystem(esper.Processor):
    """Follow each AUTO drone's route with pure pursuit and the position cascade; fly each VELOCITY
    drone at its commanded body velocity and yaw rate.

    Phase: GUIDANCE. Reads: flight_mode, route/route_stamp, vel_cmd_flu_m_s/yaw_rate_cmd_rad_s, pose,
    velocity.
    Writes: route_segment, arrived, dist_to_final_m, cross_track_m, pos_sp_enu_m, vel_sp_enu_m_s,
    vel_int_m_s, vz_sp_m_s, roll_sp_rad, pitch_sp_rad, yaw_rate_sp_rad_s (AUTO and VELOCITY rows).
    """

    phase = Phase.GUIDANCE
    order = 0

    def __init__(self) -> None:
        self._seen_version = -1
        self._rows = np.empty(0, dtype=np.intp)
        self._stamps = np.empty(0, dtype=np.int64)

    def _gather(self, ctx: StepContext) -> None:
        f = ctx.fleet
        declare_flight_arrays(f)
        self._rows, gains = gather_rows(GuidanceGains)
        ents = f.entity[self._rows]
        limits = [esper.component_for_entity(int(e), GuidanceLimits) for e in ents]
        self._gains = stack_params(gains, GuidanceGains)
        self._lim_tilt = np.deg2rad([lim.max_tilt_deg for lim in limits])
        self._lim_climb = np.array([lim.lim_climb_m_s for lim in limits])
        self._lim_descent = np.array([lim.lim_descent_m_s for lim in limits])
        self._lim_yaw_rate = np.deg2rad([lim.lim_yaw_rate_deg_s for lim in limits])
        self._lead = np.array([lim.lead_distance_m for lim in limits])
        self._zone = np.array([lim.final_approach_m for lim in limits])
        self._arrival = np.array([lim.arrival_radius_m for lim in limits])
        m = self._rows.size
        self._stamps = np.full(m, -1, dtype=np.int64)
        self._n_points = np.full(m, 2, dtype=np.intp)
        self._route = np.zeros((m, 2, 3))
        self._speeds = np.ones((m, 2, 3))
        self._yaw_sp = np.full(m, np.nan)

    def _load_routes(self, f, changed: np.ndarray) -> None:
        """Copy new routes of the ``changed`` local indices into the padded arrays."""
        rows = self._rows
        for k in changed.tolist():
            route = f.route[rows[k]]
            if route is None:
                self._n_points[k] = 2
                self._route[k] = f.pos_enu_m[rows[k]]
                continue
            w = route.points_enu_m.shape[0]
            if w > self._route.shape[1]:
                pad = w - self._route.shape[1]
                self._route = np.concatenate([self._route, np.repeat(self._route[:, -1:], pad, axis=1)], axis=1)
                self._speeds = np.concatenate([self._speeds, np.repeat(self._speeds[:, -1:], pad, axis=1)], axis=1)
            self._route[k, :w] = route.points_enu_m
            self._route[k, w:] = route.points_enu_m[-1]
            self._speeds[k, :w] = route.speeds_m_s
            self._speeds[k, w:] = route.speeds_m_s[-1]
            self._n_points[k] = w
            yaw_now = float(yaw_rad_from_quat_xyzw(f.quat_enu_flu_xyzw[rows[k]]))
            self._yaw_sp[k] = yaw_now if np.isnan(route.yaw_sp_rad) else route.yaw_sp_rad
        self._stamps[changed] = f.route_stamp[rows[changed]]

    def process(self, ctx: StepContext) -> None:
        f = ctx.fleet
        if f.version != self._seen_version:
            self._gather(ctx)
            self._seen_version = f.version
        rows = self._rows
        if rows.size == 0:
            return
        changed = np.flatnonzero(f.route_stamp[rows] != self._stamps)
        if changed.size:
            self._load_routes(f, changed)
        mode = f.flight_mode[rows]
        auto = (mode == FlightMode.AUTO) & np.array([f.route[r] is not None for r in rows.tolist()])
        if auto.any():
            self._follow_routes(ctx, np.flatnonzero(auto))
        velocity = mode == FlightMode.VELOCITY
        if velocity.any():
            self._track_velocity(ctx, np.flatnonzero(velocity))

    def _follow_routes(self, ctx: StepContext, k: np.ndarray) -> None:
        """AUTO rows (local indices ``k``): pure pursuit on the route, then the position cascade."""
        f = ctx.fleet
        r = self._rows[k]
        pos = f.pos_enu_m[r]
        res = pure_pursuit(pos, self._route[k], self._n_points[k], f.route_segment[r], self._speeds[k],
                           self._lead[k], self._zone[k])
        f.route_segment[r] = res.segment
        f.pos_sp_enu_m[r] = res.target_enu_m
        f.dist_to_final_m[r] = res.dist_to_final_m
        f.cross_track_m[r] = res.cross_track_m
        f.arrived[r] = res.dist_to_final_m < self._arrival[k]

        gains = take_params(self._gains, k)
        vel_sp = position_to_velocity_sp(res.target_enu_m, pos, res.dist_to_go_m, res.speed_lims_m_s[:, 0],
                                         np.minimum(res.speed_lims_m_s[:, 1], self._lim_climb[k]),
                                         np.minimum(res.speed_lims_m_s[:, 2], self._lim_descent[k]), gains)
        yaw = yaw_rad_from_quat_xyzw(f.quat_enu_flu_xyzw[r])
        self._velocity_loop(ctx, k, vel_sp, yaw, gains)
        f.yaw_rate_sp_rad_s[r] = heading_to_yaw_rate_sp(self._yaw_sp[k], yaw, self._lim_yaw_rate[k], gains)

    def _track_velocity(self, ctx: StepContext, k: np.ndarray) -> None:
        """VELOCITY rows (local indices ``k``): the commanded body velocity and yaw rate (ROS cmd_vel)."""
        f = ctx.fleet
        r = self._rows[k]
        yaw = yaw_rad_from_quat_xyzw(f.quat_enu_flu_xyzw[r])
        vel_sp = body_velocity_to_enu_sp(f.vel_cmd_flu_m_s[r], yaw, self._lim_climb[k], self._lim_descent[k])
        self._velocity_loop(ctx, k, vel_sp, yaw, take_params(self._gains, k))
        f.yaw_rate_sp_rad_s[r] = np.clip(f.yaw_rate_cmd_rad_s[r], -self._lim_yaw_rate[k], self._lim_yaw_rate[k])

    def _velocity_loop(self, ctx: StepContext, k: np.ndarray, vel_sp: np.ndarray, yaw: np.ndarray,
                       gains: GuidanceGains) -> None:
        """Velocity setpoint (ENU) -> tilt and vertical-speed setpoints for the rows ``k``."""
        f = ctx.fleet
        r = self._rows[k]
        f.vel_sp_enu_m_s[r] = vel_sp
        acc_h, vel_int = velocity_to_accel_sp(vel_sp, f.vel_enu_m_s[r], f.vel_int_m_s[r], ctx.dt_s,
                                              self._lim_tilt[k], gains)
        f.vel_int_m_s[r] = vel_int
        roll_sp, pitch_sp = accel_to_tilt_sp(acc_h, yaw, self._lim_tilt[k])
        f.roll_sp_rad[r] = roll_sp
        f.pitch_sp_rad[r] = pitch_sp
        f.vz_sp_m_s[r] = vel_sp[:, 2]
