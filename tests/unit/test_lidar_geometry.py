"""LiDAR ray geometry without a simulation: scan pattern, own-hull exit, boxes, PointCloud2 layout."""

from __future__ import annotations

import numpy as np
from numpy.testing import assert_allclose

from unetyemu_ecs.frames import quat_xyzw_from_euler_rpy
from unetyemu_ecs.sensors.lidar import LidarSensor, pointcloud2, ray_directions_sensor, read_points
from unetyemu_ecs.sensors.raycast import box_triangles, exit_distance_m


def test_scan_pattern_has_the_configured_rings_and_azimuths():
    dirs, rings = ray_directions_sensor(LidarSensor(horizontal_samples=8, channels=3, vertical_fov_deg=20.0,
                                                    vertical_center_deg=-10.0))
    assert dirs.shape == (24, 3) and np.allclose(np.linalg.norm(dirs, axis=1), 1.0)
    elevation = np.degrees(np.arcsin(dirs[:, 2]))
    assert_allclose(elevation.reshape(3, 8), np.repeat([[-20.0], [-10.0], [0.0]], 8, axis=1), atol=1e-12)
    azimuth = np.degrees(np.arctan2(dirs[:8, 1], dirs[:8, 0]))
    assert_allclose(azimuth, [-180.0, -135.0, -90.0, -45.0, 0.0, 45.0, 90.0, 135.0], atol=1e-9)
    assert list(rings) == [0] * 8 + [1] * 8 + [2] * 8


def test_exit_distance_leaves_the_own_hull_exactly():
    half = np.array([0.25, 0.25, 0.08])
    dirs = np.array([[1.0, 0, 0], [0, 0, -1.0], [np.sqrt(0.5), np.sqrt(0.5), 0], [0, 0, 1.0]])
    # from the centre: the face distance along each axis, the corner distance along the diagonal
    assert_allclose(exit_distance_m(np.zeros(3), dirs, half), [0.25, 0.08, 0.25 * np.sqrt(2), 0.08])
    # from above the hull: down through it (exits at the bottom face); up never crosses it
    assert_allclose(exit_distance_m(np.array([0, 0, 0.5]), dirs[[1, 3]], half), [0.58, 0.0])


def test_box_triangles_enclose_the_rotated_box():
    quat = np.asarray(quat_xyzw_from_euler_rpy(0.0, 0.0, np.pi / 2)).reshape(1, 4)
    verts, tris = box_triangles(np.array([[1.0, 2.0, 3.0]]), quat, np.array([[2.0, 1.0, 0.5]]))
    assert tris.shape == (12, 3) and verts.shape == (8, 3)
    # yawed 90 deg: the 2 m half length now lies along y
    assert_allclose(verts.min(axis=0), [0.0, 0.0, 2.5], atol=1e-12)
    assert_allclose(verts.max(axis=0), [2.0, 4.0, 3.5], atol=1e-12)


def test_pointcloud2_packs_20_byte_points_that_read_back():
    pts = np.array([[1.0, 2.0, 3.0], [-4.0, 5.5, 0.25]])
    msg = pointcloud2(pts, np.array([0.5, 0.25]), np.array([0, 15], dtype=np.uint16), 1.5, "d1/lidar_link")
    back = read_points(msg)
    assert msg.width == 2 and msg.point_step == 20 and msg.row_step == 40 and len(msg.data) == 40
    assert_allclose(np.c_[back["x"], back["y"], back["z"]], pts)
    assert list(back["ring"]) == [0, 15] and msg.header.stamp.sec == 1 and msg.header.stamp.nanosec == 500_000_000


def test_a_failed_open3d_import_names_the_system_package_that_is_missing():
    from unetyemu_ecs.sensors.raycast import open3d_import_hint

    assert open3d_import_hint("libEGL.so.1: cannot open shared object file") == \
        "install the system package: apt-get install -y libegl1"
    assert open3d_import_hint("libGL.so.1: cannot open shared object file") == \
        "install the system package: apt-get install -y libgl1"
    assert "libusb-1.0-0" in open3d_import_hint("libusb-1.0.so.0: cannot open shared object file")
    assert "pip install open3d-cpu" in open3d_import_hint("No module named 'open3d'")
