"""Built-in parts, registered through this project's own entry points exactly like plugins."""

from __future__ import annotations

from .components.aero import AeroDrag
from .components.flight import EnergyModel, GuidanceLimits, PayloadBay, QuadrotorMotors, TeleopScript
from .control.attitude import StabilizerGains
from .control.position import GuidanceGains
from .mission import MissionSpec
from .plugins import ComponentPlugin
from .systems.actuate import AeroDragSystem
from .systems.commands import FlightCommandSystem
from .systems.energy import EnergySystem
from .systems.guidance import GuidanceSystem
from .systems.mission import EmergencyLandingSystem, MissionSystem
from .systems.motors import MotorSystem
from .systems.payload import PayloadSystem
from .systems.stabilize import StabilizerSystem

QUADROTOR = frozenset({"quadrotor"})

AERO_DRAG = ComponentPlugin(
    component=AeroDrag, systems=(AeroDragSystem,),
    summary="quadratic air drag per body axis, relative to the local wind")

MOTORS = ComponentPlugin(
    component=QuadrotorMotors,
    systems=(FlightCommandSystem, MissionSystem, EmergencyLandingSystem, GuidanceSystem, StabilizerSystem,
             MotorSystem, PayloadSystem, EnergySystem),
    applies_to=QUADROTOR,
    summary="four X-configured motors, thrust applied at each motor; brings the flight stack")

GUIDANCE = ComponentPlugin(component=GuidanceLimits, applies_to=QUADROTOR,
                           summary="layer-3 limits and pure-pursuit parameters")
STABILIZER = ComponentPlugin(component=StabilizerGains, applies_to=QUADROTOR,
                             summary="layer-2 gains: vertical-speed PID, pitch/roll rate-PD, yaw-rate P")
POSITION_CONTROLLER = ComponentPlugin(component=GuidanceGains, applies_to=QUADROTOR,
                                      summary="layer-3 gains: position -> velocity -> acceleration")
PAYLOAD = ComponentPlugin(component=PayloadBay, applies_to=QUADROTOR,
                          summary="grab reach and maximum payload")
ENERGY = ComponentPlugin(component=EnergyModel, applies_to=QUADROTOR,
                         summary="actuator-disk power per motor and battery")
MISSION = ComponentPlugin(component=MissionSpec, applies_to=QUADROTOR,
                          summary="mission started at t = 0 (steps: takeoff, cruise, land, pickup, deliver, recharge, idle)")
TELEOP_SCRIPT = ComponentPlugin(component=TeleopScript, applies_to=QUADROTOR,
                                summary="scripted manual sticks [throttle, pitch, roll, yaw] over time")
