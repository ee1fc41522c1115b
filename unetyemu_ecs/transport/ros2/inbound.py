"""ROS 2 command topics -> simulation commands (docs/architecture.md §6).

``/<v>/mission`` (std_msgs/String, mission JSON), ``/<v>/target`` (std_msgs/Float32MultiArray
``[x, y, z, yaw_deg, speed]``), ``/<v>/teleop`` (Float32MultiArray: drone ``[throttle, pitch,
roll, yaw]``, car ``[throttle, brake, steering]``), ``/<v>/cmd_vel`` (geometry_msgs/Twist, body
frame: drones ``linear.x/y/z`` and ``angular.z``, cars ``linear.x`` and ``angular.z``), ``/<v>/arm``
(std_msgs/Bool: arm with the arming checks, or disarm; a car releases its brakes or parks) and
``/<v>/nav_mode`` (std_msgs/String, a drone's PX4 navigation mode by name: ``takeoff``, ``land``,
``rtl``, ``hold``, ``mission`` ...). Each message
becomes one command (source ``ros2``) built from values checked by
:mod:`unetyemu_ecs.command_checks`, the one place that knows every range; this module checks only
what is ROS-specific: the shape of a message (array lengths, a target's mandatory speed) and a
mission's JSON. Anything wrong raises ``ValueError`` with the reason.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from ...command_checks import (check_armed, check_cmd_vel, check_drive, check_mission, check_nav_mode,
                               check_set_target, check_teleop)
from ...config.schema import ConfigError
from ..bus import Arm, CmdVel, Command, Drive, LoadMission, SetNavMode, SetTarget, Teleop

COMMAND_TOPICS = {"mission": "std_msgs/msg/String", "target": "std_msgs/msg/Float32MultiArray",
                  "teleop": "std_msgs/msg/Float32MultiArray", "cmd_vel": "geometry_msgs/msg/Twist",
                  "arm": "std_msgs/msg/Bool", "nav_mode": "std_msgs/msg/String"}
SOURCE = "ros2"


@dataclass(frozen=True, slots=True)
class RejectedSample:
    """What a transport hands over for a sample it could not turn into a message (undecodable bytes,
    a string that is not UTF-8) or that failed while handled: :func:`to_command` rejects it
    with ``reason``, so it is reported like any bad command."""

    reason: str


@dataclass(frozen=True)
class CommandContext:
    """What turning a message into a command needs to know of the world (no simulation object)."""

    layout: Any                       # SceneLayout: targets must lie inside the world
    package_names: tuple[str, ...]    # a mission may name these


def to_command(world: CommandContext, vehicle: str, kind: str, topic_kind: str, msg: Any,
               hold_s: float | None = None) -> Command:
    """The command (source ``ros2``) for one inbound message (a rosbags message of the topic's type).

    ``kind`` is the vehicle's kind (``quadrotor`` or ``car``); teleop and cmd_vel lapse ``hold_s``
    seconds after they are applied unless a newer one follows (the vehicle's command timeout; None:
    held). Raises ``ValueError`` with the reason.
    """
    if isinstance(msg, RejectedSample):
        raise ValueError(msg.reason)
    if topic_kind == "mission":
        if kind != "quadrotor":
            raise ValueError("missions are for drones; drive a car with target, teleop or cmd_vel")
        try:
            spec = check_mission(vehicle, "mission", world.layout, world.package_names, str(msg.data))
        except ConfigError as exc:
            raise ValueError(f"mission rejected: {exc}") from None
        return LoadMission(vehicle, spec, source=SOURCE)
    if topic_kind == "target":
        values = list(msg.data)
        if len(values) != 5:
            raise ValueError(f"target needs [x, y, z, yaw_deg, speed] (5 values), got {len(values)}")
        x, y, z, yaw_deg, speed = values
        pos, yaw_rad, speed_m_s = check_set_target(vehicle, kind, world.layout, x, y, z,
                                                   yaw_deg if kind == "quadrotor" else None, speed)
        return SetTarget(vehicle, pos, yaw_rad, speed_m_s, source=SOURCE)
    if topic_kind == "teleop":
        values = list(msg.data)
        if kind == "quadrotor":
            if len(values) != 4:
                raise ValueError(f"drone teleop needs [throttle, pitch, roll, yaw] (4 values), got {len(values)}")
            return Teleop(vehicle, *check_teleop(vehicle, *values, hold_s=hold_s), source=SOURCE)
        if len(values) != 3:
            raise ValueError(f"car teleop needs [throttle, brake, steering] (3 values), got {len(values)}")
        return Drive(vehicle, *check_drive(vehicle, *values, hold_s=hold_s), source=SOURCE)
    if topic_kind == "cmd_vel":
        lin, ang = msg.linear, msg.angular
        if kind == "quadrotor":
            values = check_cmd_vel(vehicle, lin.x, ang.z, lin.y, lin.z, hold_s)
        else:
            values = check_cmd_vel(vehicle, lin.x, ang.z, hold_s=hold_s)
        return CmdVel(vehicle, *values, source=SOURCE)
    if topic_kind == "arm":
        return Arm(vehicle, check_armed(vehicle, msg.data), source=SOURCE)
    if topic_kind == "nav_mode":
        if kind != "quadrotor":
            raise ValueError("navigation modes are for drones; drive a car with target, teleop or cmd_vel")
        return SetNavMode(vehicle, check_nav_mode(vehicle, str(msg.data)), source=SOURCE)
    raise ValueError(f"unknown command topic {topic_kind!r}")


__all__ = ["COMMAND_TOPICS", "CommandContext", "RejectedSample", "SOURCE", "to_command"]
