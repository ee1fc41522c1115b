"""ROS 2 over DDS against a real peer: a second process with only cyclonedds + rosbags (no project code)."""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from unetyemu_ecs import Simulation, load_world_text
from unetyemu_ecs.sensors.lidar import read_points
from unetyemu_ecs.sensors.messages import deserialize, serialize
from unetyemu_ecs.transport.ros2.inbound import COMMAND_TOPICS


LISTENER = Path(__file__).resolve().parent.parent / "ros2_peer" / "listen.py"

WORLD = """
world: {name: ros2, physics_hz: 240, seed: 9}
scene:
  generator: none
  ground_size_m: 200
  buildings: [{center_m: [12.0, 0.0], size_m: [2.0, 30.0], height_m: 10.0}]
vehicles:
  - name: d1
    type: quadrotor
    preset: medium
    pose: {position_m: [0.0, 0.0, 0.3]}
    components: {lidar: {}, imu: {}, battery: {}, odometry: {}, camera: {width: 64, height: 48}}
  - name: c1
    type: car
    preset: medium
    pose: {position_m: [-10.0, 0.0, 0.9]}
    components: {gps: {}, depth_camera: {width: 64, height: 48}}
"""

DELIVERY = Path(__file__).resolve().parents[2] / "worlds" / "urban_delivery.yaml"


def _delivery_topics() -> dict[str, str]:
    """Every topic the delivery scenario publishes, with its type (all sensors fire at the first step)."""
    with Simulation.from_file(DELIVERY) as sim:
        sim.step()
        return {s.topic: s.msg.__msgtype__ for s in sim.services.sensors.latest.values()} | {
            "/clock": "rosgraph_msgs/msg/Clock"}


@pytest.fixture(scope="module")
def exchange():
    """Run the listener while the delivery scenario publishes (1 s in real time for discovery, then
    3 s as fast as it goes, every message recorded); return the topics, what the peer got and what was sent."""
    topics = _delivery_topics()
    peer = subprocess.Popen([sys.executable, str(LISTENER), "60.0", *(f"{k}={v}" for k, v in topics.items())],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    assert peer.stdout.readline().strip() == "ready"
    sent: dict[str, list] = {}
    with Simulation.from_file(DELIVERY, ros2="dds") as sim:
        start = time.monotonic()
        for i in range(int(4.0 / sim.dt_s)):
            sim.step()
            for s in sim.services.sensors.this_step:
                sent.setdefault(s.topic, []).append(s.msg)
            if i < int(1.0 / sim.dt_s):                 # the first second in real time: discovery
                time.sleep(max(0.0, start + (i + 1) * sim.dt_s - time.monotonic()))
        vehicles = list(sim.vehicle_names)
    out, err = peer.communicate(timeout=90)
    return topics, json.loads(out.strip().splitlines()[-1]), sent, vehicles


def test_every_topic_of_the_delivery_scenario_reaches_a_plain_cyclonedds_peer_and_decodes_with_jazzy_definitions(
        exchange):
    topics, got, sent, _ = exchange
    assert len(topics) >= 18                              # 16 sensor topics of the paper's sensors, /tf, /tf_static, /clock
    for topic, type_name in topics.items():
        assert got["counts"][topic] > 0, topic
        msg = deserialize(bytes.fromhex(got["last"][topic]), type_name)
        if topic == "/clock":
            assert 1.0 < msg.clock.sec + msg.clock.nanosec * 1e-9 <= 4.0
            continue
        # the peer's last sample is one of the messages the simulation produced, byte for byte
        produced = {serialize(m) for m in sent[topic]}
        assert serialize(msg) in produced, topic
    last = {t: deserialize(bytes.fromhex(got["last"][t]), ty) for t, ty in topics.items()}
    # PointCloud2: the points are the in-process scan of the same stamp
    cloud = last["/drone1/lidar/points"]
    scan = next(m for m in sent["/drone1/lidar/points"] if m.header.stamp == cloud.header.stamp)
    assert cloud.header.frame_id == "drone1/lidar_link" and len(read_points(cloud)) == cloud.width > 100
    np.testing.assert_array_equal(read_points(cloud), read_points(scan))
    # Images: sizes and encodings as configured
    rgb, depth = last["/drone3/camera/image_raw"], last["/drone2/depth/image_raw"]
    assert (rgb.width, rgb.height, rgb.encoding, rgb.step, len(rgb.data)) == (320, 240, "rgb8", 960, 320 * 240 * 3)
    assert (depth.width, depth.height, depth.encoding, depth.step) == (320, 240, "32FC1", 320 * 4)
    info = last["/drone3/camera/camera_info"]
    assert (info.width, info.height) == (320, 240) and info.k[0] > 0 and info.header.frame_id == rgb.header.frame_id
    # Imu: specific force of about +g up (drone1 is taking off); NavSatFix near the world origin
    imu = last["/drone1/imu/data"]
    assert abs(np.linalg.norm([imu.linear_acceleration.x, imu.linear_acceleration.y,
                               imu.linear_acceleration.z]) - 9.81) < 2.0 and imu.linear_acceleration.z > 7.0
    fix = last["/truck1/gps/fix"]
    assert abs(fix.latitude - 40.4168) < 0.01 and abs(fix.longitude + 3.7038) < 0.01 and fix.status.status >= 0
    # Odometry in the vehicle's odom frame, BatteryState full-ish and discharging
    odom = last["/drone1/odom"]
    assert (odom.header.frame_id, odom.child_frame_id) == ("drone1/odom", "drone1/base_link")
    assert abs(odom.pose.pose.orientation.w ** 2 + odom.pose.pose.orientation.z ** 2 +
               odom.pose.pose.orientation.x ** 2 + odom.pose.pose.orientation.y ** 2 - 1.0) < 1e-6
    battery = last["/drone1/battery"]
    assert 0.9 < battery.percentage <= 1.0 and battery.voltage > 10.0 and battery.current < 0.0
    # TF: the static tree has the sensor mounts, /tf every vehicle's base_link in its odom frame
    static = last["/tf_static"]
    assert ("drone1/base_link", "drone1/lidar_link") in {(t.header.frame_id, t.child_frame_id) for t in static.transforms}
    assert {t.child_frame_id for t in last["/tf"].transforms} >= {"drone1/base_link", "truck1/base_link"}


def test_every_writer_announces_xcdr1_and_ros2_names_in_discovery(exchange):
    topics, got, _, _ = exchange
    for topic, type_name in topics.items():
        writer = got["writers"][topic]
        pkg, _, name = type_name.split("/")
        assert writer["type"] == f"{pkg}::msg::dds_::{name}_", topic
        assert writer["xcdr1"] and not writer["xcdr2"], topic


SENDER = LISTENER.parent / "send.py"

COMMANDS = [
    ["/d1/target", "std_msgs/msg/Float32MultiArray", {"data": [5.0, 4.0, 6.0, 90.0, 3.0]}],
    # streamed, 0.2 s apart, as a teleop node does (a cmd_vel lapses after the command timeout)
    *[["/c1/cmd_vel", "geometry_msgs/msg/Twist", {"linear": {"x": 3.0}, "angular": {"z": 0.0}}]] * 20,
    # garbage: wrong length, NaN, bad JSON, a NaN in a Twist, a car beyond its top speed
    ["/d1/teleop", "std_msgs/msg/Float32MultiArray", {"data": [0.1, 0.2]}],
    ["/d1/target", "std_msgs/msg/Float32MultiArray", {"data": [1.0, "NaN", 3.0, 0.0, 2.0]}],
    ["/d1/mission", "std_msgs/msg/String", {"data": "{not json"}],
    ["/d1/cmd_vel", "geometry_msgs/msg/Twist", {"linear": {"x": 1.0, "y": "NaN"}}],
    ["/c1/cmd_vel", "geometry_msgs/msg/Twist", {"linear": {"x": 90.0}}],
    # in every transport's range but beyond this car's top speed: refused by the car's command system
    ["/c1/cmd_vel", "geometry_msgs/msg/Twist", {"linear": {"x": 28.0}}],
    # a good mission last: fly to (-5, 5) at 4 m and land there
    ["/d1/mission", "std_msgs/msg/String", {"data": json.dumps({"name": "hop", "steps": [
        {"type": "cruise", "waypoints": [{"x": -5.0, "y": 5.0, "z": 4.0}]}, {"type": "land"}]})}],
]


def test_commands_from_a_ros2_peer_drive_the_vehicles_and_garbage_is_rejected_with_reasons():
    cmds = json.loads(json.dumps(COMMANDS).replace('"NaN"', "NaN"))
    peer = subprocess.Popen([sys.executable, str(SENDER), "30.0", json.dumps(cmds)], cwd=SENDER.parent,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    assert peer.stdout.readline().strip() == "ready", peer.stderr.read()
    with Simulation(load_world_text(WORLD), ros2="dds") as sim:
        start = time.monotonic()
        car_moved = False
        while time.monotonic() - start < 25.0 and peer.poll() is None:
            sim.run(duration=0.1, rate=1.0)
            car_moved |= bool(sim.position_enu_m("c1")[0] > -8.0)       # 2 m forward
            if (sim.mission_status("d1") or {}).get("state") == "completed":
                break
        status = sim.mission_status("d1")
        events = [text for _, who, text in sim.events]
        final = sim.position_enu_m("d1")
    out, err = peer.communicate(timeout=60)
    got = json.loads(out.strip().splitlines()[-1])
    # THEN the good commands were executed: the target (replaced 1.4 s later by the mission), the
    # car's cmd_vel (it drove off), and the mission (flown and landed where it said)
    assert "target set to (5.0, 4.0, 6.0)" in events and car_moved
    assert status is not None and status["mission"] == "hop" and status["state"] == "completed", events
    assert np.linalg.norm(final[:2] - [-5.0, 5.0]) < 1.0 and final[2] < 0.5
    # AND each piece of garbage was rejected with its reason, in the event log and on /rosout
    reasons = ["4 values", "set_target('d1'): values must be finite", "mission rejected",
               "cmd_vel('d1'): values must be finite",
               "rejected /c1/cmd_vel",              # the car beyond the API's speed limit
               "is beyond the top speed"]           # ... and beyond its own (a CommandResult of source ros2)
    for reason in reasons:
        assert any(reason in e for e in events), (reason, events)
        assert any(reason in line for line in got["rosout"]), (reason, got["rosout"])
    # AND the mission's progress reached the peer as status messages, the rejected mission among them
    assert any('"completed"' in s for s in got["status"]) or any('"running"' in s for s in got["status"])
    rejected = [json.loads(s) for s in got["status"] if '"rejected"' in s]
    assert rejected and "mission rejected" in rejected[0]["reason"] and rejected[0]["mission"] is None


def test_the_simulator_is_a_ros2_node_whose_endpoints_announce_their_jazzy_type_hashes(exchange):
    topics, got, _, vehicles = exchange
    from unetyemu_ecs.sensors.messages import typestore
    # ros_discovery_info: one node, /unetyemu_sim, listing the writers the peer matched
    assert got["graph"], "no ros_discovery_info received"
    info = deserialize(bytes.fromhex(got["graph"][-1]), "rmw_dds_common/msg/ParticipantEntitiesInfo")
    (node,) = info.node_entities_info_seq
    assert (node.node_namespace, node.node_name) == ("/", "unetyemu_sim")
    writer_gids = {bytes(g.data).hex() for g in node.writer_gid_seq}
    for topic, type_name in topics.items():
        writer = got["writers"][topic]
        assert writer["gid"][:32] in writer_gids, topic
        assert writer["user_data"] == f"typehash={typestore().hash_rihs01(type_name)};", topic
    # readers: every command topic of every vehicle (mission, target, teleop, cmd_vel, arm, nav_mode), and
    # the 6 parameter service requests
    assert len(node.reader_gid_seq) == len(COMMAND_TOPICS) * len(vehicles) + 6


def test_the_ros_discovery_info_writer_announces_its_type_hash_as_rmw_does(exchange):
    # GIVEN the simulator's node seen by a peer  THEN the writer of ros_discovery_info carries
    # typehash= in its USER_DATA (rmw_cyclonedds warns "Failed to parse type hash" without it)
    _, got, _, _ = exchange
    from unetyemu_ecs.sensors.messages import typestore
    info = deserialize(bytes.fromhex(got["graph"][-1]), "rmw_dds_common/msg/ParticipantEntitiesInfo")
    ours = [ud for gid, ud in got["graph_writers"].items() if gid[:24] == bytes(info.gid.data[:12]).hex()]
    assert ours == [f"typehash={typestore().hash_rihs01('rmw_dds_common/msg/ParticipantEntitiesInfo')};"]


def test_keyboard_teleop_in_a_terminal_drives_the_drone_over_ros2():
    import os
    import pty

    from ..conftest import unetyemu_command

    # GIVEN `unetyemu teleop d1` in a pseudo-terminal and the simulation listening
    master, slave = pty.openpty()
    cmd = unetyemu_command()
    teleop = subprocess.Popen([*cmd, "teleop", "d1"], stdin=slave, stdout=slave, stderr=slave, close_fds=True)
    os.close(slave)
    try:
        with Simulation(load_world_text(WORLD), ros2="dds") as sim:
            sim.run(duration=1.5, rate=1.0)
            # WHEN the user presses w five times (climb at half the climb limit) and waits
            os.write(master, b"wwwww")
            sim.run(duration=3.0, rate=1.0)
            # THEN the drone flies in manual mode on those sticks: it climbs
            row = sim.row("d1")
            assert list(np.round(sim.fleet.stick[row], 3)) == [0.5, 0.0, 0.0, 0.0]
            assert sim.position_enu_m("d1")[2] > 3.0
            # AND space stops it (hover: sticks back to zero)
            os.write(master, b" ")
            sim.run(duration=1.0, rate=1.0)
            assert list(sim.fleet.stick[row]) == [0.0, 0.0, 0.0, 0.0]
        os.write(master, b"q")
        assert teleop.wait(timeout=10) == 0
    finally:
        if teleop.poll() is None:
            teleop.kill()
        os.close(master)


SWITCHES_WORLD = """
world: {name: ros2_switches, physics_hz: 240, seed: 9}
scene: {generator: none, ground_size_m: 200}
vehicles:
  - name: d1
    type: quadrotor
    pose: {position_m: [0.0, 0.0, 0.3]}
    components: {lidar: {ros2: false}, imu: {topic: /d1/imu_hi_rate, rate_hz: 200}, battery: {}}
  - name: c1
    type: car
    pose: {position_m: [-10.0, 0.0, 0.9]}
    ros2: false
    components: {gps: {}}
"""


def test_world_file_switches_take_a_vehicle_or_a_sensor_off_ros2_and_rename_a_topic():
    from cyclonedds.domain import DomainParticipant
    from cyclonedds.pub import DataWriter
    from cyclonedds.topic import Topic

    from unetyemu_ecs.transport.ros2.dds_backend import DdsPublisher, dds_topic_name, domain_from_env
    from unetyemu_ecs.transport.ros2.dds_types import idl_type

    with Simulation(load_world_text(SWITCHES_WORLD), ros2="dds") as sim:
        sim.run(duration=1.0)
        # THEN the renamed IMU topic and the battery are published; the LiDAR (ros2: false) and
        # everything of c1 (vehicle ros2: false) are not, although they measure for the Python API
        topics = sim.ros2_topics
        assert {"/d1/imu_hi_rate", "/d1/battery", "/clock", "/tf"} <= set(topics)
        assert "/d1/imu/data" not in topics and "/d1/lidar/points" not in topics
        assert not [t for t in topics if t.startswith("/c1/")]
        assert sim.sensor("d1", "lidar") is not None and sim.sensor("c1", "gps") is not None
        # AND from the outside: a Twist writer finds a reader on /d1/cmd_vel and none on /c1/cmd_vel
        dp = DomainParticipant(domain_from_env())
        twist = idl_type("geometry_msgs/msg/Twist")
        writers = {v: DataWriter(dp, Topic(dp, dds_topic_name(f"/{v}/cmd_vel"), twist,
                                           qos=DdsPublisher.qos_for("/x")), qos=DdsPublisher.qos_for("/x"))
                   for v in ("d1", "c1")}
        deadline = time.monotonic() + 5.0
        while not writers["d1"].get_matched_subscriptions() and time.monotonic() < deadline:
            sim.run(duration=0.05)
        time.sleep(0.5)
        assert len(writers["d1"].get_matched_subscriptions()) == 1
        assert writers["c1"].get_matched_subscriptions() == []


def test_ros2_backend_choice_auto_falls_back_to_dds_and_rclpy_without_ros_says_what_to_do(monkeypatch):
    from unetyemu_ecs.transport.ros2 import bridge, rclpy_backend
    from unetyemu_ecs.transport.ros2.dds_backend import Ros2Error

    if rclpy_backend.rclpy_available():
        pytest.skip("rclpy imports here: auto picks it (tested in test_ros2_rclpy.py)")
    assert bridge.resolve_backend("auto") == "dds"
    assert bridge.resolve_backend("off") == "off"
    with pytest.raises(ValueError, match="ros2 must be one of off, auto, rclpy, dds"):
        bridge.resolve_backend("zenoh")
    with pytest.raises(Ros2Error, match="rclpy does not import.*source /opt/ros/jazzy/setup.bash.*--ros2 dds"):
        Simulation(load_world_text(SWITCHES_WORLD), ros2="rclpy")


def test_the_rviz2_config_shows_only_topics_and_frames_the_delivery_scenario_publishes_with_matching_types():
    import yaml

    root = Path(__file__).resolve().parents[2]
    config = yaml.safe_load((root / "worlds" / "urban_delivery.rviz").read_text())
    displays = config["Visualization Manager"]["Displays"]
    with Simulation.from_file(root / "worlds" / "urban_delivery.yaml") as sim:
        sim.step()
        published = {s.topic: s.msg.__msgtype__ for s in sim.services.sensors.latest.values()}
        _, static = sim.transforms()
    expects = {"rviz_default_plugins/PointCloud2": "sensor_msgs/msg/PointCloud2",
               "rviz_default_plugins/Image": "sensor_msgs/msg/Image",
               "rviz_default_plugins/Odometry": "nav_msgs/msg/Odometry"}
    shown = [(d["Class"], d["Topic"]["Value"]) for d in displays if "Topic" in d]
    assert len(shown) == 7
    for cls, topic in shown:
        assert published.get(topic) == expects[cls], (cls, topic)
    assert config["Visualization Manager"]["Global Options"]["Fixed Frame"] == "map"
    assert "map" in {t.header.frame_id for t in static.transforms}
