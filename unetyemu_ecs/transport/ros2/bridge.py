"""Choosing and opening a ROS 2 backend (docs/architecture.md §6): ``auto`` | ``rclpy`` | ``dds`` | ``off``.

Both backends have the same shape: ``publish(topic, rosbags_msg)``, ``topics``, ``close()``, and
they call ``on_message(vehicle, topic_kind, topic, msg)`` from their own thread for every sample on
a vehicle's command topics (``msg`` is a rosbags message of the topic's type, or an
:class:`~.inbound.RejectedSample` for a sample that could not be decoded).
"""

from __future__ import annotations

from typing import Any

from .dds_backend import DdsBridge, Ros2Error
from .rclpy_backend import RclpyBridge, rclpy_available

CHOICES = ("off", "auto", "rclpy", "dds")


def resolve_backend(choice: str) -> str:
    """``off``, ``rclpy`` or ``dds`` for a user's choice; ``auto`` is ``rclpy`` when it imports, else ``dds``."""
    if choice not in CHOICES:
        raise ValueError(f"ros2 must be one of {', '.join(CHOICES)}, got {choice!r}")
    if choice == "auto":
        return "rclpy" if rclpy_available() else "dds"
    return choice


def open_bridge(backend: str, vehicles: dict[str, str], topic_types: dict[str, str], on_message: Any,
                parameters: dict[str, Any] | None = None) -> Any:
    """Start backend ``rclpy`` or ``dds`` (as :func:`resolve_backend` gives it); raises :class:`Ros2Error`.

    ``parameters``: read-only node parameters (name -> bool, int, float or str), e.g. the world's
    name and seed; both backends add ``use_sim_time`` (true).
    """
    if backend == "rclpy":
        return RclpyBridge(vehicles, topic_types, on_message, parameters)
    if backend == "dds":
        return DdsBridge(vehicles, topic_types, on_message, parameters)
    raise ValueError(f"no ROS 2 bridge for backend {backend!r}")


__all__ = ["CHOICES", "Ros2Error", "open_bridge", "resolve_backend"]
