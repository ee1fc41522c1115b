"""ROS 2 over DDS: the publish cost of one PointCloud2 of a full scan and of one image (no
subscriber), and the delivery scenario's real-time factor with ROS 2 off, on, and on with a C++
subscriber (the Fast DDS peer of the tests, built with g++ and libfastrtps-dev) taking drone1's IMU
and point cloud, drone3's images and /clock.

Run: python3 -m pytest benchmarks/test_bench_ros2.py --benchmark-only --benchmark-columns=mean,stddev,rounds -s
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from unetyemu_ecs import Simulation

from unetyemu_ecs.sensors.camera import image
from unetyemu_ecs.sensors.lidar import pointcloud2
from unetyemu_ecs.transport.ros2.dds_backend import DdsPublisher


@pytest.fixture(scope="module")
def publisher():
    pub = DdsPublisher(domain_id=77)
    yield pub
    pub.close()


def test_publish_pointcloud2_of_a_5760_point_scan(benchmark, publisher):
    rng = np.random.default_rng(1)
    msg = pointcloud2(rng.uniform(-30, 30, (5760, 3)), rng.uniform(0, 1, 5760), np.zeros(5760, dtype=np.uint16),
                      1.0, "d1/lidar_link")
    benchmark(lambda: publisher.publish("/d1/lidar/points", msg))


@pytest.mark.parametrize("width, height", [(320, 240), (640, 480)])
def test_publish_rgb8_image(benchmark, publisher, width, height):
    pixels = np.random.default_rng(2).integers(0, 255, (height, width, 3), dtype=np.uint8)
    msg = image(1.0, "d1/camera_optical_frame", width, height, "rgb8", pixels)
    benchmark.pedantic(lambda: publisher.publish(f"/d1/camera{width}/image_raw", msg), rounds=10, iterations=1, warmup_rounds=1)


ROOT = Path(__file__).resolve().parent.parent
SCENARIO_S = 20.0


@pytest.mark.parametrize("ros2, subscriber", [("off", False), ("dds", False), ("dds", True)],
                         ids=["ros2-off", "ros2-dds", "ros2-dds-fastdds-subscriber"])
def test_delivery_scenario_real_time_factor(benchmark, ros2, subscriber):
    """20 simulated seconds of worlds/urban_delivery.yaml (all its sensors), as fast as it goes."""
    peers: list[subprocess.Popen] = []

    def setup():
        sim = Simulation.from_file(ROOT / "worlds" / "urban_delivery.yaml", ros2=ros2)
        if subscriber:
            sys.path.insert(0, str(ROOT / "tests" / "fastdds_peer"))
            from peer_build import build_peer

            peer = subprocess.Popen([str(build_peer()), "/drone1/imu/data", "/drone1/lidar/points",
                                     "/drone3/camera/image_raw"], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                    text=True)
            assert peer.stdout.readline().strip() == "ready"
            peers.append(peer)
            sim.run(duration=1.5, rate=1.0)              # discovery, in real time
        return (sim,), {}

    def run(sim):
        sim.run(duration=SCENARIO_S)
        sim.close()

    benchmark.pedantic(run, setup=setup, rounds=1, iterations=1)
    rtf = SCENARIO_S / benchmark.stats.stats.mean
    benchmark.extra_info["real_time_factor"] = round(rtf, 2)
    for peer in peers:
        peer.stdin.write("quit\n")
        peer.stdin.flush()
        report = peer.stdout.read()
        peer.wait(timeout=10)
        counts = json.loads(report.strip().splitlines()[-1])
        print("\nsubscriber received: " + ", ".join(f"{k} {v['count']}" for k, v in counts.items()))
    print(f"\n{ros2}{' + subscriber' if subscriber else ''}: {SCENARIO_S:.0f} s simulated in "
          f"{benchmark.stats.stats.mean:.1f} s (real-time factor {rtf:.2f})")
