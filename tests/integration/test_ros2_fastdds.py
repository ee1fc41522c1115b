"""ROS 2 interop with an independent DDS implementation: a Fast DDS 2.9 C++ peer (what rmw_fastrtps_cpp
is built on), compiled by the test from tests/fastdds_peer/ (types generated from the Jazzy
definitions by fastddsgen), receiving sensor topics and sending commands over loopback.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
import time
import zlib
from pathlib import Path

import numpy as np
import pytest

from unetyemu_ecs import Simulation, load_world_text

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "fastdds_peer"))
from peer_build import PeerBuildError, build_peer  # noqa: E402


WORLD = """
world: {name: fastdds, physics_hz: 240, seed: 11}
scene:
  generator: none
  ground_size_m: 200
  buildings: [{center_m: [15.0, 0.0], size_m: [2.0, 30.0], height_m: 10.0}]
vehicles:
  - name: d1
    type: quadrotor
    preset: medium
    pose: {position_m: [0.0, 0.0, 0.1]}
    components: {lidar: {}, imu: {}, camera: {width: 640, height: 480, rate_hz: 10}}
"""
TOPICS = ("/d1/imu/data", "/d1/lidar/points", "/d1/camera/image_raw")


@pytest.fixture(scope="module")
def peer_exe() -> Path:
    try:
        return build_peer()
    except PeerBuildError as exc:
        pytest.fail(str(exc))


class Peer:
    """The Fast DDS peer process, driven line by line over its stdin/stdout."""

    def __init__(self, exe: Path) -> None:
        self.proc = subprocess.Popen([str(exe), *TOPICS], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                     stderr=subprocess.PIPE, text=True)
        assert self.proc.stdout.readline().strip() == "ready", self.proc.stderr.read()

    def ask(self, line: str) -> str:
        self.proc.stdin.write(line + "\n")
        self.proc.stdin.flush()
        return self.proc.stdout.readline().strip()

    def report(self) -> dict:
        return json.loads(self.ask("report"))

    def close(self) -> None:
        if self.proc.poll() is None:
            self.ask("quit")
            self.proc.wait(timeout=10)


@pytest.fixture
def peer(peer_exe):
    p = Peer(peer_exe)
    yield p
    p.close()


def _key(msg) -> tuple[int, int]:
    return msg.header.stamp.sec, msg.header.stamp.nanosec


def test_a_fast_dds_peer_receives_imu_pointclouds_clock_and_every_640x480_image_at_10_hz(peer):
    sent: dict[str, dict[tuple[int, int], object]] = {t: {} for t in TOPICS}
    with Simulation(load_world_text(WORLD), ros2="dds") as sim:
        # 4 s paced to real time (as `unetyemu run --ros2 dds` runs): a 640x480 image every 0.1 s
        start = time.monotonic()
        for i in range(int(4.0 / sim.dt_s)):
            sim.step()
            for sample in sim.services.sensors.this_step:
                if sample.topic in sent:
                    sent[sample.topic][_key(sample.msg)] = sample.msg
            time.sleep(max(0.0, start + (i + 1) * sim.dt_s - time.monotonic()))
        time.sleep(0.5)                                       # the last samples in flight
        got = peer.report()
        sim_end_s = sim.sim_time_s

    # Images: from the first one the peer saw (after discovery), every image arrived, byte for byte
    image = got["image"]
    assert (image["width"], image["height"], image["step"], image["encoding"]) == (640, 480, 1920, "rgb8")
    assert image["frame_id"] == "d1/camera_optical_frame" and image["bytes"] == 640 * 480 * 3
    received = {(s, ns): h for s, ns, h in image["samples"]}
    first = min(received)
    published = {k: m for k, m in sent["/d1/camera/image_raw"].items() if k >= first}
    assert len(published) >= 25                               # >= 2.5 s of 10 Hz after discovery
    assert set(received) == set(published), "images lost between cyclonedds and Fast DDS"
    for k, msg in published.items():
        assert received[k] == f"{zlib.crc32(bytes(msg.data)):08x}"

    # PointCloud2: the points the peer got are the in-process scan of the same stamp
    cloud = got["cloud"]
    assert cloud["frame_id"] == "d1/lidar_link" and cloud["fields"] == ["x", "y", "z", "intensity", "ring"]
    assert cloud["count"] >= 20
    scans = sent["/d1/lidar/points"]
    matched = [(k, h) for s, ns, h in cloud["samples"] if (k := (s, ns)) in scans]
    assert len(matched) >= 5
    for k, h in matched:
        assert h == f"{zlib.crc32(bytes(scans[k].data)):08x}"

    # Imu: the drone sits on the ground, so the specific force is +g up
    imu = got["imu"]
    assert imu["frame_id"] == "d1/imu_link" and imu["count"] > 100
    assert np.linalg.norm(imu["linear_acceleration"]) == pytest.approx(9.81, abs=0.5)
    assert imu["linear_acceleration"][2] > 9.0

    # Clock: one per physics step while it was matched, the last one not beyond the sim's time
    clock = got["clock"]
    assert clock["count"] > 240
    sec, nsec = clock["last"]
    assert 2.0 < sec + nsec * 1e-9 <= sim_end_s + 1e-9


def _run_until(sim: Simulation, done, timeout_s: float) -> bool:
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        sim.run(duration=0.25)
        if done():
            return True
    return False


def test_a_fast_dds_peer_flies_the_drone_with_a_target_a_twist_and_a_mission(peer):
    with Simulation(load_world_text(WORLD), ros2="dds") as sim:
        sim.run(duration=1.0, rate=1.0)                      # discovery
        events = lambda: [text for _, who, text in sim.events if who == "d1"]      # noqa: E731

        # a target [x, y, z, yaw_deg, speed]: the drone flies there and faces north
        assert peer.ask("target /d1/target 5 4 6 90 3") == "sent /d1/target"
        assert _run_until(sim, lambda: np.linalg.norm(sim.position_enu_m("d1") - [5, 4, 6]) < 0.3
                          and np.linalg.norm(sim.velocity_enu_m_s("d1")) < 0.2, 60.0), events()
        x, y, z, w = sim.attitude_enu_flu_xyzw("d1")
        assert math.degrees(math.atan2(2 * (x * y + w * z), 1 - 2 * (y * y + z * z))) == pytest.approx(90.0, abs=3.0)

        # a Twist: 2 m/s forward in the body frame = north, holding altitude
        # (sent again every 0.25 s, as a teleop node streams it: a Twist lapses after the command timeout)
        def streaming_twist_reached_2_m_s() -> bool:
            assert peer.ask("twist /d1/cmd_vel 2 0 0 0 0 0") == "sent /d1/cmd_vel"
            return bool(np.linalg.norm(sim.velocity_enu_m_s("d1")[:2] - [0, 2]) < 0.1)
        assert _run_until(sim, streaming_twist_reached_2_m_s, 30.0)
        assert abs(sim.position_enu_m("d1")[2] - 6.0) < 0.3

        # a mission (JSON in a String): fly to (-5, 5) at 4 m and land there
        mission = json.dumps({"name": "fastdds_hop", "steps": [
            {"type": "cruise", "waypoints": [{"x": -5.0, "y": 5.0, "z": 4.0}]}, {"type": "land"}]})
        assert peer.ask(f"mission /d1/mission {mission}") == "sent /d1/mission"
        assert _run_until(sim, lambda: (sim.mission_status("d1") or {}).get("state") == "completed", 60.0), events()
        assert sim.mission_status("d1")["mission"] == "fastdds_hop"
        final = sim.position_enu_m("d1")
        assert np.linalg.norm(final[:2] - [-5.0, 5.0]) < 1.0 and final[2] < 0.5
