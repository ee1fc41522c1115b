"""Ground-vehicle systems: commands, route following, speed/course control and the wheeled body.

- :class:`CarCommandSystem` (COMMANDS): targets, routes, teleop, cmd_vel, arm/park; the world
  file's ``route`` at t = 0.
- :class:`CarGuidanceSystem` (GUIDANCE): pure pursuit on the route and its speed profile.
- the drive layer (STABILIZE) is in :mod:`.car_drive`: the car's chosen drive controller.
- :class:`CarActuationSystem` (ACTUATE): suspension forces, steering angles (Ackermann), rear-wheel
  drive torque and brakes applied to each car's PyBullet body.
"""

from __future__ import annotations


import esper
import numpy as np

from ..components.body import Identity, RigidBody
from ..components.car import CarBody, CarDynamics, CarRoute
from ..control.car import (CarGuidanceParams, ackermann_pair_rad, drive_torque_scalar_n_m, pursuit_steer_of,
                           route_speed_of)
from ..control.compiled import jit
from ..control.pursuit import RouteGeometry, project_on_segment, pursue_into
from ..phases import Phase
from ..physics.car_body import CarCommander, read_suspension
from ..transport.bus import Arm, CmdVel, Drive, DriveRoute, SetTarget
from ..units import GRAVITY_M_S2
from ..world import StepContext
from .car_state import DRIVE_PARKED, DRIVE_ROUTE, CarPath, DriveMode, set_path
from .commands import serve_commands, warn_if_obstructed
from .fleet_system import FleetSystem, stack_params

STOPPED_SPEED_M_S = 0.2        # a route is done when the car is this slow within the arrival radius
ASLEEP_AFTER_S = 3.0           # a parked car still for this long is asleep in Bullet (its 2 s deactivation time)
STILL_M_S = 0.005              # ... where "still" means base speed and turn rate below this [m/s, rad/s]
ROUTE_FOLLOWING_HZ = 60.0      # pure pursuit and the speed profile (the speed and steering loops run every step)
CAR_COMMANDS = (SetTarget, DriveRoute, Drive, CmdVel, Arm)   # what a car takes; others are "unsupported"


def _gains(ent: int) -> CarGuidanceParams:
    return esper.try_component(ent, CarGuidanceParams) or CarGuidanceParams()


class CarCommandSystem(esper.Processor):
    """Turn commands into drive modes, paths and setpoints. Phase: COMMANDS (order 20).

    Reads: the inbox (the CAR_COMMANDS for cars), CarRoute components (started at t = 0), cmd_hold_until_s.
    Writes: drive_mode, drive_cmd, cmd_vel, car_path, cmd_hold_until_s (a streamed teleop/cmd_vel
    that lapses brakes the car to a stop).
    """

    phase = Phase.COMMANDS
    order = 20

    def __init__(self) -> None:
        self._started: set[int] = set()

    def process(self, ctx: StepContext) -> None:
        f = ctx.fleet
        for ent, route in esper.get_component(CarRoute):
            if ent not in self._started:
                self._started.add(ent)
                row = f.row_of(ent)
                wp = np.array([[w.x, w.y] for w in route.waypoints])
                self._give_path(ctx, ent, row, wp, route.speed_m_s, route.loop, route.laps)
        serve_commands(ctx, CarDynamics, self._apply, self._brake_after_lapse, CAR_COMMANDS)

    def _brake_after_lapse(self, ctx: StepContext, ent: int, row: int) -> None:
        """No new teleop/cmd_vel within the command timeout: brake to a stop and hold there."""
        f = ctx.fleet
        f.cmd_hold_until_s[row] = np.inf
        if f.drive_mode[row] not in (DriveMode.MANUAL, DriveMode.VELOCITY):
            return
        was = "teleop" if f.drive_mode[row] == DriveMode.MANUAL else "cmd_vel"
        f.cmd_vel[row] = (0.0, 0.0)
        _enter_mode(ctx, ent, row, DriveMode.VELOCITY)
        name = esper.component_for_entity(ent, Identity).name
        ctx.services.note(ctx.sim_time_s, name, f"{was} timed out (no new command within the command timeout): "
                                                "braking to a stop")

    def _give_path(self, ctx: StepContext, ent: int, row: int, waypoints_xy: np.ndarray, speed: float | None,
                   loop: bool, laps: int) -> None:
        f = ctx.fleet
        gains = _gains(ent)
        cruise = speed if speed is not None else gains.cruise_speed_m_s
        top = esper.component_for_entity(ent, CarDynamics).top_speed_m_s
        path = CarPath.build(f.pos_enu_m[row], waypoints_xy, min(cruise, top), gains.max_lat_accel_m_s2, loop, laps)
        _enter_mode(ctx, ent, row, DriveMode.ROUTE)
        set_path(f, row, path)

    def _apply(self, ctx: StepContext, ent: int, msg: object) -> str:
        f = ctx.fleet
        row = f.row_of(ent)
        name = msg.vehicle
        # values were range-checked once (command_checks) before they were queued; here only what
        # depends on this car (its top speed) is checked
        if isinstance(msg, SetTarget):
            self._give_path(ctx, ent, row, np.array([msg.pos_enu_m[:2]]), msg.speed_m_s, False, 0)
            ctx.services.note(ctx.sim_time_s, name, f"target set to {tuple(round(v, 2) for v in msg.pos_enu_m[:2])}")
            pos = f.pos_enu_m[row].copy()
            warn_if_obstructed(ctx, ent, name, pos, np.array([*msg.pos_enu_m[:2], pos[2]]))
            return ""
        if isinstance(msg, DriveRoute):
            wp = np.asarray(msg.waypoints, dtype=float)
            self._give_path(ctx, ent, row, wp, msg.speed_m_s, msg.loop, msg.laps)
            ctx.services.note(ctx.sim_time_s, name, f"route of {len(wp)} waypoints" + (" (loop)" if msg.loop else ""))
            return ""
        if isinstance(msg, Drive):
            f.drive_cmd[row] = (msg.throttle, msg.brake, msg.steering)
            _enter_mode(ctx, ent, row, DriveMode.MANUAL)
            return ""
        if isinstance(msg, CmdVel):
            top = esper.component_for_entity(ent, CarDynamics).top_speed_m_s
            if abs(msg.forward_m_s) > top:
                return f"forward speed {msg.forward_m_s} m/s is beyond the top speed {top} m/s"
            f.cmd_vel[row] = (msg.forward_m_s, msg.yaw_rate_rad_s)
            _enter_mode(ctx, ent, row, DriveMode.VELOCITY)
            return ""
        if isinstance(msg, Arm):
            if msg.armed:
                # released: hold where it is under speed control
                f.cmd_vel[row] = (0.0, 0.0)
                _enter_mode(ctx, ent, row, DriveMode.VELOCITY)
            else:
                _enter_mode(ctx, ent, row, DriveMode.PARKED)
            return ""
        raise TypeError(f"CarCommandSystem: {type(msg).__name__} is not in CAR_COMMANDS")


def _enter_mode(ctx: StepContext, ent: int, row: int, mode: DriveMode) -> None:
    """Switch drive mode (the drive controller restarts bumplessly: systems/car_drive.py)."""
    f = ctx.fleet
    if f.drive_mode[row] == mode:
        return
    if mode != DriveMode.ROUTE:
        set_path(f, row, None)
    f.drive_mode[row] = mode
    name = esper.component_for_entity(ent, Identity).name
    ctx.services.note(ctx.sim_time_s, name, f"drive mode {mode.name.lower()}")


class CarFleetSystem(FleetSystem):
    """A system over every car: its rows and stacked parameters, gathered again when the ECS changes.

    After a gather: ``dyn`` (:class:`CarDynamics`, (M,) fields), ``gains``
    (:class:`CarGuidanceParams`, (M,) fields; the defaults where a car has none), ``mass`` (M,) [kg],
    ``bodies`` and ``joints`` (PyBullet body ids and wheel joints, per car).
    """

    requires = (CarDynamics,)

    def gather(self, ctx: StepContext) -> None:
        ents = self.entities.tolist()
        self.dyn = stack_params(self.components[0], CarDynamics)
        self.gains = stack_params([_gains(e) for e in ents], CarGuidanceParams)
        self.mass = np.array([esper.component_for_entity(e, RigidBody).mass_kg for e in ents])
        self.bodies = [int(b) for b in ctx.fleet.body_id[self.rows]]
        self.joints = [esper.component_for_entity(e, CarBody).joints for e in ents]


class CarGuidanceSystem(CarFleetSystem):
    """Pure pursuit along each ROUTE-mode car's path and its speed profile. Phase: GUIDANCE (order 20).

    Look-ahead ``max(lead_min, lead_time * speed)``; speed setpoint: the route speed, limited so the
    car can brake to each corner's ``sqrt(a_lat R)`` and to 0 at the end. A never-ending loop steps
    back one lap when it enters its last; an open route ends (PARKED) once the car stops within the
    arrival radius of its last point. Runs at :data:`ROUTE_FOLLOWING_HZ` (and at once when a route
    changes). Writes: car_speed_sp_m_s, car_steer_sp_rad, path_segment.
    """

    phase = Phase.GUIDANCE
    order = 20

    def __init__(self) -> None:
        super().__init__()
        self._key: tuple = ()
        self._packed: tuple = ()

    def update(self, ctx: StepContext) -> None:
        f, c = ctx.fleet, self
        sel = (f.drive_mode[c.sel] == DRIVE_ROUTE).nonzero()[0]
        if sel.size == 0:
            return
        r = c.rows[sel]
        key = r.tobytes() + f.path_stamp[r].tobytes()
        decimation = max(1, round(1.0 / (ROUTE_FOLLOWING_HZ * ctx.dt_s)))
        if key == self._key and ctx.step % decimation:
            return
        if key != self._key:                       # routes changed: their geometry, once
            self._key = key
            self._packed = _pack_paths([f.car_path[i] for i in r])
        paths, geo, point_speeds, cruise, open_route = self._packed
        gains, n = c.gains, r.size
        seg, done = np.empty(n, dtype=np.intp), np.zeros(n, dtype=bool)
        n_done = _follow_car_routes(
            r, sel, f.pos_enu_m, f.R_enu_flu, f.car_speed_m_s, f.path_segment, f.car_steer_rad, gains.lead_min_m,
            gains.lead_time_s, gains.max_decel_m_s2, gains.arrival_radius_m, c.dyn.wheelbase_m, cruise, open_route,
            geo.width, geo.last_seg, geo.vec, geo.length2, geo.ok_t, geo.seg_len, geo.cum_start, geo.len_u, geo.ok_u,
            geo.cum, geo.total, geo.last, point_speeds, f.car_speed_sp_m_s, f.car_steer_sp_rad, seg, done)
        for k, p in enumerate(paths):              # loops: step back a lap, count laps
            if not (p.period or p.lap_ends):
                continue
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
        if n_done == 0:
            return
        for k in done.nonzero()[0].tolist():
            ent = int(c.entities[sel[k]])
            name = esper.component_for_entity(ent, Identity).name
            laps = len(paths[k].lap_ends)
            if laps:
                ctx.services.note(ctx.sim_time_s, name, f"route lap {laps} done")
            ctx.services.note(ctx.sim_time_s, name, "route done")
            _enter_mode(ctx, ent, int(r[k]), DriveMode.PARKED)
            f.path_done[r[k]] = True                   # after parking (which clears the path)
            f.path_laps[r[k]] = laps


@jit
def _follow_car_routes(rows, sel, pos_enu_m, R_enu_flu, car_speed_m_s, path_segment, car_steer_rad, lead_min_m,
                       lead_time_s, max_decel_m_s2, arrival_radius_m, wheelbase_m, cruise_m_s, open_route, width,
                       last_seg, vec, length2, ok_t, seg_len, cum_start, len_u, ok_u, cum, total, last, point_speeds,
                       car_speed_sp_m_s, car_steer_sp_rad, segment, done):
    """Pure pursuit and the speed profile of the ROUTE cars at fleet ``rows`` (``sel``: their indices among the
    system's cars, for the per-car parameters; geometry row k is car k's route, on the ground: z = 0). Writes their
    speed and steering setpoints, their new ``segment`` and ``done`` (stopped at the end of an open route);
    returns how many are done."""
    pos, target, speeds = np.zeros(3), np.empty(3), np.empty(3)
    n_done = 0
    for k in range(rows.shape[0]):
        r, i = rows[k], sel[k]
        pos[0], pos[1] = pos_enu_m[r, 0], pos_enu_m[r, 1]
        v = car_speed_m_s[r]
        lead = max(lead_min_m[i], lead_time_s[i] * abs(v))
        seg, to_go, cross, to_final = pursue_into(pos, path_segment[r], lead, 1e-9, k, width, last_seg, vec, length2,
                                                  ok_t, seg_len, cum_start, len_u, ok_u, cum, total, last, target,
                                                  speeds)
        segment[k] = seg
        flat = k * (width - 1) + seg
        t, _ = project_on_segment(pos, vec[flat], length2[flat], ok_t[flat])
        s_along = cum_start[flat] + t * seg_len[flat]
        speed_sp = min(cruise_m_s[k], route_speed_of(s_along, cum[k], point_speeds[k], max_decel_m_s2[i] * 0.6))
        fwd_x, fwd_y = R_enu_flu[r, 0, 0], R_enu_flu[r, 1, 0]
        half = wheelbase_m[i] / 2.0
        steer = pursuit_steer_of(target[0], target[1], pos[0] - fwd_x * half, pos[1] - fwd_y * half,
                                 np.arctan2(fwd_y, fwd_x), wheelbase_m[i])
        # the end of the route: on the last segment, within the arrival radius along the route
        # (a car that rolled a little past the end counts), and stopped
        at_end = open_route[k] and seg == last_seg[k] and to_go - cross < arrival_radius_m[i] and \
            to_final < 3.0 * arrival_radius_m[i]
        done[k] = at_end and abs(v) < STOPPED_SPEED_M_S
        n_done += done[k]
        car_speed_sp_m_s[r] = 0.0 if at_end else speed_sp
        car_steer_sp_rad[r] = car_steer_rad[r] if at_end else steer
    return n_done


def _pack_paths(paths: list[CarPath]) -> tuple:
    """The paths, their :class:`RouteGeometry` (padded to the longest), the speed limits at their points (N, W),
    their cruise speeds (N,) and which are open routes (N,) bool (not never-ending loops)."""
    width = max(len(p.points_enu_m) for p in paths)
    route = np.empty((len(paths), width, 3))
    speeds = np.zeros((len(paths), width))
    n_points = np.array([len(p.points_enu_m) for p in paths])
    for k, p in enumerate(paths):
        n = len(p.points_enu_m)
        route[k, :n], route[k, n:] = p.points_enu_m, p.points_enu_m[-1]
        speeds[k, :n], speeds[k, n:] = p.speeds_m_s, p.speeds_m_s[-1]
    route[:, :, 2] = 0.0                           # followed on the ground
    geometry = RouteGeometry(route, n_points, np.repeat(speeds[:, :, None], 3, axis=2))
    return (paths, geometry, speeds, np.array([p.cruise_m_s for p in paths], dtype=float),
            np.array([p.period == 0 for p in paths]))


class CarActuationSystem(CarFleetSystem):
    """Apply suspension, steering, drive and brakes to every car body. Phase: ACTUATE (order 30).

    Suspension per wheel: ``-k x - c x' - m g / 4`` along the chassis z axis (static rest at x = 0).
    Drive: the torque of :func:`~unetyemu_ecs.control.car.drive_torque_n_m`, split over the rear
    wheels. Brakes: ``brake * max_brake_torque`` plus rolling resistance ``C_rr m g r / 4`` on
    every wheel. Steering: Ackermann angles of the applied bicycle angle. A parked car that has been
    still for :data:`ASLEEP_AFTER_S` sleeps in Bullet and is skipped until it moves again.
    """

    phase = Phase.ACTUATE
    order = 30

    def __init__(self) -> None:
        super().__init__()
        self._commanders: dict[int, CarCommander] = {}      # body id -> commander
        self._was_parked = np.zeros(0, dtype=bool)          # per row of ``rows``: parked last step
        self._still_s = np.zeros(0)                        # how long each car has been parked and still [s]
        self._gathered = np.empty(0, dtype=np.int64)       # the entities those two arrays belong to

    def gather(self, ctx: StepContext) -> None:
        super().gather(ctx)
        # carry each car's sleep state over by entity; a new car starts as "was parked, not still"
        before = {int(e): k for k, e in enumerate(self._gathered)}
        old = np.array([before.get(int(e), -1) for e in self.entities], dtype=np.intp)
        self._was_parked = _carry_over(self._was_parked, old, True)
        self._still_s = _carry_over(self._still_s, old, 0.0)
        self._gathered = self.entities.copy()
        self._changed = np.zeros(self.rows.size, dtype=bool)
        self._wheels = np.empty((self.rows.size, 5))
        corner_weight_n = self.mass * GRAVITY_M_S2 / 4.0
        self._rolling_n_m = self.dyn.rolling_resistance_coeff * corner_weight_n * self.dyn.wheel_radius_m
        self._corner_weight_n = corner_weight_n.tolist()
        self._stiffness = self.dyn.suspension_stiffness_n_m.tolist()
        self._damping = self.dyn.suspension_damping_n_s_m.tolist()
        cid = ctx.physics.id
        self._car_commanders = [self._commanders.get(b) or self._commanders.setdefault(b, CarCommander(cid, b, j))
                                 for b, j in zip(self.bodies, self.joints)]

    def update(self, ctx: StepContext) -> None:
        f, c = ctx.fleet, self
        dyn = c.dyn
        wheels = self._wheels
        changed = _wheel_commands(c.rows, f.drive_mode, f.vel_enu_m_s, f.rate_enu_rad_s, f.car_throttle,
                                  f.car_speed_m_s, f.car_brake, f.car_steer_rad, ctx.dt_s, dyn.max_drive_torque_n_m,
                                  dyn.top_speed_m_s, dyn.max_brake_torque_n_m, self._rolling_n_m, dyn.wheelbase_m,
                                  dyn.track_m, self._was_parked, self._still_s, self._changed, wheels)
        commanders = self._car_commanders
        if changed:
            for i in self._changed.nonzero()[0].tolist():
                commanders[i].allow_sleep(bool(self._was_parked[i]))     # only a parked car may sleep
        cid = ctx.physics.id
        for commander, body, joints, k, damp, weight, (awake, drive, brake, left, right) in zip(
                commanders, c.bodies, c.joints, self._stiffness, self._damping, self._corner_weight_n,
                wheels.tolist()):
            if awake:                                   # an asleep car: Bullet does not integrate it, nothing to send
                spring = [-k * x - damp * xdot - weight for x, xdot in read_suspension(cid, body, joints)]
                commander.apply(spring, left, right, drive / 2.0, brake)


@jit
def _wheel_commands(rows, drive_mode, vel_enu_m_s, rate_enu_rad_s, car_throttle, car_speed_m_s, car_brake,
                    car_steer_rad, dt_s, max_drive_torque_n_m, top_speed_m_s, max_brake_torque_n_m, rolling_n_m,
                    wheelbase_m, track_m, was_parked, still_s, changed, out):
    """What each car's wheels get this step, ``out`` (M, 5): awake (1: commands are sent, 0: asleep), the drive
    torque at the rear axle [N m], each wheel's brake torque [N m] (brakes plus rolling resistance), the left and
    right front-wheel angles [rad]. Keeps, per row, whether the car was parked (``changed``: it parked or left
    PARKED this step; returns how many did) and how long it has been parked and still (``still_s`` [s])."""
    n_changed = 0
    for k in range(rows.shape[0]):
        r = rows[k]
        parked = drive_mode[r] == DRIVE_PARKED
        changed[k] = parked != was_parked[k]
        n_changed += changed[k]
        was_parked[k] = parked
        v, w = vel_enu_m_s[r], rate_enu_rad_s[r]
        still = parked and np.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]) < STILL_M_S and \
            np.sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2]) < STILL_M_S
        still_s[k] = still_s[k] + dt_s if still else 0.0
        out[k, 0] = 0.0 if still_s[k] > ASLEEP_AFTER_S else 1.0
        out[k, 1] = drive_torque_scalar_n_m(car_throttle[r], car_speed_m_s[r], max_drive_torque_n_m[k],
                                            top_speed_m_s[k])
        out[k, 2] = car_brake[r] * max_brake_torque_n_m[k] + rolling_n_m[k]
        out[k, 3], out[k, 4] = ackermann_pair_rad(car_steer_rad[r], wheelbase_m[k], track_m[k])
    return n_changed


def _carry_over(values: np.ndarray, old_index: np.ndarray, fill: object) -> np.ndarray:
    """``values`` re-indexed to new rows: ``values[old_index[k]]``, or ``fill`` where ``old_index[k]`` < 0."""
    out = np.full(old_index.shape, fill, dtype=values.dtype)
    known = old_index >= 0
    out[known] = values[old_index[known]]
    return out


__all__ = ["CarActuationSystem", "CarCommandSystem", "CarFleetSystem", "CarGuidanceSystem"]
