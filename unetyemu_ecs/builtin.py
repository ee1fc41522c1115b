"""Built-in parts, registered through this project's own entry points exactly like plugins."""

from __future__ import annotations

from typing import Any

from .components.aero import AeroDrag
from .components.car import CarDynamics, CarRoute
from .components.flight import EnergyModel, GuidanceLimits, PayloadBay, QuadrotorMotors, TeleopScript
from .control.attitude import StabilizerGains, angle_rate_pd_law
from .control.car import CarGuidanceParams, SpeedSteerGains, speed_pi_steer_law
from .control.layers import Layer
from .control.mixer import XQuadMixer, x_quad_priority_law
from .control.position import GuidanceGains, cascade_pid_law
from .mission import MissionSpec
from .navigation.params import FlightParamsSpec
from .plugins import ComponentPlugin, ControllerPlugin, SensorPlugin
from .sensors.battery import BatterySensor, BatterySystem
from .sensors.camera import DepthCamera, DepthCameraSystem, RgbCamera, RgbCameraSystem
from .sensors.gps import GpsSensor, GpsSystem
from .sensors.imu import ImuSensor, ImuSystem
from .sensors.lidar import LidarSensor, LidarSystem
from .sensors.odometry import OdometrySensor, OdometrySystem
from .systems.actuate import AeroDragSystem
from .systems.car import CarActuationSystem, CarCommandSystem, CarGuidanceSystem
from .systems.flight_commands import FlightCommandSystem
from .systems.energy import EnergySystem
from .systems.guidance import RouteFollowingSystem
from .systems.mission import EmergencyLandingSystem, MissionSystem
from .systems.navigator import LandDetectorSystem, NavigatorSystem
from .systems.motors import MotorSystem
from .systems.payload import PayloadSystem
from .transport.mavlink.component import MavlinkEndpoint
from .transport.api import TransportOptions, TransportPlugin
from .transport.record import create_record_transport
from .transport.ros2.transport import create_ros2_transport

QUADROTOR = frozenset({"quadrotor"})
CAR = frozenset({"car"})

AERO_DRAG = ComponentPlugin(
    component=AeroDrag, systems=(AeroDragSystem,),
    summary="quadratic air drag per body axis, relative to the local wind")

MOTORS = ComponentPlugin(
    component=QuadrotorMotors, systems=(MotorSystem,), applies_to=QUADROTOR,
    summary="four X-configured motors, thrust applied at each motor (after the mixer layer), optional lag")

GUIDANCE = ComponentPlugin(
    component=GuidanceLimits, systems=(FlightCommandSystem, MissionSystem, EmergencyLandingSystem, RouteFollowingSystem,
                                       LandDetectorSystem, NavigatorSystem),
    applies_to=QUADROTOR,
    summary="flight modes, commands, missions and route following (pure pursuit), with their limits")
PAYLOAD = ComponentPlugin(component=PayloadBay, systems=(PayloadSystem,), applies_to=QUADROTOR,
                          summary="grab reach and maximum payload")
ENERGY = ComponentPlugin(component=EnergyModel, systems=(EnergySystem,), applies_to=QUADROTOR,
                         summary="actuator-disk power per motor and battery")
MISSION = ComponentPlugin(component=MissionSpec, applies_to=QUADROTOR,
                          summary="mission started at t = 0 (steps: takeoff, cruise, land, pickup, deliver, recharge, idle)")
MAVLINK = ComponentPlugin(component=MavlinkEndpoint, applies_to=QUADROTOR,
                          summary="MAVLink endpoint like PX4 SITL instance i: API link 14540+i, GCS link 14550, system id i+1")
FLIGHT_PARAMS = ComponentPlugin(component=FlightParamsSpec, applies_to=QUADROTOR,
                                summary="PX4 flight parameters of the navigator: {MIS_TAKEOFF_ALT: 5, RTL_RETURN_ALT: 30 ...}")
TELEOP_SCRIPT = ComponentPlugin(component=TeleopScript, applies_to=QUADROTOR,
                                summary="scripted manual sticks [throttle, pitch, roll, yaw] over time")

CAR_DYNAMICS = ComponentPlugin(
    component=CarDynamics,
    systems=(CarCommandSystem, CarGuidanceSystem, CarActuationSystem),
    applies_to=CAR,
    summary="chassis on four sprung wheels: rear-wheel drive, front steering, brakes; brings the car stack")
CAR_GUIDANCE = ComponentPlugin(component=CarGuidanceParams, applies_to=CAR,
                               summary="route following: pure-pursuit look-ahead, corner speeds, arrival")
CAR_ROUTE = ComponentPlugin(component=CarRoute, applies_to=CAR,
                            summary="route driven from t = 0: waypoints [{x, y}], speed_m_s, loop, laps")

CASCADE_PID = ControllerPlugin(
    layer=Layer.POSITION, params=GuidanceGains, law=cascade_pid_law, memory={"vel_int_m_s": ((2,), 0.0)},
    summary="position P -> velocity PI -> tilt (the paper's layer 3), heading P")
ANGLE_RATE_PD = ControllerPlugin(
    layer=Layer.ATTITUDE, params=StabilizerGains, law=angle_rate_pd_law, memory={"vz_int_m_s": ((), 0.0)},
    summary="vertical-speed PID, roll/pitch angle P with rate D, yaw-rate P (the paper's layer 2)")
SPEED_PI_STEER = ControllerPlugin(
    layer=Layer.DRIVE, params=SpeedSteerGains, law=speed_pi_steer_law,
    memory={"speed_int": ((), 0.0), "engaged": ((), 0.0)},
    summary="speed PI with rolling resistance fed forward, bumpless; route steering or yaw-rate steering")
X_QUAD_PRIORITY = ControllerPlugin(
    layer=Layer.MIXER, params=XQuadMixer, law=x_quad_priority_law,
    summary="X-quad mixer, motors held in [0, F_max] with roll/pitch first, then collective, yaw last")

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

RECORD_TRANSPORT = TransportPlugin(
    create=create_record_transport,
    summary="rosbag2 recording with MCAP storage (--record PATH): every topic ROS 2 would publish, sim-time stamps")

def _create_foxglove_transport(world: Any, options: TransportOptions) -> Any:
    if options.foxglove is None:        # foxglove-sdk is imported only when a server is asked for
        return None
    from .transport.foxglove import create_foxglove_transport

    return create_foxglove_transport(world, options)


def _create_view_transport(world: Any, options: TransportOptions) -> Any:
    if options.view is None:
        return None
    from .view.transport import create_view_transport

    return create_view_transport(world, options)


FOXGLOVE_TRANSPORT = TransportPlugin(
    create=_create_foxglove_transport,
    summary="Foxglove WebSocket server (--foxglove PORT) on 127.0.0.1: scene, vehicles, TF, sensors, status, live")

VIEW_TRANSPORT = TransportPlugin(
    create=_create_view_transport,
    summary="built-in 3D web view (--view PORT) on 127.0.0.1: city, vehicles, LiDAR, camera, per-vehicle panel")

ROS2_TRANSPORT = TransportPlugin(
    create=create_ros2_transport,
    summary="ROS 2 node (--ros2 dds|rclpy): sensors, TF, /clock, mission status, /rosout; command topics")
