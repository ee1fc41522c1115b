"""GUIDANCE phase: route following, the setpoint of every drone's position layer.

The paper's §2.1.3: pure pursuit places a virtual target on the route (AUTO mode); a body-frame
velocity command (ROS ``cmd_vel``, VELOCITY mode) becomes an ENU velocity. Either is written as the
position layer's :class:`~unetyemu_ecs.control.layers.PositionSetpoint`; the drone's position
controller (``controller: {position: ...}``, default ``cascade_pid``) turns it into attitude
setpoints right after (:mod:`.controllers`).
"""

from __future__ import annotations

import numpy as np

from ..components.flight import GuidanceLimits
from ..control.position import body_velocity_to_enu_sp
from ..control.pursuit import pure_pursuit, route_lengths
from ..frames import yaw_rad_from_quat_xyzw
from ..phases import Phase
from ..world import StepContext
from .fleet_system import FleetSystem
from .flight_state import MODE_AUTO, MODE_VELOCITY


class RouteFollowingSystem(FleetSystem):
    """Follow each AUTO drone's route with pure pursuit; turn each VELOCITY drone's body-frame command
    into an ENU velocity.

    Phase: GUIDANCE (order 0). Reads: flight_mode, route/route_stamp, vel_cmd_flu_m_s, pose.
    Writes: route_segment, arrived, dist_to_final_m, cross_track_m and the position setpoint:
    pos_sp_enu_m (NaN for VELOCITY rows), vel_sp_enu_m_s, speed_limit_m_s, dist_to_go_m; yaw_sp_rad
    is set with the route (``set_route``) and NaN in VELOCITY mode (the yaw rate is commanded).
    """

    phase = Phase.GUIDANCE
    order = 0
    requires = (GuidanceLimits,)

    def gather(self, ctx: StepContext) -> None:
        (limits,) = self.components
        self._lim_climb = np.array([lim.lim_climb_m_s for lim in limits], dtype=float)
        self._lim_descent = np.array([lim.lim_descent_m_s for lim in limits], dtype=float)
        self._lead = np.array([lim.lead_distance_m for lim in limits], dtype=float)
        self._zone = np.array([lim.final_approach_m for lim in limits], dtype=float)
        self._arrival = np.array([lim.arrival_radius_m for lim in limits], dtype=float)
        m = self.rows.size
        self._stamps = np.full(m, -1, dtype=np.int64)
        self._n_points = np.full(m, 2, dtype=np.intp)
        self._route = np.zeros((m, 2, 3))
        self._speeds = np.ones((m, 2, 3))
        self._seg_lengths, self._cum_lengths = route_lengths(self._route)     # kept with the routes

    def _load_routes(self, f, changed: np.ndarray) -> None:
        """Copy new routes of the ``changed`` local indices into the padded arrays."""
        rows = self.rows
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
        self._stamps[changed] = f.route_stamp[rows[changed]]
        self._seg_lengths, self._cum_lengths = route_lengths(self._route)

    def update(self, ctx: StepContext) -> None:
        f = ctx.fleet
        rows = self.sel
        changed = np.flatnonzero(f.route_stamp[rows] != self._stamps)
        if changed.size:
            self._load_routes(f, changed)
        mode = f.flight_mode[rows]
        auto = (mode == MODE_AUTO) & f.has_route[rows]
        if auto.any():
            self._follow_routes(ctx, np.flatnonzero(auto))
        velocity = mode == MODE_VELOCITY
        if velocity.any():
            self._velocity_setpoints(ctx, np.flatnonzero(velocity))

    def _follow_routes(self, ctx: StepContext, k: np.ndarray) -> None:
        """AUTO rows (local indices ``k``): pure pursuit on the route."""
        f = ctx.fleet
        r = self.sel if k.size == self.rows.size else self.rows[k]
        res = pure_pursuit(f.pos_enu_m[r], self._route[k], self._n_points[k], f.route_segment[r], self._speeds[k],
                           self._lead[k], self._zone[k], (self._seg_lengths[k], self._cum_lengths[k]))
        f.route_segment[r] = res.segment
        f.pos_sp_enu_m[r] = res.target_enu_m
        f.dist_to_final_m[r] = res.dist_to_final_m
        f.cross_track_m[r] = res.cross_track_m
        f.arrived[r] = res.dist_to_final_m < self._arrival[k]
        f.dist_to_go_m[r] = res.dist_to_go_m
        f.speed_limit_m_s[r] = res.speed_lims_m_s
        f.vel_sp_enu_m_s[r] = 0.0

    def _velocity_setpoints(self, ctx: StepContext, k: np.ndarray) -> None:
        """VELOCITY rows (local indices ``k``): the commanded body velocity in ENU, climb/descent clamped."""
        f = ctx.fleet
        r = self.rows[k]
        yaw = yaw_rad_from_quat_xyzw(f.quat_enu_flu_xyzw[r])
        f.vel_sp_enu_m_s[r] = body_velocity_to_enu_sp(f.vel_cmd_flu_m_s[r], yaw, self._lim_climb[k], self._lim_descent[k])
        f.pos_sp_enu_m[r] = np.nan
        f.yaw_sp_rad[r] = np.nan
        f.dist_to_go_m[r] = 0.0
        f.speed_limit_m_s[r] = np.stack([np.full(len(r), np.inf), self._lim_climb[k], self._lim_descent[k]], axis=1)
