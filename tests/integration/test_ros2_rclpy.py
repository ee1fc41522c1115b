"""The ``rclpy`` backend against a sourced ROS 2 Jazzy: a plain rclpy node (its own context) sees the
simulator's topics and commands it. Skipped where rclpy does not import (our CI machines: rclpy
cannot be installed from PyPI); run on a ROS 2 machine with ``source /opt/ros/jazzy/setup.bash``.
"""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from unetyemu_ecs import Simulation, load_world_text


rclpy = pytest.importorskip("rclpy", reason="rclpy backend: needs a sourced ROS 2 Jazzy")

WORLD = """
world: {name: rclpy, physics_hz: 240, seed: 3}
scene: {generator: none, ground_size_m: 200}
vehicles:
  - name: d1
    type: quadrotor
    pose: {position_m: [0.0, 0.0, 0.3]}
    components: {imu: {}, lidar: {}}
"""


def test_auto_picks_rclpy_and_a_ros2_node_receives_the_imu_and_flies_the_drone_by_target():
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import Imu, PointCloud2
    from std_msgs.msg import Float32MultiArray

    ctx = Context()
    rclpy.init(context=ctx)
    node = rclpy.create_node("unetyemu_test_peer", context=ctx)
    got: dict[str, list] = {"imu": [], "cloud": []}
    qos = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
    node.create_subscription(Imu, "/d1/imu/data", got["imu"].append, qos)
    node.create_subscription(PointCloud2, "/d1/lidar/points", got["cloud"].append, qos)
    target = node.create_publisher(Float32MultiArray, "/d1/target", qos)
    executor = SingleThreadedExecutor(context=ctx)
    executor.add_node(node)
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
    try:
        with Simulation(load_world_text(WORLD), ros2="auto") as sim:
            assert sim.ros2_backend == "rclpy"
            sim.run(duration=2.0, rate=1.0)
            # the IMU at rest reads +g up, the cloud carries the lidar frame
            assert got["imu"] and got["imu"][-1].linear_acceleration.z == pytest.approx(9.81, abs=0.5)
            assert got["cloud"] and got["cloud"][-1].header.frame_id == "d1/lidar_link"
            # a target from the rclpy node: the drone flies there
            target.publish(Float32MultiArray(data=[3.0, 2.0, 4.0, 0.0, 2.0]))
            end = time.monotonic() + 30.0
            while time.monotonic() < end and np.linalg.norm(sim.position_enu_m("d1") - [3, 2, 4]) > 0.3:
                sim.run(duration=0.25)
            assert np.linalg.norm(sim.position_enu_m("d1") - [3, 2, 4]) < 0.3
    finally:
        executor.shutdown()
        node.destroy_node()
        ctx.try_shutdown()
