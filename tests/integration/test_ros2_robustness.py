"""The dds backend against hostile and late ROS 2 peers: any sample survives, latched topics reach late
subscribers, parameter services answer, and the README's `ros2 topic pub` commands are accepted.

Peers are separate processes with only cyclonedds + rosbags (tests/ros2_peer/probe.py).
"""

from __future__ import annotations

import json
import re
import shlex
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml
from hypothesis import HealthCheck, Phase, given, settings
from hypothesis import strategies as st

from unetyemu_ecs import Simulation, load_world_text
from unetyemu_ecs.sensors.messages import deserialize, msg_type, serialize, typestore


PROBE = Path(__file__).resolve().parent.parent / "ros2_peer" / "probe.py"
ROOT = Path(__file__).resolve().parents[2]

WORLD = """
world: {name: robust, physics_hz: 240, seed: 31}
scene: {generator: none, ground_size_m: 200}
vehicles:
  - {name: d1, type: quadrotor, preset: medium, pose: {position_m: [0.0, 0.0, 0.3]}}
  - {name: d2, type: quadrotor, preset: medium, pose: {position_m: [3.0, 0.0, 0.3]}}
  - {name: c1, type: car, preset: medium, pose: {position_m: [-10.0, 0.0, 0.9]}}
"""
TOPIC_TYPES = {"mission": "std_msgs/msg/String", "target": "std_msgs/msg/Float32MultiArray",
               "teleop": "std_msgs/msg/Float32MultiArray", "cmd_vel": "geometry_msgs/msg/Twist"}


def _peer(*args: str) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, str(PROBE), *args], cwd=PROBE.parent,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _run_while(sim: Simulation, peer: subprocess.Popen, budget_s: float = 60.0) -> dict:
    """Run ``sim`` in real time while ``peer`` runs; return the peer's last JSON line."""
    while peer.poll() is None and sim.sim_time_s < budget_s:
        sim.run(duration=0.1, rate=1.0)
    out, err = peer.communicate(timeout=60)
    assert out.strip(), err
    return json.loads(out.strip().splitlines()[-1])


def _string_cdr(raw: bytes) -> bytes:
    """A std_msgs/String sample whose data are ``raw`` (not necessarily UTF-8)."""
    return b"\x00\x01\x00\x00" + (len(raw) + 1).to_bytes(4, "little") + raw + b"\x00"


# -- item 8: the command thread survives any sample -------------------------------------------------

@st.composite
def garbage(draw, topic_kind: str) -> bytes:
    """One sample for a command topic: random bytes, or the topic's type holding garbage."""
    if draw(st.booleans()):
        head = draw(st.sampled_from([b"", b"\x00\x01\x00\x00", b"\x00\x00\x00\x00"]))
        return head + draw(st.binary(max_size=2000))
    type_name = TOPIC_TYPES[topic_kind]
    if type_name == "std_msgs/msg/String":
        text = draw(st.one_of(
            st.text(max_size=300),
            st.recursive(st.none() | st.booleans() | st.floats() | st.integers() | st.text(max_size=20),
                         lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=8), inner,
                                                                                      max_size=4),
                         max_leaves=30).map(json.dumps),
            st.binary(min_size=1, max_size=200)))
        return _string_cdr(text if isinstance(text, bytes) else text.encode())
    if type_name == "std_msgs/msg/Float32MultiArray":
        values = draw(st.lists(st.floats(width=32), max_size=12))
        msg = msg_type(type_name)(layout=msg_type("std_msgs/msg/MultiArrayLayout")(dim=[], data_offset=0),
                                  data=np.array(values, dtype=np.float32))
        return serialize(msg)
    Vector3 = msg_type("geometry_msgs/msg/Vector3")
    v = draw(st.lists(st.floats(), min_size=6, max_size=6))
    return serialize(msg_type(type_name)(linear=Vector3(x=v[0], y=v[1], z=v[2]), angular=Vector3(x=v[3], y=v[4], z=v[5])))


FIXED_GARBAGE = {  # what the field report sent, and the extremes: always part of the run
    "mission": [_string_cdr(b"\xff\xfe{not utf-8}"), _string_cdr(b"[" * 100_000), _string_cdr(b"a" * 1_000_000),
                _string_cdr(b'{"steps": [' + b'{"type": "land"},' * 20_000 + b'{"type": "land"}]}')],
    "target": [b"\x00\x01\x00\x00\xff\xff\xff\x7f", b"\x00\x01\x00\x00" + b"\x00" * 8 + b"\xff" * 8],
    "teleop": [b"", b"\x00\x01"],
    "cmd_vel": [b"\x00\x01\x00\x00" + b"\x00" * 8],
}


@settings(max_examples=1, deadline=None, phases=[Phase.generate], suppress_health_check=list(HealthCheck))
@given(data=st.data())
def test_random_bytes_and_typed_garbage_on_every_command_topic_leave_the_commands_working(data, tmp_path_factory):
    # GIVEN a simulation with two drones and a car on ROS 2, and a peer that writes, to every command
    # topic of every vehicle, random bytes and well-typed garbage (NaN, inf, huge and negative
    # numbers, wrong lengths, strings that are not UTF-8, a 1 MB string, JSON nested 100000 deep)
    payloads = []
    for vehicle in ("d1", "d2", "c1"):
        for kind, type_name in TOPIC_TYPES.items():
            samples = FIXED_GARBAGE[kind] + data.draw(st.lists(garbage(kind), min_size=3, max_size=8))
            payloads += [[f"/{vehicle}/{kind}", type_name, s.hex()] for s in samples]
    # WHEN a valid target follows all of it
    target = msg_type("std_msgs/msg/Float32MultiArray")(layout=msg_type("std_msgs/msg/MultiArrayLayout")(
        dim=[], data_offset=0), data=np.array([6.0, 4.0, 5.0, 0.0, 3.0], dtype=np.float32))
    payloads.append(["/d1/target", "std_msgs/msg/Float32MultiArray", serialize(target).hex(), "pause"])
    path = tmp_path_factory.mktemp("fuzz") / "payloads.json"
    path.write_text(json.dumps(payloads))
    peer = _peer("write", "40", str(path))
    assert peer.stdout.readline().strip() == "ready"
    with Simulation(load_world_text(WORLD), ros2="dds") as sim:
        got = _run_while(sim, peer)
        for _ in range(200):                              # up to 20 s of sim time to get there
            if np.linalg.norm(sim.position_enu_m("d1") - [6.0, 4.0, 5.0]) < 0.5:
                break
            sim.run(duration=0.1)
        final = sim.position_enu_m("d1")
        events = [text for _, _, text in sim.events]
        alive = sim.transports["ros2"].bridge.listener._thread.is_alive()
    # THEN the command thread is alive, the drone flew to the target, and the garbage was reported
    assert got["written"] + got["refused"] == len(payloads) and got["refused"] <= len(payloads) // 4
    assert alive
    assert np.linalg.norm(final - [6.0, 4.0, 5.0]) < 0.5, (final, events[-5:])
    assert any("not a valid std_msgs/msg/String" in e and "utf-8" in e for e in events), events[:20]
    assert sum(e.startswith("rejected") for e in events) >= 3 * 4


# -- items 16, 17: /rosout and mission status reach a late TransientLocal subscriber -------------

@pytest.fixture(scope="module")
def late_join():
    """A peer sends one bad command; once it is rejected, a second peer joins (TransientLocal)."""
    bad = msg_type("std_msgs/msg/Float32MultiArray")(layout=msg_type("std_msgs/msg/MultiArrayLayout")(
        dim=[], data_offset=0), data=np.array([0.1, 0.2], dtype=np.float32))
    import tempfile
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "bad.json"
        path.write_text(json.dumps([["/d1/teleop", "std_msgs/msg/Float32MultiArray", serialize(bad).hex()]]))
        sender = _peer("write", "30", str(path))
        assert sender.stdout.readline().strip() == "ready"
        with Simulation(load_world_text(WORLD), ros2="dds") as sim:
            sim.load_mission("d2", json.dumps({"name": "up", "steps": [{"type": "takeoff", "altitude_m": 30.0}]}))
            _run_while(sim, sender)
            while not any(text.startswith("rejected") for _, _, text in sim.events) and sim.sim_time_s < 60:
                sim.run(duration=0.1, rate=1.0)
            late = _peer("late", "15", "/rosout=rcl_interfaces/msg/Log", "/d1/mission/status=std_msgs/msg/String",
                         "/d2/mission/status=std_msgs/msg/String")
            got = _run_while(sim, late, budget_s=sim.sim_time_s + 60)
            status = {v: sim.mission_status(v) for v in ("d1", "d2")}
            events = [text for _, _, text in sim.events]
    return got, status, events


def test_a_late_transient_local_subscriber_of_rosout_gets_the_earlier_rejection(late_join):
    got, _, events = late_join
    # GIVEN a command rejected before the subscriber existed  THEN /rosout (TransientLocal,
    # KeepLast(1000), as rcl writes it) hands it the warning on joining
    logs = [deserialize(bytes.fromhex(h), "rcl_interfaces/msg/Log") for h in got["/rosout"]]
    assert any("4 values" in e for e in events)
    assert any("d1: rejected /d1/teleop" in log.msg and "4 values" in log.msg and log.level == 30 for log in logs)


def test_a_late_subscriber_of_mission_status_gets_the_current_status(late_join):
    got, status, _ = late_join
    # GIVEN d1 without a mission and d2 flying one  THEN a late subscriber gets each drone's status
    # at once (latched: TransientLocal, depth 1), and only the latest one
    (d1,) = [json.loads(deserialize(bytes.fromhex(h), "std_msgs/msg/String").data) for h in got["/d1/mission/status"]]
    (d2,) = [json.loads(deserialize(bytes.fromhex(h), "std_msgs/msg/String").data) for h in got["/d2/mission/status"]]
    assert d1 == {"mission": None, "state": "idle"}
    assert d2["mission"] == "up" and d2["state"] in ("running", "completed")


# -- item 22: parameter services as an rmw_cyclonedds client calls them -----------------------------

def test_parameter_services_answer_an_rmw_cyclonedds_client_with_read_only_world_parameters():
    # GIVEN the simulation of world "robust" (seed 31) on ROS 2
    peer = _peer("params", "30")
    with Simulation(load_world_text(WORLD), ros2="dds") as sim:
        # WHEN a client calls list/get/describe/get_types/set with rmw_cyclonedds' request header
        got = _run_while(sim, peer)
    # THEN each service is "available" as rmw_cyclonedds judges it (request reader and reply writer
    # announce the same serviceid), and each reply came back under the request's header
    assert got["service_available"] == {s: True for s in ("list_parameters", "get_parameters", "describe_parameters",
                                                          "get_parameter_types", "set_parameters")}
    assert got["list_parameters"]["result"]["names"] == ["use_sim_time", "world.name", "world.seed"]
    assert got["list_parameters"]["result"]["prefixes"] == ["world"]
    values = got["get_parameters"]["values"]
    assert (values[0]["type"], values[0]["bool_value"]) == (1, True)
    assert (values[1]["type"], values[1]["string_value"]) == (4, "robust")
    assert (values[2]["type"], values[2]["integer_value"]) == (2, 31)
    assert values[3]["type"] == 0                                        # not declared: NOT_SET
    assert got["get_parameter_types"]["types"] == [1, 4, 2, 0]
    assert all(d["read_only"] for d in got["describe_parameters"]["descriptors"][:3])
    (result,) = got["set_parameters"]["results"]
    assert not result["successful"] and "read-only" in result["reason"]


# -- the README's ROS 2 commands ------------------------------------------------------------------

PUB_OPTIONS_WITH_VALUE = {"-r", "--rate", "-t", "--times", "-w", "--wait-matching-subscriptions", "-n",
                          "--node-name", "--qos-profile", "--qos-depth", "--qos-history", "--qos-reliability",
                          "--qos-durability", "--keep-alive", "--max-wait-time-secs"}


def readme_pub_commands() -> list[tuple[str, str, dict]]:
    """Every `ros2 topic pub` of README.md's ```sh blocks: (topic, type, YAML fields)."""
    text = (ROOT / "README.md").read_text()
    found = []
    for block in re.findall(r"```sh\n(.*?)```", text, flags=re.S):
        for line in block.splitlines():
            if not line.strip().startswith("ros2 topic pub"):
                continue
            words = shlex.split(line, comments=True)[3:]
            positional, i = [], 0
            while i < len(words):
                if words[i].startswith("-"):
                    i += 2 if words[i] in PUB_OPTIONS_WITH_VALUE else 1
                else:
                    positional.append(words[i])
                    i += 1
            topic, type_name, *values = positional
            found.append((topic, type_name, yaml.safe_load(values[0]) if values else {}))
    return found


def build_message(type_name: str, fields: dict):
    """A rosbags message of ``type_name`` from YAML fields, defaults for the rest (as `ros2 topic pub`)."""
    from rosbags.typesys.base import Nodetype

    dtypes = {"float32": np.float32, "float64": np.float64, "uint8": np.uint8, "int8": np.int8, "byte": np.uint8,
              "int16": np.int16, "uint16": np.uint16, "int32": np.int32, "uint32": np.uint32, "int64": np.int64,
              "uint64": np.uint64, "bool": np.bool_, "char": np.uint8}
    unknown = set(fields) - {name for name, _ in typestore().fielddefs[type_name][1]}
    assert not unknown, f"{type_name} has no field(s) {sorted(unknown)}"
    kw = {}
    for name, (kind, detail) in typestore().fielddefs[type_name][1]:
        value = fields.get(name)
        if kind == Nodetype.NAME:
            kw[name] = build_message(detail, value or {})
        elif kind in (Nodetype.SEQUENCE, Nodetype.ARRAY):
            (sub_kind, sub), _ = detail
            if sub_kind == Nodetype.BASE and sub[0] != "string":
                kw[name] = np.array(value or [], dtype=dtypes[sub[0]])
            elif sub_kind == Nodetype.BASE:
                kw[name] = list(value or [])
            else:
                kw[name] = [build_message(sub, v) for v in value or []]
        else:
            kw[name] = value if value is not None else ("" if detail[0] == "string" else
                                                        False if detail[0] == "bool" else 0)
    return msg_type(type_name)(**kw)


def test_the_readme_ros2_topic_pub_commands_are_accepted_by_the_delivery_scenario(tmp_path):
    # GIVEN every `ros2 topic pub` line of the README, built as the ROS 2 CLI builds it
    commands = readme_pub_commands()
    assert len(commands) >= 4 and {t.rsplit("/", 1)[1] for t, _, _ in commands} >= {"mission", "target", "cmd_vel"}
    payloads = [[topic, ty, serialize(build_message(ty, fields)).hex()] for topic, ty, fields in commands]
    path = tmp_path / "readme.json"
    path.write_text(json.dumps(payloads))
    peer = _peer("write", "40", str(path))
    assert peer.stdout.readline().strip() == "ready"
    # WHEN a peer sends them to the README's own world
    with Simulation.from_file(ROOT / "worlds" / "urban_delivery.yaml", ros2="dds") as sim:
        got = _run_while(sim, peer)
        sim.run(duration=0.5)
        events = [(who, text) for _, who, text in sim.events]
    # THEN each was accepted: no rejection, and each commanded vehicle's command shows in the events
    assert got["written"] == len(payloads)
    assert not [e for e in events if e[1].startswith(("rejected", "warning"))], events
    for topic, _, _ in commands:
        vehicle = topic.split("/")[1]
        assert any(who == vehicle for who, _ in events), (topic, events)
