"""Built-in parts, registered through this project's own entry points exactly like plugins."""

from __future__ import annotations

from .components.aero import AeroDrag
from .components.car import CarDynamics, CarRoute
from .components.flight import EnergyModel, GuidanceLimits, PayloadBay, QuadrotorMotors, TeleopScript
from .control.attitude import StabilizerGains
from .control.car import CarControllerGains
from .control.position import GuidanceGains
from .mission import MissionSpec
from .plugins import ComponentPlugin, SensorPlugin
from .sensors.battery import BatterySensor, BatterySystem
from .sensors.camera import DepthCamera, DepthCameraSystem, RgbCamera, RgbCameraSystem
from .sensors.gps import GpsSensor, GpsSystem
from .sensors.imu import ImuSensor, ImuSystem
from .sensors.lidar import LidarSensor, LidarSystem
from .sensors.odometry import OdometrySensor, OdometrySystem
from .systems.actuate import AeroDragSystem
from .systems.car import CarActuationSystem, CarCommandSystem, CarControllerSystem, CarGuidanceSystem
from .systems.commands import FlightCommandSystem
from .systems.energy import EnergySystem
from .systems.guidance import GuidanceSystem
from .systems.mission import EmergencyLandingSystem, MissionSystem
from .systems.motors import MotorSystem
from .systems.payload import PayloadSystem
from .systems.stabilize import StabilizerSystem

QUADROTOR = frozenset({"quadrotor"})
CAR = frozenset({"car"})

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

CAR_DYNAMICS = ComponentPlugin(
    component=CarDynamics,
    systems=(CarCommandSystem, CarGuidanceSystem, CarControllerSystem, CarActuationSystem),
    applies_to=CAR,
    summary="chassis on four sprung wheels: rear-wheel drive, front steering, brakes; brings the car stack")
CAR_CONTROLLER = ComponentPlugin(component=CarControllerGains, applies_to=CAR,
                                 summary="speed PI, course control and route-following parameters")
CAR_ROUTE = ComponentPlugin(component=CarRoute, applies_to=CAR,
                            summary="route driven from t = 0: waypoints [{x, y}], speed_m_s, loop, laps")

IMU = SensorPlugin(component=ImuSensor, system=ImuSystem,
                   summary="sensor_msgs/Imu: body rates, specific force (+9.81 up at rest), orientation; noise, bias walk")
GPS = SensorPlugin(component=GpsSensor, system=GpsSystem,
                   summary="sensor_msgs/NavSatFix from ENU by WGS84 (via ECEF); optional noise")
BATTERY = SensorPlugin(component=BatterySensor, system=BatterySystem, applies_to=QUADROTOR,
                       summary="sensor_msgs/BatteryState of the drone's energy model")
ODOMETRY = SensorPlugin(component=OdometrySensor, system=OdometrySystem,
                        summary="nav_msgs/Odometry, ground truth, twist in base_link")
LIDAR = SensorPlugin(component=LidarSensor, system=LidarSystem,
                     summary="360 deg LiDAR (Open3D raycasting), sensor_msgs/PointCloud2 x y z intensity ring")
CAMERA = SensorPlugin(component=RgbCamera, system=RgbCameraSystem,
                      summary="RGB camera (ray cast): sensor_msgs/Image rgb8 + CameraInfo, optical frame")
DEPTH_CAMERA = SensorPlugin(component=DepthCamera, system=DepthCameraSystem,
                            summary="depth camera (ray cast): sensor_msgs/Image 32FC1 metres (+inf no return) + CameraInfo")
