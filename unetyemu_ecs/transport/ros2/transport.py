"""ROS 2 as a transport (entry point ``ros2``): publish from snapshots on its own thread, submit commands.

:class:`Ros2Transport` opens the backend chosen by ``Simulation(ros2=...)`` / ``--ros2`` (``dds`` or
``rclpy``, :mod:`.bridge`) when it starts. The simulation offers it one snapshot per step; a thread of
its own publishes from them (:class:`~unetyemu_ecs.transport.snapshot.SnapshotQueue`, 64 deep, the
oldest dropped and counted when the thread falls behind), so a reliable reader that stops
acknowledging slows only this thread, never the loop. What it publishes per snapshot:

- every sensor sample of the step on its topic (samples marked ``ros2=False`` stay local), and
  ``/clock`` (the snapshot's time);
- ``/<v>/mission/status`` (std_msgs/String JSON, latched: TransientLocal, KeepLast(1)) for every
  drone in the first snapshot (``{"mission": null, "state": "idle"}`` without a mission) and
  whenever it changes; ``{"mission": null, "state": "rejected", "reason": ...}`` when a mission
  sent over ROS 2 is rejected (the running mission's status follows again 0.1 s of sim time later);
- every rejected command that came over ROS 2 as a WARN on ``/rosout`` (TransientLocal,
  KeepLast(1000), as rcl writes it), taken from the snapshot's command results whose source is
  ``ros2`` — the samples that could not become a command are among them (:meth:`Inbox.reject`).

Inbound, the backend's thread turns each command sample into a command (:mod:`.inbound`) and submits
it with source ``ros2``. A topic that cannot be published is counted (``publish_errors``) and named
once in the counters (``errors``); the simulation goes on.
"""

from __future__ import annotations

import json
import threading
from collections.abc import Callable
from typing import Any

from ..api import CommandPort, Snapshot, TransportError, TransportOptions
from ..snapshot import SnapshotQueue, start_consumer, stop_consumer
from .inbound import COMMAND_TOPICS, SOURCE, CommandContext, to_command

QUEUE_DEPTH = 64            # snapshots: a quarter second at 240 Hz
ROSOUT_WARN = 30            # rcl_interfaces/Log WARN
NODE_NAME = "unetyemu_sim"
STATUS_RESEND_S = 0.1       # after a rejected mission, the running mission's status follows this much later
MAX_ERRORS_KEPT = 20


class Ros2Transport:
    """The simulation as a ROS 2 node (docs/architecture.md §6), behind the transport seam."""

    name = "ros2"

    def __init__(self, world: Any, backend: str, queue_depth: int = QUEUE_DEPTH) -> None:
        self.backend = backend
        self.domain_id: int | None = None
        vehicles = [e for e in world.entities if e.kind != "package"]
        self._kinds = {e.name: e.kind for e in vehicles if e.ros2}
        self._hidden = frozenset(e.name for e in vehicles if not e.ros2)
        self._hold_s = {v.name: v.command_timeout_s or None for v in world.spec.vehicles}
        self._context = CommandContext(world.layout, tuple(e.name for e in world.packages))
        self._parameters = {"world.name": world.spec.world.name, "world.seed": world.spec.world.seed}
        self._queue = SnapshotQueue(queue_depth)
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._port: CommandPort | None = None
        self.bridge: Any = None
        # publishing state (transport thread only)
        self._results_seen = 0
        self._status: dict[str, str] = {}            # vehicle -> newest status text from the snapshots
        self._published: dict[str, str] = {}         # vehicle -> status text last published
        self._resend_at: dict[str, float] = {}       # vehicle -> sim time to re-publish its status
        self._failed: dict[str, str] = {}            # topic -> first error
        self._msg_types: dict[str, Any] = {}
        self.published = 0
        self.publish_errors = 0
        self.commands_submitted = 0
        self.samples_rejected = 0

    # -- life cycle (simulation thread) --------------------------------------------------------
    def start(self, port: CommandPort, first: Snapshot) -> None:
        from .dds_backend import domain_from_env

        self._port = port
        self.domain_id = domain_from_env()      # what both backends join (ROS_DOMAIN_ID, default 0)
        self.bridge = self._open_bridge()
        self._queue.put(first)
        self._thread = start_consumer(self._queue, self._publish_snapshot, self._stop, self._idle,
                                      f"unetyemu-{self.name}-publish")

    def _open_bridge(self) -> Any:
        """What the publishes go to: the backend's ROS 2 node (which also delivers the command topics)."""
        from .bridge import open_bridge

        return open_bridge(self.backend, self._kinds, COMMAND_TOPICS, self._on_message, self._parameters)

    # called on the publishing thread after each snapshot and at least every 50 ms (a subclass's timers)
    _idle: Callable[[], None] | None = None

    def _wants(self, topic: str) -> bool:
        """Whether the message of ``topic`` is worth building now (a sample's message is built the first
        time it is read). Always here; a subclass whose consumers subscribe per topic says no for the
        topics nobody reads."""
        return True

    def offer(self, snapshot: Snapshot) -> None:
        self._queue.put(snapshot)

    def flush(self, timeout_s: float = 2.0) -> bool:
        if self._thread is None or not self._thread.is_alive():
            return True
        return self._queue.wait_done(timeout_s)

    def stop(self, timeout_s: float = 2.0) -> None:
        stop_consumer(self._queue, self._stop, self._thread, timeout_s)
        self._thread = None
        if self.bridge is not None:
            bridge, self.bridge = self.bridge, None
            bridge.close()

    @property
    def topics(self) -> list[str]:
        """The topics published so far."""
        return list(self.bridge.topics) if self.bridge is not None else []

    def counters(self) -> dict[str, Any]:
        return {"backend": self.backend, "domain_id": self.domain_id, "snapshots_offered": self._queue.offered,
                "snapshots_dropped": self._queue.dropped, "published": self.published,
                "publish_errors": self.publish_errors, "commands_submitted": self.commands_submitted,
                "samples_rejected": self.samples_rejected, "errors": dict(self._failed)}

    # -- inbound (the backend's thread) ----------------------------------------------------------
    def _on_message(self, vehicle: str, topic_kind: str, topic: str, sample: Any) -> None:
        port = self._port
        if port is None:
            return
        try:
            command = to_command(self._context, vehicle, self._kinds[vehicle], topic_kind, sample,
                                 hold_s=self._hold_s.get(vehicle))
        except ValueError as exc:
            self.samples_rejected += 1
            port.reject(vehicle, topic, str(exc), SOURCE)
            return
        self.commands_submitted += 1
        port.submit(command)

    # -- outbound (this transport's thread) ------------------------------------------------------
    def _type(self, name: str) -> Any:
        t = self._msg_types.get(name)
        if t is None:
            from ...sensors.messages import msg_type

            t = self._msg_types[name] = msg_type(name)
        return t

    def _publish_snapshot(self, snap: Snapshot) -> None:
        from ...sensors.messages import stamp

        t = snap.sim_time_s
        if self._wants("/clock"):
            self._publish("/clock", self._type("rosgraph_msgs/msg/Clock")(clock=stamp(t)))
        for sample in snap.sensors:
            if sample.ros2 and self._wants(sample.topic):
                self._publish(sample.topic, sample.msg)
        String = self._type("std_msgs/msg/String")
        for res in snap.results[self._results_seen:snap.results_end]:
            if res.source != SOURCE or res.ok:
                continue
            topic = res.kind if res.kind.startswith("/") else f"/{res.vehicle}/{res.kind}"
            text = res.text or res.reason
            log = self._type("rcl_interfaces/msg/Log")(stamp=stamp(t), level=ROSOUT_WARN, name=NODE_NAME,
                                                       msg=f"{res.vehicle}: rejected {topic}: {text}", file="",
                                                       function="", line=0)
            self._publish("/rosout", log)
            if topic.endswith("/mission") and res.vehicle in self._kinds:
                # say it where mission progress is watched too; the running mission's status follows
                rejected = json.dumps({"mission": None, "state": "rejected", "reason": text}, sort_keys=True)
                self._publish(f"{topic}/status", String(data=rejected))
                self._published[res.vehicle] = rejected
                self._resend_at[res.vehicle] = t + STATUS_RESEND_S
        self._results_seen = snap.results_end
        due = set()
        for vehicle, status in snap.mission_status.items():
            if vehicle not in self._hidden:
                self._status[vehicle] = json.dumps(dict(status), sort_keys=True)
                due.add(vehicle)
        for vehicle, when in list(self._resend_at.items()):
            if t + 1e-9 >= when:
                del self._resend_at[vehicle]
                due.add(vehicle)
        for vehicle in due:
            text = self._status.get(vehicle)
            if text is not None and vehicle not in self._resend_at and self._published.get(vehicle) != text:
                self._published[vehicle] = text
                self._publish(f"/{vehicle}/mission/status", String(data=text))

    def _publish(self, topic: str, msg: Any) -> None:
        try:
            self.bridge.publish(topic, msg)
            self.published += 1
        except Exception as exc:  # a transport failure must not stop the simulation
            self._publish_failed(topic, exc)

    def _publish_failed(self, topic: str, exc: Exception) -> None:
        """Count a message that could not be published; the first error of a topic is kept (counters)."""
        self.publish_errors += 1
        if topic not in self._failed and len(self._failed) < MAX_ERRORS_KEPT:
            self._failed[topic] = f"cannot publish: {type(exc).__name__}: {exc}"


def create_ros2_transport(world: Any, options: TransportOptions) -> Ros2Transport | None:
    """The ``ros2`` transport plugin's ``create``: a transport when ``options.ros2`` names a backend."""
    if options.ros2 == "off":
        return None
    if options.ros2 not in ("dds", "rclpy"):
        raise TransportError(f"ROS 2: unknown backend {options.ros2!r} (expected off, dds or rclpy)")
    return Ros2Transport(world, options.ros2)


__all__ = ["NODE_NAME", "QUEUE_DEPTH", "ROSOUT_WARN", "Ros2Transport", "create_ros2_transport"]
