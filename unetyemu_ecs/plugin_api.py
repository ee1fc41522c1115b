"""The names a plugin may import: ``from unetyemu_ecs.plugin_api import ...``.

Everything a sensor, component, world system or controller plugin needs is exported here, and only
this module (and the top-level ``unetyemu_ecs`` names) is public to plugins: other modules may change
between releases. The example plugins ``plugins/wind_gust`` and ``plugins/px4_attitude`` import
from nowhere else.

What a plugin registers (entry-point groups, each object checked when it loads):

- ``unetyemu_ecs.components``: :class:`ComponentPlugin` (a component dataclass = its world-file
  schema, and the systems that act on it);
- ``unetyemu_ecs.systems``: :class:`SystemPlugin` (a world-wide system and its config dataclass);
- ``unetyemu_ecs.sensors``: :class:`SensorPlugin` (a :class:`SensorSpec` subclass and a
  :class:`SensorSystemBase` subclass);
- ``unetyemu_ecs.controllers``: :class:`ControllerPlugin` (a pure law for one :class:`Layer`, its
  params dataclass and its memory).

What a system sees, once per step, in its only argument :class:`StepContext`:

- ``ctx.fleet`` (:class:`FleetState`): per-body arrays, one row per body, units and frames in their
  names: ``pos_enu_m``, ``vel_enu_m_s``, ``acc_enu_m_s2``, ``quat_enu_flu_xyzw``, ``rate_flu_rad_s``,
  ``wind_enu_m_s`` (written in ACTUATE), ``force_cmd_enu_n`` / ``torque_cmd_enu_n_m`` (add to them in
  ACTUATE), and the shared arrays of :data:`FLIGHT_ARRAYS` and :data:`CAR_ARRAYS` (declared before
  the first step; their comments say who writes each). A plugin's own per-row state goes in
  ``ctx.fleet.declare(name, tail_shape, dtype, fill)``.
- ``ctx.rng``: the simulation's seeded generator (never ``np.random``); a sensor gets its own stream
  from :meth:`SensorSystemBase.rng_for`.
- ``ctx.services.note(sim_time_s, vehicle, text)``: a rare event for the run's summary and log.
- rows and names: :func:`row_of_vehicle` and :func:`vehicle_of_row`; a :class:`FleetSystem`
  gathers its rows, entities and components for you whenever the world changes.
- ``ctx.sim_time_s``, ``ctx.dt_s``, ``ctx.step``; ``ctx.services.layout`` (the static scene) and
  ``ctx.services.gravity_enu_m_s2``.

Frames: world ENU (x east, y north, z up), body FLU (x forward, y left, z up), quaternions xyzw,
yaw 0 = east counter-clockwise (REP 103); SI units.
"""

from __future__ import annotations

from .components.body import FleetSlot, Identity, RigidBody
from .config.schema import Each, FieldError, Ge, Gt, Le, Lt, MaxLen
from .control.layers import (Airframe, AttitudeSetpoint, CarChassis, CarCommand, CarSetpoint, CarState, DroneState,
                             Layer, MotorCommand, PositionSetpoint, ThrustTorqueCommand)
from .control.mixer import torque_per_unit_cmd_flu_n_m
from .fleet import FleetState
from .frames import (R_from_quat_xyzw, euler_rpy_from_quat_xyzw, quat_conjugate_xyzw, quat_multiply_xyzw,
                     quat_rotate_xyzw, quat_xyzw_from_euler_rpy, yaw_rad_from_quat_xyzw)
from .phases import Phase
from .plugins import ComponentPlugin, ControllerPlugin, SensorPlugin, SystemPlugin
from .sensors.base import MountedSensor, SensorSpec, SensorSystemBase
from .systems.car_state import CAR_ARRAYS, DriveMode
from .systems.fleet_system import FleetSystem, stack_params, take_params
from .systems.flight_state import FLIGHT_ARRAYS, FlightMode
from .units import GRAVITY_M_S2
from .world import StepContext


def vehicle_of_row(ctx: StepContext, row: int) -> str:
    """The world-file name of the vehicle or package in fleet row ``row``; ``KeyError`` for a free row."""
    entity = int(ctx.fleet.entity[row])
    for name, ent in ctx.services.entities.items():
        if ent == entity:
            return name
    raise KeyError(f"fleet row {row} holds no vehicle or package")


def row_of_vehicle(ctx: StepContext, name: str) -> int:
    """The fleet row of the vehicle or package called ``name``; ``KeyError`` if there is none."""
    return ctx.fleet.row_of(ctx.services.entities[name])


__all__ = [
    "CAR_ARRAYS", "FLIGHT_ARRAYS", "GRAVITY_M_S2", "Airframe", "AttitudeSetpoint", "CarChassis", "CarCommand",
    "CarSetpoint", "CarState", "ComponentPlugin", "ControllerPlugin", "DriveMode", "DroneState", "Each", "FieldError",
    "FleetSlot", "FleetState", "FleetSystem", "FlightMode", "Ge", "Gt", "Identity", "Layer", "Le", "Lt", "MaxLen",
    "MotorCommand", "MountedSensor", "Phase", "PositionSetpoint", "R_from_quat_xyzw", "RigidBody", "SensorPlugin",
    "SensorSpec", "SensorSystemBase", "StepContext", "SystemPlugin", "ThrustTorqueCommand", "euler_rpy_from_quat_xyzw",
    "quat_conjugate_xyzw", "quat_multiply_xyzw", "quat_rotate_xyzw", "quat_xyzw_from_euler_rpy", "row_of_vehicle",
    "stack_params", "take_params", "torque_per_unit_cmd_flu_n_m", "vehicle_of_row", "yaw_rad_from_quat_xyzw",
]
