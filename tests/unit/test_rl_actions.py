"""What an agent's action means at each level, and the body-rate loop: pure functions, no simulation."""

import numpy as np
import pytest

from unetyemu_ecs.control.attitude import StabilizerGains
from unetyemu_ecs.control.body_rate import body_rates_to_torque_cmd
from unetyemu_ecs.rl.actions import (ActionScale, attitude_sp, body_rate_sp, clean_action, collective_frac, motor_fracs,
                                     velocity_sp)


def scale(n: int = 2) -> ActionScale:
    return ActionScale(hover_frac=np.full(n, 0.4), thrust_span=0.5, max_rate_rad_s=np.full(n, np.pi),
                       max_tilt_rad=np.full(n, np.deg2rad(30.0)), lim_yaw_rate_rad_s=np.full(n, 1.0),
                       max_speed_m_s=np.full(n, 8.0), lim_climb_m_s=np.full(n, 3.0), lim_descent_m_s=np.full(n, 2.0))


def test_the_zero_action_commands_hover_thrust_on_every_motor():
    assert np.allclose(motor_fracs(np.zeros((2, 4)), scale()), 0.4)
    assert np.allclose(collective_frac(np.zeros((2, 4)), scale()), 0.4)


def test_a_full_motor_action_is_hover_thrust_plus_or_minus_half_within_the_motor_range():
    fracs = motor_fracs(np.array([[1.0, -1.0, 0.5, 0.0]]), scale(1))
    assert np.allclose(fracs, [[0.6, 0.2, 0.5, 0.4]])
    big = ActionScale(**{**vars(scale(1)), "hover_frac": np.array([0.9])})
    assert motor_fracs(np.ones((1, 4)), big).max() == 1.0          # never above F_max


def test_attitude_actions_scale_to_the_tilt_and_yaw_rate_limits():
    roll, pitch, yaw_rate = attitude_sp(np.array([[0.0, 1.0, -0.5, 0.25]]), scale(1))
    assert roll[0] == pytest.approx(np.deg2rad(30.0))
    assert pitch[0] == pytest.approx(-np.deg2rad(15.0))
    assert yaw_rate[0] == pytest.approx(0.25)


def test_body_rate_actions_scale_to_the_rate_limit():
    rates = body_rate_sp(np.array([[0.0, 0.5, -1.0, 1.0]]), scale(1))
    assert np.allclose(rates, [[0.5 * np.pi, -np.pi, 1.0]])


def test_a_diagonal_velocity_action_is_no_faster_than_a_straight_one():
    vel, _ = velocity_sp(np.array([[1.0, 1.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0]]), scale())
    assert np.linalg.norm(vel[0, :2]) == pytest.approx(8.0)
    assert np.linalg.norm(vel[1, :2]) == pytest.approx(8.0)


def test_up_and_down_velocity_actions_use_the_climb_and_descent_limits():
    vel, _ = velocity_sp(np.array([[0.0, 0.0, 1.0, 0.0], [0.0, 0.0, -1.0, 0.0]]), scale())
    assert vel[:, 2].tolist() == [3.0, -2.0]


def test_actions_are_clipped_to_their_range_and_nan_counts_as_zero():
    a = clean_action([[2.0, -3.0, np.nan, 0.5]], 1)
    assert a.tolist() == [[1.0, -1.0, 0.0, 0.5]]


def test_an_action_of_the_wrong_size_names_the_shape_expected():
    with pytest.raises(ValueError, match="2 x 4 numbers"):
        clean_action(np.zeros(5), 2)


def test_the_rate_loop_pushes_toward_the_rate_setpoint_with_the_attitude_layers_gains():
    gains = StabilizerGains()
    torque = body_rates_to_torque_cmd(np.array([[1.0, -1.0, 0.5]]), np.zeros((1, 3)), gains)
    assert torque[0, 0] == pytest.approx(gains.gain_rate_d * 1.0)
    assert torque[0, 1] == pytest.approx(-gains.gain_rate_d * 1.0)
    assert torque[0, 2] == pytest.approx(gains.gain_yaw_rate_p * 0.5)


def test_the_rate_loop_is_what_the_attitude_law_does_inside():
    """The angle P + rate D law equals the rate loop around rate_sp = (kp / kd) * angle error."""
    from unetyemu_ecs.control.attitude import attitude_to_torque_cmd

    gains = StabilizerGains()
    rate = np.array([[0.3, -0.2, 0.1]])
    roll_sp, pitch_sp, roll, pitch = 0.2, -0.1, 0.05, 0.02
    law = attitude_to_torque_cmd(np.array([roll_sp]), np.array([pitch_sp]), np.array([0.4]), np.array([roll]),
                                 np.array([pitch]), rate, gains)
    k = gains.gain_att_p / gains.gain_rate_d
    rate_sp = np.array([[k * (roll_sp - roll), k * (pitch_sp - pitch), 0.4]])
    assert np.allclose(body_rates_to_torque_cmd(rate_sp, rate, gains), law)


def test_the_rate_loop_saturates_at_full_torque():
    torque = body_rates_to_torque_cmd(np.array([[100.0, -100.0, 100.0]]), np.zeros((1, 3)), StabilizerGains())
    assert torque.tolist() == [[1.0, -1.0, 1.0]]
