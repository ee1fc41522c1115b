"""The ``dds`` ROS 2 backend: a cyclonedds participant that writes ROS 2 topics as ROS 2 nodes do.

DDS topic ``rt/<topic>``, type ``<pkg>::msg::dds_::<Msg>_`` (:mod:`.dds_types`), XCDR1 data
representation (a Fast DDS reader ignores XCDR2 silently), QoS Reliable / Volatile / KeepLast(10)
(what RViz2 and ``ros2 topic echo`` expect), ``/tf_static`` TransientLocal / KeepLast(1). Unless
``CYCLONEDDS_URI`` is set, the participant uses a loopback-only configuration (interface ``lo``,
no multicast, peer 127.0.0.1) with large-message fragmentation, burst and heartbeat settings that
Fast DDS readers with default socket buffers can follow without losing images; the domain comes
from ``ROS_DOMAIN_ID`` (default 0).
"""

from __future__ import annotations

import os
from typing import Any

from ...sensors.messages import msg_type, serialize, typestore
from .dds_types import idl_type, to_idl

NODE_NAME = "unetyemu_sim"
NODE_NAMESPACE = "/"
DISCOVERY_TOPIC = "ros_discovery_info"     # no rt/ prefix: an rmw-level topic

LOOPBACK_CONFIG = """<CycloneDDS><Domain id="any">
  <General><Interfaces><NetworkInterface name="lo"/></Interfaces><AllowMulticast>false</AllowMulticast>
    <MaxMessageSize>65000B</MaxMessageSize><FragmentSize>62000B</FragmentSize></General>
  <Discovery><ParticipantIndex>auto</ParticipantIndex><MaxAutoParticipantIndex>100</MaxAutoParticipantIndex>
    <Peers><Peer address="127.0.0.1"/></Peers></Discovery>
  <Internal><BurstSize><MaxInitTransmit>150000</MaxInitTransmit><MaxRexmit>150kB</MaxRexmit></BurstSize>
    <HeartbeatInterval min="5ms" minsched="10ms">20ms</HeartbeatInterval></Internal>
</Domain></CycloneDDS>"""
# Why the Internal settings: a 640x480 image is 15 fragments of 62 kB; sent in one burst it overflows a
# reader's default 212 kB socket buffer (Fast DDS with default buffers), and with the default 100 ms
# heartbeat the lost fragments came back so slowly that images were superseded (KeepLast(10)) and
# lost: 0-12 of 30 per run. Bursts of at most 150 kB and heartbeats every 20 ms while data is
# unacknowledged: no loss at 10 and 30 Hz (tests/integration/test_ros2_fastdds.py).

TRANSIENT_LOCAL_TOPICS = ("/tf_static",)
MAX_BLOCKING_MS = 20     # a reliable write waits at most this for a slow (or dead) reader, then fails


class Ros2Error(RuntimeError):
    """ROS 2 cannot start here (bad ROS_DOMAIN_ID, cyclonedds missing or failing); the message says why."""


def domain_from_env() -> int:
    """``ROS_DOMAIN_ID`` (0 when unset), checked: ROS 2 allows 0..232."""
    text = os.environ.get("ROS_DOMAIN_ID", "").strip() or "0"
    try:
        value = int(text)
    except ValueError:
        raise Ros2Error(f"ROS_DOMAIN_ID must be an integer in 0..232, got {text!r}") from None
    if not 0 <= value <= 232:
        raise Ros2Error(f"ROS_DOMAIN_ID must be in 0..232, got {value}")
    return value


# The one place that touches cyclonedds internals (pinned: cyclonedds==11.0.1): writing a sample that
# is already serialised. Without it (another version), publishing falls back to the public path.
try:
    from cyclonedds._clayer import ddspy_write as _RAW_WRITE
except ImportError:  # pragma: no cover - depends on the installed cyclonedds
    _RAW_WRITE = None


def _write_raw(writer: Any, cdr: bytes) -> None:
    """Write XCDR1 bytes (with their 4-byte encapsulation header) as one sample of ``writer``."""
    from cyclonedds.core import DDSException

    pad = (-len(cdr)) % 4
    ret = _RAW_WRITE(writer._ref, cdr + b"\0" * pad if pad else cdr)
    if ret < 0:
        raise DDSException(ret, f"while writing a sample with {writer!r}")


def _gid(guid: bytes) -> Any:
    """An rmw Gid (16 bytes) of a DDS GUID."""
    import numpy as np

    return np.frombuffer(bytes(guid)[:16].ljust(16, b"\0"), dtype=np.uint8).copy()


def dds_topic_name(ros_topic: str) -> str:
    """``/a/b`` -> ``rt/a/b`` (ROS 2's prefix for topics)."""
    return "rt" + (ros_topic if ros_topic.startswith("/") else "/" + ros_topic)


class DdsPublisher:
    """Writers for ROS 2 topics on one DDS participant; a writer is made on a topic's first message."""

    def __init__(self, domain_id: int | None = None) -> None:
        try:
            from cyclonedds.domain import Domain, DomainParticipant
        except ImportError as exc:
            raise Ros2Error(f"the dds backend needs cyclonedds ({exc}): python3 -m pip install cyclonedds==11.0.1") from exc
        if domain_id is None:
            domain_id = domain_from_env()
        self.domain_id = domain_id
        from cyclonedds.core import Policy
        from cyclonedds.qos import Qos

        try:
            # the Domain object must live as long as the participant: it holds the configuration
            self._domain = None if os.environ.get("CYCLONEDDS_URI") else Domain(domain_id, LOOPBACK_CONFIG)
            self.participant = DomainParticipant(domain_id, qos=Qos(Policy.Userdata(b"enclave=/;")))
        except Exception as exc:        # cyclonedds reports a bad CYCLONEDDS_URI or interface this way
            raise Ros2Error(f"cannot start DDS on domain {domain_id}: {exc}") from exc
        self._writers: dict[str, Any] = {}
        self.reader_gids: list[bytes] = []              # readers of this node (the command listener's)
        self._graph = self._discovery_writer()

    @staticmethod
    def qos_for(ros_topic: str, type_name: str | None = None) -> Any:
        """ROS 2 default QoS for a topic; with ``type_name``, the endpoint USER_DATA carries the
        Jazzy type hash (``typehash=RIHS01_...;``) as rmw implementations announce it."""
        from cyclonedds.core import Policy
        from cyclonedds.qos import Qos
        from cyclonedds.util import duration

        durable = ros_topic in TRANSIENT_LOCAL_TOPICS
        policies = [Policy.Reliability.Reliable(duration(milliseconds=MAX_BLOCKING_MS)),
                    Policy.Durability.TransientLocal if durable else Policy.Durability.Volatile,
                    Policy.History.KeepLast(1 if durable else 10),
                    Policy.DataRepresentation(use_cdrv0_representation=True)]
        if type_name is not None:
            policies.append(Policy.Userdata(f"typehash={typestore().hash_rihs01(type_name)};".encode()))
        return Qos(*policies)

    def _discovery_writer(self) -> Any:
        from cyclonedds.core import Policy
        from cyclonedds.pub import DataWriter
        from cyclonedds.qos import Qos
        from cyclonedds.topic import Topic
        from cyclonedds.util import duration

        qos = Qos(Policy.Reliability.Reliable(duration(milliseconds=MAX_BLOCKING_MS)), Policy.Durability.TransientLocal,
                  Policy.History.KeepLast(1), Policy.DataRepresentation(use_cdrv0_representation=True))
        name = "rmw_dds_common/msg/ParticipantEntitiesInfo"
        return DataWriter(self.participant, Topic(self.participant, DISCOVERY_TOPIC, idl_type(name), qos=qos), qos=qos)

    def announce(self) -> None:
        """Publish this node's entities on ``ros_discovery_info`` (what ``ros2 node list`` reads)."""
        Gid = msg_type("rmw_dds_common/msg/Gid")
        node = msg_type("rmw_dds_common/msg/NodeEntitiesInfo")(
            node_namespace=NODE_NAMESPACE, node_name=NODE_NAME,
            reader_gid_seq=[Gid(data=_gid(g)) for g in self.reader_gids],
            writer_gid_seq=[Gid(data=_gid(w.guid.bytes)) for w in self._writers.values()])
        info = msg_type("rmw_dds_common/msg/ParticipantEntitiesInfo")(
            gid=Gid(data=_gid(self.participant.guid.bytes)), node_entities_info_seq=[node])
        if _RAW_WRITE is not None:
            _write_raw(self._graph, serialize(info))
        else:
            self._graph.write(to_idl(info))

    def writer(self, ros_topic: str, type_name: str) -> Any:
        from cyclonedds.pub import DataWriter
        from cyclonedds.topic import Topic

        w = self._writers.get(ros_topic)
        if w is None:
            qos = self.qos_for(ros_topic, type_name)
            topic = Topic(self.participant, dds_topic_name(ros_topic), idl_type(type_name), qos=qos)
            w = self._writers[ros_topic] = DataWriter(self.participant, topic, qos=qos)
            self.announce()                              # the node's graph entry lists every writer
        return w

    def publish(self, ros_topic: str, msg: Any) -> None:
        """Write a rosbags message object on ``ros_topic``.

        Fast path: rosbags serialises the message (numpy arrays as one copy: ~0.7 ms for a 640x480
        image) and the bytes go to the writer as they are; the public path through cyclonedds'
        own serializer walks large arrays element by element (~50 ms for the same image). Both
        produce the same XCDR1 bytes (tested).
        """
        writer = self.writer(ros_topic, msg.__msgtype__)
        if _RAW_WRITE is None:
            writer.write(to_idl(msg))
            return
        _write_raw(writer, serialize(msg))

    @property
    def topics(self) -> list[str]:
        return sorted(self._writers)

    def close(self) -> None:
        self._writers.clear()
        self._graph = None
        self.participant = None
        self._domain = None




POLL_S = 0.01


class DdsCommandListener:
    """Reads the command topics of every vehicle on its own thread and hands each message to
    ``on_message(vehicle, topic_kind, topic, sample)``; the loop never waits for DDS."""

    def __init__(self, publisher: DdsPublisher, vehicles: dict[str, str], topic_types: dict[str, str],
                 on_message: Any) -> None:
        import threading

        from cyclonedds.sub import DataReader
        from cyclonedds.topic import Topic

        dp = publisher.participant
        self._readers: list[tuple[Any, str, str, str]] = []          # reader, vehicle, topic kind, topic
        for vehicle in vehicles:
            for topic_kind, type_name in topic_types.items():
                ros_topic = f"/{vehicle}/{topic_kind}"
                qos = DdsPublisher.qos_for(ros_topic, type_name)
                reader = DataReader(dp, Topic(dp, dds_topic_name(ros_topic), idl_type(type_name), qos=qos), qos=qos)
                publisher.reader_gids.append(reader.guid.bytes)
                self._readers.append((reader, vehicle, topic_kind, ros_topic))
        publisher.announce()
        self._on_message = on_message
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="unetyemu-ros2-commands", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        # polled, not a WaitSet: waiting inside cyclonedds holds the GIL and starves the sim loop;
        # an Event wait releases it (POLL_S of latency, ~10 us of work per reader per poll)
        while not self._stop.wait(POLL_S):
            for reader, vehicle, topic_kind, ros_topic in self._readers:
                for sample in reader.take(N=32):
                    if hasattr(sample, "serialize"):                # skip invalid samples (writer gone)
                        self._on_message(vehicle, topic_kind, ros_topic, sample)

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2.0)
        self._readers.clear()


class DdsBridge:
    """The ``dds`` backend as the simulation uses it: a publisher and the command listener on one participant."""

    name = "dds"

    def __init__(self, vehicles: dict[str, str], topic_types: dict[str, str], on_message: Any) -> None:
        self.publisher = DdsPublisher()
        try:
            self.listener = DdsCommandListener(self.publisher, vehicles, topic_types, on_message)
        except Exception:
            self.publisher.close()
            raise

    def publish(self, ros_topic: str, msg: Any) -> None:
        self.publisher.publish(ros_topic, msg)

    @property
    def topics(self) -> list[str]:
        return self.publisher.topics

    def close(self) -> None:
        self.listener.close()
        self.publisher.close()


__all__ = ["DISCOVERY_TOPIC", "LOOPBACK_CONFIG", "NODE_NAME", "DdsBridge", "DdsCommandListener", "DdsPublisher",
           "Ros2Error", "dds_topic_name", "domain_from_env"]
