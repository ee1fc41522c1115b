"""Layer-2 and layer-3 laws without esper or PyBullet: hover, tilt compensation, windup, limits, signs."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from numpy.testing import assert_allclose

from unetyemu_ecs.control.attitude import (StabilizerGains, attitude_to_torque_cmd, manual_to_setpoints,
                                           vertical_speed_to_thrust_frac)
from unetyemu_ecs.control.position import (GuidanceGains, accel_to_tilt_sp, body_velocity_to_enu_sp, heading_to_yaw_rate_sp,
                                           position_to_velocity_sp, velocity_to_accel_sp)

G = 9.81
SG = StabilizerGains()
GG = GuidanceGains()


def one(x):
    return np.array([x], dtype=float)


def test_level_hover_asks_for_exactly_the_hover_thrust_fraction():
    thrust, integ = vertical_speed_to_thrust_frac(one(0), one(0), one(0), one(0), one(0.6), one(1.0), 1 / 240, SG)
    assert_allclose(thrust, 0.6)
    assert_allclose(integ, 0.0)


def test_tilt_compensation_divides_by_cos_tilt():
    tilt = np.deg2rad(30.0)
    thrust, _ = vertical_speed_to_thrust_frac(one(0), one(0), one(0), one(0), one(0.5), one(np.cos(tilt)), 0.01, SG)
    assert_allclose(thrust, 0.5 / np.cos(tilt))


def test_integrator_takes_up_an_extra_load_in_a_closed_loop():
    # GIVEN an 8 kg drone (F_max 32 N/motor) with 2.5 kg of load its parameters do not know about
    m_nominal, m_true, f_max4, dt = 8.0, 10.5, 4 * 32.0, 1 / 240
    hover = m_nominal * G / f_max4
    vz, integ, acc = 0.0, 0.0, 0.0
    for _ in range(240 * 20):
        thrust, integ = vertical_speed_to_thrust_frac(one(0), one(vz), one(acc), one(integ), one(hover), one(1.0), dt, SG)
        acc = float(thrust[0]) * f_max4 / m_true - G
        vz += acc * dt
        integ = float(integ[0])
    # THEN the vertical speed error vanishes and the thrust carries the true weight
    assert abs(vz) < 1e-3
    assert_allclose(float(thrust[0]) * f_max4, m_true * G, rtol=1e-3)


def test_integral_does_not_wind_up_while_the_output_is_saturated():
    integ = np.zeros(1)
    for _ in range(240 * 10):
        thrust, integ = vertical_speed_to_thrust_frac(one(8.0), one(0), one(0), integ, one(0.6), one(1.0), 1 / 240, SG)
        assert thrust[0] <= 1.0
    # saturated from the start: the integral never grew
    assert abs(integ[0]) < 0.05


def test_rate_pd_pushes_toward_the_setpoint_and_damps_the_rate():
    torque = attitude_to_torque_cmd(one(0.1), one(-0.1), one(0.5), one(0.0), one(0.0), np.zeros((1, 3)), SG)
    assert torque[0, 0] > 0 and torque[0, 1] < 0 and torque[0, 2] > 0
    damping = attitude_to_torque_cmd(one(0), one(0), one(0), one(0), one(0), np.array([[1.0, 1.0, 0.0]]), SG)
    assert_allclose(damping[0, :2], -SG.gain_rate_d)


def test_sticks_map_to_setpoints_with_the_documented_signs_and_limits():
    stick = np.array([[1.0, 1.0, 1.0, 1.0], [-1.0, -0.5, -0.5, -1.0], [0, 0, 0, 0]])
    vz, roll, pitch, yaw_rate = manual_to_setpoints(stick, np.full(3, 0.7), np.full(3, 8.0), np.full(3, 5.0),
                                                    np.full(3, np.pi / 2))
    assert_allclose(vz, [8.0, -5.0, 0.0])
    assert pitch[0] > 0 and roll[0] > 0           # +1 = forward = nose down, +1 = right = right side down
    assert pitch[1] < 0 and roll[1] < 0
    assert_allclose(yaw_rate, [np.pi / 2, -np.pi / 2, 0.0])
    one_axis = np.array([[0.0, 1.0, 0.0, 0.0], [0.0, 0.0, -0.5, 0.0]])
    _, roll, pitch, _ = manual_to_setpoints(one_axis, np.full(2, 0.7), np.full(2, 8.0), np.full(2, 5.0), np.ones(2))
    assert_allclose(pitch, [0.7, 0.0], atol=1e-12)   # one stick alone: its angle is stick * lim_tilt
    assert_allclose(roll, [0.0, -0.35], atol=1e-12)


def test_broken_sticks_read_as_centred_or_full_and_the_compiled_mapping_is_numpys_to_rounding():
    def numpy_mapping(stick, lim_tilt, lim_climb, lim_descent, lim_yaw_rate):     # the array law it replaced
        s = np.clip(np.nan_to_num(stick), -1.0, 1.0)
        length = np.hypot(s[:, 1], s[:, 2])
        k = np.tan(np.minimum(length, 1.0) * lim_tilt) / np.maximum(length, 1e-12)
        pitch = np.arctan(k * s[:, 1])
        return (np.where(s[:, 0] >= 0.0, s[:, 0] * lim_climb, s[:, 0] * lim_descent),
                np.arctan(k * s[:, 2] * np.cos(pitch)), pitch, s[:, 3] * lim_yaw_rate)

    rng = np.random.default_rng(7)
    sticks = rng.uniform(-1.5, 1.5, (500, 4))
    sticks[::7, 1], sticks[::11, 2], sticks[::13, 0], sticks[::17, 1:3] = np.nan, np.inf, -np.inf, 0.0
    limits = (rng.uniform(0.1, 1.0, 500), rng.uniform(1.0, 5.0, 500), rng.uniform(1.0, 5.0, 500),
              rng.uniform(0.5, 3.0, 500))
    for got, expected in zip(manual_to_setpoints(sticks, *limits), numpy_mapping(sticks, *limits)):
        assert_allclose(got, expected, rtol=1e-13, atol=0.0)
    vz, roll, pitch, _ = manual_to_setpoints(np.array([[np.nan, np.inf, 0.0, 0.0]]), 0.5, 3.0, 2.0, 1.0)
    assert (vz[0], roll[0]) == (0.0, 0.0) and pitch[0] == pytest.approx(0.5)   # NaN centred, +inf full


def total_tilt_rad(roll: np.ndarray, pitch: np.ndarray) -> np.ndarray:
    """Angle between the body z axis and the vertical for roll-then-pitch Euler angles."""
    return np.arccos(np.cos(roll) * np.cos(pitch))


def test_full_pitch_and_full_roll_together_tilt_by_the_limit_not_more():
    lim = np.deg2rad(np.full(3, 45.0))
    sticks = np.array([[1.0, 1.0, 1.0, 0.0], [1.0, -1.0, 1.0, 0.0], [1.0, 0.5, 0.5, 0.0]])
    _, roll, pitch, _ = manual_to_setpoints(sticks, lim, np.full(3, 8.0), np.full(3, 5.0), np.ones(3))
    tilt = total_tilt_rad(roll, pitch)
    assert_allclose(tilt[:2], lim[:2], rtol=1e-9)                    # was ~60 deg on a 45 deg preset
    assert_allclose(tilt[2], np.hypot(0.5, 0.5) * lim[2], rtol=1e-9)   # length of the stick vector x limit
    assert_allclose(abs(roll[0]), abs(pitch[0]), rtol=0.2)            # diagonal: both axes share the tilt


def test_velocity_setpoint_cruises_at_the_limit_far_away_and_brakes_as_sqrt_2ad_near_the_end():
    pos = np.zeros((2, 3))
    target = np.array([[3.0, 0, 0], [1.0, 0, 0]])
    vel = position_to_velocity_sp(target, pos, np.array([100.0, 1.0]), np.full(2, 10.0), np.full(2, 8.0),
                                  np.full(2, 5.0), GG)
    assert_allclose(vel[0], [10.0, 0, 0])
    assert_allclose(vel[1], [min(GG.gain_pos_p * 1.0, np.sqrt(2 * GG.lim_decel_m_s2 * 1.0)), 0, 0])


def test_climb_and_descent_limits_scale_the_whole_line_of_sight():
    pos = np.zeros((2, 3))
    target = np.array([[0.3, 0, 3.0], [0, 0, -3.0]])
    vel = position_to_velocity_sp(target, pos, np.full(2, 50.0), np.full(2, 10.0), np.full(2, 3.0), np.full(2, 1.5), GG)
    assert_allclose(vel[0, 2], 3.0)
    assert_allclose(vel[0, 0], 0.3)          # small sideways error -> small sideways speed
    assert_allclose(vel[1], [0, 0, -1.5])


def test_horizontal_acceleration_never_exceeds_g_tan_max_tilt(rng):
    vel_sp = rng.uniform(-100, 100, (200, 3))
    lim = rng.uniform(0.2, 0.8, 200)
    acc, _ = velocity_to_accel_sp(vel_sp, np.zeros((200, 3)), np.zeros((200, 2)), 1 / 240, lim, GG)
    assert np.all(np.linalg.norm(acc, axis=1) <= G * np.tan(lim) + 1e-9)
    roll, pitch = accel_to_tilt_sp(acc * 3.0, rng.uniform(-np.pi, np.pi, 200), lim)
    tilt = np.arccos(np.cos(roll) * np.cos(pitch))
    assert np.all(tilt <= lim + 1e-9)


@pytest.mark.parametrize("yaw, acc, expect", [
    (0.0, [2.0, 0.0], "pitch+"),            # facing east, accelerate east: nose down
    (0.0, [0.0, 2.0], "roll-"),             # facing east, accelerate north (left): left side down
    (np.pi / 2, [0.0, 2.0], "pitch+"),      # facing north, accelerate north
    (np.pi / 2, [2.0, 0.0], "roll+"),       # facing north, accelerate east (right): right side down
])
def test_tilt_direction_follows_the_acceleration(yaw, acc, expect):
    roll, pitch = accel_to_tilt_sp(np.array([acc]), one(yaw), one(0.7))
    value = {"pitch": pitch[0], "roll": roll[0]}[expect[:-1]]
    other = {"pitch": roll[0], "roll": pitch[0]}[expect[:-1]]
    assert (value > 0) == (expect[-1] == "+") and abs(value) > 0.1
    assert abs(other) < 1e-9


def test_yaw_rate_turns_the_short_way_across_180_and_respects_its_limit():
    rate = heading_to_yaw_rate_sp(np.array([np.deg2rad(170), np.deg2rad(-170), np.nan]),
                                  np.array([np.deg2rad(-170), np.deg2rad(170), 0.3]), np.full(3, np.pi / 2), GG)
    assert rate[0] < 0 and rate[1] > 0 and rate[2] == 0.0
    assert np.all(np.abs(rate) <= np.pi / 2)


def _gains_of(cls, rows):
    """Per-vehicle gain arrays (as the systems stack them from the world file) and the per-row scalars."""
    names = [f.name for f in dataclasses.fields(cls)]
    per_row = [cls(**{n: getattr(cls(), n) * s for n in names}) for s in rows]
    stacked = cls(**{n: np.array([getattr(g, n) for g in per_row]) for n in names})
    return stacked, per_row


def test_a_fleet_with_per_vehicle_gains_computes_what_each_vehicle_alone_computes(rng):
    # GIVEN three vehicles whose gains differ (scaled 0.5x, 1x, 1.7x) and random states
    n, dt = 3, 1 / 240
    gg, gg_rows = _gains_of(GuidanceGains, [0.5, 1.0, 1.7])
    sg, sg_rows = _gains_of(StabilizerGains, [0.5, 1.0, 1.7])
    pos_sp, pos, vel_sp, vel = (rng.uniform(-20, 20, (n, 3)) for _ in range(4))
    vel_int = rng.uniform(-1, 1, (n, 2))
    to_go, lim_h, lim_up, lim_down = rng.uniform(1, 50, n), np.full(n, 10.0), np.full(n, 8.0), np.full(n, 5.0)
    lim_tilt, yaw, yaw_sp = np.full(n, 0.6), rng.uniform(-3, 3, n), rng.uniform(-3, 3, n)
    vz_int, hover, cos_tilt = rng.uniform(-0.5, 0.5, n), np.full(n, 0.6), np.full(n, 0.95)
    att = rng.uniform(-0.3, 0.3, (4, n))
    rates = rng.uniform(-1, 1, (n, 3))

    def laws(i, g, s):
        sl = slice(None) if i is None else slice(i, i + 1)
        return [position_to_velocity_sp(pos_sp[sl], pos[sl], to_go[sl], lim_h[sl], lim_up[sl], lim_down[sl], g),
                *velocity_to_accel_sp(vel_sp[sl], vel[sl], vel_int[sl], dt, lim_tilt[sl], g),
                heading_to_yaw_rate_sp(yaw_sp[sl], yaw[sl], np.full(len(yaw[sl]), np.pi / 2), g),
                *vertical_speed_to_thrust_frac(vel_sp[sl, 2], vel[sl, 2], att[0, sl], vz_int[sl], hover[sl],
                                               cos_tilt[sl], dt, s),
                attitude_to_torque_cmd(att[1, sl], att[2, sl], att[3, sl], att[0, sl], att[1, sl], rates[sl], s)]

    # WHEN the laws run once on the fleet and once per vehicle
    fleet = laws(None, gg, sg)
    alone = [laws(i, gg_rows[i], sg_rows[i]) for i in range(n)]
    # THEN every output row equals the lone vehicle's output
    for k, out in enumerate(fleet):
        assert_allclose(out, np.concatenate([a[k] for a in alone]), rtol=1e-12, atol=1e-12)


def test_body_velocity_command_turns_with_the_heading_and_clamps_the_vertical_part():
    cmd = np.array([[2.0, 1.0, 5.0], [2.0, 1.0, -9.0], [0.0, 0.0, 0.5]])
    yaw = np.array([0.0, math.pi / 2, 1.0])
    out = body_velocity_to_enu_sp(cmd, yaw, np.array([3.0, 3.0, 3.0]), np.array([2.0, 2.0, 2.0]))
    # facing east: forward is +x (east), left is +y (north); facing north: forward is +y, left is -x
    np.testing.assert_allclose(out[0], [2.0, 1.0, 3.0], atol=1e-12)
    np.testing.assert_allclose(out[1], [-1.0, 2.0, -2.0], atol=1e-12)
    np.testing.assert_allclose(out[2], [0.0, 0.0, 0.5], atol=1e-12)
    # horizontal speed is kept whatever the heading
    assert np.linalg.norm(out[:2, :2], axis=1) == pytest.approx([math.sqrt(5)] * 2)
