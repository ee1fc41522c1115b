"""Actuator-disk (momentum theory) rotor power, vectorised.

Ideal induced power of a rotor producing thrust T in hover is ``T^1.5 / sqrt(2 rho A)``
(Mahony, Kumar & Corke 2012, "Multirotor aerial vehicles", IEEE RAM; the paper's eq. 4), divided by
an overall efficiency eta for motor, ESC and profile losses.
"""

from __future__ import annotations

import numpy as np


def rotor_power_w(thrust_n: np.ndarray, air_density_kg_m3: np.ndarray, disk_area_m2: np.ndarray,
                  efficiency: np.ndarray) -> np.ndarray:
    """Electrical power per rotor [W].

    Parameters
    ----------
    thrust_n : (M, R) [N] thrust of each rotor (negative values count as zero)
    air_density_kg_m3, disk_area_m2, efficiency : (M,) per vehicle
    """
    return actuator_disk_power_w(thrust_n, (2.0 * air_density_kg_m3 * disk_area_m2)[:, None], efficiency[:, None])


def actuator_disk_power_w(thrust_n: np.ndarray, two_rho_area_kg_m: np.ndarray, efficiency: np.ndarray) -> np.ndarray:
    """Electrical power [W] of rotors of thrust ``thrust_n`` (negative counts as zero) with ``2 rho A`` given (a
    constant of the rotor): ``T^1.5 / (sqrt(2 rho A) eta)``. Any broadcastable shapes or scalars (arithmetic
    only: kernels compile it, :mod:`.compiled`)."""
    return np.maximum(thrust_n, 0.0) ** 1.5 / (np.sqrt(two_rho_area_kg_m) * efficiency)


def hover_power_w(mass_kg: float, n_rotors: int, gravity_m_s2: float, air_density_kg_m3: float,
                  rotor_radius_m: float, efficiency: float, p0_w: float) -> float:
    """Total hover power [W] of a multirotor of ``mass_kg`` sharing its weight over ``n_rotors``."""
    per_rotor = mass_kg * gravity_m_s2 / n_rotors
    area = np.pi * rotor_radius_m ** 2
    return float(n_rotors * per_rotor ** 1.5 / (np.sqrt(2.0 * air_density_kg_m3 * area) * efficiency) + p0_w)
