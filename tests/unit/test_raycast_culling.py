"""The moving-body cast only for the rays that can meet a moving body: the same hits as casting every ray."""

from __future__ import annotations

import numpy as np
import pytest

from unetyemu_ecs.frames import quat_normalize_xyzw
from unetyemu_ecs.sensors.raycast import EXIT_MARGIN_M, MOVING_BODY, RaycastWorld, moving_body_candidates


def _ground_world() -> RaycastWorld:
    verts = np.array([[-500.0, -500.0, 0.0], [500.0, -500.0, 0.0], [500.0, 500.0, 0.0], [-500.0, 500.0, 0.0]])
    return RaycastWorld(verts, np.array([[0, 1, 2], [0, 2, 3]]), np.array([1, 1]))


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=1, keepdims=True)


@pytest.mark.parametrize("max_range_m", [np.inf, 30.0])
def test_culled_moving_body_cast_finds_exactly_the_hits_of_the_full_cast(rng, max_range_m):
    # GIVEN 40 drone-sized boxes scattered 0-60 m around three sensors above a ground plane, each sensor
    # casting 6000 rays in every direction
    world = _ground_world()
    n_boxes = 40
    centers = np.column_stack([rng.uniform(-60, 60, n_boxes), rng.uniform(-60, 60, n_boxes), rng.uniform(1, 30, n_boxes)])
    quats = quat_normalize_xyzw(rng.normal(size=(n_boxes, 4)))
    half = np.tile([0.25, 0.25, 0.08], (n_boxes, 1))
    centers[:3] = [[2.0, 0.5, 10.0], [0.0, -3.0, 9.0], [5.0, 5.0, 12.0]]        # some close by
    origins, dirs = [], []
    for o in ([0.0, 0.0, 10.0], [20.0, -10.0, 15.0], [-30.0, 25.0, 5.0]):
        d = _unit(rng.normal(size=(6000, 3)))
        origins.append(np.broadcast_to(o, d.shape))
        dirs.append(d)
    origins, dirs = np.vstack(origins), np.vstack(dirs)
    start = np.full(len(dirs), EXIT_MARGIN_M)
    radii = np.linalg.norm(half, axis=1) + EXIT_MARGIN_M
    # WHEN the moving-body cast takes every ray, and only each sensor's candidates
    full = world.cast(origins, dirs, start, start, (centers, quats, half))
    candidates = np.concatenate([k * 6000 + moving_body_candidates(origins[k * 6000], dirs[k * 6000:(k + 1) * 6000],
                                                                   max_range_m, centers, radii)
                                 for k in range(3)])
    culled = world.cast(origins, dirs, start, start, (centers, quats, half), candidates)
    # THEN far fewer rays were cast against the bodies, and every hit within range is the same
    assert len(candidates) < 0.2 * len(dirs)
    within = full.t <= max_range_m
    assert (full.cls[within] == MOVING_BODY).sum() >= 10                  # bodies were hit
    np.testing.assert_array_equal(culled.t[within], full.t[within])
    np.testing.assert_array_equal(culled.cls[within], full.cls[within])
    np.testing.assert_array_equal(culled.box[within], full.box[within])
    np.testing.assert_array_equal(culled.normal[within], full.normal[within])


def test_the_own_vehicle_is_left_out_and_a_sensor_inside_another_bodys_sphere_keeps_every_ray():
    dirs = _unit(np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, -1.0]]))
    centers = np.array([[0.0, 0.0, 0.0], [10.0, 0.0, 0.0]])
    radii = np.array([0.4, 0.4])
    # own body 0 left out: only the ray towards body 1 remains
    assert moving_body_candidates(np.zeros(3), dirs, 30.0, centers, radii, exclude=0).tolist() == [0]
    # body 1 beyond the range: nothing to cast
    assert moving_body_candidates(np.zeros(3), dirs, 5.0, centers, radii, exclude=0).size == 0
    # a sensor within body 1's bounding sphere (not its own): every ray
    assert moving_body_candidates(np.array([10.1, 0.0, 0.0]), dirs, 30.0, centers, radii, exclude=0).tolist() == [0, 1, 2]


def test_binned_candidates_of_many_sensors_sharing_a_pattern_are_exactly_the_per_sensor_candidates(rng):
    # GIVEN 12 LiDARs (360 x 16 pattern) at random attitudes among 60 drone-sized bodies, some very close,
    # one sensor inside a body's sphere and each sensor's own body in the list
    from unetyemu_ecs.frames import R_from_quat_xyzw
    from unetyemu_ecs.sensors.lidar import LidarSensor, ray_directions_sensor
    from unetyemu_ecs.sensors.raycast import direction_bins, moving_body_candidates_binned

    pattern, _ = ray_directions_sensor(LidarSensor())
    n, n_bodies = 12, 60
    origins = np.column_stack([rng.uniform(-40, 40, n), rng.uniform(-40, 40, n), rng.uniform(2, 20, n)])
    R = R_from_quat_xyzw(quat_normalize_xyzw(rng.normal(size=(n, 4))))
    centers = np.vstack([origins, np.column_stack([rng.uniform(-60, 60, n_bodies - n), rng.uniform(-60, 60, n_bodies - n),
                                                  rng.uniform(1, 25, n_bodies - n)])])
    centers[n] = origins[3] + [0.2, 0.0, 0.1]                               # sensor 3 sits inside this body's sphere
    centers[n + 1] = origins[5] + [1.5, 0.3, -0.2]                          # a body right next to sensor 5
    radii = np.full(n_bodies, np.linalg.norm([0.25, 0.25, 0.08]) + EXIT_MARGIN_M)
    max_range = np.full(n, 30.0)
    own = np.arange(n)                                                      # sensor k rides body k
    dirs_world = np.concatenate([pattern @ R[k].T for k in range(n)])
    # WHEN the candidates are found with the direction bins for all sensors at once, and sensor by sensor
    binned = moving_body_candidates_binned(origins, R, dirs_world, direction_bins(pattern), max_range, centers,
                                           radii, own)
    k = len(pattern)
    each = np.concatenate([j * k + moving_body_candidates(origins[j], dirs_world[j * k:(j + 1) * k], 30.0, centers,
                                                          radii, exclude=j) for j in range(n)])
    # THEN both are the same rays (the bins only skip rays that cannot meet a body)
    np.testing.assert_array_equal(binned, np.sort(each))
    assert k * 1 <= len(binned) < 0.3 * len(dirs_world)                     # sensor 3 keeps all its rays; most are culled
