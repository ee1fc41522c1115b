"""A live Foxglove server as a transport (entry point ``foxglove``): watch a run in Foxglove or Lichtblick, no ROS 2.

``Simulation(world, foxglove=PORT)`` / ``unetyemu run WORLD --foxglove [PORT]`` serve the Foxglove
WebSocket protocol on ``ws://127.0.0.1:PORT`` (0: a free port the OS chooses; ``url`` says which)
with foxglove-sdk's server. Every simulation has a ``foxglove.Context`` of its own, so two in one
process serve two servers; a port in use is a :class:`TransportError` naming it. Channels:

- every topic the ROS 2 transport publishes (sensors, ``/tf``, ``/tf_static``, ``/clock``,
  ``/<v>/mission/status``, ``/rosout``): CDR, with the ROS 2 Jazzy definition as a ``ros2msg``
  schema, so Foxglove's ROS panels (3D, Image, Plot, Raw Messages) decode them natively. It is the
  ROS 2 transport's publisher with this server in place of the DDS participant (as the recorder,
  :mod:`.record`, has a bag there), so what arrives is what a ROS 2 subscriber would have received;
- ``/scene`` (``foxglove.SceneUpdate``, protobuf): the city as one entity ``city`` in frame ``map``
  (the root of ``/tf``), one triangle list per scene class in its colour (:mod:`..scene.colors`),
  exactly the triangles of :func:`~unetyemu_ecs.scene.mesh.triangulate`. Built once, on the first
  subscription, and kept;
- ``/vehicles`` (``foxglove.SceneUpdate``): per vehicle a box of its body size and colour at its
  pose, an arrow along its heading and its name, in frame ``map``, every 1/VEHICLES_HZ s of sim time;
- ``/<v>/state`` (JSON with a JSON schema, plots-ready): sim time, position, altitude, speeds,
  heading, armed; for drones battery (state of charge, power, voltage, current, energy used, time
  left), payload, flight mode, navigation state, landed state, mission state and step (names, not
  numbers), every 1/STATE_HZ s of sim time.

Log times are sim time [ns] (as in the recorder). Latched topics (``/scene``, and as in the ROS 2
node's TransientLocal topics ``/tf_static``, ``/<v>/mission/status`` and the last 1000 ``/rosout``
lines) are kept serialised; when a client subscribes to one of them the publishing thread logs the
kept messages again, so a late subscriber gets them (a client already subscribed gets them twice:
the SDK addresses all of a server's clients at once).

Clients speak subprotocol ``foxglove.sdk.v1`` (foxglove-sdk's name for the Foxglove WebSocket protocol
v1): Foxglove asks for it, and Lichtblick since it added the name (lichtblick-suite/lichtblick#819);
clients that ask only for the old ``foxglove.websocket.v1`` are refused (HTTP 400) by the SDK's
server. The server advertises no capability: clients cannot publish, call services or set
parameters, and whatever else they send is answered with a status message and ignored.

Cost: the server runs in a worker process of its own (:mod:`.worker`, a selective transport), so
building, serialising and sending never take Python's interpreter lock from the simulation loop.
The worker tells the simulation which topics are subscribed (``wanted``); the samples of the others
never leave the simulation's process (each topic's first sample does, to advertise it, and every
sample of the latched ones), the vehicle arrays cross only at VEHICLES_HZ and only while ``/vehicles``
or a state is subscribed, and a step that carries nothing wanted is not sent at all: a server nobody
watches costs the loop only its snapshot. In the worker no message is built for a topic nobody
subscribes to (``Channel.has_sinks``). The server sends from its own threads (Rust) through a bounded
queue per client (CLIENT_BACKLOG messages, the oldest dropped when it is full), so a slow client
holds a bounded amount of memory. A client that stops reading (a frozen tab) is noticed by its
receive queue (:mod:`.tcp_readers`, Linux): when every connected client has stopped, the simulation
sends only the latched topics until one reads again (counters ``clients_stalled``, ``stalls``), so a
stalled client costs the loop nothing. Snapshot queues on both sides drop the oldest when they fall
behind (counted: ``snapshots_dropped``).
"""

from __future__ import annotations

import json
import math
import threading
import time
from collections import deque
from collections.abc import Iterable
from typing import Any

import foxglove                  # this module is imported only when a server is asked for (builtin.py)
import numpy as np
from foxglove.messages import (ArrowPrimitive, Color, CubePrimitive, Point3, Pose, Quaternion, SceneEntity, SceneUpdate,
                               TextPrimitive, Timestamp, TriangleListPrimitive, Vector3)
from foxglove.websocket import ServerListener

from .api import Snapshot, TransportError, TransportOptions
from .ros2.dds_backend import latched_depth
from .ros2.transport import Ros2Transport
from .snapshot import ticks_in_step
from .tcp_readers import StalledReaders
from .worker import ProcessTransport, Wants

HOST = "127.0.0.1"                 # loopback only: the server has no authentication
SERVER_NAME = "unetyemu"
QUEUE_DEPTH = 128                  # snapshots (half a second at 240 Hz) before the oldest are dropped
# messages queued per client before its oldest are dropped: what a stalled client can hold in memory
# (with its socket's buffers): a few MB of the delivery scenario's mix, at most 256 of the largest
# messages (80 MB of 320x240 depth images for a client watching only those)
CLIENT_BACKLOG = 256
VEHICLES_HZ = 20.0                 # [Hz, sim time] /vehicles
STATE_HZ = 10.0                    # [Hz, sim time] /<v>/state
# when the queue is empty, the publishing thread waits this long [s, wall] before taking the next snapshots,
# so that it wakes up once for several: measured on the delivery scenario (2 cores, no client), its CPU
# time halves (0.9 -> 0.5 s per 10 simulated s) and its context switches drop from 32 000 to 9 000
BATCH_WAIT_S = 0.02
READERS_EVERY_S = 0.1             # [s, wall] how often the clients' receive queues are looked at (tcp_readers)
WORLD_FRAME = "map"                # the root of /tf (sensors.tf)
SCENE_TOPIC = "/scene"
VEHICLES_TOPIC = "/vehicles"
DEFAULT_HALF_EXTENTS_M = (0.3, 0.3, 0.1)
DEFAULT_RGBA = (0.7, 0.7, 0.7, 1.0)
# the snapshot arrays /vehicles and /<v>/state are made of (all that crosses to the worker of them)
STATE_ARRAYS = ("pos_enu_m", "vel_enu_m_s", "quat_enu_flu_xyzw", "armed", "soc_frac", "power_w", "pack_voltage_v",
                "pack_current_a", "energy_used_j", "remaining_time_s", "payload_kg", "low_battery", "flight_mode",
                "nav_state", "landed_state", "mission_state", "mission_step")

VEHICLE_STATE_SCHEMA: dict[str, Any] = {
    "title": "unetyemu.VehicleState",
    "type": "object",
    "description": "A vehicle's state for plots (ENU metres, sim time); drone-only fields are absent for cars, "
                   "null where undefined.",
    "properties": {
        "vehicle": {"type": "string"},
        "kind": {"type": "string", "description": "quadrotor or car"},
        "sim_time_s": {"type": "number"},
        "position_enu_m": {"type": "object", "properties": {k: {"type": ["number", "null"]} for k in "xyz"}},
        "altitude_m": {"type": ["number", "null"], "description": "ENU z above the ground plane"},
        "speed_m_s": {"type": ["number", "null"]},
        "horizontal_speed_m_s": {"type": ["number", "null"]},
        "vertical_speed_m_s": {"type": ["number", "null"], "description": "positive up"},
        "heading_deg": {"type": ["number", "null"], "description": "yaw, counter-clockwise from east"},
        "armed": {"type": "boolean", "description": "drones: motors armed; cars: not parked"},
        "soc_frac": {"type": ["number", "null"], "description": "battery state of charge [0, 1]"},
        "power_w": {"type": ["number", "null"]},
        "pack_voltage_v": {"type": ["number", "null"]},
        "pack_current_a": {"type": ["number", "null"], "description": "positive discharging"},
        "energy_used_j": {"type": ["number", "null"]},
        "remaining_time_s": {"type": ["number", "null"]},
        "low_battery": {"type": "boolean"},
        "payload_kg": {"type": ["number", "null"]},
        "flight_mode": {"type": "string"},
        "nav_state": {"type": "string"},
        "landed_state": {"type": "string"},
        "mission_state": {"type": "string"},
        "mission_step": {"type": "integer", "description": "-1: none"},
    },
}


# -- schemas and messages ----------------------------------------------------------------------------
def ros2msg_schema(msgtype: str) -> Any:
    """The ``ros2msg`` schema of a ROS 2 message type (``sensor_msgs/msg/PointCloud2``): its Jazzy
    definition with those of the types it uses, as Foxglove reads them."""
    from ..sensors.messages import typestore

    text, _ = typestore().generate_msgdef(msgtype, ros_version=2)
    return foxglove.Schema(name=msgtype, encoding="ros2msg", data=text.encode())


def _timestamp(time_ns: int) -> Any:
    return Timestamp(time_ns // 1_000_000_000, time_ns % 1_000_000_000)


def scene_update(layout: Any) -> bytes:
    """The ``foxglove.SceneUpdate`` (protobuf) of the static scene: entity ``city`` in :data:`WORLD_FRAME`,
    one indexed triangle list per scene class in its colour, the triangles of ``triangulate(layout)``."""
    from ..scene.colors import class_rgb
    from ..scene.mesh import triangulate

    mesh = triangulate(layout)
    rgb = class_rgb()
    lists = []
    for cls in np.unique(mesh.cls).tolist():
        used, indices = np.unique(mesh.triangles[mesh.cls == cls], return_inverse=True)  # this class's vertices
        r, g, b = rgb[cls].tolist()
        lists.append(TriangleListPrimitive(points=[Point3(x=x, y=y, z=z) for x, y, z in mesh.vertices_m[used].tolist()],
                                           indices=indices.reshape(-1).tolist(), color=Color(r=r, g=g, b=b, a=1.0)))
    city = SceneEntity(frame_id=WORLD_FRAME, id="city", triangles=lists)
    return SceneUpdate(entities=[city]).encode()


Look = tuple[tuple[float, ...], tuple[float, ...]]      # half extents [m] along FLU x, y, z; RGBA in [0, 1]


def vehicles_update(snap: Snapshot, time_ns: int, looks: dict[str, Look]) -> bytes:
    """The ``foxglove.SceneUpdate`` (protobuf) of every vehicle in ``snap``: a box of its body, an arrow
    along its heading (body x) and its name, at its pose in :data:`WORLD_FRAME`.

    looks : vehicle -> (half extents [m] along FLU x, y, z; RGBA in [0, 1])
    """
    stamp = _timestamp(time_ns)
    white = Color(r=1.0, g=1.0, b=1.0, a=1.0)
    entities = []
    for name, p, q in zip(snap.vehicles, snap.pos_enu_m.tolist(), snap.quat_enu_flu_xyzw.tolist()):
        (hx, hy, hz), (r, g, b, a) = looks.get(name, (DEFAULT_HALF_EXTENTS_M, DEFAULT_RGBA))
        pose = Pose(position=Vector3(x=p[0], y=p[1], z=p[2]), orientation=Quaternion(x=q[0], y=q[1], z=q[2], w=q[3]))
        length_m = max(1.0, 3.0 * hx)
        entities.append(SceneEntity(
            timestamp=stamp, frame_id=WORLD_FRAME, id=name,
            cubes=[CubePrimitive(pose=pose, size=Vector3(x=2 * hx, y=2 * hy, z=2 * hz),
                                 color=Color(r=r, g=g, b=b, a=a))],
            arrows=[ArrowPrimitive(pose=pose, shaft_length=0.7 * length_m, shaft_diameter=0.08 * length_m,
                                   head_length=0.3 * length_m, head_diameter=0.2 * length_m, color=white)],
            texts=[TextPrimitive(pose=Pose(position=Vector3(x=p[0], y=p[1], z=p[2] + hz + 1.0)), billboard=True,
                                 font_size=14.0, scale_invariant=True, color=white, text=name)]))
    return SceneUpdate(entities=entities).encode()


def _number(x: float) -> float | None:
    """JSON has no NaN or infinity: those become null."""
    return x if math.isfinite(x) else None


def _enum_name(enum: Any, value: int) -> str:
    try:
        return enum(value).name
    except ValueError:
        return str(value)


def vehicle_state(snap: Snapshot, row: int) -> dict[str, Any]:
    """The ``/<v>/state`` JSON object of the vehicle in row ``row`` (see :data:`VEHICLE_STATE_SCHEMA`)."""
    from ..systems.flight_state import FlightMode, LandedState, MissionState, NavState

    a = snap.arrays
    x, y, z = a["pos_enu_m"][row].tolist()
    vx, vy, vz = a["vel_enu_m_s"][row].tolist()
    qx, qy, qz, qw = a["quat_enu_flu_xyzw"][row].tolist()
    kind = snap.kinds[row]
    state: dict[str, Any] = {
        "vehicle": snap.vehicles[row], "kind": kind, "sim_time_s": snap.sim_time_s,
        "position_enu_m": {"x": _number(x), "y": _number(y), "z": _number(z)}, "altitude_m": _number(z),
        "speed_m_s": _number(math.sqrt(vx * vx + vy * vy + vz * vz)),
        "horizontal_speed_m_s": _number(math.hypot(vx, vy)),
        "vertical_speed_m_s": _number(vz),
        "heading_deg": _number(math.degrees(math.atan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz)))),
        "armed": bool(a["armed"][row]),
    }
    if kind == "quadrotor":
        for key in ("soc_frac", "power_w", "pack_voltage_v", "pack_current_a", "energy_used_j", "remaining_time_s",
                    "payload_kg"):
            state[key] = _number(float(a[key][row]))
        state["low_battery"] = bool(a["low_battery"][row])
        state["flight_mode"] = _enum_name(FlightMode, int(a["flight_mode"][row]))
        state["nav_state"] = _enum_name(NavState, int(a["nav_state"][row]))
        state["landed_state"] = _enum_name(LandedState, int(a["landed_state"][row]))
        state["mission_state"] = _enum_name(MissionState, int(a["mission_state"][row]))
        state["mission_step"] = int(a["mission_step"][row])
    return state


# -- the server ----------------------------------------------------------------------------------------
class FoxgloveListener(ServerListener):
    """The server's callbacks (called on the server's threads): note who subscribes to what, and ask the
    publishing thread to send the latched messages of the channel again. Never raises. (The other
    callbacks are the SDK's do-nothing defaults: no capability that would call them is offered.)"""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._requests: list[str] = []
        self.clients: set[int] = set()          # ids of the clients that subscribed to something
        self.subscriptions = 0
        self.unsubscriptions = 0

    def on_subscribe(self, client: Any, channel: Any) -> None:
        try:
            with self._lock:
                self.clients.add(int(client.id))
                self.subscriptions += 1
                self._requests.append(str(channel.topic))
        except Exception:       # a callback must not fail the server's task
            pass

    def on_unsubscribe(self, client: Any, channel: Any) -> None:
        with self._lock:
            self.unsubscriptions += 1

    def take_requests(self) -> list[str]:
        """The topics subscribed to since the last call (publishing thread)."""
        with self._lock:
            requests, self._requests = self._requests, []
        return requests


class FoxgloveBridge:
    """The publishing side of a ROS 2 bridge that logs to a Foxglove WebSocket server instead of DDS.

    ``publish(topic, msg)`` takes rosbags messages (one CDR channel with a ``ros2msg`` schema per
    topic, made on its first message); :meth:`log` logs already encoded messages on the channels
    made by :meth:`add_channel`. ``time_ns`` is the log time of the next messages (sim time).
    Everything but the constructor and :meth:`close` runs on the transport's publishing thread.
    """

    def __init__(self, port: int, listener: FoxgloveListener) -> None:
        self.context = foxglove.Context()        # this simulation's own: channels and server
        try:
            self.server = foxglove.start_server(name=SERVER_NAME, host=HOST, port=port, capabilities=[],
                                                server_listener=listener, context=self.context,
                                                message_backlog_size=CLIENT_BACKLOG)
        except Exception as exc:                 # the SDK raises RuntimeError("... Address already in use ...")
            raise TransportError(f"foxglove: cannot serve the WebSocket protocol on {HOST}:{port}: {exc}") from exc
        self.port = int(self.server.port)
        self.time_ns = 0
        self._channels: dict[str, Any] = {}
        self._latched: dict[str, deque[bytes]] = {}      # topic -> its kept messages, oldest first
        self.logged = 0                          # messages handed to the server (some subscriber wanted them)
        self.skipped = 0                         # messages not serialised: nobody subscribed
        self.resent = 0                          # kept messages logged again for a new subscriber

    @property
    def url(self) -> str:
        return f"ws://{HOST}:{self.port}"

    @property
    def topics(self) -> list[str]:
        return list(self._channels)

    def add_channel(self, topic: str, schema: Any, encoding: str, keep: int = 0) -> Any:
        """Advertise ``topic`` (``schema``: a ``foxglove.Schema`` or a JSON schema dict); ``keep`` > 0
        keeps its last ``keep`` messages for late subscribers."""
        channel = self._channels[topic] = foxglove.Channel(topic, schema=schema, message_encoding=encoding,
                                                           context=self.context)
        if keep:
            self._latched[topic] = deque(maxlen=keep)
        return channel

    def wants(self, topic: str) -> bool:
        """Whether a message of ``topic`` is worth building: someone is subscribed, the topic is latched,
        or it has no channel yet (its first message says its type)."""
        channel = self._channels.get(topic)
        return channel is None or topic in self._latched or channel.has_sinks()

    def subscribed(self, topic: str) -> bool:
        channel = self._channels.get(topic)
        return channel is not None and channel.has_sinks()

    def subscribed_topics(self) -> set[str]:
        """The topics someone is subscribed to now (any thread)."""
        return {topic for topic, channel in list(self._channels.items()) if channel.has_sinks()}

    def latched_topics(self) -> frozenset[str]:
        """The topics whose messages are kept for late subscribers (any thread)."""
        return frozenset(list(self._latched))

    def publish(self, topic: str, msg: Any) -> None:
        """Log a ROS 2 message (rosbags) on ``topic`` as CDR, if anyone is subscribed or it is latched."""
        from ..sensors.messages import serialize
        from .ros2.dds_backend import latched_depth

        if topic not in self._channels:            # latched as the ROS 2 node's TransientLocal topics are
            self.add_channel(topic, ros2msg_schema(msg.__msgtype__), "cdr", keep=latched_depth(topic) or 0)
        if not self.wants(topic):
            self.skipped += 1
            return
        self.log(topic, serialize(msg))

    def log(self, topic: str, data: bytes) -> None:
        """Log encoded ``data`` on ``topic`` at ``time_ns`` (kept first if the topic is latched)."""
        kept = self._latched.get(topic)
        if kept is not None:
            kept.append(data)
        channel = self._channels[topic]
        if channel.has_sinks():
            channel.log(data, log_time=self.time_ns)
            self.logged += 1
        elif kept is None:
            self.skipped += 1

    def has_kept(self, topic: str) -> bool:
        return bool(self._latched.get(topic))

    def resend(self, topic: str) -> None:
        """Log the kept messages of ``topic`` again, stamped now (a client has just subscribed)."""
        channel = self._channels.get(topic)
        for data in list(self._latched.get(topic, ())):
            channel.log(data, log_time=self.time_ns)
            self.resent += 1

    def close(self) -> None:
        """Stop the server (its clients are disconnected) and close the channels."""
        server, self.server = self.server, None
        if server is not None:
            server.stop()
        for channel in self._channels.values():
            channel.close()
        self._channels.clear()
        self._latched.clear()


class FoxgloveTransport(Ros2Transport):
    """The ROS 2 transport's publishing, plus the scene, vehicles and states, into a Foxglove server."""

    name = "foxglove"

    def __init__(self, world: Any, port: int) -> None:
        super().__init__(world, "foxglove", queue_depth=QUEUE_DEPTH)
        self.requested_port = port
        self.port: int | None = None                 # the port served once started (the OS's choice for 0)
        self.url: str | None = None                  # ws://127.0.0.1:<port>
        self._layout = world.layout
        self._looks = {e.name: (tuple(float(v) for v in e.params.get("body_half_extents_m", DEFAULT_HALF_EXTENTS_M)),
                                tuple(float(v) for v in e.params.get("rgba", DEFAULT_RGBA)))
                       for e in world.entities if e.kind != "package"}
        self._listener = FoxgloveListener()
        self._not_built = 0                          # samples whose message was not even built: nobody subscribed
        self._stats: FoxgloveBridge | None = None   # the bridge, kept for the counters after stop()
        self._readers: StalledReaders | None = None  # the clients' receive queues (publishing thread)
        self._readers_next_s = 0.0
        self._all_stalled = False
        self.stalls = 0                              # times every connected client was found to have stopped reading
        # set by the worker process (worker_main.WantsReporter): called when what wanted() says may have changed
        self.on_wants_changed: Any = None

    # -- life cycle --------------------------------------------------------------------------------
    def _open_bridge(self) -> FoxgloveBridge:
        bridge = FoxgloveBridge(self.requested_port, self._listener)
        try:
            bridge.add_channel(SCENE_TOPIC, SceneUpdate.get_schema(), "protobuf", keep=1)
            bridge.add_channel(VEHICLES_TOPIC, SceneUpdate.get_schema(), "protobuf")
            for name in self._looks:
                bridge.add_channel(_state_topic(name), VEHICLE_STATE_SCHEMA, "json")
        except Exception:
            bridge.close()
            raise
        self.port, self.url = bridge.port, bridge.url
        self._stats = bridge
        self._readers = StalledReaders(bridge.port)
        return bridge

    def wanted(self) -> Wants:
        """What of the snapshots this server needs now (it runs in a worker process, :mod:`.worker`): the
        subscribed topics and the latched ones, every snapshot while ``/clock`` is subscribed, the arrays
        while ``/vehicles`` or a state is. When every connected client has stopped reading (:mod:`.tcp_readers`)
        only the latched topics: a stalled client costs the simulation nothing until it reads again."""
        bridge = self.bridge
        if bridge is None:
            return Wants()
        latched = bridge.latched_topics()
        if self._all_stalled:
            return Wants(latched)
        subscribed = bridge.subscribed_topics()
        arrays = VEHICLES_TOPIC in subscribed or any(_state_topic(name) in subscribed for name in self._looks)
        return Wants(latched | subscribed, "/clock" in subscribed, arrays)

    # -- publishing thread -------------------------------------------------------------------------
    def _wants(self, topic: str) -> bool:
        if self.bridge.wants(topic):
            return True
        self._not_built += 1
        return False

    def _publish_snapshot(self, snap: Snapshot) -> None:
        self.bridge.time_ns = int(round(snap.sim_time_s * 1e9))
        super()._publish_snapshot(snap)
        if not snap.arrays:                          # the worker's snapshots carry them only when wanted
            return
        t, dt = snap.sim_time_s, snap.dt_s
        if ticks_in_step(t, dt, VEHICLES_HZ) and self.bridge.subscribed(VEHICLES_TOPIC):
            self._guarded(VEHICLES_TOPIC, lambda: vehicles_update(snap, self.bridge.time_ns, self._looks))
        if ticks_in_step(t, dt, STATE_HZ):
            for row, name in enumerate(snap.vehicles):
                topic = _state_topic(name)
                if self.bridge.subscribed(topic):
                    self._guarded(topic, lambda row=row: json.dumps(vehicle_state(snap, row), allow_nan=False).encode())

    def _idle(self) -> None:
        """Send the latched messages of the channels just subscribed to (the scene is built on the first),
        look whether the clients still read, say what is wanted now, then, if no snapshot is waiting,
        wait BATCH_WAIT_S for the next ones to gather."""
        self._watch_readers()
        for topic in _unique(self._listener.take_requests()):
            if self.bridge is None:
                return
            if topic == SCENE_TOPIC and not self.bridge.has_kept(SCENE_TOPIC):
                self._guarded(SCENE_TOPIC, lambda: scene_update(self._layout))     # kept, and logged
                continue
            try:
                self.bridge.resend(topic)
            except Exception as exc:
                self._publish_failed(topic, exc)
        if self.on_wants_changed is not None:
            self.on_wants_changed()
        if not len(self._queue):
            self._stop.wait(BATCH_WAIT_S)

    def _watch_readers(self) -> None:
        """Every READERS_EVERY_S: whether every connected client has stopped reading."""
        now_s = time.monotonic()
        if self._readers is None or now_s < self._readers_next_s:
            return
        self._readers_next_s = now_s + READERS_EVERY_S
        self._readers.sample(now_s)
        stalled = self._readers.all_stalled
        if stalled and not self._all_stalled:
            self.stalls += 1
        self._all_stalled = stalled

    def _guarded(self, topic: str, encode: Any) -> None:
        """Log what ``encode()`` returns on ``topic``; a failure is counted, never raised."""
        try:
            self.bridge.log(topic, encode())
            self.published += 1
        except Exception as exc:
            self._publish_failed(topic, exc)

    # -- figures -----------------------------------------------------------------------------------
    def counters(self) -> dict[str, Any]:
        counters = super().counters()
        for key in ("backend", "commands_submitted", "samples_rejected"):      # no commands come this way
            counters.pop(key, None)
        bridge, listener = self._stats, self._listener
        counters.update({
            "url": self.url,
            "messages_logged": bridge.logged if bridge else 0,
            "messages_resent": bridge.resent if bridge else 0,
            "messages_not_serialised": (bridge.skipped if bridge else 0) + self._not_built,
            "clients_seen": len(listener.clients),
            "clients_connected": self._readers.connected if self._readers else None,
            "clients_stalled": self._readers.stalled if self._readers else None,
            "stalls": self.stalls,
            "subscriptions": listener.subscriptions,
            "unsubscriptions": listener.unsubscriptions,
        })
        return counters


def _state_topic(vehicle: str) -> str:
    return f"/{vehicle}/state"


def _unique(items: Iterable[str]) -> list[str]:
    return list(dict.fromkeys(items))


def create_foxglove_transport(world: Any, options: TransportOptions) -> ProcessTransport | None:
    """The ``foxglove`` transport plugin's ``create``: a server when ``options.foxglove`` is a port, run in a
    worker process (:mod:`.worker`) as a selective transport. Building and serialising every subscribed
    message in the simulation's process cost the delivery scenario about a tenth of its real-time factor
    (2 cores, a client subscribed to everything); there the loop pays only for pickling the unbuilt
    samples of the subscribed topics, and nothing of the topics nobody subscribes to."""
    port = getattr(options, "foxglove", None)
    if port is None:
        return None
    return ProcessTransport("foxglove", f"{__name__}:foxglove_in_this_process", world, options, arrays=STATE_ARRAYS,
                            queue_depth=QUEUE_DEPTH, keep=latched_depth, arrays_hz=VEHICLES_HZ)


def foxglove_in_this_process(world: Any, options: TransportOptions) -> FoxgloveTransport:
    """The server itself (what the worker process runs)."""
    return FoxgloveTransport(world, int(options.foxglove))


__all__ = ["CLIENT_BACKLOG", "FoxgloveBridge", "FoxgloveListener", "FoxgloveTransport", "SCENE_TOPIC", "STATE_ARRAYS",
           "VEHICLES_TOPIC", "VEHICLE_STATE_SCHEMA", "create_foxglove_transport", "foxglove_in_this_process",
           "ros2msg_schema", "scene_update", "vehicle_state", "vehicles_update"]
