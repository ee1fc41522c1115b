"""The TF tree: static mounts, 50 Hz body poses, and LiDAR points carried into the map through it."""

from __future__ import annotations

import numpy as np

from unetyemu_ecs import Simulation, load_world_text
from unetyemu_ecs.frames import R_from_quat_xyzw
from unetyemu_ecs.sensors.lidar import read_points
from unetyemu_ecs.sensors.messages import deserialize, serialize

from .test_lidar import ROOM, distance_to_room


def world(vehicles: str) -> str:
    return f"world: {{name: tf, physics_hz: 240, seed: 5}}\nscene:\n  generator: none\n  ground_size_m: 300\n{ROOM}\nvehicles:\n{vehicles}"


DRONE = ("  - name: d1\n    type: quadrotor\n    preset: medium\n    pose: {position_m: [0.0, 0.0, 0.3]}\n"
         "    components: {lidar: {mount_xyz_m: [0.1, 0.0, 0.12], mount_rpy_deg: [0.0, 10.0, 45.0]},"
         " camera: {width: 32, height: 24, mount_xyz_m: [0.3, 0.0, 0.0]}, imu: {}}\n")


def as_matrix(t) -> np.ndarray:
    tr, q = t.transform.translation, t.transform.rotation
    m = np.eye(4)
    m[:3, :3] = R_from_quat_xyzw(np.array([q.x, q.y, q.z, q.w]))
    m[:3, 3] = [tr.x, tr.y, tr.z]
    return m


def test_static_tree_holds_every_mount_and_the_camera_optical_frame():
    with Simulation(load_world_text(world(DRONE))) as sim:
        sim.step(1)
        _, static = sim.transforms()
        edges = {(t.header.frame_id, t.child_frame_id): t for t in static.transforms}
        assert set(edges) == {("map", "d1/odom"), ("d1/base_link", "d1/lidar_link"), ("d1/base_link", "d1/camera_link"),
                              ("d1/camera_link", "d1/camera_optical_frame"), ("d1/base_link", "d1/imu_link")}
        assert np.allclose(as_matrix(edges[("map", "d1/odom")]), np.eye(4))
        optical = as_matrix(edges[("d1/camera_link", "d1/camera_optical_frame")])[:3, :3]
        assert np.allclose(optical @ [0, 0, 1], [1, 0, 0]) and np.allclose(optical @ [1, 0, 0], [0, -1, 0])
        back = deserialize(serialize(static), "tf2_msgs/msg/TFMessage")
        assert serialize(back) == serialize(static)


def test_tf_runs_at_50_hz_and_lidar_points_carried_through_it_land_on_the_walls():
    with Simulation(load_world_text(world(DRONE))) as sim:
        sim.set_target("d1", 0.0, 0.0, 4.0)
        sim.run(duration=5.0)
        count, scan_step = 0, None
        for _ in range(240):
            sim.step()
            kinds = {s.sensor for s in sim.services.sensors.this_step}
            count += "tf" in kinds
            if "lidar" in kinds and "tf" in kinds:
                scan_step = (sim.transforms(), sim.sensor("d1", "lidar"))
        assert count == 50
        (tf, static), cloud = scan_step
        edges = {(t.header.frame_id, t.child_frame_id): as_matrix(t) for t in [*tf.transforms, *static.transforms]}
        assert tf.transforms[0].header.stamp == cloud.header.stamp
        map_from_lidar = edges[("map", "d1/odom")] @ edges[("d1/odom", "d1/base_link")] @ edges[("d1/base_link", "d1/lidar_link")]
        p = read_points(cloud)
        pts = np.c_[p["x"], p["y"], p["z"], np.ones(len(p))] @ map_from_lidar.T
        assert len(pts) > 3000 and distance_to_room(pts[:, :3]).max() < 0.01


def test_a_tf_message_read_later_holds_the_poses_of_its_own_stamp():
    # GIVEN a drone climbing (so its pose changes every step)
    with Simulation(load_world_text(world(DRONE))) as sim:
        sim.set_target("d1", 0.0, 0.0, 4.0)
        sim.run(duration=1.0)
        while "tf" not in {s.sensor for s in sim.services.sensors.this_step}:
            sim.step()
        pose_then = sim.position_enu_m("d1").copy()
        # WHEN the message is first read two steps later (the loop only copied the poses)
        sim.step(2)
        tf, _ = sim.transforms()
        # THEN it carries the pose at its stamp, not the pose now
        t = tf.transforms[0].transform.translation
        assert np.allclose([t.x, t.y, t.z], pose_then, atol=1e-12)
        assert not np.allclose(pose_then, sim.position_enu_m("d1"), atol=1e-4)
