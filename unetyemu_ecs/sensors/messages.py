"""ROS 2 Jazzy messages built without ROS: the message classes of ``rosbags``' Jazzy typestore.

Every sensor output is one of these message objects, ready to serialise to CDR
(:func:`serialize` / :func:`deserialize`) and publish; frames and stamps follow docs/architecture.md §3 (REP-103,
REP-105). Sim time becomes a ``builtin_interfaces/Time`` with full seconds *and* nanoseconds.
"""

from __future__ import annotations

from functools import cache
from typing import Any

import numpy as np

NS_PER_S = 1_000_000_000


@cache
def typestore() -> Any:
    """The ROS 2 Jazzy typestore (built once per process; read-only)."""
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_JAZZY)


def msg_type(name: str) -> type:
    """Message class for a ROS 2 type name such as ``sensor_msgs/msg/Imu``."""
    return typestore().types[name]


def serialize(msg: Any) -> bytes:
    """CDR (little-endian, XCDR1) bytes of a message, as ROS 2 puts them on the wire."""
    return bytes(typestore().serialize_cdr(msg, msg.__msgtype__))


def deserialize(data: bytes, name: str) -> Any:
    """The message of type ``name`` encoded in CDR ``data``."""
    return typestore().deserialize_cdr(data, name)


def stamp(sim_time_s: float) -> Any:
    """``builtin_interfaces/Time`` of a simulated time [s], exact to the nanosecond."""
    total_ns = int(round(sim_time_s * NS_PER_S))
    return msg_type("builtin_interfaces/msg/Time")(sec=total_ns // NS_PER_S, nanosec=total_ns % NS_PER_S)


def header(sim_time_s: float, frame_id: str) -> Any:
    return msg_type("std_msgs/msg/Header")(stamp=stamp(sim_time_s), frame_id=frame_id)


def vector3(v: np.ndarray) -> Any:
    return msg_type("geometry_msgs/msg/Vector3")(x=float(v[0]), y=float(v[1]), z=float(v[2]))


def point(v: np.ndarray) -> Any:
    return msg_type("geometry_msgs/msg/Point")(x=float(v[0]), y=float(v[1]), z=float(v[2]))


def quaternion(q_xyzw: np.ndarray) -> Any:
    return msg_type("geometry_msgs/msg/Quaternion")(x=float(q_xyzw[0]), y=float(q_xyzw[1]), z=float(q_xyzw[2]),
                                                    w=float(q_xyzw[3]))


def diagonal_covariance(variances: np.ndarray | list[float]) -> np.ndarray:
    """Row-major square covariance matrix (flattened) with ``variances`` on the diagonal."""
    v = np.asarray(variances, dtype=np.float64)
    return np.diag(v).reshape(-1).copy()


__all__ = ["NS_PER_S", "deserialize", "diagonal_covariance", "header", "msg_type", "point", "quaternion",
           "serialize", "stamp", "typestore", "vector3"]
