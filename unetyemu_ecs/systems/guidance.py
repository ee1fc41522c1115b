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
from ..control.compiled import jit
from ..control.position import body_velocity_to_enu_sp
from ..control.pursuit import RouteGeometry, pursue_into
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
        self._zone_min = np.maximum(self._zone, 1e-9)
        self._arrival = np.array([lim.arrival_radius_m for lim in limits], dtype=float)
        m = self.rows.size
        self._velocity_limits = np.stack([np.full(m, np.inf), self._lim_climb, self._lim_descent], axis=1)
        self._stamps = np.full(m, -1, dtype=np.int64)
        self._n_points = np.full(m, 2, dtype=np.intp)
        self._route = np.zeros((m, 2, 3))
        self._speeds = np.ones((m, 2, 3))
        self._geometry = RouteGeometry(self._route, self._n_points, self._speeds)     # kept with the routes
        self._changed, self._auto, self._velocity = (np.zeros(m, dtype=bool) for _ in range(3))

    def _load_routes(self, f, changed: np.ndarray) -> None:
        """Copy new routes of the ``changed`` local indices into the padded arrays."""
        rows = self.rows
        width = self._route.shape[1]
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
        if self._route.shape[1] == width:          # the changed rows only (each row's numbers are its own)
            self._geometry.update(changed, self._route, self._n_points, self._speeds)
        else:                                      # wider padding: every row has new padded segments
            self._geometry = RouteGeometry(self._route, self._n_points, self._speeds)

    def update(self, ctx: StepContext) -> None:
        f = ctx.fleet
        rows = self.sel
        changed, auto, velocity = self._changed, self._auto, self._velocity
        n_changed, n_auto, n_velocity = _route_rows(f.route_stamp[rows], self._stamps, f.flight_mode[rows],
                                                    f.has_route[rows], changed, auto, velocity)
        if n_changed:
            self._load_routes(f, changed.nonzero()[0])
        if n_auto == auto.size:                          # every row follows its route (none flies a velocity)
            self._follow_routes(ctx, None)
            return
        if n_auto:
            self._follow_routes(ctx, auto.nonzero()[0])
        if n_velocity == velocity.size:
            self._velocity_setpoints(ctx, None)
        elif n_velocity:
            self._velocity_setpoints(ctx, velocity.nonzero()[0])

    def _follow_routes(self, ctx: StepContext, k: np.ndarray | None) -> None:
        """AUTO rows (local indices ``k``, None: all rows): pure pursuit on the route, written into the fleet."""
        f = ctx.fleet
        g = self._geometry
        if k is None:
            rows, geo_rows, lead, zone_min, arrival = self.rows, g.rows, self._lead, self._zone_min, self._arrival
        else:
            rows, geo_rows, lead, zone_min, arrival = (self.rows[k], k, self._lead[k], self._zone_min[k],
                                                       self._arrival[k])
        _follow_into(rows, f.pos_enu_m, f.route_segment, lead, zone_min, geo_rows, g.width, g.last_seg, g.vec,
                     g.length2, g.ok_t, g.seg_len, g.cum_start, g.len_u, g.ok_u, g.cum, g.total, g.last, arrival,
                     f.pos_sp_enu_m, f.speed_limit_m_s, f.dist_to_go_m, f.cross_track_m, f.dist_to_final_m,
                     f.arrived, f.vel_sp_enu_m_s)

    def _velocity_setpoints(self, ctx: StepContext, k: np.ndarray | None) -> None:
        """VELOCITY rows (local indices ``k``, None: all rows): the commanded body velocity in ENU,
        climb/descent clamped."""
        f = ctx.fleet
        if k is None:
            r, climb, descent, limits = self.sel, self._lim_climb, self._lim_descent, self._velocity_limits
        else:
            r, climb, descent, limits = (self.rows[k], self._lim_climb[k], self._lim_descent[k],
                                         self._velocity_limits[k])
        yaw = yaw_rad_from_quat_xyzw(f.quat_enu_flu_xyzw[r])
        f.vel_sp_enu_m_s[r] = body_velocity_to_enu_sp(f.vel_cmd_flu_m_s[r], yaw, climb, descent)
        f.pos_sp_enu_m[r] = np.nan
        f.yaw_sp_rad[r] = np.nan
        f.dist_to_go_m[r] = 0.0
        f.speed_limit_m_s[r] = limits


@jit
def _route_rows(route_stamp, stamps, flight_mode, has_route, changed, auto, velocity):
    """Per row: its route changed since it was loaded (``route_stamp`` != ``stamps``), it follows its route (AUTO
    with a route), it flies a velocity (VELOCITY); returns how many of each."""
    n_changed = n_auto = n_velocity = 0
    for k in range(changed.shape[0]):
        c = route_stamp[k] != stamps[k]
        a = flight_mode[k] == MODE_AUTO and has_route[k]
        v = flight_mode[k] == MODE_VELOCITY
        changed[k], auto[k], velocity[k] = c, a, v
        n_changed += c
        n_auto += a
        n_velocity += v
    return n_changed, n_auto, n_velocity


@jit
def _follow_into(rows, pos, segment, lead_m, final_zone_min_m, geo_rows, width, last_seg, vec, length2, ok_t,
                 seg_len, cum_start, len_u, ok_u, cum, total, last, arrival_m, pos_sp, speed_limit, dist_to_go,
                 cross_track, dist_to_final, arrived, vel_sp):
    """:func:`~unetyemu_ecs.control.pursuit.pursue` of the fleet ``rows`` (M,) on the geometry's ``geo_rows`` (M,),
    written straight into the fleet's arrays at those rows: the segment, the position setpoint and speed limits,
    the distances, ``arrived`` and a zero velocity setpoint (``lead_m``, ``final_zone_min_m``, ``arrival_m``: (M,))."""
    for j in range(rows.shape[0]):
        r = rows[j]
        seg, to_go, cross, to_final = pursue_into(pos[r], segment[r], lead_m[j], final_zone_min_m[j], geo_rows[j],
                                                  width, last_seg, vec, length2, ok_t, seg_len, cum_start, len_u,
                                                  ok_u, cum, total, last, pos_sp[r], speed_limit[r])
        segment[r] = seg
        dist_to_go[r], cross_track[r], dist_to_final[r] = to_go, cross, to_final
        arrived[r] = to_final < arrival_m[j]
        vel_sp[r, 0] = vel_sp[r, 1] = vel_sp[r, 2] = 0.0
