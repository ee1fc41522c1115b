"""The ``rclpy`` ROS 2 backend: the simulator as a node of a sourced ROS 2 Jazzy (any RMW).

Used when ``rclpy`` imports (``--ros2 auto`` picks it first, ``--ros2 rclpy`` insists on it). The
node ``/unetyemu_sim`` lives in its own rclpy context, so it neither needs nor disturbs a user's
``rclpy.init()``. Messages stay the rosbags objects the sensors build: publishers send their CDR
bytes (``Publisher.publish`` takes serialised bytes and hands them to the RMW unchanged), and the
command topics are subscribed raw and decoded with rosbags, so both backends hand
:func:`~.inbound.to_command` the same objects. Graph identity, type hashes and discovery are
rclpy's own. QoS as in :mod:`.dds_backend`: Reliable / Volatile / KeepLast(10); TransientLocal ``/tf_static``
(KeepLast(1)), ``/rosout`` (1000) and ``/<v>/mission/status`` (1). Parameters (the world's name
and seed) are declared read-only on the node, which serves rclpy's parameter services.
"""

from __future__ import annotations

import threading
from typing import Any, Callable

from ...sensors.messages import deserialize, serialize
from .inbound import RejectedSample
from .dds_backend import NODE_NAME, Ros2Error, _reason, latched_depth

OnMessage = Callable[[str, str, str, Any], None]


def rclpy_available() -> bool:
    """Whether ``rclpy`` imports here (a sourced ROS 2)."""
    try:
        import rclpy  # noqa: F401
    except Exception:          # ImportError, or a half-sourced install failing to load librcl
        return False
    return True


class RclpyBridge:
    """One rclpy node: lazily created publishers, raw subscriptions on a spinning thread."""

    name = "rclpy"

    def __init__(self, vehicles: dict[str, str], topic_types: dict[str, str], on_message: OnMessage,
                 parameters: dict[str, Any] | None = None) -> None:
        try:
            import rclpy
            from rclpy.context import Context
            from rclpy.executors import SingleThreadedExecutor
        except Exception as exc:
            raise Ros2Error(f"--ros2 rclpy: rclpy does not import ({exc}); source a ROS 2 Jazzy "
                            f"(source /opt/ros/jazzy/setup.bash) or use --ros2 dds") from exc
        try:
            self._context = Context()
            rclpy.init(context=self._context)       # honours ROS_DOMAIN_ID and the RMW's own configuration
            self.node = rclpy.create_node(NODE_NAME, context=self._context)
        except Exception as exc:
            raise Ros2Error(f"cannot start the rclpy node {NODE_NAME!r}: {exc}") from exc
        self._declare(parameters or {})
        self._publishers: dict[str, Any] = {}
        self._subscriptions = []
        for vehicle in vehicles:
            for topic_kind, type_name in topic_types.items():
                topic = f"/{vehicle}/{topic_kind}"
                self._subscriptions.append(self.node.create_subscription(
                    self._msg_class(type_name), topic, self._callback(vehicle, topic_kind, topic, type_name, on_message),
                    self._qos(topic), raw=True))
        self._executor = SingleThreadedExecutor(context=self._context)
        self._executor.add_node(self.node)
        self._thread = threading.Thread(target=self._spin, name="unetyemu-ros2-rclpy", daemon=True)
        self._thread.start()

    def _declare(self, parameters: dict[str, Any]) -> None:
        """Read-only node parameters, and ``use_sim_time`` true (the simulator publishes ``/clock``)."""
        from rcl_interfaces.msg import ParameterDescriptor
        from rclpy.parameter import Parameter

        for name, value in parameters.items():
            self.node.declare_parameter(name, value, ParameterDescriptor(read_only=True))
        self.node.set_parameters([Parameter("use_sim_time", Parameter.Type.BOOL, True)])

    @staticmethod
    def _msg_class(type_name: str) -> type:
        from rosidl_runtime_py.utilities import get_message

        try:
            return get_message(type_name)
        except Exception as exc:
            raise Ros2Error(f"the sourced ROS 2 has no message type {type_name!r} ({exc})") from exc

    @staticmethod
    def _qos(topic: str) -> Any:
        from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

        depth = latched_depth(topic)
        return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=depth or 10,
                          reliability=ReliabilityPolicy.RELIABLE,
                          durability=DurabilityPolicy.TRANSIENT_LOCAL if depth else DurabilityPolicy.VOLATILE)

    @staticmethod
    def _callback(vehicle: str, topic_kind: str, topic: str, type_name: str, on_message: OnMessage) -> Callable:
        def receive(cdr: bytes) -> None:          # executor thread: must survive any sample
            try:
                msg = deserialize(bytes(cdr), type_name)
            except Exception as exc:  # e.g. a string that is not UTF-8
                msg = RejectedSample(f"not a valid {type_name}: {_reason(exc)}")
            try:
                on_message(vehicle, topic_kind, topic, msg)
            except Exception as exc:
                try:
                    on_message(vehicle, topic_kind, topic, RejectedSample(f"{_reason(exc)} while handling the sample"))
                except Exception:
                    pass              # nothing left to report through; the executor goes on
        return receive

    def _spin(self) -> None:
        try:
            self._executor.spin()
        except Exception:                         # the context was shut down under it (close)
            pass

    def publish(self, ros_topic: str, msg: Any) -> None:
        """Publish a rosbags message object on ``ros_topic`` (its CDR bytes, as they are)."""
        pub = self._publishers.get(ros_topic)
        if pub is None:
            pub = self._publishers[ros_topic] = self.node.create_publisher(
                self._msg_class(msg.__msgtype__), ros_topic, self._qos(ros_topic))
        pub.publish(serialize(msg))

    @property
    def topics(self) -> list[str]:
        return sorted(self._publishers)

    def close(self) -> None:
        self._executor.shutdown(timeout_sec=1.0)
        self.node.destroy_node()
        self._context.try_shutdown()
        self._thread.join(timeout=2.0)
        self._publishers.clear()


__all__ = ["RclpyBridge", "rclpy_available"]
