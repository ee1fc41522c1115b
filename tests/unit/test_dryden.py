"""Dryden turbulence and the 1-cosine gust in unetyemu_ecs.control.dryden.

Statistical tolerances. The filters start in their stationary distribution, so every sample is
usable; the standard error of a pooled variance estimate is about sqrt(2 / N_eff), N_eff being the
number of independent samples (bodies x run length / twice the correlation time). The variance run
has N_eff ~ 2500 per axis: the standard error of the standard deviation is ~1.5 % (six seeds
scattered by 0.6-1.1 %), and the 5 % bound is > 3 standard errors wide, yet tight enough to catch
a wrong discretisation (forward Euler at 5 Hz would put the pooled sigma_w 13 % high) or a wrong
gain (a missing sqrt(2) is 41 %). The autocorrelation run has N_eff ~ 4000: its standard error
is ~0.02, hence the 0.05 bound around e^-1 = 0.37 (a time constant off by 25 % moves it by 0.08).
"""

from __future__ import annotations

from functools import cache

import numpy as np
import pytest
from numpy.testing import assert_allclose

from unetyemu_ecs.control.dryden import (M_PER_FT, M_S_PER_KNOT, W20_LIGHT_M_S, DrydenParams, dryden_axes_enu,
                                         dryden_sigma_and_scale, dryden_stationary_state, dryden_step, gust_enu_m_s,
                                         one_minus_cosine_gust_m_s)

LIGHT = DrydenParams(wind_speed_20ft_m_s=W20_LIGHT_M_S)
WIND_SPEED_M_S = 20.0      # mean wind the hovering bodies see: sets V = 20 m/s, short correlation times
RATE_HZ = 240.0


def _fleet(count: int, heights_m: list[float], toward_deg: list[float]):
    """Hovering bodies with heights and mean-wind directions cycling through the given lists."""
    rows = np.arange(count)
    height_m = np.asarray(heights_m)[rows % len(heights_m)]
    ang = np.deg2rad(np.asarray(toward_deg)[rows % len(toward_deg)])
    wind = WIND_SPEED_M_S * np.stack([np.cos(ang), np.sin(ang), np.zeros(count)], axis=1)
    return height_m, wind, np.zeros((count, 3))


def _run(seed: int, count: int, seconds: float, dt_s: float, heights_m: list[float], toward_deg: list[float],
         keep_series: bool):
    """Run hovering bodies from the stationary state; return the mean square of (u, v, w) / sigma per
    axis over all samples and, if asked, the normalised (steps, count, 3) series in turbulence axes."""
    rng = np.random.default_rng(seed)
    height_m, wind, vel = _fleet(count, heights_m, toward_deg)
    sigma, _ = dryden_sigma_and_scale(height_m, LIGHT.wind_speed_20ft_m_s)
    R_enu_uvw = dryden_axes_enu(wind)
    state = dryden_stationary_state(count, rng)
    steps = int(round(seconds / dt_s))
    sum_sq = np.zeros(3)
    series = np.empty((steps, count, 3)) if keep_series else None
    for k in range(steps):
        state, turb_enu = dryden_step(state, height_m, wind, vel, dt_s, rng, LIGHT)
        uvw = np.einsum("mji,mj->mi", R_enu_uvw, turb_enu) / sigma
        sum_sq += (uvw ** 2).sum(axis=0)
        if keep_series:
            series[k] = uvw
    return sum_sq / (steps * count), series


@cache
def _mixed_fleet_mean_square(rate_hz: float) -> tuple[float, ...]:
    # 600 bodies at 10 m and 40 m, mean wind toward east, north and south-west (mixed rows catch
    # broadcasting bugs); 30 s at 240 Hz is 7200 steps
    seconds = 30.0 if rate_hz > 50.0 else 120.0
    mean_sq, _ = _run(7, 600, seconds, 1.0 / rate_hz, [10.0, 40.0], [0.0, 90.0, 225.0], keep_series=False)
    return tuple(mean_sq)


@cache
def _ground_level_series() -> np.ndarray:
    # 500 bodies at 3 m (held at the 10 ft values, the shortest correlation times): 20 s at 240 Hz
    _, series = _run(11, 500, 20.0, 1.0 / RATE_HZ, [3.0], [30.0], keep_series=True)
    return series


def _autocorrelation(x: np.ndarray, lag: int) -> float:
    return float(np.mean(x[:-lag] * x[lag:]) / np.mean(x * x))


def _lag_steps(axis: int) -> int:
    _, scale_m = dryden_sigma_and_scale(np.array([3.0]), LIGHT.wind_speed_20ft_m_s)
    return int(round(scale_m[0, axis] / WIND_SPEED_M_S * RATE_HZ))


def test_intensities_and_scales_at_50_ft_in_a_15_knot_wind_match_a_hand_computation():
    # by hand: W20 = 15 kt = 7.7167 m/s; sigma_w = 0.1 W20 = 0.77167 m/s;
    # k = 0.177 + 0.000823 * 50 = 0.21815; k^0.4 = 0.54388; k^1.2 = 0.16089
    sigma, scale_m = dryden_sigma_and_scale(np.array([50.0 * M_PER_FT]), 15.0 * M_S_PER_KNOT)
    assert_allclose(sigma[0], [0.77167 / 0.54388, 0.77167 / 0.54388, 0.77167], rtol=1e-4)
    assert_allclose(scale_m[0], [50.0 / 0.16089 * 0.3048, 50.0 / 0.16089 * 0.3048, 50.0 * 0.3048], rtol=1e-4)


def test_low_altitude_formulas_hold_their_10_ft_values_below_and_1000_ft_values_above():
    sigma, scale_m = dryden_sigma_and_scale(np.array([0.0, 10.0 * M_PER_FT, 500.0, 1000.0 * M_PER_FT]), 10.0)
    assert_allclose(sigma[0], sigma[1])
    assert_allclose(scale_m[0], scale_m[1])
    assert_allclose(scale_m[1, 2], 10.0 * M_PER_FT)
    # at 1000 ft, k = 1: the turbulence is isotropic with L = h
    assert_allclose(sigma[2], sigma[3])
    assert_allclose(sigma[3], 1.0, rtol=1e-12)
    assert_allclose(scale_m[3], 1000.0 * M_PER_FT, rtol=1e-12)


@pytest.mark.parametrize("axis", [0, 1, 2], ids=["u", "v", "w"])
def test_standard_deviation_matches_sigma_over_a_long_240_hz_run(axis):
    assert_allclose(np.sqrt(_mixed_fleet_mean_square(RATE_HZ)[axis]), 1.0, atol=0.05)


@pytest.mark.parametrize("rate_hz", [100.0, 5.0])
def test_variance_does_not_depend_on_the_step_size(rate_hz):
    # 5 Hz is a step of 0.4 L_w / V at 10 m: forward Euler would overshoot sigma_w there by 21 %
    assert_allclose(np.sqrt(_mixed_fleet_mean_square(rate_hz)), 1.0, atol=0.05)


def test_longitudinal_autocorrelation_at_lag_l_over_v_is_one_over_e():
    # first-order filter: R_u(tau) = sigma_u^2 exp(-tau V / L_u)
    rho = _autocorrelation(_ground_level_series()[:, :, 0], _lag_steps(0))
    assert abs(rho - np.exp(-1.0)) < 0.05


def test_vertical_autocorrelation_at_lag_l_over_v_is_half_of_one_over_e():
    # second-order filter: R_w(tau) = sigma_w^2 exp(-tau V / L_w) (1 - tau V / (2 L_w))
    rho = _autocorrelation(_ground_level_series()[:, :, 2], _lag_steps(2))
    assert abs(rho - 0.5 * np.exp(-1.0)) < 0.05


def _short_series(seed: int, steps: int = 50) -> np.ndarray:
    rng = np.random.default_rng(seed)
    height_m, wind, vel = _fleet(3, [5.0, 20.0, 80.0], [0.0, 90.0, 180.0])
    state = np.zeros((3, 5))
    out = []
    for _ in range(steps):
        state, turb = dryden_step(state, height_m, wind, vel, 1.0 / RATE_HZ, rng, LIGHT)
        out.append(turb)
    return np.array(out)


def test_same_seed_gives_the_same_series():
    assert_allclose(_short_series(1234), _short_series(1234), atol=0.0, rtol=0.0)


def test_different_seed_gives_a_different_series():
    assert not np.allclose(_short_series(1234), _short_series(4321))


def test_zero_wind_at_20_ft_gives_zero_turbulence():
    rng = np.random.default_rng(1234)
    height_m, wind, vel = _fleet(4, [10.0], [0.0, 45.0])
    state = dryden_stationary_state(4, rng)
    for _ in range(10):
        state, turb = dryden_step(state, height_m, wind, vel, 1.0 / RATE_HZ, rng,
                                  DrydenParams(wind_speed_20ft_m_s=0.0))
        assert np.all(turb == 0.0)


def test_turbulence_axes_follow_the_mean_wind_and_default_to_east_in_calm_air():
    R = dryden_axes_enu(np.array([[0.0, 7.0, 1.0], [0.0, 0.0, 3.0]]))
    # wind toward north: u north, v west (its left), w up
    assert_allclose(R[0], [[0, -1, 0], [1, 0, 0], [0, 0, 1]], atol=1e-15)
    assert_allclose(R[1], np.eye(3))


def test_turning_the_mean_wind_turns_the_turbulence_with_it():
    def one_step(toward_deg: float) -> np.ndarray:
        rng = np.random.default_rng(1234)
        height_m, wind, vel = _fleet(1, [15.0], [toward_deg])
        return dryden_step(dryden_stationary_state(1, rng), height_m, wind, vel, 1.0 / RATE_HZ, rng, LIGHT)[1][0]
    east, north = one_step(0.0), one_step(90.0)
    assert_allclose(north, [-east[1], east[0], east[2]], atol=1e-12)


def test_flying_through_calm_air_sees_what_hovering_in_the_same_wind_sees():
    # Taylor's frozen turbulence: only the speed relative to the mean wind sets the time scale
    def series(mean_wind_enu_m_s: list[float], vel_enu_m_s: list[float]) -> np.ndarray:
        rng = np.random.default_rng(1234)
        state, out = dryden_stationary_state(1, rng), []
        for _ in range(100):
            state, turb = dryden_step(state, np.array([15.0]), np.array([mean_wind_enu_m_s]), np.array([vel_enu_m_s]),
                                      1.0 / RATE_HZ, rng, LIGHT)
            out.append(turb[0])
        return np.array(out)
    hovering_in_wind = series([10.0, 0.0, 0.0], [0.0, 0.0, 0.0])
    flying_in_calm = series([0.0, 0.0, 0.0], [10.0, 0.0, 0.0])
    flying_downwind_faster = series([10.0, 0.0, 0.0], [20.0, 0.0, 0.0])
    slow_run = series([2.0, 0.0, 0.0], [0.0, 0.0, 0.0])
    assert_allclose(flying_in_calm, hovering_in_wind, atol=1e-12)
    assert_allclose(flying_downwind_faster, hovering_in_wind, atol=1e-12)
    assert not np.allclose(slow_run, hovering_in_wind)


def test_drifting_with_the_wind_uses_the_convection_speed_floor():
    def first_step(vel_enu_m_s: list[float], floor_m_s: float) -> np.ndarray:
        rng = np.random.default_rng(1234)
        params = DrydenParams(wind_speed_20ft_m_s=W20_LIGHT_M_S, min_convection_speed_m_s=floor_m_s)
        return dryden_step(dryden_stationary_state(1, rng), np.array([15.0]), np.array([[3.0, 0.0, 0.0]]),
                           np.array([vel_enu_m_s]), 1.0 / RATE_HZ, rng, params)[1]
    assert_allclose(first_step([3.0, 0.0, 0.0], 0.5), first_step([2.5, 0.0, 0.0], 0.5), atol=1e-12)
    assert_allclose(first_step([3.0, 0.0, 0.0], 1.0), first_step([3.1, 0.0, 0.0], 1.0), atol=1e-12)


def test_non_positive_step_is_rejected():
    rng = np.random.default_rng(1234)
    with pytest.raises(ValueError, match="dt_s"):
        dryden_step(np.zeros((1, 5)), np.array([10.0]), np.zeros((1, 3)), np.zeros((1, 3)), 0.0, rng, LIGHT)


def test_one_minus_cosine_gust_peaks_at_its_amplitude_one_gust_length_in():
    amplitude_m_s, length_m = 6.0, 40.0
    dist_m = np.array([0.0, 10.0, 20.0, 40.0, 60.0, 80.0])
    assert_allclose(one_minus_cosine_gust_m_s(dist_m, amplitude_m_s, length_m),
                    [0.0, 3.0 * (1 - np.cos(np.pi / 4)), 3.0, 6.0, 3.0, 0.0], atol=1e-12)


def test_one_minus_cosine_gust_is_zero_outside_twice_its_length():
    dist_m = np.array([-50.0, -1e-9, 80.0 + 1e-9, 500.0])
    assert np.all(one_minus_cosine_gust_m_s(dist_m, 6.0, 40.0) == 0.0)


def test_timed_gust_blows_along_its_direction_and_peaks_one_rise_time_after_start():
    # GIVEN an updraft gust of 4 m/s starting at t = 2 s with a 1.5 s rise (direction not normalised)
    t_s = np.array([1.9, 2.0, 3.5, 5.0, 5.1])
    gust = gust_enu_m_s(t_s, 2.0, 4.0, 1.5, [0.0, 0.0, 2.0])
    # THEN it is vertical, peaks at 3.5 s and is over after 5 s
    assert gust.shape == (5, 3)
    assert_allclose(gust[:, :2], 0.0)
    assert_allclose(gust[:, 2], [0.0, 0.0, 4.0, 0.0, 0.0], atol=1e-12)
