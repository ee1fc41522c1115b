"""RGB and depth cameras against known geometry: plane depths, coinciding edges, intrinsics, messages."""

from __future__ import annotations

import numpy as np
import pytest

from unetyemu_ecs import Simulation, load_world_text
from unetyemu_ecs.frames import R_from_quat_xyzw, quat_xyzw_from_euler_rpy
from unetyemu_ecs.sensors.camera import R_LINK_OPTICAL, pixel_rays_optical, read_image
from unetyemu_ecs.sensors.messages import deserialize, serialize

WALL = "  buildings: [{center_m: [20.5, 0.0], size_m: [1.0, 60.0], height_m: 40.0}]"


def world(vehicles: str, wall: bool = True) -> str:
    return (f"world: {{name: cams, physics_hz: 240, seed: 5}}\nscene:\n  generator: none\n  ground_size_m: 300\n"
            f"{WALL if wall else ''}\nvehicles:\n{vehicles}")


def car(name: str, comps: str = "", x: float = 0.0, y: float = 0.0, yaw_deg: float = 0.0) -> str:
    text = (f"  - name: {name}\n    type: car\n    preset: medium\n"
            f"    pose: {{position_m: [{x}, {y}, 0.9], yaw_deg: {yaw_deg}}}\n")
    return text + (f"    components: {{{comps}}}\n" if comps else "")


def test_depth_of_the_ground_seen_from_a_tilted_hovering_drone_matches_the_plane_everywhere():
    # GIVEN a hovering drone whose depth camera looks 60 deg down at flat ground
    comps = "depth_camera: {width: 160, height: 120, mount_rpy_deg: [0.0, 60.0, 0.0]}"
    drone = ("  - name: d1\n    type: quadrotor\n    preset: medium\n    pose: {position_m: [0.0, 0.0, 0.3]}\n"
             f"    components: {{{comps}}}\n")
    with Simulation(load_world_text(world(drone, wall=False))) as sim:
        sim.set_target("d1", 0.0, 0.0, 6.0)
        sim.run(duration=8.0)
        depth = read_image(sim.sensor("d1", "depth_camera"))
        # THEN every pixel's depth is the z (optical) of that pixel's ray meeting the plane z = 0,
        # computed here from the exact sensor pose at the same step
        R_body = R_from_quat_xyzw(sim.attitude_enu_flu_xyzw("d1"))
        R_mount = R_from_quat_xyzw(np.asarray(quat_xyzw_from_euler_rpy(0.0, np.deg2rad(60.0), 0.0)).reshape(4))
        R_opt = R_body @ R_mount @ R_LINK_OPTICAL
        cam_z = sim.position_enu_m("d1")[2]
        d_opt, z_opt = pixel_rays_optical(160, 120, 90.0)
        d_world = d_opt @ R_opt.T
        expected = np.where(d_world[:, 2] < -1e-6, cam_z / -d_world[:, 2] * z_opt, np.inf).reshape(120, 160)
        seen = np.isfinite(expected) & (expected < 150.0)
        assert seen.mean() > 0.5
        assert np.abs(depth[seen] - expected[seen]).max() < 0.01
        assert np.all(np.isinf(depth[~np.isfinite(expected)]))       # sky: +inf (REP-118)


def test_a_camera_inside_its_own_car_sees_through_it_and_the_wall_depth_is_exact():
    comps = "depth_camera: {width: 64, height: 48}"                  # mounted at the chassis centre
    with Simulation(load_world_text(world(car("c1", comps)))) as sim:
        sim.run(duration=0.5)
        depth = read_image(sim.sensor("c1", "depth_camera"))
        # the wall face is at x = 20; the camera at x = 0: the upper half sees only the wall, at z = 20 m
        upper = depth[:20]
        assert np.abs(upper - 20.0).max() < 0.01


def test_rgb_and_depth_edges_of_a_box_coincide_and_sit_where_camera_info_projects_it():
    # GIVEN a camera on a car's bumper and a second car broadside 10 m ahead, in front of a wall
    cam = "camera: {mount_xyz_m: [2.3, 0.0, -0.3]}, depth_camera: {mount_xyz_m: [2.3, 0.0, -0.3]}"
    with Simulation(load_world_text(world(car("c1", cam) + car("target", x=14.0, yaw_deg=90.0)))) as sim:
        sim.run(duration=0.5)
        rgb = read_image(sim.sensor("c1", "camera")).astype(int)
        depth = read_image(sim.sensor("c1", "depth_camera"))
        info = sim.sensor("c1", "camera_info")
        fx, cx, cy = info.k[0], info.k[2], info.k[5]
        cam = sim.position_enu_m("c1") + [2.3, 0.0, -0.3]
        # rows above the horizon (wall behind, no ground): compare horizontal neighbour edges
        rows = slice(0, int(cy) - 2)
        depth_edge = np.abs(np.diff(depth[rows], axis=1)) > 0.5
        rgb_edge = np.abs(np.diff(rgb[rows], axis=1)).max(axis=2) > 10
        assert depth_edge.sum() > 20
        assert np.array_equal(depth_edge, rgb_edge)
        # the target's near face (x = 14 - 0.9) spans y = +/-2.25: its sides project to u = cx -/+ f y / d
        d = 14.0 - 0.9 - cam[0]
        cols = np.flatnonzero(depth_edge.any(axis=0))
        assert abs(cols.min() + 0.5 - (cx - fx * 2.25 / d)) <= 1.0
        assert abs(cols.max() + 0.5 - (cx + fx * 2.25 / d)) <= 1.0
        # its roof (z = 0.9 + 0.7) projects to v = cy - f (z_top - z_cam) / d
        target_top = sim.position_enu_m("target")[2] + 0.7
        top_row = np.flatnonzero(np.isclose(depth[:, int(cx)], d, atol=0.05))[0]
        assert abs(top_row - (cy - fx * (target_top - cam[2]) / d)) <= 1.0


def test_image_and_camera_info_round_trip_through_cdr_with_design_names():
    comps = "camera: {width: 320, height: 240, hfov_deg: 70.0}"
    with Simulation(load_world_text(world(car("c1", comps)))) as sim:
        sim.run(duration=0.2)
        samples = sim.services.sensors.latest
        img, info = samples[("c1", "camera")], samples[("c1", "camera_info")]
        assert img.topic == "/c1/camera/image_raw" and info.topic == "/c1/camera/camera_info"
        assert img.msg.header.frame_id == info.msg.header.frame_id == "c1/camera_optical_frame"
        assert img.msg.encoding == "rgb8" and img.msg.step == 320 * 3 and len(img.msg.data) == 320 * 240 * 3
        back = deserialize(serialize(img.msg), "sensor_msgs/msg/Image")
        assert np.array_equal(read_image(back), read_image(img.msg))
        k = deserialize(serialize(info.msg), "sensor_msgs/msg/CameraInfo").k
        assert k[0] == pytest.approx(160.0 / np.tan(np.deg2rad(35.0))) and k[2] == 159.5 and k[5] == 119.5


def test_an_rgb_and_a_depth_camera_with_the_same_view_come_from_one_cast_and_agree_on_every_pixel():
    # GIVEN a car with an RGB-D camera (RGB and depth with the same mount and image, looking up 30 deg over
    # the wall) and a second car with a depth camera only
    view = "width: 64, height: 48, mount_xyz_m: [2.3, 0.0, -0.3], mount_rpy_deg: [0.0, -30.0, 0.0]"
    cams = f"camera: {{{view}}}, depth_camera: {{{view}}}"
    with Simulation(load_world_text(world(car("c1", cams) + car("c2", "depth_camera: {width: 64, height: 48}", y=8.0)
                                          + car("target", x=14.0, yaw_deg=90.0)))) as sim:
        sim.step(1)
        casts: list[int] = []
        real_cast = sim.services.raycast.cast_prepared

        def counted_cast(rays, *args, **kwargs):
            casts.append(len(rays))
            return real_cast(rays, *args, **kwargs)

        sim.services.raycast.cast_prepared = counted_cast
        # WHEN the next frames are due (10 Hz: within 24 steps)
        for _ in range(24):
            sim.step()
            if casts:
                break
        # THEN the three frames cost two casts of one image each: the RGB batch (c1's view) and the depth
        # batch, which holds only c2's view (c1's depth frame takes the RGB frame's hits)
        assert casts == [64 * 48, 64 * 48]
        rgb = read_image(sim.sensor("c1", "camera")).astype(int)
        depth = read_image(sim.sensor("c1", "depth_camera"))
        # AND the sky (no hit within range) is the same set of pixels in both images
        sky = (np.abs(rgb - np.round(np.array([0.62, 0.76, 0.92]) * 255)).max(axis=2) == 0)
        assert sky.any() and np.array_equal(sky, np.isinf(depth))
