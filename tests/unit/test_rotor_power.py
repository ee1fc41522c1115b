"""Momentum-theory rotor power against the textbook: eq. 4 in hover, Leishman's climb ratio, Glauert's
forward-flight inflow, the vortex-ring fit and windmill brake state in descent, profile power with advance
ratio, and the power bucket of a trimmed quadrotor. No esper, no PyBullet."""

from __future__ import annotations

import numpy as np
from numpy.testing import assert_allclose

from unetyemu_ecs.control.energy import rotor_power_w
from unetyemu_ecs.control.rotor_power import (glauert_inflow_m_s, hover_induced_velocity_m_s, induced_velocity_m_s,
                                              profile_hover_power_w, rotor_shaft_power_w)

G_M_S2 = 9.81
RHO_KG_M3 = 1.2
AREA_M2 = 0.06
THRUST_N = 20.0                 # one rotor of an 8 kg quadrotor in hover
V_TIP_M_S = 80.0
V_H_M_S = float(np.sqrt(THRUST_N / (2 * RHO_KG_M3 * AREA_M2)))   # textbook hover induced velocity, ~11.8 m/s

# Leishman (2006) ch. 2 empirical axial-descent fit v_i/v_h = k + k1 x + k2 x^2 + k3 x^3 + k4 x^4, x = V_c/v_h
LEISHMAN_VRS_FIT = (1.15, -1.125, -1.372, -1.718, -0.655)


def induced(v_axial_m_s, v_inplane_m_s, thrust_n=THRUST_N):
    """Induced velocity of the reference rotor for arrays of axial and in-plane air speed."""
    v_axial_m_s = np.asarray(v_axial_m_s, dtype=float)
    shape = np.broadcast(v_axial_m_s, np.asarray(v_inplane_m_s)).shape
    return induced_velocity_m_s(np.broadcast_to(np.asarray(thrust_n, dtype=float), shape),
                                np.broadcast_to(v_axial_m_s, shape),
                                np.broadcast_to(np.asarray(v_inplane_m_s, dtype=float), shape), RHO_KG_M3, AREA_M2)


def shaft_power(v_axial_m_s, v_inplane_m_s, thrust_n=THRUST_N, profile_hover_w=0.0):
    v_axial_m_s = np.asarray(v_axial_m_s, dtype=float)
    shape = np.broadcast(v_axial_m_s, np.asarray(v_inplane_m_s), np.asarray(thrust_n)).shape
    return rotor_shaft_power_w(np.broadcast_to(np.asarray(thrust_n, dtype=float), shape),
                               np.broadcast_to(v_axial_m_s, shape),
                               np.broadcast_to(np.asarray(v_inplane_m_s, dtype=float), shape),
                               RHO_KG_M3, AREA_M2, profile_hover_w, V_TIP_M_S)


def leishman_fit(x):
    k0, k1, k2, k3, k4 = LEISHMAN_VRS_FIT
    return k0 + k1 * x + k2 * x ** 2 + k3 * x ** 3 + k4 * x ** 4


# --- 1. hover ------------------------------------------------------------------------------------


def test_hover_shaft_power_over_eta_is_exactly_eq_4(rng):
    # GIVEN 50 vehicles of 4 rotors with mixed thrusts, air densities, disk areas and efficiencies
    m = 50
    thrust_n = rng.uniform(0.0, 60.0, (m, 4))
    thrust_n[0, 0] = 0.0                                   # an idle rotor draws nothing
    rho = rng.uniform(0.9, 1.3, m)
    area = rng.uniform(0.01, 0.2, m)
    eta = rng.uniform(0.5, 0.9, m)
    zero = np.zeros((m, 4))
    # WHEN the rotors hover (no axial, no in-plane air speed), whatever their hover profile power
    shaft = rotor_shaft_power_w(thrust_n, zero, zero, rho[:, None], area[:, None], 5.0, V_TIP_M_S)
    # THEN P = T^1.5 / (sqrt(2 rho A) eta): the hover profile power lives in eta, nothing is added
    assert_allclose(shaft / eta[:, None], rotor_power_w(thrust_n, rho, area, eta), rtol=1e-9, atol=0.0)
    assert_allclose(shaft / eta[:, None], thrust_n ** 1.5 / (np.sqrt(2 * rho * area) * eta)[:, None], rtol=1e-9)


def test_hover_induced_velocity_is_sqrt_t_over_2_rho_a():
    assert_allclose(hover_induced_velocity_m_s(np.array([THRUST_N, 0.0, -3.0]), RHO_KG_M3, AREA_M2),
                    [V_H_M_S, 0.0, 0.0])
    assert_allclose(induced(0.0, 0.0), V_H_M_S, rtol=1e-12)


# --- 2. axial climb ------------------------------------------------------------------------------


def test_axial_climb_power_follows_leishmans_ratio_to_hover():
    # GIVEN climb rates from 0 to 5 v_h with no in-plane air speed
    climb_m_s = np.linspace(0.0, 5.0, 51) * V_H_M_S
    # WHEN the shaft power is divided by the hover shaft power T v_h
    ratio = shaft_power(climb_m_s, 0.0) / (THRUST_N * V_H_M_S)
    # THEN P_c / P_h = V_c/(2 v_h) + sqrt((V_c/(2 v_h))^2 + 1)   (Leishman ch. 2, axial climb)
    half = climb_m_s / (2 * V_H_M_S)
    assert_allclose(ratio, half + np.sqrt(half ** 2 + 1.0), rtol=1e-9)


def test_axial_climb_inflow_satisfies_momentum_theory():
    climb_m_s = np.linspace(0.0, 5.0, 51) * V_H_M_S
    v_i = induced(climb_m_s, 0.0)
    # T = 2 rho A v_i (V_c + v_i)  <=>  v_i (V_c + v_i) = v_h^2; climbing faster needs less induced velocity
    assert_allclose(v_i * (climb_m_s + v_i), V_H_M_S ** 2, rtol=1e-9)
    assert np.all(np.diff(v_i) < 0)


# --- 3. forward flight ---------------------------------------------------------------------------


def test_forward_flight_inflow_satisfies_glauerts_relation():
    # GIVEN a level disk (V_c = 0) in edgewise flight from 0 to 20 v_h
    v_inplane_m_s = np.linspace(0.0, 20.0, 401) * V_H_M_S
    v_i = induced(0.0, v_inplane_m_s)
    # THEN v_i = v_h^2 / sqrt(V_h^2 + v_i^2), whose positive root is v_i^2 = (sqrt(V^4 + 4 v_h^4) - V^2) / 2
    assert_allclose(v_i, V_H_M_S ** 2 / np.sqrt(v_inplane_m_s ** 2 + v_i ** 2), rtol=1e-9)
    closed_form = np.sqrt((np.sqrt(v_inplane_m_s ** 4 + 4 * V_H_M_S ** 4) - v_inplane_m_s ** 2) / 2)
    assert_allclose(v_i, closed_form, rtol=1e-9)


def test_forward_flight_induced_velocity_falls_with_speed_toward_v_h_squared_over_v():
    v_inplane_m_s = np.linspace(0.0, 10.0, 201) * V_H_M_S
    v_i = induced(0.0, v_inplane_m_s)
    assert np.all(np.diff(v_i) < 0)
    # at high speed the disk sees fresh air: v_i -> v_h^2 / V (Glauert's high-speed limit)
    assert_allclose(v_i[-1], V_H_M_S ** 2 / v_inplane_m_s[-1], rtol=0.01)


# --- 4. tilted disk in forward flight ------------------------------------------------------------


def test_tilted_disk_total_inflow_satisfies_glauerts_relation():
    # GIVEN a disk tilted forward by a (0..70 deg) into an airspeed V (0..10 v_h)
    speed_m_s = np.linspace(0.0, 10.0, 101)[:, None] * V_H_M_S
    tilt_rad = np.deg2rad(np.linspace(0.0, 70.0, 15))[None, :]
    v_axial_m_s, v_inplane_m_s = speed_m_s * np.sin(tilt_rad), speed_m_s * np.cos(tilt_rad)
    # WHEN the inflow is computed
    u = v_axial_m_s + induced(v_axial_m_s, v_inplane_m_s)
    # THEN u = V_c + v_h^2 / sqrt(V_h^2 + u^2)   (Leishman §5.3)
    assert_allclose(u, v_axial_m_s + V_H_M_S ** 2 / np.sqrt(v_inplane_m_s ** 2 + u ** 2), rtol=1e-9)


# --- 5. descent ----------------------------------------------------------------------------------


def test_induced_velocity_is_continuous_where_climb_meets_descent_in_axial_flight():
    eps = 1e-9 * V_H_M_S
    v_i = induced(np.array([-eps, 0.0, eps]), 0.0)
    assert_allclose(v_i, V_H_M_S, atol=1e-6 * V_H_M_S)


def test_induced_velocity_is_continuous_where_vortex_ring_meets_windmill_brake():
    # momentum theory's windmill brake state at V_c = -2 v_h gives v_i = -V_c/2 - 0 = v_h, but leaves it
    # with a vertical tangent: v_i = v_h (1 + d/2 - sqrt(d + d^2/4)) at V_c = -(2 + d) v_h, so a step of
    # d moves v_i by ~sqrt(d) v_h; d = 1e-13 keeps that under 1e-6 v_h
    eps = 1e-13 * V_H_M_S
    v_i = induced(-2 * V_H_M_S + np.array([-eps, 0.0, eps]), 0.0)
    assert_allclose(v_i, V_H_M_S, atol=1e-6 * V_H_M_S)
    d = 1e-6
    assert_allclose(induced(-(2 + d) * V_H_M_S, 0.0), V_H_M_S * (1 + d / 2 - np.sqrt(d + d * d / 4)), rtol=1e-9)


def test_vortex_ring_induced_velocity_follows_the_shifted_empirical_fit():
    # GIVEN Leishman's fit, ~1.97 v_h at x = -1, shifted by the straight line that makes it meet
    # momentum theory (v_i = v_h) at both x = 0 and x = -2, as the module docstring documents
    assert_allclose(leishman_fit(-1.0), 1.966, atol=1e-3)
    shift_at_0, shift_at_minus2 = 1.0 - leishman_fit(0.0), 1.0 - leishman_fit(-2.0)
    x = np.array([-0.5, -1.0, -1.5])
    expected = leishman_fit(x) + shift_at_0 + (shift_at_minus2 - shift_at_0) * (-x / 2.0)
    # WHEN the rotor descends axially in the vortex-ring band
    v_i = induced(x * V_H_M_S, 0.0)
    # THEN the induced velocity is the shifted fit, well above hover's (the ring recirculates the wake)
    assert_allclose(v_i / V_H_M_S, expected, rtol=1e-9)
    assert_allclose(v_i[1] / V_H_M_S, 1.803, atol=1e-3)
    assert np.all(v_i > V_H_M_S)


def test_fast_axial_descent_is_momentum_theorys_windmill_brake_state():
    descent_m_s = -np.array([2.5, 3.0, 4.0, 6.0]) * V_H_M_S
    v_i = induced(descent_m_s, 0.0)
    assert_allclose(v_i, -descent_m_s / 2 - np.sqrt(descent_m_s ** 2 / 4 - V_H_M_S ** 2), rtol=1e-9)
    assert_allclose(v_i[1] / V_H_M_S, (3 - np.sqrt(5)) / 2, rtol=1e-9)     # x = -3: 0.382 v_h


def test_descent_with_in_plane_speed_above_v_h_is_glauerts_normal_state():
    # GIVEN in-plane speeds of 1 to 3 v_h (the vortex ring is blown away) and slow descents for which
    # Glauert's relation has a positive total inflow (|V_c| V_h < v_h^2)
    v_inplane_m_s = np.linspace(1.0, 3.0, 9)[:, None] * V_H_M_S
    v_axial_m_s = -np.linspace(0.0, 0.95, 20)[None, :] * V_H_M_S ** 2 / v_inplane_m_s
    # WHEN the inflow is computed
    u = v_axial_m_s + induced(v_axial_m_s, v_inplane_m_s)
    # THEN it is Glauert's, with no trace of the vortex-ring fit
    assert np.all(u > 0)
    assert_allclose(u, v_axial_m_s + V_H_M_S ** 2 / np.sqrt(v_inplane_m_s ** 2 + u ** 2), rtol=1e-9)


def test_induced_velocity_is_continuous_at_zero_axial_speed_in_slow_forward_flight():
    eps = 1e-9 * V_H_M_S
    v_i = induced(np.array([-eps, eps]), 0.5 * V_H_M_S)
    assert_allclose(v_i[0], v_i[1], atol=1e-6 * V_H_M_S)


def test_in_plane_speed_above_v_h_keeps_induced_velocity_below_v_h_in_steep_descent():
    # with V_h >= v_h, T = 2 rho A v_i sqrt(V_h^2 + u^2) >= 2 rho A v_i V_h gives v_i <= v_h^2 / V_h <= v_h
    v_i = induced(-3.0 * V_H_M_S, np.array([1.0, 2.0]) * V_H_M_S)
    assert np.all(v_i <= V_H_M_S ** 2 / (np.array([1.0, 2.0]) * V_H_M_S) + 1e-9)


# --- 6. profile power ----------------------------------------------------------------------------


def test_hover_profile_power_is_sigma_cd0_over_8_rho_a_vtip_cubed():
    # sigma 0.1, C_d0 0.01, rho 1.2, A 0.06 m^2, V_tip 80 m/s: 1.25e-4 * 1.2 * 0.06 * 512000 = 4.608 W
    assert_allclose(profile_hover_power_w(0.1, 0.01, RHO_KG_M3, AREA_M2, V_TIP_M_S), 4.608, rtol=1e-12)


def test_profile_power_increment_is_zero_in_hover_and_grows_as_4_65_mu_squared():
    p0h_w = profile_hover_power_w(0.1, 0.01, RHO_KG_M3, AREA_M2, V_TIP_M_S)
    mu = np.linspace(0.0, 0.4, 9)
    v_inplane_m_s = mu * V_TIP_M_S
    for v_axial_m_s in (0.0, 0.3 * V_H_M_S):
        # the increment is the difference between the same rotor with and without profile drag
        increment_w = (shaft_power(v_axial_m_s, v_inplane_m_s, profile_hover_w=p0h_w)
                       - shaft_power(v_axial_m_s, v_inplane_m_s, profile_hover_w=0.0))
        assert_allclose(increment_w, 4.65 * mu ** 2 * p0h_w, rtol=1e-9, atol=1e-12)
        assert increment_w[0] == 0.0


# --- 7. trimmed quadrotor: the power bucket --------------------------------------------------------

MASS_KG = 8.0
ROTOR_RADIUS_M = 0.14
RHO_TRIM_KG_M3 = 1.15
FLAT_PLATE_AREA_M2 = 0.05       # equivalent flat-plate drag area f = C_D A of the whole airframe
ETA = 0.7


def trimmed_quadrotor_power_w(airspeed_m_s):
    """Total electrical power of a point-mass quadrotor in steady level flight at each airspeed.

    Trim: drag D = rho V^2 f / 2 is balanced by tilting the thrust forward by a with tan a = D / W,
    thrust T = sqrt(W^2 + D^2) shared over 4 rotors; each disk then meets V sin a along its axis and
    V cos a in its plane.
    """
    weight_n = MASS_KG * G_M_S2
    drag_n = 0.5 * RHO_TRIM_KG_M3 * airspeed_m_s ** 2 * FLAT_PLATE_AREA_M2
    tilt_rad = np.arctan2(drag_n, weight_n)
    per_rotor_n = np.hypot(weight_n, drag_n) / 4
    area_m2 = np.pi * ROTOR_RADIUS_M ** 2
    p0h_w = profile_hover_power_w(0.1, 0.01, RHO_TRIM_KG_M3, area_m2, V_TIP_M_S)
    shaft_w = rotor_shaft_power_w(per_rotor_n, airspeed_m_s * np.sin(tilt_rad), airspeed_m_s * np.cos(tilt_rad),
                                  RHO_TRIM_KG_M3, area_m2, p0h_w, V_TIP_M_S)
    return 4 * shaft_w / ETA, drag_n


def test_trimmed_quadrotor_power_has_a_bucket_with_one_minimum():
    # GIVEN an 8 kg quadrotor with 0.14 m rotors and f = 0.05 m^2, trimmed at 0..50 m/s
    airspeed_m_s = np.linspace(0.0, 50.0, 1001)
    power_w, _ = trimmed_quadrotor_power_w(airspeed_m_s)
    # THEN hover is eq. 4 for a quarter of the weight on each rotor
    area_m2 = np.pi * ROTOR_RADIUS_M ** 2
    assert_allclose(power_w[0], 4 * (MASS_KG * G_M_S2 / 4) ** 1.5 / (np.sqrt(2 * RHO_TRIM_KG_M3 * area_m2) * ETA),
                    rtol=1e-9)
    # AND the slope changes sign once, from falling (induced-power relief) to rising (parasite power)
    slope = np.diff(power_w)
    changes = np.flatnonzero(np.diff(np.sign(slope)))
    assert changes.size == 1
    i_min = int(np.argmin(power_w))
    assert changes[0] + 1 == i_min
    assert np.all(slope[:i_min] < 0) and np.all(slope[i_min:] > 0)
    v_min_power_m_s = airspeed_m_s[i_min]
    v_h = np.sqrt(MASS_KG * G_M_S2 / 4 / (2 * RHO_TRIM_KG_M3 * area_m2))        # ~11.8 m/s
    # the bucket's bottom lies above v_h (induced power still falling) and below 2 v_h, about 16.7 m/s
    assert v_h < v_min_power_m_s < 2 * v_h
    assert_allclose(v_min_power_m_s, 16.7, atol=0.1)
    assert power_w[i_min] < 0.8 * power_w[0]


def test_trimmed_quadrotor_power_falls_just_above_hover():
    power_w, _ = trimmed_quadrotor_power_w(np.array([0.0, 1.0, 2.0, 4.0]))
    assert np.all(np.diff(power_w) < 0)


def test_trimmed_quadrotor_power_rises_toward_the_cube_of_speed_when_fast():
    # GIVEN airspeeds far past the bucket
    airspeed_m_s = np.array([30.0, 40.0, 50.0])
    power_w, drag_n = trimmed_quadrotor_power_w(airspeed_m_s)
    # THEN the parasite power D V = rho f V^3 / 2 takes a growing share of the shaft power ...
    parasite_share = drag_n * airspeed_m_s / (power_w * ETA)
    assert np.all(np.diff(parasite_share) > 0) and parasite_share[-1] > 0.85
    # ... and the local exponent d ln P / d ln V climbs toward 3 without passing it
    v_lo, v_hi = airspeed_m_s * 0.99, airspeed_m_s * 1.01
    exponent = np.log(trimmed_quadrotor_power_w(v_hi)[0] / trimmed_quadrotor_power_w(v_lo)[0]) / np.log(v_hi / v_lo)
    assert np.all(np.diff(exponent) > 0)
    assert 2.5 < exponent[-1] < 3.0


# --- 8. windmill brake state ---------------------------------------------------------------------


def test_windmill_brake_shaft_power_is_negative_so_callers_must_clamp():
    # GIVEN a fast axial descent (V_c < -2 v_h): the air drives the rotor
    descent_m_s = -np.array([2.5, 3.0, 5.0]) * V_H_M_S
    # WHEN the shaft power is computed
    shaft_w = shaft_power(descent_m_s, 0.0)
    # THEN it is T u with u = V_c/2 - sqrt(V_c^2/4 - v_h^2) < 0: energy flows out of the air; the module
    # returns it signed and leaves the clamp of electrical power at zero (no regenerating ESC) to callers
    u = descent_m_s / 2 - np.sqrt(descent_m_s ** 2 / 4 - V_H_M_S ** 2)
    assert_allclose(shaft_w, THRUST_N * u, rtol=1e-9)
    assert np.all(shaft_w < 0)


# --- 9. shapes -----------------------------------------------------------------------------------


def test_fleet_arrays_of_m_by_4_rotors_come_back_m_by_4_and_row_by_row_equal(rng):
    # GIVEN 7 vehicles with mixed air density, disk area, profile power and tip speed, in mixed flight states
    m = 7
    thrust_n = rng.uniform(5.0, 40.0, (m, 4))
    v_axial_m_s = rng.uniform(-30.0, 15.0, (m, 4))
    v_inplane_m_s = rng.uniform(0.0, 25.0, (m, 4))
    rho, area = rng.uniform(0.9, 1.3, (m, 1)), rng.uniform(0.02, 0.2, (m, 1))
    p0h, v_tip = rng.uniform(1.0, 10.0, (m, 1)), rng.uniform(60.0, 120.0, (m, 1))
    # WHEN computed as one fleet and one vehicle at a time (N = 1)
    fleet_w = rotor_shaft_power_w(thrust_n, v_axial_m_s, v_inplane_m_s, rho, area, p0h, v_tip)
    fleet_vi = induced_velocity_m_s(thrust_n, v_axial_m_s, v_inplane_m_s, rho, area)
    # THEN shapes are kept and no parameter leaks between rows through broadcasting
    assert fleet_w.shape == (m, 4) and fleet_vi.shape == (m, 4)
    for k in range(m):
        row = slice(k, k + 1)
        assert_allclose(fleet_w[row], rotor_shaft_power_w(thrust_n[row], v_axial_m_s[row], v_inplane_m_s[row],
                                                          rho[row], area[row], p0h[row], v_tip[row]), rtol=1e-12)


def test_numpy_scalars_give_numpy_scalars():
    for v_axial_m_s in (np.float64(2.0), np.float64(-5.0)):
        power_w = rotor_shaft_power_w(np.float64(THRUST_N), v_axial_m_s, np.float64(3.0), RHO_KG_M3, AREA_M2, 4.0,
                                      V_TIP_M_S)
        assert np.ndim(power_w) == 0 and np.isfinite(power_w)
        same_w = shaft_power(np.array([v_axial_m_s]), np.array([3.0]), profile_hover_w=4.0)
        assert_allclose(power_w, same_w[0], rtol=1e-12)


def test_python_float_scalars_work():
    power_w = rotor_shaft_power_w(THRUST_N, 0.0, 0.0, RHO_KG_M3, AREA_M2, 0.0, V_TIP_M_S)
    assert_allclose(power_w, THRUST_N * V_H_M_S, rtol=1e-9)


def test_the_solver_warm_started_from_the_previous_steps_root_tracks_the_cold_solution(rng):
    # a fleet step at 240 Hz of an aggressive manoeuvre: thrust and airflow move a little
    n = 400
    v_h = rng.uniform(3.0, 15.0, n)
    v_axial, v_inplane = rng.uniform(-6.0, 8.0, n), rng.uniform(0.0, 25.0, n)
    before = glauert_inflow_m_s(v_axial, v_inplane, v_h)
    v_h2, v_axial2 = v_h * (1 + rng.uniform(-0.005, 0.005, n)), v_axial + rng.uniform(-0.02, 0.02, n)
    v_inplane2 = np.maximum(v_inplane + rng.uniform(-0.02, 0.02, n), 0.0)
    cold = glauert_inflow_m_s(v_axial2, v_inplane2, v_h2)
    warm = glauert_inflow_m_s(v_axial2, v_inplane2, v_h2, guess_m_s=before)
    assert_allclose(warm, cold, rtol=1e-6, atol=1e-6)          # far below anything power notices
    # held for a second step (the simulator starts each step from the last), it is the cold root
    assert_allclose(glauert_inflow_m_s(v_axial2, v_inplane2, v_h2, guess_m_s=warm), cold, rtol=1e-10, atol=1e-10)
    # and what it converges to is Glauert's relation
    assert_allclose(cold, v_axial2 + v_h2 ** 2 / np.sqrt(v_inplane2 ** 2 + cold ** 2), rtol=1e-9)
