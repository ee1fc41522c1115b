"""Geofence containment: PX4's rule (inside some inclusion zone, or none exist; inside no exclusion zone)."""

from __future__ import annotations

import numpy as np
import pytest

from unetyemu_ecs.navigation.geofence import Geofence

SQUARE = [(0.0, 0.0), (100.0, 0.0), (100.0, 100.0), (0.0, 100.0)]


def test_empty_fence_allows_everything():
    fence = Geofence()
    assert fence.empty
    assert fence.contains((1e4, -1e4, 50.0)) is True
    assert fence.contains(np.zeros((3, 3))).tolist() == [True, True, True]


def test_inclusion_polygon_contains_inside_points_only_and_ignores_height():
    # GIVEN a 100 m square inclusion zone
    fence = Geofence(inclusion_polygons=(SQUARE,))
    # WHEN points inside, outside and at any height are checked (vectorised)
    pts = np.array([[50.0, 50.0, 0.0], [50.0, 50.0, 9000.0], [150.0, 50.0, 10.0], [-1.0, 50.0, 10.0],
                    [50.0, 101.0, 10.0]])
    # THEN only the horizontal position counts
    assert fence.contains(pts).tolist() == [True, True, False, False, False]


def test_concave_polygon():
    # an L shape: the notch (75, 75) is outside
    ell = [(0, 0), (100, 0), (100, 50), (50, 50), (50, 100), (0, 100)]
    fence = Geofence(inclusion_polygons=(ell,))
    assert fence.contains(np.array([[25.0, 75.0], [75.0, 25.0], [75.0, 75.0]])).tolist() == [True, True, False]


def test_inclusion_circle_and_union_of_inclusions():
    # GIVEN a square and a circle of 20 m around (300, 0): being in either is enough
    fence = Geofence(inclusion_polygons=(SQUARE,), inclusion_circles=((300.0, 0.0, 20.0),))
    pts = np.array([[50.0, 50.0], [310.0, 5.0], [330.0, 0.0], [200.0, 0.0]])
    assert fence.contains(pts).tolist() == [True, True, False, False]


def test_exclusion_zones_cut_holes():
    # GIVEN a square inclusion zone with a circular hole and an excluded triangle
    fence = Geofence(inclusion_polygons=(SQUARE,), exclusion_circles=((50.0, 50.0, 10.0),),
                     exclusion_polygons=([(80.0, 0.0), (100.0, 0.0), (100.0, 20.0)],))
    pts = np.array([[50.0, 50.0], [50.0, 65.0], [95.0, 5.0], [85.0, 15.0]])
    assert fence.contains(pts).tolist() == [False, True, False, True]


def test_exclusion_only_fence_allows_everything_else():
    fence = Geofence(exclusion_circles=((0.0, 0.0, 5.0),))
    assert fence.contains((0.0, 0.0, 0.0)) is False
    assert fence.contains((6.0, 0.0, 0.0)) is True


@pytest.mark.parametrize("kwargs, message", [
    ({"inclusion_polygons": ([(0, 0), (1, 1)],)}, "K >= 3"),
    ({"exclusion_polygons": ([(0, 0), (1, np.nan), (1, 0)],)}, "finite"),
    ({"inclusion_circles": ((0.0, 0.0, 0.0),)}, "radius > 0"),
])
def test_bad_zones_are_refused_with_the_field_named(kwargs, message):
    with pytest.raises(ValueError, match=message):
        Geofence(**kwargs)
