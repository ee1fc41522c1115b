"""Recording as a transport (entry point ``record``): a rosbag2 with MCAP storage of what ROS 2 would publish.

``Simulation(record=PATH)`` / ``unetyemu run WORLD --record [PATH]`` write every topic the ROS 2
transport publishes -- sensors, ``/tf`` and ``/tf_static``, ``/clock``, mission status, ``/rosout`` --
into a rosbag2 directory ``PATH`` (``metadata.yaml`` and ``PATH/<name>.mcap``), with ROS 2 Jazzy
message definitions, CDR serialisation and sim-time stamps, without ROS 2 installed and without the
DDS transport running: ``ros2 bag info PATH``, ``ros2 bag play PATH``, Foxglove and Lichtblick read
it. It is the ROS 2 transport's publisher with a bag in place of the DDS participant, so what is
recorded is exactly what a ROS 2 subscriber would have received. It runs in a worker process of its
own (:mod:`.worker`: the simulation's process only pickles each step's unbuilt sensor samples into a
pipe), and there writes from its own thread and snapshot queue (deep: 1024 snapshots); a disk too
slow for the simulation drops the oldest snapshots and counts them (``snapshots_dropped``), the loop
never waits. ``record_topics`` (glob patterns) keeps a chosen set of topics; the messages of the
others are never built.
"""

from __future__ import annotations

from fnmatch import fnmatchcase
from pathlib import Path
from typing import Any

from .api import Snapshot, TransportError, TransportOptions
from .ros2.transport import Ros2Transport
from .worker import ProcessTransport

RECORD_QUEUE_DEPTH = 1024          # snapshots (4 s at 240 Hz) before the oldest are dropped
BAG_VERSION = 8                    # rosbag2 metadata version that Humble to Jazzy read


def bag_directory(path: str | Path) -> Path:
    """The rosbag2 directory of ``path`` (``run.mcap`` and ``run`` both name the bag ``run``)."""
    p = Path(path)
    return p.with_suffix("") if p.suffix == ".mcap" else p


class BagBridge:
    """The publishing side of a ROS 2 bridge that writes into a rosbag2 (MCAP storage) instead of DDS.

    ``time_ns`` is the stamp of the next writes (the snapshot's sim time); one connection per topic,
    with the message type's Jazzy definition and hash.
    """

    def __init__(self, directory: Path) -> None:
        from rosbags.rosbag2 import StoragePlugin, Writer

        from ..sensors.messages import serialize, typestore

        self.directory = directory
        self._serialize = serialize          # rosbags' CDR bytes (own writers for /tf, clouds, images)
        self._typestore = typestore()
        self._writer = Writer(directory, version=BAG_VERSION, storage_plugin=StoragePlugin.MCAP)
        self._writer.open()
        self._connections: dict[str, Any] = {}
        self.time_ns = 0
        self.written: dict[str, int] = {}        # topic -> messages written

    @property
    def topics(self) -> list[str]:
        return list(self._connections)

    def publish(self, topic: str, msg: Any) -> None:
        conn = self._connections.get(topic)
        if conn is None:
            conn = self._connections[topic] = self._writer.add_connection(
                topic, msg.__msgtype__, typestore=self._typestore,
                offered_qos_profiles=offered_qos(topic))
        self._writer.write(conn, self.time_ns, self._serialize(msg))
        self.written[topic] = self.written.get(topic, 0) + 1

    def close(self) -> None:
        self._writer.close()


def offered_qos(topic: str) -> list[Any]:
    """The QoS the live ROS 2 transport offers on ``topic`` (reliable; transient local with its depth
    for the latched topics: ``/tf_static``, mission status, ``/rosout``; else volatile, keep last 10),
    so that ``ros2 bag play`` republishes each topic as the simulation did. The times are ROS 2's
    defaults (infinite: 0 s)."""
    from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime

    from .ros2.dds_backend import VOLATILE_DEPTH, latched_depth

    latched = latched_depth(topic)
    never = QosTime(sec=0, nsec=0)
    return [Qos(history=QosHistory.KEEP_LAST, depth=latched or VOLATILE_DEPTH.get(topic, 10),
                reliability=QosReliability.RELIABLE,
                durability=QosDurability.TRANSIENT_LOCAL if latched else QosDurability.VOLATILE,
                deadline=never, lifespan=never, liveliness=QosLiveliness.AUTOMATIC,
                liveliness_lease_duration=never, avoid_ros_namespace_conventions=False)]


class RecordTransport(Ros2Transport):
    """The ROS 2 transport's publishing into a bag: no DDS, no command topics."""

    name = "record"

    def __init__(self, world: Any, path: Path, topics: tuple[str, ...] = ()) -> None:
        super().__init__(world, "record", queue_depth=RECORD_QUEUE_DEPTH)
        self.path = bag_directory(path)
        self.patterns = tuple(topics)
        self._chosen: dict[str, bool] = {}          # topic -> whether a pattern matches it (transport thread)

    def _wants(self, topic: str) -> bool:
        chosen = self._chosen.get(topic)
        if chosen is None:
            chosen = self._chosen[topic] = not self.patterns or any(fnmatchcase(topic, p) for p in self.patterns)
        return chosen

    def _publish(self, topic: str, msg: Any) -> None:
        if self._wants(topic):
            super()._publish(topic, msg)

    def _open_bridge(self) -> BagBridge:
        if self.path.exists():
            raise TransportError(f"record: {self.path} exists already (a rosbag2 is a new directory: "
                                 "choose another name or remove it)")
        if not self.path.parent.is_dir():
            raise TransportError(f"record: cannot write {self.path}: {self.path.parent} is not a directory")
        try:
            return BagBridge(self.path)
        except Exception as exc:
            raise TransportError(f"record: cannot open the bag {self.path}: {exc}") from exc

    def _publish_snapshot(self, snap: Snapshot) -> None:
        self.bridge.time_ns = int(round(snap.sim_time_s * 1e9))
        super()._publish_snapshot(snap)

    def counters(self) -> dict[str, Any]:
        counters = super().counters()
        counters["path"] = str(self.path)
        if self.patterns:
            seen = [t for t, chosen in list(self._chosen.items()) if chosen]
            counters["topics_chosen"] = len(seen)
            counters["patterns_matching_nothing"] = [p for p in self.patterns
                                                     if not any(fnmatchcase(t, p) for t in seen)]
        return counters


def create_record_transport(world: Any, options: TransportOptions) -> ProcessTransport | None:
    """The ``record`` transport plugin's ``create``: a recorder when ``options.record`` names a bag, run
    in a worker process (:mod:`.worker`): building, serialising and writing every message in the
    simulation's process cost the delivery scenario a sixth of its real-time factor, on 2 cores."""
    if getattr(options, "record", None) is None:
        return None
    return ProcessTransport("record", f"{__name__}:recorder_in_this_process", world, options,
                            queue_depth=RECORD_QUEUE_DEPTH)


def recorder_in_this_process(world: Any, options: TransportOptions) -> RecordTransport:
    """The recorder itself (what the worker process runs)."""
    return RecordTransport(world, Path(options.record), tuple(getattr(options, "record_topics", ())))


__all__ = ["BagBridge", "RecordTransport", "bag_directory", "create_record_transport", "offered_qos",
           "recorder_in_this_process"]
