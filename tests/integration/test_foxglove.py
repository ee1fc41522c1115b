"""The Foxglove live server: a real foxglove-sdk server and a small client of the Foxglove WebSocket protocol.

The client (:class:`FoxgloveClient`, ``websockets``' sync client, loopback only) reads the server's
``serverInfo`` and ``advertise`` messages, subscribes by topic and collects the binary MessageData
frames (opcode 0x01: u32 subscription id, u64 log time [ns], payload) on a thread of its own while
the test thread steps the simulation. Payloads are decoded as a Foxglove client would: CDR with the
advertised ROS 2 type (rosbags' Jazzy typestore), protobuf with the advertised FileDescriptorSet,
JSON. Every check is on content (ranges, sizes, stamps, counts), never on wall time: waits have
generous timeouts only.

The server speaks subprotocol ``foxglove.sdk.v1`` (foxglove-sdk's name for the Foxglove WebSocket
protocol v1); it refuses the old name ``foxglove.websocket.v1``.
"""

from __future__ import annotations

import base64
import contextlib
import json
import socket
import struct
import threading
import time
from collections.abc import Callable, Iterable
from typing import Any

import numpy as np
import pytest
from websockets.exceptions import InvalidStatus
from websockets.sync import client as websockets_sync

from unetyemu_ecs import Simulation, load_world
from unetyemu_ecs.cli import main as cli_main
from unetyemu_ecs.scene.mesh import triangulate
from unetyemu_ecs.sensors.messages import typestore
from unetyemu_ecs.transport.api import TransportError

from ..conftest import WORLDS

SUBPROTOCOL = "foxglove.sdk.v1"
MESSAGE_DATA = 0x01                 # server -> client binary opcode
LIDAR, IMAGE, DEPTH = "/drone1/lidar/points", "/drone3/camera/image_raw", "/drone2/depth/image_raw"
WAIT_S = 60.0                       # generous: only ever waited out when something is broken


class FoxgloveClient:
    """A minimal Foxglove WebSocket protocol client that reads on its own thread.

    ``want``: topics to subscribe to as soon as they are advertised (``"*"``: all). Collected:
    ``channels`` (topic -> advertised channel), ``messages`` (topic -> [(log time ns, payload)]),
    ``statuses`` (the server's status messages), ``server_info``.
    """

    def __init__(self, url: str, want: Iterable[str] = (), max_queue: int = 64,
                 rcvbuf_bytes: int | None = None) -> None:
        sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        if rcvbuf_bytes is not None:          # before connecting: a fixed receive window, no autotuning
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, rcvbuf_bytes)
        host, port = url.removeprefix("ws://").split(":")
        sock.connect((host, int(port)))
        self._stack = contextlib.ExitStack()
        self.ws = self._stack.enter_context(websockets_sync.connect(
            url, sock=sock, subprotocols=[SUBPROTOCOL], max_size=None, open_timeout=WAIT_S, max_queue=max_queue))
        self.paused = threading.Event()       # set: the client stops reading (a stalled client)
        self.server_info: dict[str, Any] | None = None
        self.channels: dict[str, dict[str, Any]] = {}
        self.messages: dict[str, list[tuple[int, bytes]]] = {}
        self.statuses: list[dict[str, Any]] = []
        self._want = set(want)
        self._subscribed: dict[int, str] = {}          # subscription id -> topic
        self._next_id = 1
        self._cond = threading.Condition()
        self._send_lock = threading.Lock()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._read, name="foxglove-test-client", daemon=True)
        self._thread.start()

    # -- protocol ------------------------------------------------------------------------------------
    def _read(self) -> None:
        while not self._stop.is_set():
            if self.paused.is_set():
                time.sleep(0.05)
                continue
            try:
                frame = self.ws.recv(timeout=0.1)
            except TimeoutError:
                continue
            except Exception:               # closed
                return
            with self._cond:
                if isinstance(frame, str):
                    self._on_text(json.loads(frame))
                elif frame[0] == MESSAGE_DATA:
                    sub_id, log_time_ns = struct.unpack_from("<IQ", frame, 1)
                    self.messages.setdefault(self._subscribed[sub_id], []).append((log_time_ns, bytes(frame[13:])))
                self._cond.notify_all()

    def _on_text(self, msg: dict[str, Any]) -> None:
        if msg["op"] == "serverInfo":
            self.server_info = msg
        elif msg["op"] == "advertise":
            for channel in msg["channels"]:
                self.channels[channel["topic"]] = channel
            self._subscribe_wanted()
        elif msg["op"] == "status":
            self.statuses.append(msg)

    def _subscribe_wanted(self) -> None:
        taken = set(self._subscribed.values())
        todo = [t for t in self.channels if ("*" in self._want or t in self._want) and t not in taken]
        subs = []
        for topic in todo:
            self._subscribed[self._next_id] = topic
            subs.append({"id": self._next_id, "channelId": self.channels[topic]["id"]})
            self._next_id += 1
        if subs:
            self.send({"op": "subscribe", "subscriptions": subs})

    def subscribe(self, *topics: str) -> None:
        with self._cond:
            self._want.update(topics)
            self._subscribe_wanted()

    def send(self, msg: dict[str, Any] | str | bytes) -> None:
        with self._send_lock:
            self.ws.send(json.dumps(msg) if isinstance(msg, dict) else msg)

    # -- waiting and reading --------------------------------------------------------------------------
    def wait_for(self, condition: Callable[[], bool], what: str, timeout_s: float = WAIT_S) -> None:
        with self._cond:
            if not self._cond.wait_for(condition, timeout_s):
                raise AssertionError(f"waited {timeout_s} s for {what}; statuses {self.statuses[-3:]}, "
                                     f"topics {sorted(self.messages)}")

    def wait_messages(self, topic: str, n: int = 1) -> list[tuple[int, bytes]]:
        self.wait_for(lambda: len(self.messages.get(topic, ())) >= n, f"{n} message(s) on {topic}")
        with self._cond:
            return list(self.messages[topic])

    def decoded(self, topic: str) -> list[tuple[int, Any]]:
        """The messages received on a CDR topic, deserialised with the advertised ROS 2 type."""
        msgtype = self.channels[topic]["schemaName"]
        with self._cond:
            items = list(self.messages.get(topic, ()))
        return [(t, typestore().deserialize_cdr(payload, msgtype)) for t, payload in items]

    def protobuf(self, topic: str, payload: bytes) -> Any:
        """``payload`` decoded with the channel's advertised protobuf FileDescriptorSet."""
        from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

        channel = self.channels[topic]
        assert channel["encoding"] == "protobuf" and channel["schemaEncoding"] == "protobuf"
        files = descriptor_pb2.FileDescriptorSet.FromString(base64.b64decode(channel["schema"])).file
        pool, added = descriptor_pool.DescriptorPool(), set()
        while len(added) < len(files):                 # in dependency order
            for f in files:
                if f.name not in added and all(d in added for d in f.dependency):
                    pool.Add(f)
                    added.add(f.name)
        return message_factory.GetMessageClass(pool.FindMessageTypeByName(channel["schemaName"])).FromString(payload)

    def close(self) -> None:
        self._stop.set()
        self._stack.close()
        self._thread.join(5.0)

    def __enter__(self) -> FoxgloveClient:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()


def server_subscriptions(sim: Simulation) -> int:
    """How many subscriptions the server has taken so far (its counters, current after a flush)."""
    assert sim.flush_transports(WAIT_S)
    return sim.transport_counters()["foxglove"]["subscriptions"]


def wait_taken(sim: Simulation, before: int, *clients: FoxgloveClient) -> None:
    """Wait until the server has taken the subscriptions ``clients`` sent since it had ``before``
    (the protocol does not acknowledge a subscription)."""
    expected = before + sum(len(c._subscribed) for c in clients)
    deadline = time.monotonic() + WAIT_S
    while server_subscriptions(sim) < expected:
        assert time.monotonic() < deadline, f"the server never took {expected - before} subscription(s)"
        time.sleep(0.02)


def sync(sim: Simulation, *clients: FoxgloveClient) -> None:
    """Take one more step and wait until every client (subscribed to ``/clock``) has its ``/clock``: the
    server sends a client's messages in the order they were logged, so all logged before have arrived."""
    sim.step()
    assert sim.flush_transports(WAIT_S)
    now_ns = round(sim.sim_time_s * 1e9)
    for client in clients:
        client.wait_for(lambda c=client: c.messages.get("/clock") and c.messages["/clock"][-1][0] >= now_ns,
                        "the /clock of the step after the run")


def run_flushed(sim: Simulation, duration_s: float, chunk_s: float = 0.1) -> None:
    """Run ``duration_s`` of sim time in chunks, letting the transports catch up after each: their
    queues never overflow, so what is checked does not depend on how fast this machine is."""
    for _ in range(round(duration_s / chunk_s)):
        sim.run(duration=chunk_s)
        assert sim.flush_transports(WAIT_S)


@pytest.fixture(scope="module")
def served():
    """The delivery scenario with a Foxglove server on a free port; 0.3 s run before anyone connects."""
    sim = Simulation(load_world(WORLDS / "urban_delivery.yaml"), foxglove=0)
    try:
        run_flushed(sim, 0.3)
        before_clients = dict(sim.transport_counters()["foxglove"])
        yield sim, sim.transports["foxglove"], before_clients
    finally:
        sim.close()


def test_the_server_is_on_loopback_says_who_it_is_and_takes_no_client_data(served):
    sim, fox, _ = served
    assert fox.url == f"ws://127.0.0.1:{fox.port}" and fox.port > 0
    with FoxgloveClient(fox.url) as client:
        client.wait_for(lambda: client.server_info is not None and LIDAR in client.channels, "serverInfo and advertise")
        assert client.server_info["capabilities"] == []          # no clientPublish, services, parameters
        scene, state, lidar = client.channels["/scene"], client.channels["/drone1/state"], client.channels[LIDAR]
        assert (scene["encoding"], scene["schemaName"]) == ("protobuf", "foxglove.SceneUpdate")
        assert state["encoding"] == "json" and state["schemaEncoding"] == "jsonschema"
        assert json.loads(state["schema"])["properties"]["soc_frac"]
        assert (lidar["encoding"], lidar["schemaEncoding"], lidar["schemaName"]) == (
            "cdr", "ros2msg", "sensor_msgs/msg/PointCloud2")
        assert lidar["schema"].startswith("std_msgs/Header header") and "MSG: sensor_msgs/PointField" in lidar["schema"]
        for topic in ("/clock", "/tf", "/tf_static", "/drone1/imu/data", "/drone1/battery", IMAGE, DEPTH,
                      "/drone1/mission/status", "/vehicles", "/truck1/state"):
            assert topic in client.channels, sorted(client.channels)
    with pytest.raises(InvalidStatus, match="400"):              # the old name of the subprotocol is refused
        websockets_sync.connect(fox.url, subprotocols=["foxglove.websocket.v1"], open_timeout=WAIT_S)


def test_nothing_is_serialised_before_anyone_subscribes(served):
    _, _, before = served
    assert before["messages_logged"] == 0 and before["clients_seen"] == 0
    assert before["messages_not_serialised"] > 0 and before["snapshots_offered"] == 73    # the world, 72 steps
    # the server runs in a process of its own; of the samples only each topic's first (which advertises
    # it) and the latched ones left the simulation's process, and no step that had nothing else
    assert before["worker"]["samples_held_back"] > 100 and before["worker"]["snapshots_held_back"] > 30


def test_lidar_and_camera_frames_arrive_as_cdr_with_physical_content(served):
    sim, fox, _ = served
    topics = (LIDAR, IMAGE, DEPTH, "/drone3/camera/camera_info", "/clock")
    before = server_subscriptions(sim)
    with FoxgloveClient(fox.url, want=topics) as client:
        client.wait_for(lambda: len(client._subscribed) == len(topics), "the subscriptions to be sent")
        wait_taken(sim, before, client)
        start_ns = round(sim.sim_time_s * 1e9)
        run_flushed(sim, 1.0)                                   # LiDAR and cameras at 10 Hz
        end_ns = round(sim.sim_time_s * 1e9)
        sync(sim, client)
        clouds, images, depths, info = ([(t, m) for t, m in client.decoded(topic) if t <= end_ns]
                                        for topic in topics[:4])
    for items in (clouds, images, depths):
        assert len(items) == 10 and start_ns < items[0][0]      # 10 Hz for 1 s, none from before
        stamps = [t for t, _ in items]
        assert stamps == sorted(stamps) and len(set(stamps)) == len(stamps)
        for t, msg in items:                                     # log time = header stamp = sim time
            assert msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec == t
    for _, cloud in clouds:
        assert cloud.header.frame_id.startswith("drone1/")
        assert cloud.width * cloud.height * cloud.point_step == len(cloud.data)
        assert cloud.row_step == cloud.width * cloud.point_step
        offsets = {f.name: f.offset for f in cloud.fields}
        raw = np.asarray(cloud.data, dtype=np.uint8).reshape(-1, cloud.point_step)
        xyz = np.stack([raw[:, offsets[a]:offsets[a] + 4].copy().view("<f4")[:, 0] for a in "xyz"], axis=1)
        ranges_m = np.linalg.norm(xyz, axis=1)
        assert cloud.width > 100                                 # on its pad: the ground and the city around
        assert np.all(np.isfinite(ranges_m)) and ranges_m.min() > 0.05 and ranges_m.max() <= 30.0 + 1e-3
    for _, img in images:
        assert (img.width, img.height, img.encoding) == (320, 240, "rgb8")
        assert img.width * img.height * 3 == len(img.data) == img.step * img.height
        pixels = np.asarray(img.data, dtype=np.uint8).reshape(img.height, img.width, 3)
        assert len(np.unique(pixels.reshape(-1, 3), axis=0)) > 3         # sky, ground, city: not blank
    for _, depth in depths:
        assert depth.encoding == "32FC1" and depth.width * depth.height * 4 == len(depth.data)
        metres = np.frombuffer(np.asarray(depth.data, dtype=np.uint8).tobytes(), dtype="<f4")
        hits = metres[np.isfinite(metres)]
        assert hits.size and hits.min() > 0.0
    assert info and (info[-1][1].width, info[-1][1].height) == (320, 240)


def test_a_late_subscriber_gets_the_city_the_static_tree_and_the_mission_status(served):
    sim, fox, _ = served
    assert sim.sim_time_s > 0.2                                  # all three were published long ago
    with FoxgloveClient(fox.url, want=("/scene", "/tf_static", "/drone1/mission/status")) as client:
        scene = client.protobuf("/scene", client.wait_messages("/scene")[0][1])
        client.wait_messages("/tf_static")
        tf_static = client.decoded("/tf_static")[0][1]
        status = client.wait_messages("/drone1/mission/status")
    (city,) = scene.entities
    assert (city.id, city.frame_id) == ("city", "map")                  # the root of /tf
    mesh = triangulate(sim.definition.layout)
    assert sum(len(t.indices) for t in city.triangles) == 3 * len(mesh.triangles)
    assert len(city.triangles) == len(np.unique(mesh.cls))               # one list per scene class
    assert sum(len(t.points) for t in city.triangles) == len(np.unique(mesh.triangles))
    for tri in city.triangles:
        assert max(tri.indices) < len(tri.points) and tri.color.a == 1.0
    frames = {(tf.header.frame_id, tf.child_frame_id) for tf in tf_static.transforms}
    assert ("map", "drone1/odom") in frames and ("map", "truck1/odom") in frames
    text = typestore().deserialize_cdr(status[-1][1], "std_msgs/msg/String").data
    assert json.loads(text)["mission"] == "rooftop_delivery"


def test_vehicles_and_plots_ready_states_follow_the_simulation(served):
    sim, fox, _ = served
    sim.step(-sim.step_count % 24)                              # to a multiple of 0.1 s: the states' period
    topics = ("/vehicles", "/drone1/state", "/truck1/state", "/clock")
    before, seen = server_subscriptions(sim), fox.counters()["clients_seen"]
    with FoxgloveClient(fox.url, want=topics) as client:
        client.wait_for(lambda: len(client._subscribed) == len(topics), "the subscriptions to be sent")
        wait_taken(sim, before, client)
        run_flushed(sim, 0.5)                                   # /vehicles at 20 Hz, states at 10 Hz
        end_s, end_ns, truck_pos_m = sim.sim_time_s, round(sim.sim_time_s * 1e9), sim.position_enu_m("truck1")
        sync(sim, client)
        vehicles, drone, truck = ([p for t, p in client.messages[topic] if t <= end_ns] for topic in topics[:3])
    update = client.protobuf("/vehicles", vehicles[-1])
    drone, truck = [json.loads(p) for p in drone], [json.loads(p) for p in truck]
    assert len(vehicles) == 10 and len(drone) == len(truck) == 5        # 0.5 s at 20 Hz and 10 Hz
    names = [e.id for e in update.entities]
    assert names == ["drone1", "drone2", "drone3", "car1", "car2", "car3", "truck1"]
    truck_entity = update.entities[names.index("truck1")]
    assert truck_entity.frame_id == "map" and len(truck_entity.cubes) == 1
    assert truck_entity.cubes[0].size.x == pytest.approx(6.4)          # the truck preset: 3.2 m half length
    times = [s["sim_time_s"] for s in drone]
    assert times == sorted(times) and np.allclose(np.diff(times), 0.1, atol=1e-6)
    last = drone[-1]
    assert last["kind"] == "quadrotor" and 0.0 < last["soc_frac"] <= 1.0 and last["pack_voltage_v"] > 10.0
    assert last["power_w"] > 0.0 and last["mission_state"] == "RUNNING" and last["mission_step"] >= 0
    assert last["flight_mode"] in ("DISARMED", "AUTO") and isinstance(last["nav_state"], str)
    assert truck[-1]["kind"] == "car" and "soc_frac" not in truck[-1] and truck[-1]["horizontal_speed_m_s"] > 1.0
    assert truck[-1]["sim_time_s"] == pytest.approx(end_s)               # the run ends on a multiple of 0.1 s
    assert [truck[-1]["position_enu_m"][k] for k in "xyz"] == pytest.approx(truck_pos_m.tolist())
    assert server_subscriptions(sim) and fox.counters()["clients_seen"] == seen + 1


def test_a_stalled_client_costs_the_simulation_nothing_and_gets_only_the_newest_messages(served):
    sim, fox, _ = served
    # subscribed to everything (cameras: ~5 MB/s), then it stops reading: its socket's buffers fill
    # (a 64 KiB receive window; websockets pauses reading at one queued frame), then its queue in the server
    before = server_subscriptions(sim)
    with FoxgloveClient(fox.url, want=("*",), max_queue=1, rcvbuf_bytes=65536) as stalled, \
            FoxgloveClient(fox.url, want=("/clock",)) as live:
        stalled.wait_for(lambda: {IMAGE, DEPTH, LIDAR, "/clock"} <= set(stalled._subscribed.values()),
                         "the stalled client's subscriptions")
        live.wait_for(lambda: "/clock" in live._subscribed.values(), "the live client's subscription")
        wait_taken(sim, before, stalled, live)
        stalled.paused.set()
        steps, start_ns = sim.step_count, round(sim.sim_time_s * 1e9)
        run_flushed(sim, 2.0)                                   # the publishing thread never waits for it
        assert sim.step_count == steps + 480
        end_ns = round(sim.sim_time_s * 1e9)
        for client in (live, stalled):                           # the stalled client reads again
            client.paused.clear()
            client.wait_for(lambda c=client: c.messages.get("/clock") and c.messages["/clock"][-1][0] == end_ns,
                            "the last /clock")
        window = {name: [t for t, _ in c.messages["/clock"] if t > start_ns] for name, c in (("live", live),
                                                                                           ("stalled", stalled))}
    assert window["live"] == sorted(window["live"]) and window["stalled"] == sorted(window["stalled"])
    # the server kept a bounded backlog for the stalled client and dropped its oldest messages
    assert len(window["stalled"]) < len(window["live"]), {k: len(v) for k, v in window.items()}
    counters = fox.counters()
    assert counters["publish_errors"] == 0 and counters["errors"] == {}


def test_a_lone_client_that_stops_reading_stops_what_the_simulation_sends_until_it_reads_again(served):
    sim, fox, _ = served
    before = server_subscriptions(sim)
    with FoxgloveClient(fox.url, want=("*",), max_queue=1, rcvbuf_bytes=65536) as client:
        client.wait_for(lambda: {IMAGE, DEPTH, LIDAR, "/clock"} <= set(client._subscribed.values()),
                        "the client's subscriptions")
        wait_taken(sim, before, client)
        client.paused.set()

        def run_until(connected: int, stalled: int, what: str) -> dict[str, Any]:
            deadline = time.monotonic() + WAIT_S
            while ((counters := sim.transport_counters()["foxglove"])["clients_connected"],
                   counters["clients_stalled"]) != (connected, stalled):
                assert time.monotonic() < deadline, f"the server never found {what}: {counters}"
                run_flushed(sim, 0.1)
            return counters

        # its 64 KiB window fills at the first camera frames; STALL_S later the server knows (the
        # connections of the clients before it may take a moment to close)
        stalled = run_until(1, 1, "the client stalled")
        assert stalled["stalls"] >= 1
        run_flushed(sim, 1.0)                                   # LiDAR, cameras, IMUs, odometry, /clock ...
        after = sim.transport_counters()["foxglove"]
        held_back = after["worker"]["samples_held_back"] - stalled["worker"]["samples_held_back"]
        assert held_back > 400                                  # none of them left the simulation's process
        assert after["messages_logged"] - stalled["messages_logged"] < 0.02 * held_back   # latched status only
        client.paused.clear()                                   # it reads again: everything flows again
        run_until(1, 0, "the client reading again")
        start_ns = round(sim.sim_time_s * 1e9)
        run_flushed(sim, 0.5)
        sync(sim, client)
        images = [t for t, _ in client.messages[IMAGE] if t > start_ns]
    assert len(images) >= 4                                     # 10 Hz for 0.5 s, from after it came back


def test_garbage_from_a_client_is_answered_and_survived(served):
    sim, fox, _ = served
    with FoxgloveClient(fox.url) as bad:
        bad.wait_for(lambda: "/clock" in bad.channels, "advertise")
        bad.send(b"\xff\x00\x01garbage")                                     # unknown binary opcode
        bad.send(b"\x01" + struct.pack("<I", 99) + b"\x00" * 64)             # MessageData on a channel never advertised
        bad.send("{not json")
        bad.send({"op": "subscribe", "subscriptions": [{"id": 1, "channelId": 987654}]})
        bad.send({"op": "unsubscribe", "subscriptionIds": [424242]})
        bad.send({"op": "advertise", "channels": [{"id": 1, "topic": "/drone1/cmd_vel", "encoding": "json",
                                                    "schemaName": "x"}]})   # client publish: not offered
        bad.send({"op": "subscribe", "subscriptions": "nonsense"})
        bad.send({"op": "getParameters", "parameterNames": ["world.seed"]})
        bad.wait_for(lambda: len(bad.statuses) >= 5, "status answers")
        before = server_subscriptions(sim)
        bad.subscribe("/clock")                                                # and it still works
        wait_taken(sim, before, bad)
        # /clock leaves with the worker's batches (every 20 ms of wall time), so how many a tenth of a simulated
        # second gives depends on this machine's speed: run until five have come
        deadline = time.monotonic() + WAIT_S
        while len(bad.messages.get("/clock", ())) < 5:
            assert time.monotonic() < deadline, f"no five /clock messages in {WAIT_S} s; statuses {bad.statuses[-3:]}"
            run_flushed(sim, 0.1)
            time.sleep(0.05)
    assert any("clientPublish" in s["message"] for s in bad.statuses)
    assert fox.counters()["publish_errors"] == 0


def test_a_second_server_on_the_same_port_is_a_clear_error_and_two_simulations_serve_two(served):
    _, fox, _ = served
    with pytest.raises(TransportError, match=rf"foxglove: .*127\.0\.0\.1:{fox.port}\b.*in use"):
        Simulation(load_world(WORLDS / "empty.yaml"), foxglove=fox.port)
    with Simulation(load_world(WORLDS / "empty.yaml"), foxglove=0) as other:       # a server of its own
        other_fox = other.transports["foxglove"]
        assert other_fox.url != fox.url
        other.run(duration=0.1)
        with FoxgloveClient(other_fox.url) as client:
            client.wait_for(lambda: "/clock" in client.channels, "the empty world's channels")
            assert not any(t.startswith("/drone") for t in client.channels)      # not the delivery world's
    other_fox.stop()                                                           # stopped already: nothing happens
    with Simulation(load_world(WORLDS / "empty.yaml"), foxglove=other_fox.port) as again:    # the port is free
        assert again.transports["foxglove"].url == other_fox.url


def test_counters_and_the_cli(tmp_path, capsys):
    out = tmp_path / "run"
    assert cli_main(["run", str(WORLDS / "empty.yaml"), "--duration", "0.2", "--out", str(out), "--quiet",
                     "--foxglove", "0"]) == 0
    assert "foxglove: ws://127.0.0.1:" in capsys.readouterr().err
    counters = json.loads((out / "summary.json").read_text())["transports"]["foxglove"]
    assert counters["url"].startswith("ws://127.0.0.1:") and counters["snapshots_dropped"] == 0
    for key in ("messages_logged", "messages_not_serialised", "clients_seen", "publish_errors", "errors"):
        assert key in counters
