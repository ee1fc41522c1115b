"""The LiDAR clouds' and the cameras' own CDR writers give, byte for byte, what rosbags' generic serializer gives."""

from __future__ import annotations

import numpy as np
import pytest

from unetyemu_ecs.sensors.camera import image
from unetyemu_ecs.sensors.lidar import POINT_DTYPE, pointcloud2_of_points
from unetyemu_ecs.sensors.messages import deserialize, image_cdr, pointcloud2_cdr, serialize, typestore


def generic(msg) -> bytes:
    return bytes(typestore().serialize_cdr(msg, msg.__msgtype__))


# frame names of every length mod 4 (the padding after the header's string), one not ASCII
FRAMES = ["a", "d1/lidar", "drone_12/lidar_link", "drône/lidar", "x" * 7]


@pytest.mark.parametrize("n_points", [0, 1, 3, 5760])
def test_a_point_cloud_is_written_exactly_as_rosbags_writes_it(n_points):
    rng = np.random.default_rng(n_points)
    points = np.zeros(n_points, dtype=POINT_DTYPE)
    for name in ("x", "y", "z", "intensity"):
        points[name] = rng.normal(0.0, 10.0, n_points)
    points["ring"] = rng.integers(0, 16, n_points)
    for frame in FRAMES:
        for time_s in (0.0, 3.25, 98765.4321):
            msg = pointcloud2_of_points(points, time_s, frame)
            data = serialize(msg)
            assert data == pointcloud2_cdr(msg) == generic(msg)
            back = deserialize(data, "sensor_msgs/msg/PointCloud2")
            assert back.header.frame_id == frame and back.width == n_points
            assert np.array_equal(np.frombuffer(back.data.tobytes(), dtype=POINT_DTYPE), points)


@pytest.mark.parametrize("encoding, dtype, channels", [("rgb8", np.uint8, 3), ("32FC1", "<f4", 1), ("mono8", np.uint8, 1)])
@pytest.mark.parametrize("width, height", [(1, 1), (3, 2), (320, 240)])
def test_an_image_is_written_exactly_as_rosbags_writes_it(encoding, dtype, channels, width, height):
    rng = np.random.default_rng(width)
    pixels = (rng.uniform(0, 255, (height, width, channels)).astype(dtype) if channels > 1
              else rng.uniform(0, 255, (height, width)).astype(dtype))
    for frame in FRAMES:
        msg = image(1.5, frame, width, height, encoding, pixels)
        data = serialize(msg)
        assert data == image_cdr(msg) == generic(msg)
        back = deserialize(data, "sensor_msgs/msg/Image")
        assert (back.encoding, back.width, back.height, back.step) == (encoding, width, height, msg.step)
        assert back.data.tobytes() == pixels.tobytes()
