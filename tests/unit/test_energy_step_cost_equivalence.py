"""The energy system's cheaper per-step forms give bit for bit what the plain formulas give: the shared OCV
exponential, the RC constants kept between steps, the rotor constants kept in ``gather``; and a SOC changed from outside
the energy system is the one the next step starts from."""

from __future__ import annotations

import numpy as np
from numpy.testing import assert_allclose, assert_array_equal

from unetyemu_ecs import Simulation, load_world_text
from unetyemu_ecs.control.battery_ecm import (LipoPackParams, advance_pack, cell_ocv_and_integral_v, cell_ocv_v,
                                              energy_remaining_wh, pack_current_for_power_a, pack_terminal_v,
                                              rc_decay, step_pack, terminal_from_ocv_v)
from unetyemu_ecs.control.rotor_power import (PROFILE_MU2_FACTOR, hover_induced_velocity_m_s,
                                              hover_induced_velocity_of_loading_m_s, shaft_power_from_inflow_w,
                                              shaft_power_of_positive_thrust_w)
from unetyemu_ecs.systems.energy import EnergySystem

P = LipoPackParams()
CELLS, Q_AH, R0, R1, TAU = P.cells_series, P.capacity_ah, P.r0_pack_ohm, P.r1_pack_ohm, P.tau1_s
RNG = np.random.default_rng(7)


def test_shared_exponential_gives_the_ocv_and_its_integral_exactly():
    soc = np.concatenate([RNG.uniform(-0.2, 1.2, 500), [0.0, -0.0, 1.0, 0.5]])
    ocv, integral = cell_ocv_and_integral_v(soc)
    assert_array_equal(ocv, cell_ocv_v(soc))
    assert_array_equal(CELLS * Q_AH * integral, energy_remaining_wh(soc, Q_AH, CELLS))
    # the formulas as they were written before the split
    s = np.minimum(np.maximum(soc, 0.0), 1.0)
    assert_array_equal(ocv, -1.031 * np.exp(-35.0 * s) + 3.685 + s * (0.2156 + s * (-0.1178 + s * 0.3201)))
    assert_array_equal(integral, -1.031 / -35.0 * (np.exp(-35.0 * s) - 1.0)
                       + s * (3.685 + s * (0.2156 / 2 + s * (-0.1178 / 3 + s * 0.3201 / 4))))


def test_advance_pack_with_kept_constants_is_step_pack_exactly():
    soc, v_rc = RNG.uniform(0.0, 1.0, 200), RNG.uniform(-0.5, 0.5, 200)
    current = RNG.uniform(-80.0, 400.0, 200)
    for dt_s in (1.0 / 240.0, 0.01, 1.0):
        pack = step_pack(soc, v_rc, current, dt_s, Q_AH, R0, R1, TAU, CELLS)
        decay, rise = rc_decay(dt_s, np.full(200, TAU))
        new_soc, new_v_rc = advance_pack(soc, v_rc, current, dt_s, 3600.0 * Q_AH, decay, rise, R1)
        assert_array_equal(new_soc, pack.soc_frac)
        assert_array_equal(new_v_rc, pack.v_rc_v)
        assert_array_equal(terminal_from_ocv_v(CELLS * cell_ocv_and_integral_v(new_soc)[0], new_v_rc, current, R0),
                           pack.terminal_v)
        # the formulas as they were written before the split
        expected_soc = np.minimum(np.maximum(soc - current * dt_s / (3600.0 * Q_AH), 0.0), 1.0)
        d = np.exp(-dt_s / TAU)
        assert_array_equal(new_soc, expected_soc)
        assert_array_equal(new_v_rc, v_rc * d + current * R1 * (1.0 - d))
        assert_array_equal(pack.terminal_v, CELLS * cell_ocv_v(new_soc) - new_v_rc - current * R0)


def test_pack_current_without_a_limited_pack_is_the_root_as_it_was():
    e_v = CELLS * cell_ocv_v(RNG.uniform(0.0, 1.0, 100))
    v_rc = RNG.uniform(-0.2, 0.2, 100)
    power = RNG.uniform(-2000.0, 3000.0, 100)
    current, limited = pack_current_for_power_a(power, e_v, v_rc, R0)
    assert not limited.any()
    e = e_v - v_rc
    assert_array_equal(current, 2.0 * power / (e + np.sqrt(np.maximum(e * e - 4.0 * R0 * power, 0.0))))
    big = power.copy()
    big[::7] = 1e7                                  # past the maximum-power point: the limited branch still runs
    current, limited = pack_current_for_power_a(big, e_v, v_rc, R0)
    assert limited[::7].all() and not limited[1::7].any()
    assert_array_equal(current[::7], e[::7] / (2.0 * R0))


def test_rotor_constants_kept_give_the_same_induced_velocity_and_shaft_power():
    thrust = RNG.uniform(-5.0, 60.0, (50, 4))
    rho, area = RNG.uniform(0.9, 1.3, (50, 1)), RNG.uniform(0.05, 0.3, (50, 1))
    thrust_pos = np.maximum(thrust, 0.0)
    assert_array_equal(hover_induced_velocity_of_loading_m_s(thrust_pos, 2.0 * rho * area),
                       hover_induced_velocity_m_s(thrust, rho, area))
    assert_array_equal(hover_induced_velocity_m_s(thrust, rho, area),
                       np.sqrt(np.maximum(thrust, 0.0) / (2.0 * rho * area)))
    inflow, v_inplane = RNG.uniform(-2.0, 15.0, (50, 4)), RNG.uniform(0.0, 20.0, (50, 1))
    profile, tip = RNG.uniform(5.0, 50.0, (50, 1)), RNG.uniform(100.0, 200.0, (50, 1))
    shaft = shaft_power_from_inflow_w(thrust, inflow, v_inplane, profile, tip)
    assert_array_equal(shaft_power_of_positive_thrust_w(thrust_pos, inflow, v_inplane, profile * PROFILE_MU2_FACTOR,
                                                        tip), shaft)
    mu = v_inplane / tip
    assert_array_equal(shaft, np.maximum(thrust, 0.0) * inflow + profile * PROFILE_MU2_FACTOR * mu * mu)


WORLD = """world: {name: p, physics_hz: 240, seed: 1}
scene: {generator: none, ground_size_m: 200}
vehicles:
  - {name: d1, type: quadrotor, preset: medium, pose: {position_m: [0, 0, 0.2]}}
  - {name: d2, type: quadrotor, preset: medium, pose: {position_m: [4, 0, 0.2]}}
"""


def test_a_soc_changed_from_outside_sets_the_next_steps_current_and_voltage():
    sim = Simulation(load_world_text(WORLD))
    try:
        sim.set_target("d1", 0, 0, 3.0)
        sim.set_target("d2", 4, 0, 3.0)
        sim.run(duration=1.0)
        energy = next(s for s in sim._fleet_systems if isinstance(s, EnergySystem))
        f, rows = sim.fleet, energy.rows
        cells, r0 = energy._params["cells"], energy._params["r0_pack_ohm"]
        f.soc_frac[rows[1]] = 0.4                    # e.g. a battery swap
        soc, v_rc = f.soc_frac[rows].copy(), f.pack_v_rc_v[rows].copy()
        sim.step()
        current = f.pack_current_a[rows]
        power = f.power_w[rows]
        # the compiled step's exponential may differ from NumPy's in the last bit
        expected, _ = pack_current_for_power_a(power, cells * cell_ocv_v(soc), v_rc, r0)
        assert_allclose(current, expected, rtol=1e-12)
        assert_allclose(f.pack_voltage_v[rows], pack_terminal_v(f.soc_frac[rows], f.pack_v_rc_v[rows], current, r0,
                                                                cells), rtol=1e-12)
    finally:
        sim.close()
