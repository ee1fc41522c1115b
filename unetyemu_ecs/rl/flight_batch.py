"""N drones in one simulation, flown by an agent at one action level: the engine of every environment.

The batch is a :class:`~unetyemu_ecs.app.Simulation` built from a world file like any other, with the
same systems for everything physical: per-motor thrust with its lag, the rigid-body physics, air
drag, the actuator-disk energy and battery, the payload bay's constraints, impacts and the sensors.
The agent takes the place of what would fly the drones otherwise: the navigator, missions, route
following and command handling are taken out, and so are the controller layers above the chosen
action level (see :mod:`.actions`); the layers below it run at the physics rate as they always do.

Resetting never rebuilds the world: the state after construction (PyBullet's, every fleet array, the
sensor schedules) is kept in memory and put back, the whole of it for the whole batch or row by row
for the copies whose episode ended (a vector environment's autoreset), before each copy is placed
at its new start.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import esper
import numpy as np

from ..app import Simulation
from ..components.body import RigidBody
from ..components.flight import GuidanceLimits, QuadrotorMotors
from ..config.world_file import load_world_text
from ..control.attitude import StabilizerGains
from ..control.body_rate import body_rates_to_torque_cmd
from ..frames import quat_xyzw_from_euler_rpy
from ..phases import Phase
from ..sensors.base import SensorSystemBase
from ..sensors.tf import TransformSystem
from ..systems.commands import InboxSystem, UnclaimedCommandSystem
from ..systems.controllers import AttitudeControllerSystem, MixerSystem, PositionControllerSystem
from ..systems.flight_commands import FlightCommandSystem
from ..systems.fleet_system import stack_params
from ..systems.flight_state import MODE_ATTITUDE, MODE_VELOCITY
from ..systems.guidance import RouteFollowingSystem
from ..systems.impacts import ImpactMonitorSystem
from ..systems.mission import EmergencyLandingSystem, MissionSystem
from ..systems.navigator import LandDetectorSystem, NavigatorSystem
from ..systems.payload import PayloadSystem
from ..units import GRAVITY_M_S2
from ..world import StepContext
from .actions import (ACTION_LEVELS, ActionScale, attitude_sp, body_rate_sp, clean_action, collective_frac,
                      motor_fracs, velocity_sp)

# what flies the drones when no agent does: out of an agent's batch
_FLYING_SYSTEMS = (FlightCommandSystem, MissionSystem, EmergencyLandingSystem, RouteFollowingSystem, NavigatorSystem,
                   LandDetectorSystem, TransformSystem)
_COMMAND_SYSTEMS = (InboxSystem, UnclaimedCommandSystem)
# controller layers above each action level (taken out: the agent's command replaces their output)
_LAYERS_ABOVE = {"motors": (PositionControllerSystem, AttitudeControllerSystem, MixerSystem),
                 "rates": (PositionControllerSystem, AttitudeControllerSystem),
                 "attitude": (PositionControllerSystem,),
                 "velocity": ()}
THRUST_SPAN = 0.5               # a full collective or motor action: hover thrust +/- 50 %
DEFAULT_MAX_RATE_RAD_S = math.pi   # a full rates action: 180 deg/s


class BodyRateSystem:
    """STABILIZE phase, for a batch flown at the ``rates`` level: collective thrust and body-rate
    setpoints (fleet arrays ``thrust_cmd_frac`` and ``rate_sp_flu_rad_s``) -> the mixer's input
    (``thrust_frac_sp``, ``torque_cmd``), by :func:`~..control.body_rate.body_rates_to_torque_cmd`
    with each drone's attitude gains, every physics step."""

    phase = Phase.STABILIZE
    order = 0

    def __init__(self, rows: np.ndarray, gains: StabilizerGains) -> None:
        self.rows = rows
        self.gains = gains

    def process(self, ctx: StepContext) -> None:
        f, r = ctx.fleet, self.rows
        f.thrust_frac_sp[r] = f.thrust_cmd_frac[r]
        f.torque_cmd[r] = body_rates_to_torque_cmd(f.rate_sp_flu_rad_s[r], f.rate_flu_rad_s[r], self.gains)


@dataclass
class SavedState:
    """A batch's state kept in memory: PyBullet's, every fleet array, the clock and the sensor schedules."""

    physics_state: int
    arrays: dict[str, np.ndarray]
    step_count: int
    sensor_due_s: list[list[float]]


def _fleet_array_names(fleet: Any) -> list[str]:
    return [*fleet._declared, "quat_enu_flu_xyzw", "R_enu_flu", "odometer_m"]


class FlightBatch:
    """Drones ``drones`` of the world in ``world_text`` (YAML), flown at ``level`` (see :mod:`.actions`),
    one action every ``1 / control_hz`` seconds of sim time.

    Parameters
    ----------
    world_text : a world file's text; its drones start where it puts them (their pose then is the
        state a reset restores before a copy is placed)
    drones : the names of the drones the agent flies, in the order of the action's rows
    level : ``motors``, ``rates``, ``attitude`` or ``velocity``
    control_hz : actions per simulated second; the world's ``physics_hz`` must be a whole multiple
    max_speed_m_s : horizontal speed of a full velocity action (None: each drone's cruise speed)
    max_rate_rad_s : body rate of a full rates action
    """

    def __init__(self, world_text: str, drones: list[str], level: str, control_hz: float, *,
                 max_speed_m_s: float | None = None,
                 max_rate_rad_s: float = DEFAULT_MAX_RATE_RAD_S, file: str = "<environment>") -> None:
        if level not in ACTION_LEVELS:
            raise ValueError(f"action level must be one of {', '.join(ACTION_LEVELS)}, got {level!r}")
        self.level = level
        self.sim = Simulation(load_world_text(world_text, file=file))
        try:
            self._build(drones, control_hz, max_speed_m_s, max_rate_rad_s)
        except BaseException:
            self.sim.close()
            raise

    def _build(self, drones: list[str], control_hz: float, max_speed_m_s: float | None, max_rate_rad_s: float) -> None:
        sim = self.sim
        physics_hz = 1.0 / sim.dt_s
        if not (math.isfinite(control_hz) and 0 < control_hz <= physics_hz):
            raise ValueError(f"control_hz must be in (0, {physics_hz:g}] Hz (the physics rate), got {control_hz!r}")
        substeps = physics_hz / control_hz
        if abs(substeps - round(substeps)) > 1e-9:
            raise ValueError(f"control_hz {control_hz:g} Hz must divide the physics rate {physics_hz:g} Hz")
        self.substeps = int(round(substeps))
        self.control_dt_s = self.substeps * sim.dt_s
        self.names = list(drones)
        self.rows = np.array([sim.row(n) for n in drones], dtype=np.intp)
        self.bodies = [sim.component(n, RigidBody).body_id for n in drones]
        removed = _FLYING_SYSTEMS + _COMMAND_SYSTEMS + _LAYERS_ABOVE[self.level]
        for system in list(sim.ecs.systems):
            if isinstance(system, removed):
                sim.ecs.remove_system(type(system))
        motors = [sim.component(n, QuadrotorMotors) for n in drones]
        limits = [sim.component(n, GuidanceLimits) for n in drones]
        mass = np.array([sim.component(n, RigidBody).mass_kg for n in drones])
        f_max = np.array([m.max_thrust_per_motor_n for m in motors])
        self.hover_thrust_n = mass * GRAVITY_M_S2 / 4.0
        cruise = np.array([lim.cruise_speed_m_s for lim in limits])
        self.scale = ActionScale(
            hover_frac=self.hover_thrust_n / f_max, thrust_span=THRUST_SPAN,
            max_rate_rad_s=np.full(len(drones), float(max_rate_rad_s)),
            max_tilt_rad=np.deg2rad([lim.max_tilt_deg for lim in limits]),
            lim_yaw_rate_rad_s=np.deg2rad([lim.lim_yaw_rate_deg_s for lim in limits]),
            max_speed_m_s=cruise if max_speed_m_s is None else np.full(len(drones), float(max_speed_m_s)),
            lim_climb_m_s=np.array([lim.lim_climb_m_s for lim in limits]),
            lim_descent_m_s=np.array([lim.lim_descent_m_s for lim in limits]))
        f = sim.fleet
        f.declare("rate_sp_flu_rad_s", (3,), np.float64, 0.0)
        if self.level == "rates":
            with sim.ecs.active():
                gains = [esper.try_component(sim.entity(n), StabilizerGains) or StabilizerGains() for n in drones]
            sim.ecs.add_system(BodyRateSystem(self.rows, stack_params(gains, StabilizerGains)))
        self._payload = next((s for s in sim.ecs.systems if isinstance(s, PayloadSystem)), None)
        self._impacts = next((s for s in sim.ecs.systems if isinstance(s, ImpactMonitorSystem)), None)
        self._sensors = [s for s in sim.ecs.systems if isinstance(s, SensorSystemBase)]
        # the state a reset restores: armed, every motor at hover thrust, setpoints at rest
        r = self.rows
        f.flight_mode[r] = MODE_VELOCITY if self.level == "velocity" else MODE_ATTITUDE
        f.motor_thrust_n[r] = self.hover_thrust_n[:, None]
        f.motor_frac_cmd[r] = self.scale.hover_frac[:, None]
        f.thrust_cmd_frac[r] = self.scale.hover_frac
        f.pos_sp_enu_m[r] = np.nan
        f.vel_sp_enu_m_s[r] = 0.0
        f.yaw_sp_rad[r] = np.nan
        f.speed_limit_m_s[r] = np.stack([self.scale.max_speed_m_s, self.scale.lim_climb_m_s,
                                         self.scale.lim_descent_m_s], axis=1)
        with sim.ecs.active():                        # every system gathers its rows (and declares its arrays)
            for system in sim.ecs.systems:
                if hasattr(system, "refresh"):
                    system.refresh(sim._context())
        self._saved = self._save()
        self.last_action = np.zeros((len(drones), 4))

    # -- state -------------------------------------------------------------------------------------
    def _save(self) -> SavedState:
        sim = self.sim
        f = sim.fleet
        return SavedState(sim.physics.save_state(), {name: getattr(f, name).copy() for name in _fleet_array_names(f)},
                          sim.step_count, [[m.next_due_s for m in s.sensors] for s in self._sensors])

    def restore(self, seed: int | None = None) -> None:
        """The whole batch back to the saved state: physics, fleet arrays, sim clock, sensor schedules and
        noise streams (reseeded from ``seed`` when given), payloads released, newest sensor samples and
        the event notices of the episodes before gone."""
        sim, saved = self.sim, self._saved
        self._release(np.arange(len(self.names)))
        f = sim.fleet
        sim.physics.drop_contacts(f.body_id[f.rows])     # then every body back where it was saved
        sim.physics.restore_state(saved.physics_state)
        for name, values in saved.arrays.items():
            getattr(f, name)[...] = values
        sim.step_count = saved.step_count
        if seed is not None:
            sim.rng = np.random.default_rng(seed)
        for system, due in zip(self._sensors, saved.sensor_due_s):
            for mounted, due_s in zip(system.sensors, due):
                mounted.next_due_s = due_s
            system._rng.clear()                     # noise streams start again from the (new) seed
        sim.services.sensors.latest.clear()
        sim.services.events.clear()                 # a notice per pickup or impact: bounded over a long training
        if self._impacts is not None:
            self._impacts._last_touch_s.clear()
            self._impacts.forget_motion(f)
        self.last_action[:] = 0.0

    def _release(self, k: np.ndarray) -> None:
        if self._payload is None:
            return
        with self.sim.ecs.active():
            ctx = self.sim._context()
            for i in np.asarray(k).tolist():
                if self.sim.fleet.payload_entity[self.rows[i]] >= 0:
                    self._payload.release(ctx, int(self.rows[i]))

    def place(self, k: np.ndarray, pos_enu_m: np.ndarray, yaw_rad: np.ndarray,
              vel_enu_m_s: np.ndarray | None = None) -> None:
        """Start drones ``k`` (indices into :attr:`names`) again: what they carry released, their fleet rows
        back to the saved state, then at ``pos_enu_m`` (K, 3) [m] facing ``yaw_rad`` (K,)
        [rad, ENU] with velocity ``vel_enu_m_s`` (K, 3) [m/s] (default at rest), hovering."""
        k = np.asarray(k, dtype=np.intp).reshape(-1)
        pos = np.asarray(pos_enu_m, dtype=float).reshape(-1, 3)
        yaw = np.asarray(yaw_rad, dtype=float).reshape(-1)
        vel = np.zeros_like(pos) if vel_enu_m_s is None else np.asarray(vel_enu_m_s, dtype=float).reshape(-1, 3)
        self._release(k)
        f = self.sim.fleet
        rows = self.rows[k]
        for name, values in self._saved.arrays.items():
            getattr(f, name)[rows] = values[rows]
        for i, row_k in enumerate(k.tolist()):
            quat = quat_xyzw_from_euler_rpy(0.0, 0.0, float(yaw[i]))
            self.sim.physics.reset_body(self.bodies[row_k], pos[i], quat, vel[i])
        self.last_action[k] = 0.0
        self.refresh_state(rows)

    def place_bodies(self, names: list[str], pos_enu_m: Any, yaw_rad: Any = 0.0) -> None:
        """Put bodies ``names`` (packages, other vehicles) at ``pos_enu_m`` (K, 3) [m] facing ``yaw_rad``
        (K,) or one for all [rad], at rest."""
        pos = np.asarray(pos_enu_m, dtype=float).reshape(-1, 3)
        yaw = np.broadcast_to(np.asarray(yaw_rad, dtype=float), (len(names),))
        for name, p_i, yaw_i in zip(names, pos, yaw.tolist()):
            body = self.sim.component(name, RigidBody).body_id
            self.sim.physics.reset_body(body, p_i, quat_xyzw_from_euler_rpy(0.0, 0.0, yaw_i))
        self.refresh_state(np.array([self.sim.row(name) for name in names], dtype=np.intp))

    def refresh_state(self, rows: np.ndarray) -> None:
        """Read the physics into the fleet arrays again after bodies were moved; ``rows`` start with zero
        acceleration, the other rows keep theirs."""
        sim = self.sim
        f = sim.fleet
        keep = f.acc_enu_m_s2.copy()
        with sim.ecs.active():
            sim._state.prime(sim._context())
        keep[rows] = 0.0
        f.acc_enu_m_s2[...] = keep
        if self._impacts is not None:
            self._impacts.forget_motion(f)

    def measure_sensors(self) -> None:
        """Take every sensor's measurement now (after a reset, so the first observation has them)."""
        sim = self.sim
        with sim.ecs.active():
            ctx = sim._context()
            for system in self._sensors:
                if system.sensors:
                    system.measure(ctx, list(system.sensors), sim.sim_time_s)

    # -- stepping ----------------------------------------------------------------------------------
    def act(self, action: np.ndarray, k: np.ndarray | None = None) -> None:
        """Command drones ``k`` (all by default) with ``action`` ((K, 4) in [-1, 1], see :mod:`.actions`)."""
        idx = np.arange(len(self.names)) if k is None else np.asarray(k, dtype=np.intp).reshape(-1)
        a = clean_action(action, idx.size)
        self.last_action[idx] = a
        scale = self.scale if k is None else _take(self.scale, idx)
        f, r = self.sim.fleet, self.rows[idx]
        if self.level == "motors":
            f.motor_frac_cmd[r] = motor_fracs(a, scale)
        elif self.level == "rates":
            f.thrust_cmd_frac[r] = collective_frac(a, scale)
            f.rate_sp_flu_rad_s[r] = body_rate_sp(a, scale)
        elif self.level == "attitude":
            f.thrust_cmd_frac[r] = collective_frac(a, scale)
            f.roll_sp_rad[r], f.pitch_sp_rad[r], f.yaw_rate_sp_rad_s[r] = attitude_sp(a, scale)
        else:
            f.vel_sp_enu_m_s[r], f.yaw_rate_cmd_rad_s[r] = velocity_sp(a, scale)

    def advance(self) -> None:
        """One control period: :attr:`substeps` physics steps through every remaining system."""
        self.sim.step(self.substeps)

    def impacts(self) -> np.ndarray:
        """Impacts of each drone so far (the impact monitor's count), (N,) int."""
        return self.sim.fleet.impacts[self.rows].copy()

    def close(self) -> None:
        self.sim.close()


def _take(scale: ActionScale, idx: np.ndarray) -> ActionScale:
    return ActionScale(**{k: (v[idx] if isinstance(v, np.ndarray) else v) for k, v in vars(scale).items()})


__all__ = ["BodyRateSystem", "FlightBatch", "SavedState", "THRUST_SPAN"]
