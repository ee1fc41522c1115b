"""Pure pursuit: the virtual target leads the drone along the route and settles on the last point."""

from __future__ import annotations

import numpy as np
from numpy.testing import assert_allclose

from unetyemu_ecs.control.pursuit import pure_pursuit


def _one(route, pos, seg=0, speeds=None, lead=3.0, zone=5.0):
    route = np.asarray(route, dtype=float)[None]
    if speeds is None:
        speeds = np.ones_like(route)
    return pure_pursuit(np.asarray(pos, dtype=float)[None], route, np.array([route.shape[1]]), np.array([seg]),
                        np.asarray(speeds, dtype=float).reshape(route.shape), np.array([lead]), np.array([zone]))


def test_target_is_the_lead_distance_ahead_of_the_projection_on_a_straight_route():
    # GIVEN a 20 m route east and a drone 1 m north of its 5 m mark
    res = _one([[0, 0, 10], [20, 0, 10]], [5, 1, 10])
    # THEN the target is 3 m further along, on the route, and the cross-track error is 1 m
    assert_allclose(res.target_enu_m[0], [8, 0, 10], atol=1e-12)
    assert_allclose(res.cross_track_m[0], 1.0)
    assert_allclose(res.dist_to_go_m[0], 15.0 + 1.0)


def test_lead_shrinks_linearly_inside_the_final_approach_zone():
    # GIVEN a drone 2.5 m before the end with a 5 m final zone
    res = _one([[0, 0, 0], [20, 0, 0]], [17.5, 0, 0])
    # THEN the lead is 3 * 2.5/5 = 1.5 m
    assert_allclose(res.target_enu_m[0], [19.0, 0, 0], atol=1e-12)
    # AND at the end the target sits on the last point
    res = _one([[0, 0, 0], [20, 0, 0]], [20.2, 0, 0])
    assert_allclose(res.target_enu_m[0], [20, 0, 0], atol=1e-12)


def test_target_turns_the_corner_onto_the_next_segment():
    # GIVEN an L-shaped route and a drone 1 m before the corner
    res = _one([[0, 0, 0], [10, 0, 0], [10, 10, 0]], [9, 0, 0])
    # THEN the target is 2 m past the corner on the second leg
    assert_allclose(res.target_enu_m[0], [10, 2, 0], atol=1e-12)
    assert res.segment[0] == 0


def test_segment_advances_once_the_drone_is_past_the_corner():
    res = _one([[0, 0, 0], [10, 0, 0], [10, 10, 0]], [10.3, 1.0, 0])
    assert res.segment[0] == 1
    assert_allclose(res.target_enu_m[0], [10, 4, 0], atol=1e-12)


def test_speeds_interpolate_along_the_segment():
    speeds = [[2, 1, 1], [6, 3, 1]]
    res = _one([[0, 0, 0], [20, 0, 0]], [5, 0, 0], speeds=speeds)
    assert_allclose(res.speed_lims_m_s[0], [3, 1.5, 1])


def test_fleet_of_mixed_route_lengths_matches_drone_by_drone(rng):
    # GIVEN three drones, routes of 2, 3 and 4 points padded to W = 4
    routes = [rng.uniform(-20, 20, (n, 3)) for n in (2, 3, 4)]
    padded = np.stack([np.vstack([r, np.repeat(r[-1:], 4 - len(r), axis=0)]) for r in routes])
    pos = rng.uniform(-20, 20, (3, 3))
    speeds = rng.uniform(1, 5, (3, 4, 3))
    fleet = pure_pursuit(pos, padded, np.array([2, 3, 4]), np.zeros(3, int), speeds, np.full(3, 3.0), np.full(3, 5.0))
    # WHEN each is computed alone
    for m, r in enumerate(routes):
        one = pure_pursuit(pos[m:m + 1], r[None], np.array([len(r)]), np.zeros(1, int), speeds[m:m + 1, :len(r)],
                           np.array([3.0]), np.array([5.0]))
        # THEN the fleet result is the same
        assert_allclose(fleet.target_enu_m[m], one.target_enu_m[0], atol=1e-9)
        assert fleet.segment[m] == one.segment[0]
