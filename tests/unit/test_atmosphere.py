"""International Standard Atmosphere (troposphere) in unetyemu_ecs.control.atmosphere.

References are the tabulated values of ISO 2533:1975 / U.S. Standard Atmosphere 1976 (Table I):
sea level 288.15 K, 101325 Pa, 1.2250 kg/m^3; 600 m 1.1560 and 700 m 1.1448 kg/m^3 (so 1.150 at
650 m); 11 000 m 216.65 K, 22632 Pa, 0.36392 kg/m^3. The tables print 4-5 significant digits, which
sets the tolerances below (half a unit of the last printed digit).
"""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose

from unetyemu_ecs.control.atmosphere import (AirState, air_state_at_temperature, isa_air_state, isa_density_kg_m3,
                                             isa_pressure_pa, isa_temperature_k)

CELSIUS_TO_K = 273.15


def test_sea_level_is_the_isa_reference_state():
    state = isa_air_state(0.0)
    assert isinstance(state, AirState)
    assert_allclose(state.temperature_k, 288.15)
    assert_allclose(state.pressure_pa, 101_325.0)
    assert_allclose(state.density_kg_m3, 1.2250, atol=5e-5)


def test_density_at_650_m_matches_the_table_to_three_decimals():
    # the table gives 1.1560 at 600 m and 1.1448 at 700 m; 650 m lies between at 1.150
    assert_allclose(isa_density_kg_m3(650.0), 1.150, atol=5e-4)
    assert_allclose(isa_temperature_k(650.0), 288.15 - 0.0065 * 650.0)


def test_tropopause_state_matches_the_table():
    state = isa_air_state(11_000.0)
    assert_allclose(state.temperature_k, 216.65)
    assert_allclose(state.pressure_pa, 22_632.0, atol=0.5)
    assert_allclose(state.density_kg_m3, 0.36392, atol=5e-6)


def test_density_and_pressure_fall_monotonically_with_altitude():
    alt_m = np.linspace(-500.0, 11_000.0, 231)
    assert np.all(np.diff(isa_pressure_pa(alt_m)) < 0.0)
    assert np.all(np.diff(isa_density_kg_m3(alt_m)) < 0.0)
    # below sea level the air is denser than the reference
    assert isa_density_kg_m3(-500.0) > 1.225


def test_functions_keep_the_shape_of_a_fleet_of_altitudes():
    alt_m = np.array([[0.0, 650.0], [1_000.0, 11_000.0]])
    state = isa_air_state(alt_m)
    assert state.density_kg_m3.shape == state.temperature_k.shape == state.pressure_pa.shape == (2, 2)
    assert_allclose(state.density_kg_m3[0, 1], isa_density_kg_m3(650.0))


def test_hot_day_air_is_thinner_by_the_ratio_of_absolute_temperatures():
    # GIVEN a 35 °C day at 650 m, where the ISA has 10.8 °C
    alt_m, hot_k = 650.0, 35.0 + CELSIUS_TO_K
    isa = isa_air_state(alt_m)
    # WHEN the density is computed from the actual temperature at the ISA pressure
    hot = air_state_at_temperature(alt_m, hot_k)
    # THEN the pressure is unchanged and the density drops by T_isa / T (about 8 %)
    assert_allclose(hot.pressure_pa, isa.pressure_pa)
    assert_allclose(hot.density_kg_m3, isa.density_kg_m3 * isa.temperature_k / hot_k, rtol=1e-12)
    assert hot.density_kg_m3 < 0.93 * isa.density_kg_m3


def test_isa_temperature_gives_back_the_isa_density():
    alt_m = np.array([0.0, 650.0, 5_000.0])
    assert_allclose(air_state_at_temperature(alt_m, isa_temperature_k(alt_m)).density_kg_m3,
                    isa_density_kg_m3(alt_m), rtol=1e-14)


@pytest.mark.parametrize("alt_m", [-501.0, 11_001.0, np.array([0.0, 20_000.0])])
def test_altitude_outside_the_troposphere_is_rejected(alt_m):
    with pytest.raises(ValueError, match="troposphere"):
        isa_air_state(alt_m)


def test_temperature_in_celsius_is_rejected():
    with pytest.raises(ValueError, match="kelvin"):
        air_state_at_temperature(650.0, 35.0)
