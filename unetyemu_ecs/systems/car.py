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
from ..control.car import CarGuidanceParams, ackermann_angles, drive_torque_n_m, pure_pursuit_steer, route_speed_sp
from ..control.pursuit import pure_pursuit
from ..frames import R_from_quat_xyzw
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


def _heading(quat_xyzw: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Forward unit vectors (N, 3) and yaw (N,) [rad] from ENU/FLU quaternions."""
    fwd = R_from_quat_xyzw(quat_xyzw)[:, :, 0]
    return fwd, np.arctan2(fwd[:, 1], fwd[:, 0])


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
            self._packed = _pack_paths([f.car_path[i] for i in r])
        paths, route, speeds, n_points, cum, cruise = self._packed
        pos = f.pos_enu_m[r].copy()
        pos[:, 2] = 0.0
        fwd, yaw = _heading(f.quat_enu_flu_xyzw[r])
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

        s_along = cum[np.arange(len(r)), res.segment] + _along(pos, route, res.segment)
        speed_sp = np.minimum(cruise, route_speed_sp(s_along, cum, speeds[:, :, 0], gains.max_decel_m_s2[sel] * 0.6))
        wheelbase = c.dyn.wheelbase_m[sel]
        rear_axle = pos - fwd * (wheelbase / 2.0)[:, None]
        steer = pure_pursuit_steer(res.target_enu_m, rear_axle, yaw, wheelbase)

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


def _pack_paths(paths: list[CarPath]) -> tuple:
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


def _along(pos: np.ndarray, route: np.ndarray, seg: np.ndarray) -> np.ndarray:
    """Distance (N,) [m] of each car's projection along its active segment."""
    m = np.arange(len(seg))
    a, b = route[m, seg], route[m, seg + 1]
    d = b - a
    length = np.linalg.norm(d, axis=1)
    t = np.clip(np.einsum("ni,ni->n", pos - a, d) / np.maximum(length, 1e-9) ** 2, 0.0, 1.0)
    return t * length


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
        cid = ctx.physics.id
        self._car_commanders = [self._commanders.get(b) or self._commanders.setdefault(b, CarCommander(cid, b, j))
                                 for b, j in zip(self.bodies, self.joints)]

    def update(self, ctx: StepContext) -> None:
        f, c = ctx.fleet, self
        r = c.rows
        dyn = c.dyn
        cid = ctx.physics.id
        commanders = self._car_commanders
        parked = f.drive_mode[r] == DRIVE_PARKED
        for i in np.flatnonzero(self._was_parked != parked):
            commanders[i].allow_sleep(bool(parked[i]))     # only a parked car may sleep
        self._was_parked = parked
        still = parked & (np.linalg.norm(f.vel_enu_m_s[r], axis=1) < STILL_M_S) & \
            (np.linalg.norm(f.rate_enu_rad_s[r], axis=1) < STILL_M_S)
        self._still_s = np.where(still, self._still_s + ctx.dt_s, 0.0)
        asleep = self._still_s > ASLEEP_AFTER_S            # Bullet does not integrate it: nothing to send
        drive = drive_torque_n_m(f.car_throttle[r], f.car_speed_m_s[r], dyn.max_drive_torque_n_m, dyn.top_speed_m_s)
        corner_weight_n = c.mass * GRAVITY_M_S2 / 4.0
        rolling = dyn.rolling_resistance_coeff * corner_weight_n * dyn.wheel_radius_m
        brake = f.car_brake[r] * dyn.max_brake_torque_n_m + rolling
        steer = ackermann_angles(f.car_steer_rad[r], dyn.wheelbase_m, dyn.track_m)
        k, damp = dyn.suspension_stiffness_n_m, dyn.suspension_damping_n_s_m
        for i, (body, joints) in enumerate(zip(c.bodies, c.joints)):
            if asleep[i]:
                continue
            x, xdot = read_suspension(cid, body, joints)
            spring = -k[i] * x - damp[i] * xdot - corner_weight_n[i]
            wheel_torque = np.array([0.0, 0.0, drive[i] / 2.0, drive[i] / 2.0])
            commanders[i].apply(spring, steer[i], wheel_torque, np.full(4, brake[i]))


def _carry_over(values: np.ndarray, old_index: np.ndarray, fill: object) -> np.ndarray:
    """``values`` re-indexed to new rows: ``values[old_index[k]]``, or ``fill`` where ``old_index[k]`` < 0."""
    out = np.full(old_index.shape, fill, dtype=values.dtype)
    known = old_index >= 0
    out[known] = values[old_index[known]]
    return out


__all__ = ["CarActuationSystem", "CarCommandSystem", "CarFleetSystem", "CarGuidanceSystem"]
