"""The energy system's compiled step runs the same laws as the NumPy functions callers use, drone by drone and
rotor by rotor, reads and writes only its drones' rows, and keeps the physics: eq. 4 in hover, a charger
filling the pack, the motors stopped at the cut-off."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose

from unetyemu_ecs.control.battery_ecm import (cell_ocv_v, energy_remaining_wh, pack_current_for_power_a, rc_decay,
                                              step_pack)
from unetyemu_ecs.control.energy import rotor_power_w
from unetyemu_ecs.control.energy_step import J_PER_WH, energy_params, energy_step, fleet_power_w
from unetyemu_ecs.control.rotor_power import (PROFILE_MU2_FACTOR, glauert_inflow_m_s, hover_induced_velocity_m_s,
                                              shaft_power_from_inflow_w, vortex_ring_correction_m_s)
from unetyemu_ecs.frames import R_from_quat_xyzw

CAPACITY = 9                      # fleet rows; the drones sit in some of them, in this order
ROWS = np.array([5, 1, 3, 7], dtype=np.intp)
M = ROWS.size
RHO, RADIUS_M, ETA, P0_W, TIP_M_S = 1.225, 0.14, 0.8, 15.0, 120.0
AREA_M2 = np.pi * RADIUS_M ** 2
PROFILE_HOVER_W = 6.0
ARM_M = 0.25
DT_S = 1.0 / 240.0
CELLS, CELL_R0, CELL_R1, TAU_S, CAPACITY_AH, CUTOFF_CELL_V = 6.0, 1e-3, 0.627e-3, 32.85, 22.0, 3.5


@pytest.fixture
def rng():
    return np.random.default_rng(11)


def axial_per_rate(m: int) -> np.ndarray:
    """(m, 2, 4): [w_x, w_y] @ this is each rotor's axial speed, rotors FL, FR, BR, BL of an X frame of ARM_M."""
    d = ARM_M / np.sqrt(2.0)
    x = np.array([d, d, -d, -d])
    y = np.array([d, -d, -d, d])
    return np.repeat(np.stack([y, -x])[None], m, axis=0)


def params(momentum: list[bool], lipo: list[bool], soc_low: float = 0.2) -> np.ndarray:
    p = energy_params(len(momentum))
    p["momentum"], p["lipo"] = momentum, lipo
    p["two_rho_area_kg_m"] = 2.0 * RHO * AREA_M2
    p["efficiency"], p["p0_w"], p["tip_speed_m_s"] = ETA, P0_W, TIP_M_S
    p["profile_mu2_w"] = PROFILE_HOVER_W * PROFILE_MU2_FACTOR
    p["cells"], p["r0_pack_ohm"], p["r1_pack_ohm"] = CELLS, CELLS * CELL_R0, CELLS * CELL_R1
    p["rc_decay"], p["rc_rise"] = rc_decay(DT_S, np.full(len(momentum), TAU_S))
    p["capacity_eff_as"] = 3600.0 * CAPACITY_AH
    p["cells_capacity_ah"] = CELLS * CAPACITY_AH
    p["cutoff_pack_v"] = CELLS * CUTOFF_CELL_V
    p["ideal_capacity_j"] = 500.0 * J_PER_WH
    p["ideal_pack_v"] = CELLS * 3.7
    p["low_battery_frac"] = soc_low
    p["filter_gain"] = 1.0 - np.exp(-DT_S / 2.0)
    return p


class Fleet:
    """The fleet arrays the step reads and writes, with random flight states in every row."""

    def __init__(self, rng: np.random.Generator) -> None:
        self.motor_thrust_n = rng.uniform(-2.0, 40.0, (CAPACITY, 4))
        self.ground_effect_factor = rng.uniform(1.0, 1.3, (CAPACITY, 4))
        self.vel_enu_m_s = rng.uniform(-15.0, 15.0, (CAPACITY, 3))
        self.wind_enu_m_s = rng.uniform(-5.0, 5.0, (CAPACITY, 3))
        q = rng.normal(size=(CAPACITY, 4))
        self.R_enu_flu = R_from_quat_xyzw(q / np.linalg.norm(q, axis=1, keepdims=True))
        self.rate_flu_rad_s = rng.uniform(-3.0, 3.0, (CAPACITY, 3))
        self.glauert_inflow_m_s = np.zeros((CAPACITY, 4))         # no root yet: the solver starts cold
        self.charging = np.zeros(CAPACITY, dtype=bool)
        self.charge_power_w = np.zeros(CAPACITY)
        self.soc_frac = rng.uniform(0.3, 0.9, CAPACITY)
        self.pack_v_rc_v = rng.uniform(0.0, 0.3, CAPACITY)
        self.power_w = np.zeros(CAPACITY)
        self.power_filt_w = np.full(CAPACITY, 500.0)
        self.pack_current_a = np.zeros(CAPACITY)
        self.pack_voltage_v = np.zeros(CAPACITY)
        self.energy_j = np.zeros(CAPACITY)
        self.energy_used_j = np.zeros(CAPACITY)
        self.remaining_time_s = np.zeros(CAPACITY)
        self.low_battery = np.zeros(CAPACITY, dtype=bool)
        self.motors_enabled = np.ones(CAPACITY, dtype=bool)

    def power(self, p: np.ndarray) -> np.ndarray:
        return fleet_power_w(ROWS, p, axial_per_rate(M), self.motor_thrust_n, self.ground_effect_factor,
                             self.vel_enu_m_s, self.wind_enu_m_s, self.R_enu_flu, self.rate_flu_rad_s,
                             self.glauert_inflow_m_s)

    def step(self, p: np.ndarray) -> None:
        energy_step(ROWS, p, axial_per_rate(M), DT_S, self.motor_thrust_n, self.ground_effect_factor, self.vel_enu_m_s,
                    self.wind_enu_m_s, self.R_enu_flu, self.rate_flu_rad_s, self.glauert_inflow_m_s, self.charging,
                    self.charge_power_w, self.soc_frac, self.pack_v_rc_v, self.power_w, self.power_filt_w,
                    self.pack_current_a, self.pack_voltage_v, self.energy_j, self.energy_used_j,
                    self.remaining_time_s, self.low_battery, self.motors_enabled)


def momentum_power_with_numpy_w(f: Fleet) -> np.ndarray:
    """(M,) the momentum model's power of the drones in ROWS, from the NumPy laws on whole arrays."""
    v_rel = f.vel_enu_m_s[ROWS] - f.wind_enu_m_s[ROWS]
    v_flu = np.einsum("mij,mi->mj", f.R_enu_flu[ROWS], v_rel)
    v_axial = v_flu[:, 2:3] + np.einsum("mk,mkj->mj", f.rate_flu_rad_s[ROWS, :2], axial_per_rate(M))
    v_inplane = np.hypot(v_flu[:, 0:1], v_flu[:, 1:2])
    thrust = f.motor_thrust_n[ROWS] / f.ground_effect_factor[ROWS]
    v_h = hover_induced_velocity_m_s(thrust, RHO, AREA_M2)
    inflow = glauert_inflow_m_s(v_axial, v_inplane, v_h) + vortex_ring_correction_m_s(v_axial, v_inplane, v_h)
    shaft = shaft_power_from_inflow_w(thrust, inflow, v_inplane, PROFILE_HOVER_W, TIP_M_S)
    return (np.maximum(shaft, 0.0) / ETA).sum(axis=1) + P0_W


def test_compiled_power_is_the_numpy_laws_drone_by_drone(rng):
    for _ in range(20):                       # climbs, descents (vortex ring, windmill brake), forward flight
        f = Fleet(rng)
        assert_allclose(f.power(params([True] * M, [True] * M)), momentum_power_with_numpy_w(f), rtol=1e-10)
        f = Fleet(rng)
        thrust = f.motor_thrust_n[ROWS] / f.ground_effect_factor[ROWS]
        eq4 = rotor_power_w(thrust, np.full(M, RHO), np.full(M, AREA_M2), np.full(M, ETA)).sum(axis=1) + P0_W
        assert_allclose(f.power(params([False] * M, [True] * M)), eq4, rtol=1e-12)


def test_each_drone_has_its_own_power_model():
    f = Fleet(np.random.default_rng(3))
    mixed = f.power(params([True, False, True, False], [True] * M))
    both = [Fleet(np.random.default_rng(3)).power(params([m] * M, [True] * M)) for m in (True, False)]
    assert_allclose(mixed, np.where([True, False, True, False], both[0], both[1]), rtol=1e-12)


def test_hovering_level_in_still_air_it_is_the_papers_eq_4():
    f = Fleet(np.random.default_rng(5))
    f.vel_enu_m_s[:] = f.wind_enu_m_s[:] = f.rate_flu_rad_s[:] = 0.0
    f.R_enu_flu[:] = np.eye(3)
    f.ground_effect_factor[:] = 1.0
    f.motor_thrust_n[:] = 2.5 * 9.81 / 4.0
    expected = 4.0 * (2.5 * 9.81 / 4.0) ** 1.5 / (np.sqrt(2.0 * RHO * AREA_M2) * ETA) + P0_W
    assert_allclose(f.power(params([True] * M, [True] * M)), expected, rtol=1e-12)


def test_the_solver_keeps_each_rotors_root_for_the_next_step(rng):
    f = Fleet(rng)
    f.power(params([True] * M, [True] * M))
    kept = f.glauert_inflow_m_s.copy()
    assert np.all(kept[ROWS] != 0.0)
    others = np.setdiff1d(np.arange(CAPACITY), ROWS)
    assert np.all(kept[others] == 0.0)                  # rows of other bodies untouched
    f.power(params([True] * M, [True] * M))             # the same state again: the warm start finds the same root
    assert_allclose(f.glauert_inflow_m_s, kept, rtol=1e-10, atol=1e-12)


def test_a_lipo_step_is_step_pack_at_the_current_that_delivers_the_power(rng):
    f = Fleet(rng)
    before = {k: v.copy() for k, v in vars(f).items()}
    p = params([True] * M, [True] * M)
    f.step(p)
    power = momentum_power_with_numpy_w(Fleet(np.random.default_rng(11)))
    assert_allclose(f.power_w[ROWS], power, rtol=1e-10)
    soc, v_rc = before["soc_frac"][ROWS], before["pack_v_rc_v"][ROWS]
    current, _ = pack_current_for_power_a(f.power_w[ROWS], CELLS * cell_ocv_v(soc), v_rc, CELLS * CELL_R0)
    pack = step_pack(soc, v_rc, current, DT_S, CAPACITY_AH, CELLS * CELL_R0, CELLS * CELL_R1, TAU_S, CELLS)
    assert_allclose(f.pack_current_a[ROWS], current, rtol=1e-12)
    assert_allclose(f.soc_frac[ROWS], pack.soc_frac, rtol=1e-12)
    assert_allclose(f.pack_v_rc_v[ROWS], pack.v_rc_v, rtol=1e-12)
    assert_allclose(f.pack_voltage_v[ROWS], pack.terminal_v, rtol=1e-12)
    assert_allclose(f.energy_j[ROWS], energy_remaining_wh(pack.soc_frac, CAPACITY_AH, CELLS) * J_PER_WH, rtol=1e-12)
    assert_allclose(f.energy_used_j[ROWS], f.power_w[ROWS] * DT_S, rtol=1e-15)
    filt = 500.0 + (1.0 - np.exp(-DT_S / 2.0)) * (f.power_w[ROWS] - 500.0)
    assert_allclose(f.power_filt_w[ROWS], filt, rtol=1e-12)
    assert_allclose(f.remaining_time_s[ROWS], f.energy_j[ROWS] / filt, rtol=1e-12)
    others = np.setdiff1d(np.arange(CAPACITY), ROWS)
    for name, was in before.items():                    # no other row is written
        assert np.array_equal(getattr(f, name)[others], was[others]), name


def test_an_ideal_bucket_loses_the_energy_drawn_at_its_fixed_voltage(rng):
    f = Fleet(rng)
    soc = f.soc_frac[ROWS].copy()
    f.step(params([True] * M, [False] * M))
    capacity_j = 500.0 * J_PER_WH
    assert_allclose(f.energy_j[ROWS], soc * capacity_j - f.power_w[ROWS] * DT_S, rtol=1e-12)
    assert_allclose(f.soc_frac[ROWS], f.energy_j[ROWS] / capacity_j, rtol=1e-12)
    assert_allclose(f.pack_voltage_v[ROWS], CELLS * 3.7)
    assert_allclose(f.pack_current_a[ROWS], f.power_w[ROWS] / (CELLS * 3.7), rtol=1e-12)


def test_a_charger_stronger_than_the_load_fills_the_pack(rng):
    f = Fleet(rng)
    f.charging[ROWS[0]] = True
    f.charge_power_w[ROWS[0]] = 3000.0 + 4 * 40.0 ** 1.5 / (np.sqrt(2 * RHO * AREA_M2) * ETA)   # above any draw
    soc = f.soc_frac.copy()
    f.step(params([True] * M, [True] * M))
    assert f.pack_current_a[ROWS[0]] < 0.0 and f.soc_frac[ROWS[0]] > soc[ROWS[0]]
    assert np.all(f.soc_frac[ROWS[1:]] < soc[ROWS[1:]])


def test_a_pack_below_its_cut_off_stops_only_its_own_motors_and_a_low_one_says_so(rng):
    f = Fleet(rng)
    f.soc_frac[ROWS[2]] = 1e-6                          # nearly empty: the terminal voltage sags below cut-off
    f.motor_thrust_n[ROWS[2]] = 40.0
    f.soc_frac[ROWS[1]] = 0.1                           # low but flying
    f.step(params([True] * M, [True] * M))
    assert list(f.motors_enabled[ROWS]) == [True, True, False, True]
    assert f.pack_voltage_v[ROWS[2]] < CELLS * CUTOFF_CELL_V
    assert list(f.low_battery[ROWS]) == [False, True, True, False]
