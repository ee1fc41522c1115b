"""ROS 2 Jazzy messages built without ROS: the message classes of ``rosbags``' Jazzy typestore.

Every sensor output is one of these message objects, ready to serialise to CDR
(:func:`serialize` / :func:`deserialize`) and publish; frames and stamps follow docs/architecture.md §3 (REP-103,
REP-105). Sim time becomes a ``builtin_interfaces/Time`` with full seconds *and* nanoseconds.
"""

from __future__ import annotations

import struct
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
    fast = _FAST_CDR.get(msg.__msgtype__)
    return fast(msg) if fast is not None else bytes(typestore().serialize_cdr(msg, msg.__msgtype__))


_CDR_HEADER = b"\x00\x01\x00\x00"              # XCDR1 (CDR_LE), no options
_STAMP = struct.Struct("<iI")
_LENGTH = struct.Struct("<I")
_POSE = struct.Struct("<7d")


def _cdr_string(out: bytearray, text: str) -> None:
    """Append a CDR string at a 4-aligned offset: its length with the NUL, its UTF-8 bytes, the NUL."""
    data = text.encode()
    out += _LENGTH.pack(len(data) + 1)
    out += data
    out += b"\x00"


def tf_message_cdr(msg: Any) -> bytes:
    """:func:`serialize` of a ``tf2_msgs/msg/TFMessage``, byte for byte what rosbags writes, in a tenth of
    its time: /tf carries every vehicle's transform 50 times a second, and rosbags' generic serializer
    made it most of a ROS 2 publishing thread's work (60 drones: 1.5 ms a message)."""
    out = bytearray(_CDR_HEADER)
    out += _LENGTH.pack(len(msg.transforms))
    for tf in msg.transforms:                       # offsets count from after the 4-byte header
        out += b"\x00" * (-(len(out) - 4) % 4)
        stamp_ = tf.header.stamp
        out += _STAMP.pack(stamp_.sec, stamp_.nanosec)
        _cdr_string(out, tf.header.frame_id)
        out += b"\x00" * (-(len(out) - 4) % 4)
        _cdr_string(out, tf.child_frame_id)
        out += b"\x00" * (-(len(out) - 4) % 8)
        t, r = tf.transform.translation, tf.transform.rotation
        out += _POSE.pack(t.x, t.y, t.z, r.x, r.y, r.z, r.w)
    return bytes(out)


def _cdr_header(out: bytearray, header_: Any) -> None:
    """Append a std_msgs/Header at a 4-aligned offset."""
    out += _STAMP.pack(header_.stamp.sec, header_.stamp.nanosec)
    _cdr_string(out, header_.frame_id)


def _cdr_uint8_sequence(out: bytearray, data: Any) -> None:
    """Append a ``uint8[]`` (its length at the next 4-aligned offset, then its bytes: one copy of a numpy array)."""
    out += b"\x00" * (-(len(out) - 4) % 4)
    out += _LENGTH.pack(len(data))
    out += data if isinstance(data, (bytes, bytearray)) else memoryview(np.ascontiguousarray(data, dtype=np.uint8))


_FIELD_TAIL = struct.Struct("<IB")


def pointcloud2_cdr(msg: Any) -> bytes:
    """:func:`serialize` of a ``sensor_msgs/msg/PointCloud2``, byte for byte what rosbags writes: every LiDAR
    of a fleet publishes one per scan, and rosbags' generic serializer walks the message field by field."""
    out = bytearray(_CDR_HEADER)
    _cdr_header(out, msg.header)
    out += b"\x00" * (-(len(out) - 4) % 4)
    out += _LENGTH.pack(msg.height) + _LENGTH.pack(msg.width) + _LENGTH.pack(len(msg.fields))
    for f in msg.fields:
        _cdr_string(out, f.name)
        out += b"\x00" * (-(len(out) - 4) % 4)
        out += _FIELD_TAIL.pack(f.offset, f.datatype)
        out += b"\x00" * (-(len(out) - 4) % 4)
        out += _LENGTH.pack(f.count)
    out += bytes((bool(msg.is_bigendian),))
    out += b"\x00" * (-(len(out) - 4) % 4)
    out += _LENGTH.pack(msg.point_step) + _LENGTH.pack(msg.row_step)
    _cdr_uint8_sequence(out, msg.data)
    out += bytes((bool(msg.is_dense),))
    return bytes(out)


def image_cdr(msg: Any) -> bytes:
    """:func:`serialize` of a ``sensor_msgs/msg/Image``, byte for byte what rosbags writes (one copy of the
    pixels into the message's bytes)."""
    out = bytearray(_CDR_HEADER)
    _cdr_header(out, msg.header)
    out += b"\x00" * (-(len(out) - 4) % 4)
    out += _LENGTH.pack(msg.height) + _LENGTH.pack(msg.width)
    _cdr_string(out, msg.encoding)
    out += bytes((int(msg.is_bigendian) & 0xFF,))
    out += b"\x00" * (-(len(out) - 4) % 4)
    out += _LENGTH.pack(msg.step)
    _cdr_uint8_sequence(out, msg.data)
    return bytes(out)


_FAST_CDR = {"tf2_msgs/msg/TFMessage": tf_message_cdr, "sensor_msgs/msg/PointCloud2": pointcloud2_cdr,
             "sensor_msgs/msg/Image": image_cdr}


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


__all__ = ["NS_PER_S", "deserialize", "diagonal_covariance", "header", "image_cdr", "msg_type", "point",
           "pointcloud2_cdr", "quaternion", "serialize", "stamp", "tf_message_cdr", "typestore", "vector3"]
