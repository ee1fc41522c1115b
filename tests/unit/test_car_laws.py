"""Ground-vehicle laws without esper or PyBullet: steering geometry, torque curve, speed control, corner speeds."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose

from unetyemu_ecs.control.car import (SpeedSteerGains, ackermann_angles, bicycle_limit_rad, corner_speeds_m_s,
                                      drive_torque_n_m, pure_pursuit_steer, route_speed_sp, speed_to_throttle_brake,
                                      steer_limit_rad, yaw_rate_to_steer)

L, T = np.array([2.7]), np.array([1.55])


def test_ackermann_wheels_turn_about_one_centre_on_the_rear_axle_line():
    delta = np.deg2rad([10.0, -20.0])
    angles = ackermann_angles(delta, np.full(2, 2.7), np.full(2, 1.55))
    radius = 2.7 / np.tan(np.abs(delta))                      # turn centre from the centre line
    inner = np.where(delta > 0, angles[:, 0], angles[:, 1])   # left wheel is inner in a left turn
    outer = np.where(delta > 0, angles[:, 1], angles[:, 0])
    assert_allclose(np.abs(inner), np.arctan(2.7 / (radius - 0.775)))
    assert_allclose(np.abs(outer), np.arctan(2.7 / (radius + 0.775)))
    assert np.all(np.abs(inner) > np.abs(delta)) and np.all(np.abs(outer) < np.abs(delta))
    assert np.all(np.sign(angles) == np.sign(delta)[:, None])
    assert_allclose(ackermann_angles(np.zeros(1), L, T), 0.0)


def test_bicycle_limit_puts_the_inner_wheel_exactly_on_the_wheel_limit():
    lim = np.deg2rad([30.0])
    delta = bicycle_limit_rad(lim, L, T)
    assert_allclose(ackermann_angles(delta, L, T)[0, 0], lim[0])


def test_steering_limit_falls_linearly_to_its_scale_at_50_m_s():
    lim = steer_limit_rad(np.array([0.0, 25.0, 50.0, 80.0]), np.deg2rad(30.0), 0.3)
    assert_allclose(np.rad2deg(lim), [30.0, 19.5, 9.0, 9.0])


def test_drive_torque_fades_to_zero_at_top_speed_and_reverses_with_negative_throttle():
    tq = drive_torque_n_m(np.array([1.0, 1.0, 1.0, -1.0, -1.0]), np.array([0.0, 12.5, 25.0, 0.0, 10.0]),
                          3000.0, 25.0)
    assert_allclose(tq, [3000.0, 1500.0, 0.0, -3000.0, -3000.0])


def test_speed_control_drives_below_the_setpoint_brakes_above_and_holds_a_stopped_car():
    g = SpeedSteerGains()
    args = dict(dt_s=1 / 240, feedforward_n=np.full(3, 220.0), mass_kg=np.full(3, 1500.0),
                wheel_radius_m=np.full(3, 0.4), max_drive_n_m=np.full(3, 3000.0), max_brake_n_m=np.full(3, 2000.0),
                top_speed_m_s=np.full(3, 25.0), gains=g)
    throttle, brake, _ = speed_to_throttle_brake(np.array([10.0, 2.0, 0.0]), np.array([5.0, 8.0, 0.0]),
                                                 np.zeros(3), **args)
    assert throttle[0] > 0 and brake[0] == 0          # too slow: drive
    assert throttle[1] == 0 and brake[1] > 0          # too fast: brake, no throttle
    assert throttle[2] == 0 and brake[2] == 1.0       # stopped and asked to stay: full brake
    # the largest braking is the comfort limit: brake fraction = m a r / (4 T_brake)
    _, brake, _ = speed_to_throttle_brake(np.array([0.0]), np.array([20.0]), np.zeros(1),
                                          **{k: (v[:1] if isinstance(v, np.ndarray) else v) for k, v in args.items()})
    assert brake[0] == pytest.approx((1500 * g.max_decel_m_s2 - 220.0) * 0.4 / (4 * 2000.0))


def test_yaw_rate_to_steer_is_the_bicycle_model_when_the_rate_is_met():
    steer = yaw_rate_to_steer(np.array([0.25]), np.array([0.25]), np.array([5.0]), L, SpeedSteerGains())
    assert_allclose(steer, np.arctan(2.7 * 0.25 / 5.0))


def test_pure_pursuit_steers_onto_the_arc_through_the_target():
    # target 10 m ahead and 10 m left of the rear axle: the arc through it has radius 10 m
    steer = pure_pursuit_steer(np.array([[10.0, 10.0, 0.0]]), np.zeros((1, 3)), np.zeros(1), L)
    assert_allclose(steer, np.arctan(2.7 / 10.0))
    right = pure_pursuit_steer(np.array([[10.0, -10.0, 0.0]]), np.zeros((1, 3)), np.zeros(1), L)
    assert_allclose(right, -steer)


def test_corner_speeds_follow_lateral_acceleration_and_an_open_route_stops_at_its_end():
    # a quarter circle of radius 12 m sampled every 30 degrees, between two straights
    ang = np.deg2rad([0, 30, 60, 90])
    arc = np.c_[12 * np.sin(ang), 12 - 12 * np.cos(ang), np.zeros(4)]
    pts = np.vstack([[-30.0, 0.0, 0.0], arc, [12.0, 42.0, 0.0]])
    v = corner_speeds_m_s(pts, 8.0, 2.5, loop=False)
    assert_allclose(v[2:4], np.sqrt(2.5 * 12.0))
    assert v[0] == 8.0 and v[-1] == 0.0


def test_route_speed_brakes_in_time_for_what_lies_ahead():
    cum = np.array([[0.0, 50.0, 100.0]])
    limits = np.array([[8.0, 3.0, 0.0]])
    sp = route_speed_sp(np.array([40.0, 90.0, 60.0]), np.repeat(cum, 3, axis=0), np.repeat(limits, 3, axis=0),
                        np.full(3, 2.0))
    assert_allclose(sp, [np.sqrt(9 + 2 * 2 * 10), np.sqrt(2 * 2 * 10), np.sqrt(2 * 2 * 40)])
