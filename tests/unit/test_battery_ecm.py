"""LiPo pack equivalent circuit without esper or PyBullet: OCV curve, R0 jump, RC relaxation, coulomb
counting, power demand, charging, cut-off, capacity fade, energy."""

from __future__ import annotations

import numpy as np
from numpy.testing import assert_allclose

from unetyemu_ecs.control.battery_ecm import (LipoPackParams, cell_ocv_v, energy_remaining_wh, full_cycles_of,
                                              pack_current_for_power_a, pack_cut_off, pack_terminal_v, soh_frac,
                                              step_pack)

P = LipoPackParams()
CELLS, Q_AH, R0, R1, TAU = P.cells_series, P.capacity_ah, P.r0_pack_ohm, P.r1_pack_ohm, P.tau1_s


def one(x):
    return np.array([x], dtype=float)


def step(soc, v_rc, current, dt_s, q_eff_ah=Q_AH):
    return step_pack(soc, v_rc, current, dt_s, q_eff_ah, R0, R1, TAU, CELLS)


def test_ocv_rises_monotonically_from_empty_to_full():
    ocv = cell_ocv_v(np.linspace(0.0, 1.0, 1001))
    assert np.all(np.diff(ocv) > 0.0)


def test_ocv_spans_the_lipo_range_full_near_4v2_and_the_cut_off_near_empty():
    # Chen & Rincon-Mora's fit tops out at 4.10 V: within 0.1 V of the 4.20 V charge voltage
    assert_allclose(cell_ocv_v(one(1.0)), P.cell_full_v, atol=0.1)
    # the 3.5 V/cell cut-off lies in the last 10 % of the charge, and an empty cell is below 3.0 V
    assert cell_ocv_v(one(0.0))[0] < 3.0 < P.cell_cutoff_v < cell_ocv_v(one(0.1))[0]


def test_full_pack_at_rest_reads_cells_times_4v2():
    v = pack_terminal_v(one(1.0), one(0.0), one(0.0), R0, CELLS)
    assert_allclose(v, CELLS * 4.2, atol=CELLS * 0.1)     # the OCV fit's 0.1 V/cell shortfall at full


def test_current_step_from_rest_drops_the_terminal_voltage_by_exactly_i_r0():
    # GIVEN a pack at rest at half charge; WHEN 80 A is switched on (no time has passed yet)
    soc, i_a = one(0.5), one(80.0)
    rest = pack_terminal_v(soc, one(0.0), one(0.0), R0, CELLS)
    after = step(soc, one(0.0), i_a, 0.0)
    # THEN only the ohmic drop appears: the RC pair has not charged
    assert_allclose(rest - after.terminal_v, 80.0 * R0, rtol=1e-12)
    assert_allclose(after.v_rc_v, 0.0)


def test_rc_voltage_is_one_minus_one_over_e_of_the_way_after_one_time_constant():
    # GIVEN 80 A from rest, held for one tau = R1 C1 in 37 steps
    soc, v_rc, i_a = one(0.5), one(0.0), one(80.0)
    for _ in range(37):
        s = step(soc, v_rc, i_a, TAU / 37)
        soc, v_rc = s.soc_frac, s.v_rc_v
    # THEN the exact discretisation lands on I R1 (1 - 1/e) whatever the step count
    assert_allclose(v_rc, 80.0 * R1 * (1.0 - np.exp(-1.0)), rtol=1e-12)
    ocv = CELLS * cell_ocv_v(soc)
    assert_allclose(ocv - s.terminal_v, 80.0 * (R0 + R1 * (1.0 - np.exp(-1.0))), rtol=1e-12)


def test_overpotential_relaxes_to_i_times_r0_plus_r1_under_a_held_current():
    s = step(one(0.5), one(0.0), one(80.0), 20.0 * TAU)
    ocv = CELLS * cell_ocv_v(s.soc_frac)
    assert_allclose(ocv - s.terminal_v, 80.0 * (R0 + R1), rtol=1e-8)   # e^-20 of R1's share is left


def test_constant_current_lowers_soc_by_i_t_over_the_effective_capacity():
    # GIVEN a pack at 90 % health; WHEN 50 A flows for 10 min
    q_eff = Q_AH * 0.9
    s = step(one(0.8), one(0.0), one(50.0), 600.0, q_eff)
    assert_allclose(0.8 - s.soc_frac, 50.0 * 600.0 / (3600.0 * q_eff), rtol=1e-12)


def test_current_for_a_power_demand_delivers_exactly_that_power_at_the_terminals(rng):
    soc = rng.uniform(0.05, 1.0, 200)
    v_rc = rng.uniform(0.0, 0.5, 200)
    e_v = CELLS * cell_ocv_v(soc) - v_rc
    power = rng.uniform(0.0, 0.99, 200) * e_v ** 2 / (4.0 * R0)
    current, limited = pack_current_for_power_a(power, CELLS * cell_ocv_v(soc), v_rc, R0)
    assert not limited.any()
    assert_allclose(pack_terminal_v(soc, v_rc, current, R0, CELLS) * current, power, rtol=1e-9)
    assert np.all(current <= e_v / (2.0 * R0))         # the low-current root, not the wasteful one


def test_demand_above_the_maximum_power_point_is_flagged_and_gets_its_current():
    e_v = CELLS * cell_ocv_v(one(0.3))
    p_max = e_v ** 2 / (4.0 * R0)
    current, limited = pack_current_for_power_a(np.concatenate([0.999 * p_max, 1.2 * p_max]),
                                                np.repeat(e_v, 2), np.zeros(2), R0)
    assert list(limited) == [False, True]
    assert_allclose(current[1], e_v / (2.0 * R0))
    assert_allclose((e_v - current[1] * R0) * current[1], p_max)   # it still delivers the maximum


def test_charging_current_raises_soc_and_the_voltage_by_i_r0_at_once():
    # GIVEN a pack at rest at 40 %; WHEN a 0.5C charger pushes 11 A in for 10 min
    soc, rest = one(0.4), pack_terminal_v(one(0.4), one(0.0), one(0.0), R0, CELLS)
    jump = step(soc, one(0.0), one(-11.0), 0.0)
    assert_allclose(jump.terminal_v - rest, 11.0 * R0, rtol=1e-12)
    later = step(soc, one(0.0), one(-11.0), 600.0)
    assert_allclose(later.soc_frac - 0.4, 11.0 * 600.0 / (3600.0 * Q_AH), rtol=1e-12)
    assert later.v_rc_v[0] < 0.0 and later.terminal_v[0] > jump.terminal_v[0]


def test_a_charger_power_gives_a_negative_current_that_absorbs_it():
    soc, v_rc = one(0.4), one(-0.05)
    current, limited = pack_current_for_power_a(one(-500.0), CELLS * cell_ocv_v(soc), v_rc, R0)
    assert current[0] < 0.0 and not limited[0]
    assert_allclose(pack_terminal_v(soc, v_rc, current, R0, CELLS) * current, -500.0, rtol=1e-12)


def test_soc_stays_within_zero_and_one():
    full = step(one(0.999), one(0.0), one(-22.0), 3600.0)
    empty = step(one(0.001), one(0.0), one(22.0), 3600.0)
    assert full.soc_frac[0] == 1.0 and empty.soc_frac[0] == 0.0


def test_capacity_fades_to_the_end_of_life_fraction_at_the_rated_cycle_life():
    cycles = np.array([0.0, 0.5 * P.cycle_life, P.cycle_life])
    assert_allclose(soh_frac(cycles, P.cycle_life, P.eol_capacity_frac), [1.0, 0.9, 0.8])


def test_a_full_discharge_and_recharge_count_as_one_cycle():
    # a 1C discharge for 1 h, then a 1C recharge for 1 h
    used = full_cycles_of(one(Q_AH), 3600.0, Q_AH) + full_cycles_of(one(-Q_AH), 3600.0, Q_AH)
    assert_allclose(used, 1.0)


def test_cut_off_when_a_cell_under_load_falls_below_the_cut_off_or_the_pack_is_empty():
    v = CELLS * np.array([3.6, 3.49, 3.8])
    soc = np.array([0.2, 0.2, 0.0])
    assert list(pack_cut_off(v, soc, CELLS, P.cell_cutoff_v)) == [False, True, True]


def test_open_circuit_energy_grows_by_cells_q_ocv_per_unit_of_charge():
    soc, d = np.linspace(0.0, 0.99, 100), 1e-6
    de = energy_remaining_wh(soc + d, Q_AH, CELLS) - energy_remaining_wh(soc, Q_AH, CELLS)
    assert_allclose(de / d, CELLS * Q_AH * cell_ocv_v(soc + d / 2), rtol=1e-6)
    assert_allclose(energy_remaining_wh(one(0.0), Q_AH, CELLS), 0.0, atol=1e-12)
    # the fit's mean OCV is 3.80 V against the 3.7 V nominal: within 3 % of the rated 488 Wh
    assert_allclose(energy_remaining_wh(one(1.0), Q_AH, CELLS), P.energy_nominal_wh, rtol=0.03)


def test_a_1500_w_hover_delivers_most_of_the_rated_energy_before_the_cut_off():
    soc, v_rc, t_s, dt = one(1.0), one(0.0), 0.0, 1.0
    while True:
        current, limited = pack_current_for_power_a(one(1500.0), CELLS * cell_ocv_v(soc), v_rc, R0)
        s = step(soc, v_rc, current, dt)
        soc, v_rc, t_s = s.soc_frac, s.v_rc_v, t_s + dt
        if pack_cut_off(s.terminal_v, soc, CELLS, P.cell_cutoff_v)[0]:
            break
    delivered_wh = 1500.0 * t_s / 3600.0
    # losses in R0 + R1 (~3 %) and the charge left below 3.5 V/cell under load (~7 %) stay unused
    assert 0.85 * P.energy_nominal_wh < delivered_wh < P.energy_nominal_wh
    assert 0.0 < soc[0] < 0.15 and not limited[0]


def test_a_mixed_fleet_steps_each_pack_as_if_it_were_alone():
    small = LipoPackParams(cells_series=4, capacity_ah=5.0, r0_cell_ohm=4e-3, r1_cell_ohm=2e-3, tau1_s=15.0)
    packs = (P, small)
    soc, v_rc, i_a = np.array([0.7, 0.4]), np.array([0.1, -0.02]), np.array([60.0, -3.0])

    def arr(name):
        return np.array([getattr(p, name) for p in packs], dtype=float)

    both = step_pack(soc, v_rc, i_a, 2.5, arr("capacity_ah"), arr("r0_pack_ohm"), arr("r1_pack_ohm"),
                     arr("tau1_s"), arr("cells_series"))
    for k, p in enumerate(packs):
        alone = step_pack(soc[k:k + 1], v_rc[k:k + 1], i_a[k:k + 1], 2.5, p.capacity_ah, p.r0_pack_ohm,
                          p.r1_pack_ohm, p.tau1_s, p.cells_series)
        for got, want in zip(both, alone):
            assert_allclose(got[k], want[0], rtol=1e-14)


def test_series_cells_multiply_resistance_and_keep_the_cell_time_constant():
    assert_allclose(P.r0_pack_ohm, CELLS * P.r0_cell_ohm)
    assert_allclose(P.r1_pack_ohm * (P.c1_cell_f / CELLS), P.tau1_s)    # pack C1 = cell C1 / cells
    assert_allclose(P.lim_discharge_a, 25.0 * 22.0)
