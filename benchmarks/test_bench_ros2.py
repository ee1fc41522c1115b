"""ROS 2 publish cost over DDS (no subscriber): one PointCloud2 of a full scan and one image.

Run: python3 -m pytest benchmarks/test_bench_ros2.py --benchmark-only --benchmark-columns=mean,stddev,rounds
"""

from __future__ import annotations

import numpy as np
import pytest

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
