"""The ``dds`` ROS 2 backend: a cyclonedds participant that writes ROS 2 topics as ROS 2 nodes do.

DDS topic ``rt/<topic>``, type ``<pkg>::msg::dds_::<Msg>_`` (:mod:`.dds_types`), XCDR1 data
representation (a Fast DDS reader ignores XCDR2 silently), QoS Reliable / Volatile / KeepLast(10)
(what RViz2 and ``ros2 topic echo`` expect); TransientLocal: ``/tf_static`` KeepLast(1), ``/rosout``
KeepLast(1000) (as rcl), ``/<v>/mission/status`` KeepLast(1) (latched). The node's parameter
services are in :mod:`.dds_params`. Unless ``CYCLONEDDS_URI`` is set, the network configuration
follows ROS 2's variables (:func:`dds_config`): by default discoverable by default-configured ROS 2
nodes on this machine while the simulator's multicast never leaves it (TTL 0),
``ROS_AUTOMATIC_DISCOVERY_RANGE`` (SUBNET, LOCALHOST, OFF, SYSTEM_DEFAULT) and ``ROS_STATIC_PEERS``
as in ROS 2; every variant keeps large-message fragmentation, burst and heartbeat settings that
Fast DDS readers with default socket buffers can follow without losing images. The domain comes
from ``ROS_DOMAIN_ID`` (default 0).
"""

from __future__ import annotations

import os
import threading
import time
from typing import Any
from xml.sax.saxutils import quoteattr

from ...sensors.messages import deserialize, msg_type, serialize, typestore
from ..api import TransportError
from .dds_types import idl_type, to_idl

NODE_NAME = "unetyemu_sim"
NODE_NAMESPACE = "/"
DISCOVERY_TOPIC = "ros_discovery_info"     # no rt/ prefix: an rmw-level topic

# Settings every configuration keeps: a 640x480 image is 15 fragments of 62 kB; sent in one burst it
# overflows a reader's default 212 kB socket buffer (Fast DDS with default buffers), and with the
# default 100 ms heartbeat the lost fragments came back so slowly that images were superseded
# (KeepLast(10)) and lost: 0-12 of 30 per run. Bursts of at most 150 kB and heartbeats every 20 ms
# while data is unacknowledged: no loss at 10 and 30 Hz (tests/integration/test_ros2_fastdds.py).
_SIZES = "<MaxMessageSize>65000B</MaxMessageSize><FragmentSize>62000B</FragmentSize>"
_INTERNAL = ("<Internal><BurstSize><MaxInitTransmit>150000</MaxInitTransmit><MaxRexmit>150kB</MaxRexmit></BurstSize>"
             '<HeartbeatInterval min="5ms" minsched="10ms">20ms</HeartbeatInterval></Internal>')
_INDEXED = "<ParticipantIndex>auto</ParticipantIndex><MaxAutoParticipantIndex>100</MaxAutoParticipantIndex>"

RANGES = ("", "SUBNET", "LOCALHOST", "OFF", "SYSTEM_DEFAULT")


def _host_interfaces() -> list[str]:
    """Non-loopback network interfaces of this network namespace that are up, running and can multicast."""
    import fcntl
    import socket
    import struct

    found = []
    try:
        names = [name for _, name in socket.if_nameindex()]
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            for name in names:
                request = struct.pack("16sH14x", name.encode()[:15], 0)
                flags = struct.unpack("16sH14x", fcntl.ioctl(s.fileno(), 0x8913, request))[1]   # SIOCGIFFLAGS
                if flags & 0x1 and flags & 0x40 and flags & 0x1000 and not flags & 0x8:   # UP RUNNING MULTICAST !LOOPBACK
                    found.append(name)
    except (OSError, ImportError, AttributeError):   # not Linux: loopback only (SIOCGIFFLAGS is Linux's)
        return []
    return found


def static_peers_from_env() -> list[str]:
    """``ROS_STATIC_PEERS`` as a list of addresses (semicolon-separated, as ROS 2 reads it)."""
    peers = [p.strip() for p in os.environ.get("ROS_STATIC_PEERS", "").split(";") if p.strip()]
    for peer in peers:
        if any(c in peer for c in "<>&\"' ") or len(peer) > 253:
            raise Ros2Error(f"ROS_STATIC_PEERS: {peer!r} is not a host name or address")
    return peers


def discovery_range_from_env() -> str:
    """``ROS_AUTOMATIC_DISCOVERY_RANGE`` checked; ``""`` when unset (the simulator's default)."""
    value = os.environ.get("ROS_AUTOMATIC_DISCOVERY_RANGE", "").strip().upper()
    if value not in RANGES:
        raise Ros2Error(f"ROS_AUTOMATIC_DISCOVERY_RANGE must be one of SUBNET, LOCALHOST, OFF, SYSTEM_DEFAULT, "
                        f"got {os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE']!r}")
    return value


def dds_config(discovery_range: str, static_peers: list[str], host_interfaces: list[str] | None = None) -> str:
    """The cyclonedds XML for a ROS 2 discovery range (``""`` = unset) and static peers.

    - unset: multicast discovery on the host's default interface *and* loopback, with a multicast
      TTL of 0: a default-configured ROS 2 node on this machine finds the simulator, the
      simulator's multicast never leaves the machine, and its unicast goes to the addresses of
      participants that found it (on this machine: its own addresses). Not a firewall: a
      participant elsewhere whose multicast discovery reaches this host (another ROS 2 machine on
      the same LAN and domain) gets answers too; ``LOCALHOST`` or a domain id of your own avoids it.
    - ``SUBNET``: the same with cyclonedds' normal TTL (32): the LAN sees the simulator.
    - ``LOCALHOST``: loopback only, no multicast, unicast discovery on 127.0.0.1.
    - ``OFF``: no automatic discovery (loopback, no multicast); only static peers.
    - ``SYSTEM_DEFAULT``: cyclonedds' own network defaults.
    Static peers are added in every range. Every variant keeps the large-message settings.
    """
    if host_interfaces is None:
        host_interfaces = _host_interfaces()
    peers = "".join(f"<Peer address={quoteattr(p)}/>" for p in static_peers)
    if discovery_range in ("", "SUBNET"):
        auto = '<NetworkInterface autodetermine="true"/>' if host_interfaces else ""
        ttl = "<MulticastTimeToLive>0</MulticastTimeToLive>" if discovery_range == "" else ""
        general = (f'<Interfaces>{auto}<NetworkInterface name="lo" multicast="true"/></Interfaces>{ttl}')
        discovery = f'{_INDEXED}<Peers><Peer address="127.0.0.1"/>{peers}</Peers>'
    elif discovery_range == "LOCALHOST":
        general = '<Interfaces><NetworkInterface name="lo"/></Interfaces><AllowMulticast>false</AllowMulticast>'
        discovery = f'{_INDEXED}<Peers><Peer address="127.0.0.1"/>{peers}</Peers>'
    elif discovery_range == "OFF":
        general = '<Interfaces><NetworkInterface name="lo"/></Interfaces><AllowMulticast>false</AllowMulticast>'
        discovery = f"{_INDEXED}<Peers>{peers}</Peers>" if peers else "<ParticipantIndex>none</ParticipantIndex>"
    else:                                                # SYSTEM_DEFAULT
        general, discovery = "", f"<Peers>{peers}</Peers>" if peers else ""
    disc = f"<Discovery>{discovery}</Discovery>" if discovery else ""
    return (f'<CycloneDDS><Domain id="any"><General>{general}{_SIZES}</General>{disc}{_INTERNAL}'
            f"</Domain></CycloneDDS>")


def discovery_description() -> str:
    """One line for users: how the dds backend is discoverable with the current environment."""
    if os.environ.get("CYCLONEDDS_URI"):
        return "network settings from CYCLONEDDS_URI"
    words = {"": "discoverable on this machine only (multicast TTL 0; ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET "
                 "opens it to the LAN)",
             "SUBNET": "discoverable on the LAN (ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET)",
             "LOCALHOST": "loopback only (ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST)",
             "OFF": "no automatic discovery (ROS_AUTOMATIC_DISCOVERY_RANGE=OFF)",
             "SYSTEM_DEFAULT": "cyclonedds network defaults (ROS_AUTOMATIC_DISCOVERY_RANGE=SYSTEM_DEFAULT)"}
    peers = static_peers_from_env()
    return words[discovery_range_from_env()] + (f", static peers {', '.join(peers)}" if peers else "")


LOOPBACK_CONFIG = dds_config("LOCALHOST", [])

LATCHED_DEPTH = {"/tf_static": 1, "/rosout": 1000}   # TransientLocal topics and their KeepLast depth (as rcl/tf2)
TRANSIENT_LOCAL_TOPICS = tuple(LATCHED_DEPTH)


VOLATILE_DEPTH = {"/parameter_events": 1000}          # rcl's parameter events profile


def latched_depth(ros_topic: str) -> int | None:
    """KeepLast depth of a TransientLocal topic, or None for a Volatile one (KeepLast(10)).

    ``/tf_static`` 1 (tf2's static broadcaster), ``/rosout`` 1000 (rcl's logger), every
    ``/<v>/mission/status`` 1 (latched: a late subscriber gets the current status).
    """
    if ros_topic in LATCHED_DEPTH:
        return LATCHED_DEPTH[ros_topic]
    return 1 if ros_topic.endswith("/mission/status") else None
MAX_BLOCKING_MS = 20     # a reliable write waits at most this for a slow (or dead) reader, then fails


class Ros2Error(TransportError):
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
# is already serialised, and taking samples as bytes. Without it (another version), publishing falls back to the public path.
try:
    from cyclonedds._clayer import ddspy_take as _RAW_TAKE
    from cyclonedds._clayer import ddspy_write as _RAW_WRITE
except ImportError:  # pragma: no cover - depends on the installed cyclonedds
    _RAW_TAKE = _RAW_WRITE = None


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

        config = None if os.environ.get("CYCLONEDDS_URI") else dds_config(discovery_range_from_env(),
                                                                          static_peers_from_env())
        try:
            # the Domain object must live as long as the participant: it holds the configuration
            self._domain = None if config is None else Domain(domain_id, config)
            self.participant = DomainParticipant(domain_id, qos=Qos(Policy.Userdata(b"enclave=/;")))
        except Exception as exc:        # cyclonedds reports a bad CYCLONEDDS_URI or interface this way
            raise Ros2Error(f"cannot start DDS on domain {domain_id}: {exc}") from exc
        self._writers: dict[str, Any] = {}
        self.reader_gids: list[bytes] = []              # readers of this node (commands, service requests)
        self.writer_gids: list[bytes] = []              # writers besides the topic writers (service replies)
        self._graph = self._discovery_writer()

    @staticmethod
    def qos_for(ros_topic: str, type_name: str | None = None) -> Any:
        """ROS 2 default QoS for a topic; with ``type_name``, the endpoint USER_DATA carries the
        Jazzy type hash (``typehash=RIHS01_...;``) as rmw implementations announce it."""
        from cyclonedds.core import Policy
        from cyclonedds.qos import Qos
        from cyclonedds.util import duration

        depth = latched_depth(ros_topic)
        policies = [Policy.Reliability.Reliable(duration(milliseconds=MAX_BLOCKING_MS)),
                    Policy.Durability.TransientLocal if depth else Policy.Durability.Volatile,
                    Policy.History.KeepLast(depth or VOLATILE_DEPTH.get(ros_topic, 10)),
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

        name = "rmw_dds_common/msg/ParticipantEntitiesInfo"
        qos = Qos(Policy.Reliability.Reliable(duration(milliseconds=MAX_BLOCKING_MS)), Policy.Durability.TransientLocal,
                  Policy.History.KeepLast(1), Policy.DataRepresentation(use_cdrv0_representation=True),
                  Policy.Userdata(f"typehash={typestore().hash_rihs01(name)};".encode()))
        return DataWriter(self.participant, Topic(self.participant, DISCOVERY_TOPIC, idl_type(name), qos=qos), qos=qos)

    def announce(self) -> None:
        """Publish this node's entities on ``ros_discovery_info`` (what ``ros2 node list`` reads)."""
        Gid = msg_type("rmw_dds_common/msg/Gid")
        node = msg_type("rmw_dds_common/msg/NodeEntitiesInfo")(
            node_namespace=NODE_NAMESPACE, node_name=NODE_NAME,
            reader_gid_seq=[Gid(data=_gid(g)) for g in self.reader_gids],
            writer_gid_seq=[Gid(data=_gid(g)) for g in [w.guid.bytes for w in self._writers.values()] + self.writer_gids])
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




SWEEP_S = 0.5                   # every reader is also looked at this often (a notification may precede its listener)
TAKE_N = 32                     # samples taken per reader and wake-up; a full take looks again at once
MAX_REASON_CHARS = 300          # a rejection reason quotes at most this much of an exception's text


def take_raw(reader: Any, n: int = 32, with_info: bool = False) -> list:
    """Take up to ``n`` valid samples of ``reader`` as their XCDR bytes (with the encapsulation header),
    without decoding them: a sample that cannot be decoded must not cost the others. With
    ``with_info``: ``(bytes, sample_info)`` pairs."""
    if _RAW_TAKE is None:                     # pragma: no cover - another cyclonedds: decode, then re-encode
        samples = [s for s in reader.take(N=n) if hasattr(s, "serialize")]
        return [(s.serialize(use_version_2=False), s.sample_info) if with_info else s.serialize(use_version_2=False)
                for s in samples]
    from cyclonedds.core import DDSException, InstanceState, SampleState, ViewState

    ret = _RAW_TAKE(reader._ref, SampleState.Any | ViewState.Any | InstanceState.Any, n)
    if isinstance(ret, int):
        raise DDSException(ret, f"while taking samples of {reader!r}")
    # invalid samples (a writer went away) carry no data
    return [(bytes(data), info) if with_info else bytes(data) for data, info in ret if info.valid_data]


def _reason(exc: BaseException) -> str:
    text = f"{type(exc).__name__}: {exc}"
    return text if len(text) <= MAX_REASON_CHARS else text[:MAX_REASON_CHARS] + "..."


class DdsCommandListener:
    """Reads the command topics of every vehicle on its own thread and hands each message (a rosbags
    message of the topic's type) to ``on_message(vehicle, topic_kind, topic, msg)``; the loop never
    waits for DDS.

    The thread survives any sample: one that does not decode as the topic's type (bytes that are
    not CDR, a string that is not UTF-8, a length beyond the data) is handed over as a
    :class:`~.inbound.RejectedSample` carrying the reason, which the command API rejects like any
    bad command (event log, ``/rosout``); an exception raised by ``on_message`` itself is handed
    over the same way. ``services`` are further ``(reader, handle(cdr, sample_info))`` pairs served
    on the same thread (the parameter services).
    """

    def __init__(self, publisher: DdsPublisher, vehicles: dict[str, str], topic_types: dict[str, str],
                 on_message: Any, services: list[tuple[Any, Any]] = ()) -> None:
        from cyclonedds.sub import DataReader
        from cyclonedds.topic import Topic

        dp = publisher.participant
        self._lock = threading.Lock()
        self._ready: set[int] = set()                     # indices of readers with data (their listeners say so)
        self._wake = threading.Event()
        self._readers: list[tuple[Any, str, str, str, str]] = []   # reader, vehicle, topic kind, topic, type
        for vehicle in vehicles:
            for topic_kind, type_name in topic_types.items():
                ros_topic = f"/{vehicle}/{topic_kind}"
                qos = DdsPublisher.qos_for(ros_topic, type_name)
                reader = DataReader(dp, Topic(dp, dds_topic_name(ros_topic), idl_type(type_name), qos=qos), qos=qos,
                                    listener=self._listener(len(self._readers)))
                publisher.reader_gids.append(reader.guid.bytes)
                self._readers.append((reader, vehicle, topic_kind, ros_topic, type_name))
        publisher.announce()
        self._services = list(services)
        for k, (reader, _handle) in enumerate(self._services):
            reader.set_listener(self._listener(len(self._readers) + k))
        self._on_message = on_message
        self.failures = 0                                 # samples or callbacks that raised (reported)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="unetyemu-ros2-commands", daemon=True)
        self._thread.start()

    def _listener(self, index: int) -> Any:
        """A listener that marks reader ``index`` as having data and wakes the thread (called on a DDS thread)."""
        from cyclonedds.core import Listener

        def data_available(_reader: Any) -> None:
            with self._lock:
                self._ready.add(index)
            self._wake.set()

        return Listener(on_data_available=data_available)

    def _run(self) -> None:
        # woken by the readers' listeners, not polled: a poll of every command reader of 60 drones every
        # 10 ms held the GIL a third of the time; waiting in cyclonedds (a WaitSet) holds it all the time.
        # An Event wait releases it; a sweep of every reader each SWEEP_S catches data that arrived
        # before a listener was set.
        next_sweep = time.monotonic() + SWEEP_S
        n_readers = len(self._readers)
        while not self._stop.is_set():
            self._wake.wait(SWEEP_S)
            self._wake.clear()
            if self._stop.is_set():
                return
            with self._lock:
                ready, self._ready = self._ready, set()
            if time.monotonic() >= next_sweep:
                ready = set(range(n_readers + len(self._services)))
                next_sweep = time.monotonic() + SWEEP_S
            again = set()
            for index in sorted(ready):
                if index < n_readers:
                    full = self._take_commands(*self._readers[index])
                else:
                    full = self._serve(*self._services[index - n_readers])
                if full:
                    again.add(index)
            if again:                                     # more than one take's worth waiting: at once
                with self._lock:
                    self._ready |= again
                self._wake.set()

    def _take_commands(self, reader: Any, vehicle: str, topic_kind: str, ros_topic: str, type_name: str) -> bool:
        """Deliver the samples waiting on one command reader; True when the take was full (more may wait)."""
        try:
            samples = take_raw(reader, TAKE_N)
        except Exception as exc:                 # cyclonedds itself failed: say so, go on
            self._deliver(vehicle, topic_kind, ros_topic, _rejected(f"cannot take a sample: {_reason(exc)}"))
            return False
        for cdr in samples:
            try:
                msg = deserialize(cdr, type_name)
            except Exception as exc:
                msg = _rejected(f"not a valid {type_name}: {_reason(exc)}")
            self._deliver(vehicle, topic_kind, ros_topic, msg)
        return len(samples) >= TAKE_N

    def _serve(self, reader: Any, handle: Any) -> bool:
        """Answer the requests waiting on one service reader; True when the take was full."""
        try:
            requests = take_raw(reader, TAKE_N, with_info=True)
            for cdr, info in requests:
                handle(cdr, info)
        except Exception as exc:                 # a bad request: no reply, the server goes on
            self.failures += 1
            _warn_once(f"ROS 2 service request failed: {_reason(exc)}")
            return False
        return len(requests) >= TAKE_N

    def _deliver(self, vehicle: str, topic_kind: str, ros_topic: str, msg: Any) -> None:
        try:
            self._on_message(vehicle, topic_kind, ros_topic, msg)
            return
        except Exception as exc:                      # the callback's own failure is reported as a rejection
            self.failures += 1
            reason = f"{_reason(exc)} while handling the sample"
        try:
            self._on_message(vehicle, topic_kind, ros_topic, _rejected(reason))
        except Exception as exc:                      # cannot even report it: stderr, once per kind of failure
            _warn_once(f"ROS 2 command on {ros_topic} failed: {reason}; reporting it failed too: {_reason(exc)}")

    def close(self) -> None:
        self._stop.set()
        self._wake.set()
        self._thread.join(timeout=2.0)
        self._readers.clear()
        self._services.clear()


_WARNED: set[str] = set()


def _warn_once(text: str) -> None:
    import sys

    key = text.split(":", 1)[0]
    if key not in _WARNED:
        _WARNED.add(key)
        print(f"unetyemu: {text}", file=sys.stderr)


def _rejected(reason: str) -> Any:
    from .inbound import RejectedSample

    return RejectedSample(reason)


class DdsBridge:
    """The ``dds`` backend as the simulation uses it: a publisher, the command listener and the
    parameter services on one participant.

    Made at start, so that late subscribers find them: ``/rosout`` and every vehicle's
    ``/<v>/mission/status`` writer (both TransientLocal); ``parameters`` (name -> bool, int, float
    or str, read-only) are served with ``use_sim_time`` (true: the simulator publishes ``/clock``).
    """

    name = "dds"

    def __init__(self, vehicles: dict[str, str], topic_types: dict[str, str], on_message: Any,
                 parameters: dict[str, Any] | None = None) -> None:
        from .dds_params import ParameterServer

        self.publisher = DdsPublisher()
        try:
            self.publisher.writer("/rosout", "rcl_interfaces/msg/Log")
            for vehicle in vehicles:
                self.publisher.writer(f"/{vehicle}/mission/status", "std_msgs/msg/String")
            self.parameters = ParameterServer(self.publisher, {"use_sim_time": True, **(parameters or {})})
            self.listener = DdsCommandListener(self.publisher, vehicles, topic_types, on_message,
                                               self.parameters.services)
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
           "Ros2Error", "dds_config", "dds_topic_name", "discovery_description", "discovery_range_from_env",
           "domain_from_env", "latched_depth", "static_peers_from_env", "take_raw"]
