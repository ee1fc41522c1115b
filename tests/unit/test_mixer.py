"""X-quad mixing: the paper's eq. 2 when it fits, every motor in [0, F_max] always."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from numpy.testing import assert_allclose

from unetyemu_ecs.control.mixer import MIX_X, SPIN_REACTION_SIGN, mix_x_quad, motor_positions_flu_m


def body_torque(frac: np.ndarray, arm_m: float = 0.3, kappa_m: float = 0.016) -> np.ndarray:
    """Torque on the body (FLU) of thrusts ``frac`` (4,) at the motor positions, plus rotor reactions."""
    r = motor_positions_flu_m(np.array([arm_m]))[0]
    forces = np.zeros((4, 3))
    forces[:, 2] = frac
    return np.cross(r, forces).sum(axis=0) + np.array([0, 0, kappa_m * frac @ SPIN_REACTION_SIGN])


def test_unsaturated_mix_is_the_papers_equation_2():
    # FL = T - p + r - y, FR = T - p - r + y, BR = T + p - r - y, BL = T + p + r + y (halved torques)
    t, r, p, y = 0.5, 0.2, -0.1, 0.05
    out = mix_x_quad(np.array([t]), np.array([[r, p, y]]))[0]
    assert_allclose(out, t + 0.5 * np.array([-p + r - y, -p - r + y, p - r - y, p + r + y]))


def test_positive_commands_produce_positive_body_torques():
    # GIVEN positive roll, pitch and yaw commands one at a time
    for axis in range(3):
        cmd = np.zeros((1, 3))
        cmd[0, axis] = 0.3
        torque = body_torque(mix_x_quad(np.array([0.5]), cmd)[0])
        # THEN the torque about that FLU axis is positive (roll right-down, pitch nose-down, yaw CCW)
        assert torque[axis] > 0
        others = [a for a in range(3) if a != axis]
        assert_allclose(torque[others], 0.0, atol=1e-12)


finite = st.floats(-5.0, 5.0, allow_nan=False)


@settings(max_examples=400, deadline=None)
@given(t=st.floats(-1.0, 2.0, allow_nan=False), r=finite, p=finite, y=finite)
def test_every_motor_stays_in_0_to_1_for_any_command(t, r, p, y):
    out = mix_x_quad(np.array([t]), np.array([[r, p, y]]))
    assert np.all(out >= 0.0) and np.all(out <= 1.0)


@settings(max_examples=300, deadline=None)
@given(t=st.floats(0.0, 1.0), r=finite, p=finite, y=finite)
def test_saturation_keeps_the_roll_pitch_direction_and_gives_up_yaw_first(t, r, p, y):
    out = mix_x_quad(np.array([t]), np.array([[r, p, y]]))[0]
    achieved = np.linalg.lstsq(MIX_X, out - out.mean(), rcond=None)[0]      # [roll, pitch, yaw]
    # roll:pitch ratio preserved (direction of the tilt torque)
    if abs(r) + abs(p) > 1e-6:
        cmd = np.array([r, p]) / np.hypot(r, p)
        got = achieved[:2]
        assert np.hypot(*got) > 0
        assert_allclose(got / np.hypot(*got), cmd, atol=1e-6)
        # yaw is scaled at least as much as roll/pitch
        rp_scale = np.hypot(*got) / np.hypot(r, p)
        if abs(y) > 1e-6:
            assert achieved[2] / y <= rp_scale + 1e-9
    # the yaw that remains has the commanded sign
    assert achieved[2] * y >= -1e-12


def test_collective_is_kept_when_there_is_room():
    out = mix_x_quad(np.array([0.3]), np.array([[0.2, 0.0, 0.0]]))[0]
    assert_allclose(out.mean(), 0.3)


def test_nan_commands_switch_that_drone_off_and_leave_the_others_alone():
    out = mix_x_quad(np.array([0.5, np.nan, 0.5]), np.array([[0, 0, 0], [0, 0, 0], [np.nan, 0, 0]]))
    assert_allclose(out[1], 0.0)
    assert_allclose(out[2], 0.0)
    assert_allclose(out[0], 0.5)


def test_fleet_of_mixed_commands_matches_one_by_one(rng):
    t = rng.uniform(-0.2, 1.2, 50)
    cmd = rng.uniform(-2, 2, (50, 3))
    fleet = mix_x_quad(t, cmd)
    for k in range(50):
        assert_allclose(fleet[k], mix_x_quad(t[k:k + 1], cmd[k:k + 1])[0])
