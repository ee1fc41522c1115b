"""ROS 2 command topics -> simulation commands, validated (docs/architecture.md §6).

``/<v>/mission`` (std_msgs/String, mission JSON), ``/<v>/target`` (std_msgs/Float32MultiArray
``[x, y, z, yaw_deg, speed]``), ``/<v>/teleop`` (Float32MultiArray: drone ``[throttle, pitch,
roll, yaw]``, car ``[throttle, brake, steering]``), ``/<v>/cmd_vel`` (geometry_msgs/Twist, body
frame: drones ``linear.x/y/z`` and ``angular.z``, cars ``linear.x`` and ``angular.z``). Each message
becomes one call of the simulation's command API, which validates it and queues it for the loop
(thread-safe); anything wrong (bad JSON, wrong array length, NaN/inf, out of range) raises
``ValueError`` with the reason. The command API checks every range with
:mod:`unetyemu_ecs.command_checks` (shared by every transport); this module checks only what is
ROS-specific: array lengths, finite message fields, a target's mandatory speed.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from ...command_checks import finite_floats
from ...config.schema import ConfigError

COMMAND_TOPICS = {"mission": "std_msgs/msg/String", "target": "std_msgs/msg/Float32MultiArray",
                  "teleop": "std_msgs/msg/Float32MultiArray", "cmd_vel": "geometry_msgs/msg/Twist"}


@dataclass(frozen=True, slots=True)
class RejectedSample:
    """What a transport hands over for a sample it could not turn into a message (undecodable bytes,
    a string that is not UTF-8) or that failed while handled: :func:`apply_command` rejects it
    with ``reason``, so it is reported like any bad command."""

    reason: str


def apply_command(sim: Any, vehicle: str, kind: str, topic_kind: str, msg: Any,
                  hold_s: float | None = None) -> None:
    """Turn one inbound message (a rosbags message of the topic's type) into a command of ``sim``.

    ``kind`` is the vehicle's kind (``quadrotor`` or ``car``); teleop and cmd_vel lapse ``hold_s``
    seconds after they arrive unless a newer one follows (the vehicle's command timeout; None: held).
    Raises ``ValueError`` with the reason.
    """
    if isinstance(msg, RejectedSample):
        raise ValueError(msg.reason)
    try:
        if topic_kind == "mission":
            if kind != "quadrotor":
                raise ValueError("missions are for drones; drive a car with target, teleop or cmd_vel")
            sim.load_mission(vehicle, str(msg.data))
        elif topic_kind == "target":
            values = list(msg.data)
            if len(values) != 5:
                raise ValueError(f"target needs [x, y, z, yaw_deg, speed] (5 values), got {len(values)}")
            x, y, z, yaw_deg, speed = finite_floats("target values", values)
            if speed <= 0.0:
                raise ValueError(f"target speed must be > 0, got {speed}")
            sim.set_target(vehicle, x, y, z, yaw_deg=yaw_deg if kind == "quadrotor" else None, speed=speed)
        elif topic_kind == "teleop":
            values = list(msg.data)
            if kind == "quadrotor":
                if len(values) != 4:
                    raise ValueError(f"drone teleop needs [throttle, pitch, roll, yaw] (4 values), got {len(values)}")
                sim.teleop(vehicle, *values, hold_s=hold_s)                  # the API checks finite and in range
            else:
                if len(values) != 3:
                    raise ValueError(f"car teleop needs [throttle, brake, steering] (3 values), got {len(values)}")
                sim.drive(vehicle, *values, hold_s=hold_s)
        elif topic_kind == "cmd_vel":
            lin = finite_floats("cmd_vel linear", [msg.linear.x, msg.linear.y, msg.linear.z])
            ang = finite_floats("cmd_vel angular", [msg.angular.x, msg.angular.y, msg.angular.z])
            if kind == "quadrotor":
                sim.cmd_vel(vehicle, lin[0], ang[2], left_m_s=lin[1], up_m_s=lin[2], hold_s=hold_s)
            else:
                sim.cmd_vel(vehicle, lin[0], ang[2], hold_s=hold_s)
        else:
            raise ValueError(f"unknown command topic {topic_kind!r}")
    except ConfigError as exc:
        raise ValueError(f"mission rejected: {exc}") from None


__all__ = ["COMMAND_TOPICS", "RejectedSample", "apply_command"]
