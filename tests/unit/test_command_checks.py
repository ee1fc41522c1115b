"""The command range checks (unetyemu_ecs.command_checks) without a simulation: each refusal names the
command, the vehicle, the field and its range; what passes comes back as floats in SI units."""

from __future__ import annotations

import math

import numpy as np
import pytest

from unetyemu_ecs.command_checks import (MAX_LAPS, check_armed, check_cmd_vel, check_drive, check_drive_route,
                                         check_hold_s, check_in_world, check_set_target, check_teleop,
                                         finite_floats)
from unetyemu_ecs.scene.primitives import SceneLayout

# A world spanning x in [-150, 150] m, y in [-100, 100] m (ENU), nothing built on it.
LAYOUT = SceneLayout((), {}, {}, np.array([-150.0, -100.0]), np.array([150.0, 100.0]))
EXTENT = r"x in \[-150, 150\] m, y in \[-100, 100\] m"


@pytest.mark.parametrize("hold_s", [0, 0.0, -1.0, float("nan"), float("inf"), 3600.001, 3601, True, "1"])
def test_a_hold_time_outside_0_to_an_hour_is_refused_naming_the_command_and_range(hold_s):
    # GIVEN a hold time that is not a number of seconds in (0, 3600]
    # WHEN a teleop command carries it
    # THEN it is refused, naming the command, the field and the range
    with pytest.raises(ValueError, match=r"teleop\('d1'\): hold_s must be None or a number of seconds "
                                         r"in \(0, 3600\]"):
        check_teleop("d1", 0.0, 0.0, 0.0, 0.0, hold_s)


def test_a_hold_time_of_none_or_up_to_an_hour_is_kept():
    assert check_hold_s("drive('c1')", None) is None
    assert check_hold_s("drive('c1')", np.float32(0.5)) == 0.5
    assert check_hold_s("drive('c1')", 3600) == 3600.0 and isinstance(check_hold_s("x", 3600), float)


def test_a_target_outside_the_world_names_the_worlds_extent():
    # GIVEN a world 300 m x 200 m WHEN a target lies 1 m beyond its east edge
    # THEN the refusal names the command, the point and the world's extent
    with pytest.raises(ValueError, match=rf"set_target\('d1'\): \(151, 0\) is outside the world, which spans {EXTENT}"):
        check_set_target("d1", "quadrotor", LAYOUT, 151.0, 0.0, 10.0)
    # AND a point on the edge is inside
    check_in_world("set_target('d1')", LAYOUT, [(150.0, -100.0)])


def test_a_drone_target_height_must_be_between_the_ground_and_10_km_but_a_car_ignores_it():
    with pytest.raises(ValueError, match=r"set_target\('d1'\): z must be in \[0, 10000\] m"):
        check_set_target("d1", "quadrotor", LAYOUT, 0.0, 0.0, 10_001.0)
    with pytest.raises(ValueError, match=r"z must be in \[0, 10000\] m"):
        check_set_target("d1", "quadrotor", LAYOUT, 0.0, 0.0, -0.1)
    pos, _, _ = check_set_target("c1", "car", LAYOUT, 1.0, 2.0, -0.1)
    assert pos == (1.0, 2.0, -0.1)


@pytest.mark.parametrize("speed", [0.0, -1.0, 30.001, 1e300])
def test_a_target_speed_outside_0_to_30_m_s_is_refused(speed):
    with pytest.raises(ValueError, match=r"set_target\('d1'\): speed must be in \(0, 30\] m/s"):
        check_set_target("d1", "quadrotor", LAYOUT, 10.0, 0.0, 5.0, speed=speed)


@pytest.mark.parametrize("yaw_deg", [360.5, -361.0, 1e300])
def test_a_target_heading_beyond_a_turn_either_way_is_refused(yaw_deg):
    with pytest.raises(ValueError, match=r"set_target\('d1'\): yaw_deg must be in \[-360, 360\] deg"):
        check_set_target("d1", "quadrotor", LAYOUT, 0.0, 0.0, 5.0, yaw_deg=yaw_deg)


def test_a_valid_target_comes_back_as_floats_with_the_yaw_in_radians():
    # GIVEN numpy numbers, as a transport decodes them
    pos, yaw_rad, speed = check_set_target("d1", "quadrotor", LAYOUT, np.float32(10.0), np.int64(-5), 20.0,
                                           yaw_deg=90.0, speed=np.float64(30.0))
    assert pos == (10.0, -5.0, 20.0) and all(type(v) is float for v in pos)
    assert yaw_rad == pytest.approx(math.pi / 2) and speed == 30.0 and type(speed) is float
    assert check_set_target("d1", "quadrotor", LAYOUT, 0.0, 0.0, 5.0)[1:] == (None, None)


@pytest.mark.parametrize("values", [(True, 0.0, 5.0), (float("nan"), 0.0, 5.0), (0.0, "1", 5.0),
                                    (0.0, 0.0, float("inf"))])
def test_a_target_that_is_not_finite_numbers_is_refused(values):
    with pytest.raises(ValueError, match=r"set_target\('d1'\): values must be finite numbers"):
        check_set_target("d1", "quadrotor", LAYOUT, *values)


@pytest.mark.parametrize("kwargs", [{"forward_m_s": 30.5}, {"forward_m_s": -31.0}, {"left_m_s": 31.0},
                                    {"up_m_s": -40.0}])
def test_cmd_vel_beyond_30_m_s_is_refused_naming_the_limits(kwargs):
    args = {"forward_m_s": 0.0, "yaw_rate_rad_s": 0.0} | kwargs
    with pytest.raises(ValueError, match=r"cmd_vel\('d1'\): speeds must be within \+-30 m/s and the yaw rate "
                                         r"within \+-6\.28319 rad/s"):
        check_cmd_vel("d1", **args)


def test_cmd_vel_beyond_a_turn_a_second_is_refused_and_at_the_limits_is_kept():
    with pytest.raises(ValueError, match=r"cmd_vel\('c1'\): .*yaw rate within \+-6\.28319 rad/s"):
        check_cmd_vel("c1", 1.0, 2 * math.pi + 1e-6)
    assert check_cmd_vel("d1", 30, -2 * math.pi, -30.0, 30.0, hold_s=0.5) == (30.0, -2 * math.pi, -30.0, 30.0, 0.5)


def test_cmd_vel_refuses_non_numbers_before_ranges():
    with pytest.raises(ValueError, match=r"cmd_vel\('c1'\): values must be finite numbers"):
        check_cmd_vel("c1", False, 0.0)
    with pytest.raises(ValueError, match=r"cmd_vel\('c1'\): values must be finite numbers"):
        check_cmd_vel("c1", 1.0, float("nan"))


@pytest.mark.parametrize("sticks", [(1.01, 0, 0, 0), (0, -1.5, 0, 0), (0, 0, float("nan"), 0), (0, 0, 0, None)])
def test_drone_sticks_outside_minus_1_to_1_are_refused(sticks):
    with pytest.raises(ValueError, match=r"teleop\('d1'\): sticks must be finite numbers in \[-1, 1\]"):
        check_teleop("d1", *sticks)


def test_drone_sticks_at_full_deflection_are_kept():
    assert check_teleop("d1", 1, -1.0, np.float32(0.5), 0.0) == ((1.0, -1.0, 0.5, 0.0), None)


@pytest.mark.parametrize("controls", [(1.1, 0.0, 0.0), (0.0, -0.1, 0.0), (0.0, 1.1, 0.0), (0.0, 0.0, -1.1),
                                      (float("nan"), 0.0, 0.0)])
def test_car_controls_outside_their_ranges_are_refused_naming_every_range(controls):
    with pytest.raises(ValueError, match=r"drive\('c1'\): need throttle in \[-1, 1\], brake in \[0, 1\], "
                                         r"steering in \[-1, 1\]"):
        check_drive("c1", *controls)


def test_car_controls_in_range_are_kept_with_their_hold_time():
    assert check_drive("c1", -1, 1, 1.0, hold_s=2.0) == (-1.0, 1.0, 1.0, 2.0)
    with pytest.raises(ValueError, match=r"drive\('c1'\): hold_s must be None"):
        check_drive("c1", 0.0, 0.0, 0.0, hold_s=0.0)


@pytest.mark.parametrize("armed", ["yes", "False", 1, 0, None])
def test_arm_takes_only_booleans(armed):
    with pytest.raises(ValueError, match=r"arm\('d1'\): armed must be True or False"):
        check_armed("d1", armed)


def test_arm_takes_numpy_booleans():
    assert check_armed("d1", np.bool_(False)) is False and check_armed("d1", True) is True


@pytest.mark.parametrize("kwargs, message", [
    ({"waypoints": []}, r"need at least one finite \(x, y\) waypoint"),
    ({"waypoints": [(0.0, float("nan"))]}, r"need at least one finite \(x, y\) waypoint"),
    ({"waypoints": [(0.0, "a")]}, r"waypoints must be \(x, y\) pairs of numbers"),
    ({"waypoints": [(0.0, 1.0, 2.0)]}, r"waypoints must be \(x, y\) pairs of numbers"),
    ({"waypoints": [(0.0, 0.0), (0.0, 101.0)]}, rf"\(0, 101\) is outside the world, which spans {EXTENT}"),
    ({"speed": 0.0}, r"speed must be a number in \(0, 30\] m/s, got 0.0"),
    ({"speed": float("inf")}, r"speed must be a number in \(0, 30\] m/s"),
    ({"speed": 30.5}, r"speed must be a number in \(0, 30\] m/s, got 30.5"),
    ({"speed": "5"}, r"speed must be a number in \(0, 30\] m/s, got '5'"),
    ({"speed": True}, r"speed must be a number in \(0, 30\] m/s, got True"),
    ({"waypoints": [("1", 2)]}, r"waypoints must be \(x, y\) pairs of numbers"),
    ({"waypoints": [(True, 2)]}, r"waypoints must be \(x, y\) pairs of numbers"),
    ({"waypoints": [(1.0, 1.0)] * 1001}, "at most 1000 waypoints, got 1001"),
    ({"loop": "yes"}, "loop must be True or False, got 'yes'"),
    ({"waypoints": [(0, 0), (10, 0)], "loop": True}, "a loop needs at least 3 waypoints, got 2"),
    ({"laps": 2}, r"laps must be an integer in \[0, 10000\] and needs loop=True"),
    ({"loop": True, "laps": MAX_LAPS + 1}, r"laps must be an integer in \[0, 10000\]"),
    ({"loop": True, "laps": -1}, r"laps must be an integer in \[0, 10000\]"),
    ({"loop": True, "laps": 2.0}, r"laps must be an integer in \[0, 10000\]"),
    ({"loop": True, "laps": True}, r"laps must be an integer in \[0, 10000\]"),
])
def test_a_bad_route_is_refused_naming_what_is_wrong(kwargs, message):
    args = {"waypoints": [(0, 0), (10, 0), (10, 10)]} | kwargs
    with pytest.raises(ValueError, match=r"drive_route\('c1'\): " + message):
        check_drive_route("c1", LAYOUT, **args)


def test_a_valid_route_comes_back_as_float_pairs():
    wp, speed, loop, laps = check_drive_route("c1", LAYOUT, [(0, 0), (10, np.float32(0)), [10, 10]], speed=5,
                                              loop=True, laps=np.int64(3))
    assert wp == ((0.0, 0.0), (10.0, 0.0), (10.0, 10.0)) and (speed, loop, laps) == (5.0, True, 3)
    assert type(laps) is int and type(speed) is float


def test_finite_floats_names_the_field_and_shows_the_values_as_floats():
    assert finite_floats("target values", [np.float32(1.5), 2]) == [1.5, 2.0]
    with pytest.raises(ValueError, match=r"cmd_vel linear must be finite numbers, got \[1\.0, nan, 0\.0\]"):
        finite_floats("cmd_vel linear", [np.float32(1.0), np.float32("nan"), 0.0])
