"""International Standard Atmosphere, troposphere only, vectorised.

Sources: ISO 2533:1975 *Standard Atmosphere* (identical to ICAO Doc 7488/3 and, below 32 km, to the
U.S. Standard Atmosphere 1976, NOAA-S/T 76-1562). In the troposphere the layer has a constant
temperature gradient, so the hydrostatic equation integrates in closed form::

    T = T0 + L h                          T0 = 288.15 K, L = -0.0065 K/m
    p = p0 (T / T0) ** (-g0 / (R L))      p0 = 101325 Pa, g0 = 9.80665 m/s^2
    rho = p / (R T)                       R = 287.05287 J/(kg K), the specific gas constant of air

``g0 / (R L)`` is the ``g0 M / (R* L)`` of the molar form (M = 0.0289644 kg/mol), written with ISO
2533's specific constant so that pressure and density use one value of R. ``h`` is the geopotential
altitude above mean sea level; below 11 km it differs from the geometric altitude by less than 0.2 %
(``h = r z / (r + z)``, r = 6356.766 km), i.e. 0.16 m at 1 km, which this module ignores.

The standard gravity g0 here is the ISA's defining constant 9.80665 m/s^2, not the simulator's
``units.GRAVITY_M_S2`` (9.81): the table values (1.225 kg/m^3 at sea level, 0.3639 kg/m^3 at 11 km)
depend on it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

ISA_T0_K = 288.15
ISA_P0_PA = 101_325.0
ISA_LAPSE_RATE_K_M = -0.0065
ISA_STANDARD_GRAVITY_M_S2 = 9.80665
AIR_GAS_CONSTANT_J_KG_K = 287.05287
ISA_ALT_MIN_M = -500.0       # below any land surface (Dead Sea shore -430 m); the layer's formulas hold there
ISA_ALT_MAX_M = 11_000.0     # tropopause: above it the temperature is constant and these formulas fail
AIR_TEMP_MIN_K = 150.0
AIR_TEMP_MAX_K = 400.0

__all__ = ["AirState", "isa_temperature_k", "isa_pressure_pa", "isa_density_kg_m3", "isa_air_state",
           "air_state_at_temperature"]


@dataclass(frozen=True, slots=True)
class AirState:
    """Thermodynamic state of the air at one or more points (all fields share one shape)."""

    density_kg_m3: np.ndarray
    temperature_k: np.ndarray
    pressure_pa: np.ndarray


def _checked_alt_m(alt_msl_m: ArrayLike) -> np.ndarray:
    alt = np.asarray(alt_msl_m, dtype=np.float64)
    if not np.all((alt >= ISA_ALT_MIN_M) & (alt <= ISA_ALT_MAX_M)):
        raise ValueError(f"ISA troposphere covers {ISA_ALT_MIN_M:g}..{ISA_ALT_MAX_M:g} m geopotential altitude; "
                         f"got {alt.min():g}..{alt.max():g} m")
    return alt


def isa_temperature_k(alt_msl_m: ArrayLike) -> np.ndarray:
    """Return the ISA temperature [K] at geopotential altitude ``alt_msl_m`` (...) [m], -500..11000 m."""
    return ISA_T0_K + ISA_LAPSE_RATE_K_M * _checked_alt_m(alt_msl_m)


def isa_pressure_pa(alt_msl_m: ArrayLike) -> np.ndarray:
    """Return the ISA static pressure [Pa] at geopotential altitude ``alt_msl_m`` (...) [m]."""
    exponent = -ISA_STANDARD_GRAVITY_M_S2 / (AIR_GAS_CONSTANT_J_KG_K * ISA_LAPSE_RATE_K_M)   # 5.25588
    return ISA_P0_PA * (isa_temperature_k(alt_msl_m) / ISA_T0_K) ** exponent


def isa_density_kg_m3(alt_msl_m: ArrayLike) -> np.ndarray:
    """Return the ISA air density [kg/m^3] at geopotential altitude ``alt_msl_m`` (...) [m]."""
    return isa_air_state(alt_msl_m).density_kg_m3


def isa_air_state(alt_msl_m: ArrayLike) -> AirState:
    """Return density, temperature and pressure of the ISA at ``alt_msl_m`` (...) [m], each of that shape."""
    temperature_k = isa_temperature_k(alt_msl_m)
    pressure_pa = isa_pressure_pa(alt_msl_m)
    return AirState(density_kg_m3=pressure_pa / (AIR_GAS_CONSTANT_J_KG_K * temperature_k),
                    temperature_k=temperature_k, pressure_pa=pressure_pa)


def air_state_at_temperature(alt_msl_m: ArrayLike, temperature_k: ArrayLike) -> AirState:
    """Return the air state on a non-standard (hot or cold) day: ISA pressure, actual temperature.

    The altitude is taken as the *pressure altitude*: the pressure is the ISA pressure at
    ``alt_msl_m`` and the density follows from the measured temperature by the ideal gas law,
    ``rho = p_isa(h) / (R T)``, so ``rho / rho_isa = T_isa / T``. This is the density-altitude
    convention of aviation performance charts (pressure altitude + outside air temperature). For a
    geometric altitude on a day whose whole air column is warmer, the true pressure differs from
    ``p_isa`` by about ``(h / 8.4 km) (dT / T)``: 0.5 % at 650 m on a +20 K day, below the accuracy of
    any drag or rotor coefficient it feeds.

    Parameters
    ----------
    alt_msl_m : (...) [m], geopotential (pressure) altitude, -500..11000 m
    temperature_k : (...) [K], actual air temperature, broadcastable with ``alt_msl_m``;
        150..400 K (the coldest and hottest air ever measured are 184 K and 330 K; the bounds also
        catch a temperature given in degrees Celsius)
    """
    temperature_k = np.asarray(temperature_k, dtype=np.float64)
    if not np.all((temperature_k >= AIR_TEMP_MIN_K) & (temperature_k <= AIR_TEMP_MAX_K)):
        raise ValueError(f"temperature_k must lie in {AIR_TEMP_MIN_K:g}..{AIR_TEMP_MAX_K:g} K "
                         "(kelvin, not degrees Celsius)")
    pressure_pa, temperature_k = (np.array(a) for a in np.broadcast_arrays(isa_pressure_pa(alt_msl_m), temperature_k))
    return AirState(density_kg_m3=pressure_pa / (AIR_GAS_CONSTANT_J_KG_K * temperature_k),
                    temperature_k=temperature_k, pressure_pa=pressure_pa)
