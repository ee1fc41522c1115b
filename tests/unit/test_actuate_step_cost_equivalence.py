"""The cheaper per-step forms of the stabilize and actuate laws give bit for bit what the plain formulas gave: the
compiled mixer (its clamps ordered as numpy's), the vertical-speed loop
(the anti-windup looked at only when an output saturates), the attitude torques (written into one array instead of
stacked); the compiled rotor wrench and quadratic drag give them to rounding (sums in another order)."""

from __future__ import annotations

import numpy as np
from numpy.testing import assert_allclose, assert_array_equal

from unetyemu_ecs.control.aero import quadratic_drag_enu_n
from unetyemu_ecs.control.attitude import (MIN_COS_TILT, StabilizerGains, attitude_to_torque_cmd,
                                           vertical_speed_to_thrust_frac)
from unetyemu_ecs.control.mixer import MIX_X, mix_x_quad
from unetyemu_ecs.control.rotor_wrench import rotor_wrench_enu
from unetyemu_ecs.frames import R_from_quat_xyzw
from unetyemu_ecs.units import GRAVITY_M_S2

RNG = np.random.default_rng(11)


# the functions as they were written before the per-step cost was cut
def reference_mix_x_quad(thrust_frac, torque_cmd):
    thrust = np.asarray(thrust_frac, dtype=float).reshape(-1)
    torque = np.asarray(torque_cmd, dtype=float).reshape(-1, 3)
    if not (np.isfinite(thrust).all() and np.isfinite(torque).all()):
        bad = ~np.isfinite(thrust) | ~np.all(np.isfinite(torque), axis=1)
        thrust, torque = np.where(bad, 0.0, thrust), np.where(bad[:, None], 0.0, torque)
    torque = np.minimum(np.maximum(torque, -1e6), 1e6)
    thrust = np.minimum(np.maximum(thrust, 0.0), 1.0)
    rp = torque[:, :2] @ MIX_X[:, :2].T
    yw = torque[:, 2:3] * MIX_X[:, 2][None, :]
    rp_max, rp_min = rp.max(axis=1), rp.min(axis=1)
    spread = rp_max - rp_min
    if (spread > 1.0).any():
        shrink = np.where(spread > 1.0, 1.0 / np.maximum(spread, 1e-12), 1.0)
        rp = rp * shrink[:, None]
        rp_max, rp_min = rp_max * shrink, rp_min * shrink
    thrust = np.minimum(np.maximum(thrust, -rp_min), 1.0 - rp_max)
    base = thrust[:, None] + rp
    room = np.divide(np.where(yw > 0.0, 1.0 - base, -base), yw, out=np.full_like(base, np.inf),
                     where=np.abs(yw) > 1e-12)
    scale = np.minimum(np.maximum(room.min(axis=1), 0.0), 1.0)
    out = base + scale[:, None] * yw
    return np.minimum(np.maximum(out, 0.0), 1.0)


def reference_vertical_speed_to_thrust_frac(vz_sp_m_s, vz_m_s, acc_z_m_s2, vz_int, hover_thrust_frac, cos_tilt,
                                            dt_s, gains):
    err = vz_sp_m_s - vz_m_s
    tilt = np.maximum(cos_tilt, MIN_COS_TILT)

    def output(integral):
        a_cmd = gains.gain_vz_p * err + gains.gain_vz_i * integral - gains.gain_vz_d * acc_z_m_s2
        return hover_thrust_frac * (1.0 + a_cmd / GRAVITY_M_S2) / tilt

    trial = np.minimum(np.maximum(vz_int + err * dt_s, -gains.lim_vz_int_m_s), gains.lim_vz_int_m_s)
    u = output(trial)
    winding = ((u > 1.0) & (err > 0.0)) | ((u < 0.0) & (err < 0.0))
    if winding.any():
        trial = np.where(winding, vz_int, trial)
        u = output(trial)
    return np.minimum(np.maximum(u, 0.0), 1.0), trial


def reference_attitude_to_torque_cmd(roll_sp_rad, pitch_sp_rad, yaw_rate_sp_rad_s, roll_rad, pitch_rad,
                                     rate_flu_rad_s, gains):
    u_roll = gains.gain_att_p * (roll_sp_rad - roll_rad) - gains.gain_rate_d * rate_flu_rad_s[:, 0]
    u_pitch = gains.gain_att_p * (pitch_sp_rad - pitch_rad) - gains.gain_rate_d * rate_flu_rad_s[:, 1]
    u_yaw = gains.gain_yaw_rate_p * (yaw_rate_sp_rad_s - rate_flu_rad_s[:, 2])
    return np.minimum(np.maximum(np.stack([u_roll, u_pitch, u_yaw], axis=1), -1.0), 1.0)


def reference_rotor_wrench_enu(thrust_n, R_enu_flu, torque_matrix_flu):
    thrust = np.asarray(thrust_n, dtype=float)
    force = thrust.sum(axis=1)[:, None] * R_enu_flu[:, :, 2]
    torque_flu = np.einsum("nkj,nj->nk", torque_matrix_flu, thrust)
    return force, np.einsum("nij,nj->ni", R_enu_flu, torque_flu)


def reference_quadratic_drag_enu_n(vel_rel_enu_m_s, R_enu_flu, drag_coeff, area_flu_m2, air_density_kg_m3):
    v_flu = np.einsum("mji,mj->mi", R_enu_flu, vel_rel_enu_m_s)
    speed = np.linalg.norm(vel_rel_enu_m_s, axis=1)
    f_flu = -0.5 * (air_density_kg_m3 * drag_coeff * speed)[:, None] * area_flu_m2 * v_flu
    return np.einsum("mij,mj->mi", R_enu_flu, f_flu)


def random_rotations(n):
    q = RNG.normal(size=(n, 4))
    return R_from_quat_xyzw(q / np.linalg.norm(q, axis=1)[:, None])


def assert_same_bits(a, b):
    """Equal values, NaN where NaN, and the same sign of every zero."""
    assert_array_equal(a, b)
    assert_array_equal(np.signbit(a), np.signbit(b))


def test_mixer_gives_the_plain_mix_for_random_commands_of_every_size():
    for n in (1, 2, 7, 1000):
        thrust = RNG.uniform(-0.3, 1.3, n)
        torque = RNG.normal(0.0, 0.6, (n, 3))
        assert_same_bits(mix_x_quad(thrust, torque), reference_mix_x_quad(thrust, torque))


def test_mixer_gives_the_plain_mix_when_roll_pitch_saturates_and_yaw_is_zero_or_tiny():
    thrust = np.array([0.0, -0.0, 1.0, 0.5, 0.5, 0.5, 0.2, 0.9, 0.5])
    torque = np.array([[3.0, -2.0, 0.0], [0.0, 0.0, -0.0], [-0.0, 0.0, 0.0], [1.0, 1.0, 1.0], [5e5, -5e5, 2e6],
                       [0.0, 0.0, 1e-13], [0.0, 0.0, -3e-12], [-0.7, 0.4, 0.9], [1e300, -1e300, 1e300]])
    assert_same_bits(mix_x_quad(thrust, torque), reference_mix_x_quad(thrust, torque))
    assert_same_bits(mix_x_quad(0.4, [0.0, 0.0, 0.0]), reference_mix_x_quad(0.4, [0.0, 0.0, 0.0]))


def test_mixer_turns_off_the_same_drones_for_nan_and_infinite_inputs():
    thrust = np.array([np.nan, 0.5, np.inf, 0.5, -np.inf, 0.5, 0.3])
    torque = np.array([[0.1, 0.1, 0.1], [np.nan, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, np.inf, 0.0],
                       [0.0, 0.0, 0.0], [0.0, 0.0, -np.inf], [0.2, -0.1, 0.05]])
    out = mix_x_quad(thrust, torque)
    assert_same_bits(out, reference_mix_x_quad(thrust, torque))
    assert_array_equal(out[:6], 0.0)
    # finite values whose sum overflows are not taken for infinite ones
    big = np.array([[1e308, 1e308, 1e308]])
    assert_same_bits(mix_x_quad([1.0], big), reference_mix_x_quad([1.0], big))


def test_vertical_speed_loop_gives_the_plain_output_saturated_or_not_winding_or_not():
    gains = StabilizerGains()
    for n in (1, 5, 1000):
        vz_sp, vz = RNG.uniform(-8.0, 8.0, n), RNG.uniform(-8.0, 8.0, n)
        acc, vz_int = RNG.uniform(-30.0, 30.0, n), RNG.uniform(-5.0, 5.0, n)
        hover, cos_tilt = RNG.uniform(0.1, 0.9, n), RNG.uniform(-1.0, 1.0, n)
        for dt_s in (1.0 / 240.0, 0.5):
            got = vertical_speed_to_thrust_frac(vz_sp, vz, acc, vz_int, hover, cos_tilt, dt_s, gains)
            want = reference_vertical_speed_to_thrust_frac(vz_sp, vz, acc, vz_int, hover, cos_tilt, dt_s, gains)
            assert_same_bits(got[0], want[0])
            assert_same_bits(got[1], want[1])


def test_vertical_speed_loop_gives_the_plain_output_in_hover_and_for_nan_and_array_gains():
    n = 6
    gains = StabilizerGains(gain_vz_p=RNG.uniform(0.0, 10.0, n), gain_vz_i=RNG.uniform(0.0, 5.0, n))
    vz_sp = np.array([0.0, -0.0, np.nan, 3.0, -3.0, 0.0])
    vz = np.array([0.0, 0.0, 0.0, np.nan, 0.0, 0.0])
    acc, vz_int = np.zeros(n), np.array([0.0, -0.0, 0.0, 0.0, -4.0, 4.0])
    hover, cos_tilt = np.full(n, 0.5), np.ones(n)
    got = vertical_speed_to_thrust_frac(vz_sp, vz, acc, vz_int, hover, cos_tilt, 1.0 / 240.0, gains)
    want = reference_vertical_speed_to_thrust_frac(vz_sp, vz, acc, vz_int, hover, cos_tilt, 1.0 / 240.0, gains)
    assert_same_bits(got[0], want[0])
    assert_same_bits(got[1], want[1])


def test_attitude_torques_are_the_plain_ones_for_scalar_and_per_drone_gains():
    for n in (1, 3, 1000):
        args = [RNG.uniform(-2.0, 2.0, n) for _ in range(5)] + [RNG.uniform(-20.0, 20.0, (n, 3))]
        args[2][: n // 2] = 0.0                                    # zero yaw-rate setpoints
        for gains in (StabilizerGains(), StabilizerGains(gain_att_p=RNG.uniform(0.0, 5.0, n),
                                                         gain_rate_d=RNG.uniform(0.0, 1.0, n),
                                                         gain_yaw_rate_p=RNG.uniform(0.0, 2.0, n))):
            got = attitude_to_torque_cmd(*args, gains)
            assert got.flags.c_contiguous and got.shape == (n, 3)
            assert_same_bits(got, reference_attitude_to_torque_cmd(*args, gains))


def test_attitude_torques_take_a_strided_rate_view_and_scalar_setpoints():
    rates = RNG.normal(size=(4, 6))[:, ::2]
    args = (0.1, -0.2, 0.0, RNG.normal(size=4), RNG.normal(size=4), rates)
    assert_same_bits(attitude_to_torque_cmd(*args, StabilizerGains()),
                     reference_attitude_to_torque_cmd(*args, StabilizerGains()))


def test_rotor_wrench_is_the_plain_sum_and_products():
    for n in (1, 4, 1000):
        thrust, R = RNG.uniform(0.0, 20.0, (n, 4)), random_rotations(n)
        matrix = RNG.normal(size=(n, 3, 4))
        for got, want in zip(rotor_wrench_enu(thrust, R, matrix), reference_rotor_wrench_enu(thrust, R, matrix)):
            assert_allclose(got, want, rtol=1e-13, atol=1e-12)


def test_quadratic_drag_is_the_plain_formula():
    for n in (1, 3, 1000):
        v = RNG.normal(0.0, 15.0, (n, 3))
        v[0] = 0.0
        R, cd, area, rho = random_rotations(n), RNG.uniform(0.1, 2.0, n), RNG.uniform(0.0, 0.2, (n, 3)), np.full(n, 1.2)
        assert_allclose(quadratic_drag_enu_n(v, R, cd, area, rho), reference_quadratic_drag_enu_n(v, R, cd, area, rho),
                        rtol=1e-13, atol=1e-12)
