"""LiDAR against known geometry: hits on known walls, exact rotation, moving bodies, no self-hits."""

from __future__ import annotations

import numpy as np
import pytest

from unetyemu_ecs import Simulation, load_world_text
from unetyemu_ecs.frames import R_from_quat_xyzw, quat_xyzw_from_euler_rpy
from unetyemu_ecs.sensors.lidar import read_points
from unetyemu_ecs.sensors.messages import deserialize, serialize

# A room: walls with inner faces at x = +/-10 and y = +/-8, 20 m high, on flat ground.
ROOM = """
  buildings:
    - {center_m: [10.5, 0.0], size_m: [1.0, 30.0], height_m: 20.0}
    - {center_m: [-10.5, 0.0], size_m: [1.0, 30.0], height_m: 20.0}
    - {center_m: [0.0, 8.5], size_m: [20.0, 1.0], height_m: 20.0}
    - {center_m: [0.0, -8.5], size_m: [20.0, 1.0], height_m: 20.0}"""


def world(vehicles: str, room: bool = True) -> str:
    return (f"world: {{name: lidar, physics_hz: 240, seed: 5}}\nscene:\n  generator: none\n  ground_size_m: 300\n"
            f"{ROOM if room else ''}\nvehicles:\n{vehicles}")


def car(name: str, lidar: str = "{mount_xyz_m: [0.0, 0.0, 1.0]}", x: float = 0.0, y: float = 0.0,
        yaw_deg: float = 0.0) -> str:
    comps = f"    components: {{lidar: {lidar}}}\n" if lidar else ""
    return (f"  - name: {name}\n    type: car\n    preset: medium\n"
            f"    pose: {{position_m: [{x}, {y}, 0.9], yaw_deg: {yaw_deg}}}\n{comps}")


def landed_drone(lidar: str = "{}") -> str:
    """Drone d1 (medium) standing at the origin with a LiDAR (``lidar``: its options)."""
    return ("  - name: d1\n    type: quadrotor\n    preset: medium\n    pose: {position_m: [0.0, 0.0, 0.3]}\n"
            f"    components: {{lidar: {lidar}}}\n")


def xyz(msg) -> np.ndarray:
    p = read_points(msg)
    return np.c_[p["x"], p["y"], p["z"]].astype(np.float64)


def sensor_pose(sim: Simulation, name: str, mount_xyz, mount_rpy_deg=(0.0, 0.0, 0.0)):
    R_body = R_from_quat_xyzw(sim.attitude_enu_flu_xyzw(name))
    R_mount = R_from_quat_xyzw(np.asarray(quat_xyzw_from_euler_rpy(*np.deg2rad(mount_rpy_deg))).reshape(4))
    return sim.position_enu_m(name) + R_body @ np.asarray(mount_xyz, float), R_body @ R_mount


def distance_to_room(points_world: np.ndarray) -> np.ndarray:
    x, y, z = points_world.T
    return np.minimum.reduce([np.abs(x - 10), np.abs(x + 10), np.abs(y - 8), np.abs(y + 8), np.abs(z)])


@pytest.mark.parametrize("mount_rpy", [(0.0, 0.0, 0.0), (30.0, 0.0, 0.0), (0.0, -20.0, 135.0), (15.0, 25.0, 90.0)])
def test_every_hit_in_a_box_room_lies_on_a_wall_or_the_floor_within_1_cm_at_any_attitude(mount_rpy):
    lidar = f"{{mount_xyz_m: [0.0, 0.0, 1.0], mount_rpy_deg: [{mount_rpy[0]}, {mount_rpy[1]}, {mount_rpy[2]}]}}"
    with Simulation(load_world_text(world(car("c1", lidar)))) as sim:
        sim.run(duration=1.0)
        msg = sim.sensor("c1", "lidar")
        pos, R = sensor_pose(sim, "c1", (0.0, 0.0, 1.0), mount_rpy)
        pts_world = xyz(msg) @ R.T + pos
        # the room is closed sideways: only rays that go up above the 20 m walls can escape
        assert msg.width > 0.8 * 360 * 16
        assert distance_to_room(pts_world).max() < 0.01


def test_rings_keep_their_configured_elevations_in_the_sensor_frame_at_yaw_90():
    # the reference implementation rotated rays in the world frame: its channels collapsed near yaw +/-90
    with Simulation(load_world_text(world(car("c1", "{mount_xyz_m: [0.0, 0.0, 1.0]}", yaw_deg=90.0)))) as sim:
        sim.run(duration=1.0)
        p = read_points(sim.sensor("c1", "lidar"))
        elevation = np.degrees(np.arctan2(p["z"], np.hypot(p["x"], p["y"])))
        expected = -22.5 + 45.0 * p["ring"] / 15.0
        assert np.abs(elevation - expected).max() < 1e-3
        assert set(np.unique(p["ring"])) == set(range(16))


def test_turning_the_sensor_by_yaw_90_rotates_the_cloud_by_exactly_minus_90():
    clouds = {}
    for yaw in (0.0, 90.0):
        lidar = f"{{mount_xyz_m: [0.0, 0.0, 1.0], mount_rpy_deg: [0.0, 0.0, {yaw}]}}"
        with Simulation(load_world_text(world(car("c1", lidar)))) as sim:
            sim.run(duration=1.0)
            clouds[yaw] = xyz(sim.sensor("c1", "lidar"))
    rz = np.array([[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])        # rotation by -90 deg about z
    a, b = clouds[0.0] @ rz.T, clouds[90.0]
    assert len(a) == len(b)
    key = lambda pts: np.lexsort((np.round(np.degrees(np.arctan2(pts[:, 1], pts[:, 0]))) % 360,
                                  np.round(np.degrees(np.arctan2(pts[:, 2], np.hypot(pts[:, 0], pts[:, 1]))), 1)))
    assert np.abs(a[key(a)] - b[key(b)]).max() < 1e-4


def test_a_moving_car_appears_in_the_scan_at_its_current_pose():
    # GIVEN a drone hovering at 2 m with a LiDAR, and a car driving past 8 m in front of it
    drone = landed_drone()
    with Simulation(load_world_text(world(drone + car("c1", lidar="", x=8.0, y=-60.0, yaw_deg=90.0), room=False))) as sim:
        sim.set_target("d1", 0.0, 0.0, 2.0)
        sim.cmd_vel("c1", 10.0, 0.0)
        for _ in range(240 * 12):
            sim.step()
            if abs(sim.position_enu_m("c1")[1]) < 3.0 and any(s.sensor == "lidar" for s in sim.services.sensors.this_step):
                break
        # WHEN the scan of this very step is read (the car moves 1 m in 0.1 s)
        msg = sim.sensor("d1", "lidar")
        pos, R = sensor_pose(sim, "d1", (0.0, 0.0, 0.0))
        world_pts = xyz(msg) @ R.T + pos
        # THEN points lie on the car's chassis box at its current pose, to within 1 cm
        c_pos = sim.position_enu_m("c1")
        c_R = R_from_quat_xyzw(sim.attitude_enu_flu_xyzw("c1"))
        local = (world_pts - c_pos) @ c_R
        half = np.array([2.25, 0.9, 0.7])
        outside = np.linalg.norm(np.maximum(np.abs(local) - half, 0.0), axis=1)
        inside = np.min(half - np.abs(local), axis=1)
        on_box = (outside < 0.01) & (inside < 0.01)
        assert on_box.sum() > 30
        assert np.all(inside[outside == 0.0] < 0.01)          # nothing inside the car


def test_the_drone_never_sees_itself_and_the_cloud_round_trips_through_cdr():
    drone = landed_drone("{channels: 32, vertical_fov_deg: 90.0}")
    with Simulation(load_world_text(world(drone))) as sim:
        sim.set_target("d1", 0.0, 0.0, 3.0)
        sim.run(duration=5.0)
        msg = sim.sensor("d1", "lidar")
        pts = xyz(msg)
        half = np.array([0.25, 0.25, 0.08])                   # the medium drone's hull, sensor at its centre
        assert np.all(np.any(np.abs(pts) > half + 1e-4, axis=1))      # no point on or in the own hull
        assert np.sum(pts[:, 2] < -2.9) > 100                  # ...while the floor 3 m below is seen through it
        back = deserialize(serialize(msg), "sensor_msgs/msg/PointCloud2")
        assert np.array_equal(read_points(back), read_points(msg))
        assert [f.name for f in back.fields] == ["x", "y", "z", "intensity", "ring"] and back.point_step == 20
        assert back.header.frame_id == "d1/lidar_link"
        intensity = read_points(msg)["intensity"]
        assert np.all((intensity >= 0.0) & (intensity <= 1.0)) and intensity.max() > 0.1


def test_a_lidar_cast_on_one_thread_sees_the_same_walls():
    # a sweep runs each simulation on one core: Simulation(raycast_threads=1) casts on one thread
    scans = []
    for threads in (0, 1):
        with Simulation(load_world_text(world(car("c1"))), raycast_threads=threads) as sim:
            sim.run(duration=0.5)
            assert sim.services.raycast.threads == threads
            scans.append(xyz(sim.sensor("c1", "lidar")))
    assert np.array_equal(scans[0], scans[1])
    with pytest.raises(ValueError, match="raycast_threads must be an integer"):
        Simulation(load_world_text(world(car("c1"))), raycast_threads=-1)


def test_a_cloud_kept_from_an_earlier_scan_stays_as_it_was_while_later_scans_reuse_memory():
    # GIVEN a drone climbing in the room with a LiDAR, and a scan kept by its reader
    drone = landed_drone()
    with Simulation(load_world_text(world(drone))) as sim:
        sim.set_target("d1", 0.0, 0.0, 8.0)
        sim.run(duration=1.0)
        kept = sim.sensor("d1", "lidar")
        kept_points = read_points(kept).copy()
        # WHEN twenty more scans are taken (their arrays are free again once the next scan replaces them)
        later = []
        for _ in range(20):
            sim.run(duration=0.1)
            msg = sim.sensor("d1", "lidar")
            later.append((np.asarray(msg.data).ctypes.data, read_points(msg).copy()))
            del msg
        # THEN the kept scan is untouched, the later ones differ from it (the drone climbed), and they were
        # written into a few reused arrays, not twenty new ones
        assert np.array_equal(read_points(kept), kept_points)
        assert all(len(points) != len(kept_points) or not np.array_equal(points, kept_points) for _, points in later)
        assert len({address for address, _ in later}) <= 3
