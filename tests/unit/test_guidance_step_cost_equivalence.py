"""The guidance phase's cheaper per-step forms give what the plain formulas gave: bit for bit, pure pursuit on a route
geometry kept with the routes (a single segment without the search, several with the two projections batched) and the
route-following system's all-rows and subset paths; to rounding, the compiled ``cascade_pid`` position law (every
row flying to a position or none, something limited or nothing, every heading held or some) and each of its public
stages.

The reference functions below are the code as it was before those changes, copied verbatim."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from unetyemu_ecs.components.flight import GuidanceLimits
from unetyemu_ecs.control.layers import Airframe, AttitudeSetpoint, DroneState, PositionSetpoint
from unetyemu_ecs.control.position import (GuidanceGains, accel_to_tilt_sp, body_velocity_to_enu_sp, cascade_pid_law,
                                           heading_to_yaw_rate_sp, position_to_velocity_sp, velocity_to_accel_sp)
from unetyemu_ecs.control.pursuit import RouteGeometry, pure_pursuit, pursue, route_lengths
from unetyemu_ecs.frames import row_norm, yaw_rad_from_quat_xyzw
from unetyemu_ecs.systems.flight_state import MODE_AUTO, MODE_DISARMED, MODE_MANUAL, MODE_VELOCITY, Route
from unetyemu_ecs.systems.guidance import RouteFollowingSystem
from unetyemu_ecs.units import GRAVITY_M_S2, wrap_angle_rad

RNG = np.random.default_rng(11)


def assert_same_to_rounding(got, want, err_msg=""):
    """Equal to the last bits: the compiled laws sum in another order and take sin, cos, tan and atan from the C
    library, which differ from numpy's vectorised ones by an ulp now and then."""
    assert_allclose(got, want, rtol=1e-13, atol=1e-15, err_msg=err_msg)


# -- the code before the change (references) -------------------------------------------------------------------------
def _project_ref(pos, a, b):
    d = b - a
    length2 = np.einsum("mi,mi->m", d, d)
    t = np.divide(np.einsum("mi,mi->m", pos - a, d), length2, out=np.ones_like(length2), where=length2 > 1e-12)
    t = np.minimum(np.maximum(t, 0.0), 1.0)
    return t, np.sqrt(length2), row_norm(pos - (a + t[:, None] * d))


def pure_pursuit_ref(pos_enu_m, route_enu_m, n_points, segment, speeds_m_s, lead_m, final_zone_m, lengths=None):
    m_idx = np.arange(pos_enu_m.shape[0])
    last_seg = n_points - 2
    seg = np.minimum(segment.astype(np.intp), last_seg)
    for _ in range(route_enu_m.shape[1]):
        can = seg < last_seg
        if not can.any():
            break
        a = route_enu_m[m_idx, seg]
        b = route_enu_m[m_idx, seg + 1]
        c = route_enu_m[m_idx, np.minimum(seg + 2, route_enu_m.shape[1] - 1)]
        t, _, dist_cur = _project_ref(pos_enu_m, a, b)
        t_next, _, dist_next = _project_ref(pos_enu_m, b, c)
        step = can & ((t >= 1.0) | ((dist_next <= dist_cur) & (t_next > 0.0)))
        if not step.any():
            break
        seg = seg + step
    a = route_enu_m[m_idx, seg]
    b = route_enu_m[m_idx, seg + 1]
    t, seg_len, cross = _project_ref(pos_enu_m, a, b)
    seg_lengths, cum = lengths if lengths is not None else route_lengths(route_enu_m)
    total = cum[m_idx, n_points - 1]
    s_proj = cum[m_idx, seg] + t * seg_len
    remaining = np.maximum(total - s_proj, 0.0)
    lead = lead_m * np.minimum(remaining / np.maximum(final_zone_m, 1e-9), 1.0)
    s_target = np.minimum(s_proj + lead, total)
    j = np.count_nonzero(cum <= s_target[:, None] + 1e-12, axis=1) - 1
    j = np.minimum(np.maximum(j, 0), last_seg)
    seg_len_j = seg_lengths[m_idx, j]
    u = np.divide(s_target - cum[m_idx, j], seg_len_j, out=np.ones_like(seg_len_j), where=seg_len_j > 1e-12)
    u = np.minimum(np.maximum(u, 0.0), 1.0)
    p_j = route_enu_m[m_idx, j]
    target = p_j + u[:, None] * (route_enu_m[m_idx, j + 1] - p_j)
    v_seg = speeds_m_s[m_idx, seg]
    speeds = v_seg + t[:, None] * (speeds_m_s[m_idx, seg + 1] - v_seg)
    dist_to_final = row_norm(route_enu_m[m_idx, n_points - 1] - pos_enu_m)
    return target, seg, speeds, remaining + cross, cross, dist_to_final


def _ratio_or_inf_ref(num, den, tiny=1e-9):
    num, den = np.broadcast_arrays(np.asarray(num, dtype=float), np.asarray(den, dtype=float))
    return np.divide(num, den, out=np.full(den.shape, np.inf), where=den > tiny)


def _per_row_ref(gain):
    gain = np.asarray(gain, dtype=float)
    return gain[..., None] if gain.ndim else float(gain)


def position_to_velocity_sp_ref(pos_sp_enu_m, pos_enu_m, dist_to_go_m, lim_speed_h_m_s, lim_climb_m_s,
                                lim_descent_m_s, gains):
    delta = pos_sp_enu_m - pos_enu_m
    dist = row_norm(delta)
    unit = delta * np.divide(1.0, dist, out=np.zeros_like(dist), where=dist > 1e-9)[:, None]
    d_go = np.maximum(dist_to_go_m, dist)
    speed = np.minimum(gains.gain_pos_p * d_go, np.sqrt(2.0 * gains.lim_decel_m_s2 * d_go))
    h = np.hypot(unit[:, 0], unit[:, 1])
    v_lim = np.where(unit[:, 2] >= 0.0, lim_climb_m_s, lim_descent_m_s)
    speed = np.minimum(speed, _ratio_or_inf_ref(lim_speed_h_m_s, h))
    speed = np.minimum(speed, _ratio_or_inf_ref(v_lim, np.abs(unit[:, 2])))
    return unit * speed[:, None]


def velocity_to_accel_sp_ref(vel_sp_enu_m_s, vel_enu_m_s, vel_int, dt_s, lim_tilt_rad, gains):
    err = vel_sp_enu_m_s[:, :2] - vel_enu_m_s[:, :2]
    lim_int = gains.lim_vel_int_m_s2 / np.maximum(gains.gain_vel_i, 1e-12)
    trial = vel_int + err * dt_s
    trial *= np.minimum(1.0, lim_int / np.maximum(row_norm(trial), 1e-12))[:, None]
    acc = _per_row_ref(gains.gain_vel_p) * err + _per_row_ref(gains.gain_vel_i) * trial
    lim_acc = GRAVITY_M_S2 * np.tan(lim_tilt_rad)
    norm = row_norm(acc)
    limited = norm > lim_acc
    if limited.any():
        acc *= np.where(limited, lim_acc / np.maximum(norm, 1e-12), 1.0)[:, None]
        return acc, np.where(limited[:, None], vel_int, trial)
    return acc, trial


def accel_to_tilt_sp_ref(acc_sp_h_enu_m_s2, yaw_rad, lim_tilt_rad):
    acc = np.asarray(acc_sp_h_enu_m_s2, dtype=float)
    norm = row_norm(acc)
    lim_acc = GRAVITY_M_S2 * np.tan(lim_tilt_rad)
    if (norm > lim_acc).any():
        acc = acc * np.where(norm > lim_acc, lim_acc / np.maximum(norm, 1e-12), 1.0)[:, None]
    c, s = np.cos(yaw_rad), np.sin(yaw_rad)
    a_fwd = c * acc[:, 0] + s * acc[:, 1]
    a_left = -s * acc[:, 0] + c * acc[:, 1]
    pitch = np.arctan(a_fwd / GRAVITY_M_S2)
    roll = np.arctan(-a_left * np.cos(pitch) / GRAVITY_M_S2)
    return roll, pitch


def heading_to_yaw_rate_sp_ref(yaw_sp_rad, yaw_rad, lim_yaw_rate_rad_s, gains):
    err = yaw_sp_rad - yaw_rad
    err = wrap_angle_rad(np.where(np.isfinite(err), err, 0.0))
    return np.minimum(np.maximum(gains.gain_yaw_p * err, -lim_yaw_rate_rad_s), lim_yaw_rate_rad_s)


def body_velocity_to_enu_sp_ref(vel_flu_m_s, yaw_rad, lim_climb_m_s, lim_descent_m_s):
    c, s = np.cos(yaw_rad), np.sin(yaw_rad)
    fwd, left, up = vel_flu_m_s[:, 0], vel_flu_m_s[:, 1], vel_flu_m_s[:, 2]
    return np.stack([c * fwd - s * left, s * fwd + c * left, np.clip(up, -lim_descent_m_s, lim_climb_m_s)], axis=1)


def cascade_pid_law_ref(sp, state, airframe, params, memory, dt_s):
    to_pos = sp.flies_to_position
    pos = state.pos_enu_m
    target = np.where(to_pos[:, None], sp.pos_enu_m, pos)
    vel_to_pos = position_to_velocity_sp_ref(target, pos, np.where(to_pos, sp.dist_to_go_m, 0.0),
                                             sp.speed_limit_m_s[:, 0],
                                             np.minimum(sp.speed_limit_m_s[:, 1], airframe.lim_climb_m_s),
                                             np.minimum(sp.speed_limit_m_s[:, 2], airframe.lim_descent_m_s), params)
    vel_sp = np.where(to_pos[:, None], vel_to_pos, sp.vel_enu_m_s)
    acc_h, vel_int = velocity_to_accel_sp_ref(vel_sp, state.vel_enu_m_s, memory["vel_int_m_s"], dt_s,
                                              airframe.max_tilt_rad, params)
    yaw = yaw_rad_from_quat_xyzw(state.quat_enu_flu_xyzw)
    roll_sp, pitch_sp = accel_to_tilt_sp_ref(acc_h, yaw, airframe.max_tilt_rad)
    hold_heading = np.isfinite(sp.yaw_rad)
    lim_rate = airframe.lim_yaw_rate_rad_s
    if hold_heading.all():
        yaw_rate = heading_to_yaw_rate_sp_ref(sp.yaw_rad, yaw, lim_rate, params)
    else:
        yaw_rate = np.where(hold_heading,
                            heading_to_yaw_rate_sp_ref(np.where(hold_heading, sp.yaw_rad, yaw), yaw, lim_rate, params),
                            np.minimum(np.maximum(sp.yaw_rate_rad_s, -lim_rate), lim_rate))
    return AttitudeSetpoint(vel_sp[:, 2], roll_sp, pitch_sp, yaw_rate), {"vel_int_m_s": vel_int}


class RouteFollowingRef(RouteFollowingSystem):
    """The route-following system as it was (every step gathers its rows' routes and calls pure pursuit)."""

    def gather(self, ctx):
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
        self._seg_lengths, self._cum_lengths = route_lengths(self._route)

    def _load_routes(self, f, changed):
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

    def update(self, ctx):
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

    def _follow_routes(self, ctx, k):
        f = ctx.fleet
        r = self.sel if k.size == self.rows.size else self.rows[k]
        target, seg, speeds, to_go, cross, to_final = pure_pursuit_ref(
            f.pos_enu_m[r], self._route[k], self._n_points[k], f.route_segment[r], self._speeds[k], self._lead[k],
            self._zone[k], (self._seg_lengths[k], self._cum_lengths[k]))
        f.route_segment[r] = seg
        f.pos_sp_enu_m[r] = target
        f.dist_to_final_m[r] = to_final
        f.cross_track_m[r] = cross
        f.arrived[r] = to_final < self._arrival[k]
        f.dist_to_go_m[r] = to_go
        f.speed_limit_m_s[r] = speeds
        f.vel_sp_enu_m_s[r] = 0.0

    def _velocity_setpoints(self, ctx, k):
        f = ctx.fleet
        r = self.rows[k]
        yaw = yaw_rad_from_quat_xyzw(f.quat_enu_flu_xyzw[r])
        f.vel_sp_enu_m_s[r] = body_velocity_to_enu_sp_ref(f.vel_cmd_flu_m_s[r], yaw, self._lim_climb[k],
                                                          self._lim_descent[k])
        f.pos_sp_enu_m[r] = np.nan
        f.yaw_sp_rad[r] = np.nan
        f.dist_to_go_m[r] = 0.0
        f.speed_limit_m_s[r] = np.stack([np.full(len(r), np.inf), self._lim_climb[k], self._lim_descent[k]], axis=1)


# -- inputs ------------------------------------------------------------------------------------------------------------
def _routes(m: int, w: int, degenerate: bool = True):
    """Padded routes of 2..w points, with (``degenerate``) repeated points and a route of one repeated point,
    and positions on points, on segments, far off and past the end; segments from 0 to beyond the last."""
    route = RNG.uniform(-30.0, 30.0, (m, w, 3))
    n_points = RNG.integers(2, w + 1, m).astype(np.intp)
    n_points[0] = w
    if degenerate:
        route[1 % m, :] = route[1 % m, 0]                               # all one point: zero-length segments
        if w > 2:
            route[2 % m, 1] = route[2 % m, 0]                           # a repeated point inside a route
    route[3 % m, :, 2] = 10.0                                           # level route
    for i in range(m):
        route[i, n_points[i]:] = route[i, n_points[i] - 1]
    speeds = RNG.uniform(0.5, 12.0, (m, w, 3))
    for i in range(m):
        speeds[i, n_points[i]:] = speeds[i, n_points[i] - 1]
    k = RNG.integers(0, w, m)
    pos = route[np.arange(m), k] + RNG.normal(0.0, 3.0, (m, 3)) * RNG.integers(0, 2, (m, 1))   # half exactly on points
    pos[4 % m] = route[4 % m, n_points[4 % m] - 1] + np.array([0.5, 0.0, 0.0])                 # past the end
    segment = RNG.integers(0, w + 1, m)
    lead = RNG.uniform(0.5, 8.0, m)
    zone = RNG.uniform(0.0, 10.0, m)
    zone[::3] = 0.0                                                     # a car's zone: none
    return pos, route, n_points, segment, speeds, lead, zone


@pytest.mark.parametrize("m, w", [(1, 2), (7, 2), (1, 3), (9, 3), (12, 5), (40, 8)])
def test_pursuit_on_kept_geometry_is_bit_for_bit_pure_pursuit(m, w):
    for trial in range(40):
        pos, route, n_points, segment, speeds, lead, zone = _routes(m, w, degenerate=trial % 2 == 0)
        ref = pure_pursuit_ref(pos, route, n_points, segment, speeds, lead, zone)
        got = pursue(pos, segment, lead, np.maximum(zone, 1e-9), RouteGeometry(route, n_points, speeds))
        for g, want in zip(got, ref):
            assert_array_equal(g, want)
        res = pure_pursuit(pos, route, n_points, segment, speeds, lead, zone)
        for g, want in zip((res.target_enu_m, res.segment, res.speed_lims_m_s, res.dist_to_go_m, res.cross_track_m,
                            res.dist_to_final_m), ref):
            assert_array_equal(g, want)


@pytest.mark.parametrize("m, w", [(1, 2), (8, 2), (8, 4), (30, 6)])
def test_pursuit_of_a_subset_of_rows_on_geometry_updated_row_by_row_is_pure_pursuit_of_those_rows(m, w):
    pos, route, n_points, segment, speeds, lead, zone = _routes(m, w)
    geometry = RouteGeometry(route, n_points, speeds)
    for trial in range(40):
        # GIVEN new routes for some rows, the geometry updated for those rows only
        new = _routes(m, w, degenerate=trial % 2 == 0)
        changed = np.flatnonzero(RNG.random(m) < 0.4)
        pos, segment, lead, zone = new[0], new[3], new[5], new[6]
        route[changed], n_points[changed], speeds[changed] = new[1][changed], new[2][changed], new[4][changed]
        geometry.update(changed, route, n_points, speeds)
        # THEN pursuing a subset of the rows, or all of them, is pure pursuit of those rows
        rows = np.flatnonzero(RNG.integers(0, 2, m)) if m > 1 else np.arange(1)
        ref = pure_pursuit_ref(pos[rows], route[rows], n_points[rows], segment[rows], speeds[rows], lead[rows],
                               zone[rows])
        got = pursue(pos[rows], segment[rows], lead[rows], np.maximum(zone[rows], 1e-9), geometry, rows)
        for g, want in zip(got, ref):
            assert_array_equal(g, want)
        got = pursue(pos, segment, lead, np.maximum(zone, 1e-9), geometry)
        for g, want in zip(got, pure_pursuit_ref(pos, route, n_points, segment, speeds, lead, zone)):
            assert_array_equal(g, want)


def test_geometry_of_no_route_is_empty():
    geometry = RouteGeometry(np.zeros((0, 2, 3)), np.zeros(0, np.intp), np.zeros((0, 2, 3)))
    assert all(a.size == 0 for a in pursue(np.zeros((0, 3)), np.zeros(0, np.intp), np.zeros(0), np.zeros(0), geometry))


def test_single_segment_route_at_its_start_on_its_end_and_of_zero_length_is_what_it_was():
    # GIVEN one-segment routes: a drone exactly at the start, one at the end, one on a zero-length route,
    # one level with the route, and a segment index above the last one
    route = np.array([[[0.0, 0.0, 10.0], [20.0, 0.0, 10.0]], [[0.0, 0.0, 10.0], [20.0, 0.0, 10.0]],
                      [[5.0, 5.0, 5.0], [5.0, 5.0, 5.0]], [[-0.0, 0.0, -0.0], [0.0, -3.0, 0.0]]])
    pos = np.array([[0.0, 0.0, 10.0], [20.0, 0.0, 10.0], [5.0, 5.0, 5.0], [-0.0, 0.0, -0.0]])
    speeds = np.ones_like(route)
    n_points, segment = np.full(4, 2), np.array([0, 3, 1, 0])
    lead, zone = np.array([3.0, 3.0, 0.0, 2.0]), np.array([5.0, 0.0, 5.0, 0.0])
    ref = pure_pursuit_ref(pos, route, n_points, segment, speeds, lead, zone)
    got = pursue(pos, segment, lead, np.maximum(zone, 1e-9), RouteGeometry(route, n_points, speeds))
    for g, want in zip(got, ref):
        assert_array_equal(g, want)
        assert_array_equal(np.signbit(g), np.signbit(want))


# -- the route-following system ------------------------------------------------------------------------------------
def _fleet(n: int) -> SimpleNamespace:
    quat = RNG.normal(size=(n, 4))
    return SimpleNamespace(
        route=np.full(n, None, dtype=object), route_stamp=np.zeros(n, np.int64), has_route=np.zeros(n, bool),
        flight_mode=np.full(n, MODE_AUTO, np.int64), pos_enu_m=RNG.uniform(-20.0, 20.0, (n, 3)),
        route_segment=np.zeros(n, np.int64), pos_sp_enu_m=np.zeros((n, 3)), dist_to_final_m=np.zeros(n),
        cross_track_m=np.zeros(n), arrived=np.zeros(n, bool), dist_to_go_m=np.zeros(n),
        speed_limit_m_s=np.zeros((n, 3)), vel_sp_enu_m_s=np.zeros((n, 3)), yaw_sp_rad=np.zeros(n),
        quat_enu_flu_xyzw=quat / np.linalg.norm(quat, axis=1, keepdims=True),
        vel_cmd_flu_m_s=RNG.normal(0.0, 3.0, (n, 3)))


def _give_route(f, row: int, points: int) -> None:
    pts = np.vstack([f.pos_enu_m[row], RNG.uniform(-30.0, 30.0, (points - 1, 3))])
    f.route[row] = Route(pts, RNG.uniform(1.0, 10.0, (points, 3)), float("nan"))
    f.has_route[row] = True
    f.route_stamp[row] += 1
    f.route_segment[row] = 0


def _system(cls, rows: np.ndarray, ctx):
    from unetyemu_ecs.fleet import row_selector
    system = cls()
    system.rows, system.sel = rows, row_selector(rows)
    limits = [GuidanceLimits(max_tilt_deg=30.0, lim_climb_m_s=3.0 + i % 3, lim_descent_m_s=2.0 + i % 2,
                             lim_yaw_rate_deg_s=90.0, lead_distance_m=2.0 + 0.5 * i, final_approach_m=4.0 + i % 4,
                             arrival_radius_m=0.3 + 0.1 * (i % 5), cruise_speed_m_s=5.0, climb_speed_m_s=2.0,
                             descent_speed_m_s=1.5, takeoff_altitude_m=2.0) for i in range(rows.size)]
    system.components = (limits,)
    system.gather(ctx)
    return system


@pytest.mark.parametrize("rows, max_points", [(np.arange(1), 2), (np.arange(6), 2), (np.arange(6), 5),
                                              (np.array([0, 2, 3, 7, 8, 11]), 2), (np.array([1, 4, 5, 9, 10]), 4)])
def test_route_following_system_writes_what_it_wrote_over_steps_of_changing_routes_and_modes(rows, max_points):
    # GIVEN the same fleet twice, one run by the system as it was and one by the system as it is
    n = 12
    f_ref, f_new = _fleet(n), None
    for row in rows.tolist():
        _give_route(f_ref, row, 2)
    f_new = SimpleNamespace(**{k: v.copy() for k, v in vars(f_ref).items()})
    ctx_ref, ctx_new = SimpleNamespace(fleet=f_ref), SimpleNamespace(fleet=f_new)
    ref, new = _system(RouteFollowingRef, rows, ctx_ref), _system(RouteFollowingSystem, rows, ctx_new)
    for step in range(60):
        # WHEN the drones move, and now and then a drone gets a new route, loses it or changes mode
        move = RNG.normal(0.0, 0.7, (n, 3))
        for f in (f_ref, f_new):
            f.pos_enu_m += move
        if step % 7 == 3:
            row = int(RNG.choice(rows))
            _give_route(f_ref, row, int(RNG.integers(2, max_points + 1)))
            for name in ("route", "has_route", "route_stamp", "route_segment"):
                getattr(f_new, name)[row] = getattr(f_ref, name)[row]
        if step % 11 == 5:
            modes = RNG.choice([MODE_AUTO, MODE_AUTO, MODE_VELOCITY, MODE_MANUAL, MODE_DISARMED], n)
            if step == 27:
                modes[:] = MODE_VELOCITY
            if step == 38:
                modes[:] = MODE_AUTO
            f_ref.flight_mode[:] = modes
            f_new.flight_mode[:] = modes
        if step == 49:
            row = int(rows[0])
            for f in (f_ref, f_new):
                f.route[row], f.has_route[row] = None, False
                f.route_stamp[row] += 1
        ref.update(ctx_ref)
        new.update(ctx_new)
        # THEN every array it writes is bit for bit the same
        for name, values in vars(f_ref).items():
            if name != "route":
                assert_array_equal(getattr(f_new, name), values, err_msg=f"{name} at step {step}")


# -- the position law --------------------------------------------------------------------------------------------------
def _gains(n: int, scalar: bool = False) -> GuidanceGains:
    if scalar:
        return GuidanceGains(gain_pos_p=1.3, gain_vel_p=2.2, gain_vel_i=0.4, lim_vel_int_m_s2=1.5, gain_yaw_p=1.7,
                             lim_decel_m_s2=2.5)
    return GuidanceGains(gain_pos_p=RNG.uniform(0.3, 2.0, n), gain_vel_p=RNG.uniform(0.5, 4.0, n),
                         gain_vel_i=np.where(RNG.random(n) < 0.2, 0.0, RNG.uniform(0.0, 1.0, n)),
                         lim_vel_int_m_s2=np.where(RNG.random(n) < 0.2, 0.0, RNG.uniform(0.0, 3.0, n)),
                         gain_yaw_p=RNG.uniform(0.5, 3.0, n), lim_decel_m_s2=RNG.uniform(0.5, 5.0, n))


def _lines_of_sight(n: int):
    """Targets (N, 3) around positions with the degenerate cases: at the position, straight up and down, level."""
    pos = RNG.uniform(-50.0, 50.0, (n, 3))
    delta = RNG.normal(0.0, 10.0, (n, 3)) * RNG.choice([1e-12, 1e-3, 1.0, 5.0], (n, 1))
    kind = RNG.integers(0, 5, n)
    delta[kind == 0] = 0.0                                # at the target
    delta[kind == 1, :2] = 0.0                            # straight up or down
    delta[kind == 2, 2] = 0.0                             # level
    return pos + delta, pos


@pytest.mark.parametrize("n", [1, 2, 9, 64])
def test_line_of_sight_velocity_is_what_it_was(n):
    for trial in range(40):
        target, pos = _lines_of_sight(n)
        gains = _gains(n, scalar=trial % 4 == 0)
        to_go = RNG.uniform(0.0, 40.0, n) * RNG.integers(0, 2, n)
        lim_h, climb, descent = RNG.uniform(0.0, 10.0, n), RNG.uniform(0.5, 4.0, n), RNG.uniform(0.5, 3.0, n)
        if trial % 5 == 1:
            target[:, 2] = pos[:, 2] + 1.0                # every row climbing
        if trial % 5 == 2:
            target[:, 2] = pos[:, 2] - 1.0                # every row descending
        if trial % 7 == 3:
            lim_h, climb, descent = 6.0, 3.0, 2.0         # scalar limits
        assert_same_to_rounding(position_to_velocity_sp(target, pos, to_go, lim_h, climb, descent, gains),
                           position_to_velocity_sp_ref(target, pos, to_go, lim_h, climb, descent, gains))


@pytest.mark.parametrize("n", [1, 3, 50])
def test_velocity_pi_and_its_limits_are_what_they_were(n):
    for trial in range(40):
        gains = _gains(n, scalar=trial % 4 == 0)
        scale = [0.01, 1.0, 30.0][trial % 3]            # nothing limited, some, all
        vel_sp, vel = RNG.normal(0.0, scale, (n, 3)), RNG.normal(0.0, scale, (n, 3))
        vel_int = RNG.normal(0.0, [0.0, 0.5, 50.0][trial % 3], (n, 2))
        tilt = RNG.uniform(0.1, 0.8, n)
        for vel_given in (vel, vel[:, :2].copy()):       # a horizontal-only measured velocity too
            acc, integral = velocity_to_accel_sp(vel_sp, vel_given, vel_int.copy(), 1.0 / 240.0, tilt, gains)
            acc_ref, integral_ref = velocity_to_accel_sp_ref(vel_sp, vel_given, vel_int.copy(), 1.0 / 240.0, tilt,
                                                             gains)
            assert_array_equal(acc, acc_ref)
            assert_array_equal(integral, integral_ref)


@pytest.mark.parametrize("n", [1, 4, 40])
def test_tilt_of_an_acceleration_is_what_it_was(n):
    for trial in range(40):
        acc = RNG.normal(0.0, [0.5, 5.0, 50.0][trial % 3], (n, 2))
        acc[0] = [0.0, -0.0]
        yaw = RNG.uniform(-4.0, 4.0, n)
        yaw[-1] = [0.0, -0.0, np.pi, -np.pi][trial % 4]
        tilt = RNG.uniform(0.1, 0.8, n)
        for y in (yaw, float(yaw[0])):
            roll, pitch = accel_to_tilt_sp(acc, y, tilt)
            roll_ref, pitch_ref = accel_to_tilt_sp_ref(acc, y, tilt)
            assert_same_to_rounding(roll, roll_ref)
            assert_same_to_rounding(pitch, pitch_ref)


@pytest.mark.parametrize("n", [1, 5, 60])
def test_yaw_rate_to_a_heading_is_what_it_was(n):
    for trial in range(40):
        yaw = RNG.uniform(-np.pi, np.pi, n)
        yaw_sp = yaw + RNG.choice([0.0, np.pi, -np.pi, 2 * np.pi, 1e-9], n) + RNG.normal(0.0, 2.0, n) * (trial % 2)
        if trial % 3 == 0:
            yaw_sp[::2] = [np.nan, np.inf, -np.inf][trial % 3]
        gains = _gains(n, scalar=trial % 4 == 0)
        lim = RNG.uniform(0.2, 3.0, n)
        assert_array_equal(heading_to_yaw_rate_sp(yaw_sp, yaw, lim, gains),
                           heading_to_yaw_rate_sp_ref(yaw_sp, yaw, lim, gains))
    gains = _gains(1, scalar=True)
    assert_array_equal(heading_to_yaw_rate_sp(0.5, -2.9, 1.0, gains), heading_to_yaw_rate_sp_ref(0.5, -2.9, 1.0, gains))


@pytest.mark.parametrize("n", [1, 3, 30])
def test_body_velocity_command_in_enu_is_what_it_was_with_signed_zeros_and_ties_at_the_limits(n):
    for trial in range(20):
        vel, yaw = RNG.normal(0.0, 3.0, (n, 3)), RNG.uniform(-4.0, 4.0, n)
        climb, descent = RNG.uniform(0.5, 4.0, n), RNG.uniform(0.5, 3.0, n)
        vel[0, 2] = [0.0, -0.0, climb[0], -descent[0], 50.0][trial % 5]
        if trial % 4 == 1:
            climb[:], descent[:] = 0.0, -0.0                 # zero limits: the clamp ties with signed zeros
            vel[:, 2] = RNG.choice([0.0, -0.0, 1.0, -1.0], n)
        for y in (yaw, float(yaw[0])):
            got = body_velocity_to_enu_sp(vel, y, climb, descent)
            want = body_velocity_to_enu_sp_ref(vel, y, climb, descent)
            assert_array_equal(got, want)
            assert_array_equal(np.signbit(got), np.signbit(want))
            assert got.dtype == want.dtype and got.shape == want.shape
    got = body_velocity_to_enu_sp(vel.astype(np.float32), yaw.astype(np.float32), 2.0, 1.0)
    want = body_velocity_to_enu_sp_ref(vel.astype(np.float32), yaw.astype(np.float32), 2.0, 1.0)
    assert_array_equal(got, want)
    assert got.dtype == want.dtype
    for fn in (body_velocity_to_enu_sp, body_velocity_to_enu_sp_ref):    # limits of another shape: refused alike
        with pytest.raises(ValueError):
            fn(vel, yaw, climb[None], descent[None])


def test_yaw_of_quaternions_from_one_product_is_the_written_out_formula():
    q = RNG.normal(size=(500, 4)) * RNG.choice([1e-3, 1.0, 1e3], (500, 1))
    q[0], q[1], q[2] = [0.0, 0.0, 0.0, 1.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 0.0]
    x, y, z, w = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    want = np.arctan2(2.0 * (x * y + w * z), x * x + y * y + z * z + w * w - 2.0 * (y * y + z * z))
    assert_same_to_rounding(yaw_rad_from_quat_xyzw(q), want)
    assert_same_to_rounding(yaw_rad_from_quat_xyzw(q[:1]), want[:1])
    assert_same_to_rounding(yaw_rad_from_quat_xyzw(q.reshape(2, 250, 4)), want.reshape(2, 250))


def _law_inputs(n: int, trial: int):
    target, pos = _lines_of_sight(n)
    kind = trial % 4                                      # all to a position, none, mixed, mixed with held headings
    flies = np.ones(n, bool) if kind == 0 else np.zeros(n, bool) if kind == 1 else RNG.random(n) < 0.5
    sp_pos = np.where(flies[:, None], target, np.nan)
    yaw_sp = RNG.uniform(-np.pi, np.pi, n)
    if kind >= 2 or trial % 5 == 0:
        yaw_sp[RNG.random(n) < 0.5] = np.nan
    scale = [0.05, 1.0, 20.0][trial % 3]
    sp = PositionSetpoint(sp_pos, RNG.normal(0.0, scale, (n, 3)),
                          np.column_stack([RNG.uniform(0.0, 10.0, n), RNG.uniform(0.5, 5.0, n),
                                           RNG.uniform(0.5, 5.0, n)]),
                          RNG.uniform(0.0, 40.0, n) * RNG.integers(0, 2, n), yaw_sp, RNG.normal(0.0, 1.0, n))
    quat = RNG.normal(size=(n, 4))
    state = DroneState(pos, RNG.normal(0.0, scale, (n, 3)), RNG.normal(size=(n, 3)),
                       quat / np.linalg.norm(quat, axis=1, keepdims=True), RNG.normal(size=(n, 3)))
    ones = np.ones(n)
    airframe = Airframe(mass_kg=ones, inertia_flu_kg_m2=np.ones((n, 3)), max_thrust_per_motor_n=ones,
                        arm_length_m=ones, yaw_moment_coeff_m=ones, motor_tau_s=ones,
                        torque_per_cmd_flu_n_m=np.ones((n, 3)), hover_thrust_frac=ones,
                        max_tilt_rad=RNG.uniform(0.1, 0.8, n), lim_climb_m_s=RNG.uniform(0.5, 4.0, n),
                        lim_descent_m_s=RNG.uniform(0.5, 3.0, n), lim_yaw_rate_rad_s=RNG.uniform(0.2, 3.0, n))
    memory = {"vel_int_m_s": RNG.normal(0.0, [0.0, 0.5, 50.0][trial % 3], (n, 2))}
    return sp, state, airframe, _gains(n), memory


@pytest.mark.parametrize("n", [1, 2, 7, 100])
def test_cascade_pid_law_is_what_it_was_for_every_mix_of_rows(n):
    for trial in range(48):
        sp, state, airframe, gains, memory = _law_inputs(n, trial)
        out, mem = cascade_pid_law(sp, state, airframe, gains, {"vel_int_m_s": memory["vel_int_m_s"].copy()}, 1 / 240)
        ref, mem_ref = cascade_pid_law_ref(sp, state, airframe, gains, {"vel_int_m_s": memory["vel_int_m_s"].copy()},
                                           1 / 240)
        for name in ("vz_m_s", "roll_rad", "pitch_rad", "yaw_rate_rad_s"):
            assert_same_to_rounding(getattr(out, name), getattr(ref, name), err_msg=f"{name}, trial {trial}")
        assert_same_to_rounding(mem["vel_int_m_s"], mem_ref["vel_int_m_s"])
