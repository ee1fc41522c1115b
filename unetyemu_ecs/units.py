"""Physical constants and angle helpers, in SI units with the unit in every name.

``GRAVITY_M_S2`` is 9.81 m/s², the value used by the paper's scene and by every vehicle default
in this project (docs/architecture.md §4), not the standard gravity 9.80665 m/s² (CGPM 1901). The 0.03 %
difference is below the accuracy of the vehicle models; keeping one value everywhere means hover
thrust, IMU readings and PyBullet's gravity agree exactly. ``AIR_DENSITY_KG_M3`` is the ISA
sea-level density at 15 °C (ISO 2533:1975).

The helpers are vectorised: they take scalars or numpy arrays of any shape and return the same
shape (a numpy scalar for scalar input).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from .control.compiled import jit

GRAVITY_M_S2 = 9.81
AIR_DENSITY_KG_M3 = 1.225
DEG_TO_RAD = np.pi / 180.0
RAD_TO_DEG = 180.0 / np.pi

__all__ = [
    "GRAVITY_M_S2",
    "AIR_DENSITY_KG_M3",
    "DEG_TO_RAD",
    "RAD_TO_DEG",
    "deg_to_rad",
    "rad_to_deg",
    "wrap_angle_rad",
]


def deg_to_rad(angle_deg: ArrayLike) -> np.ndarray:
    """Convert degrees to radians.

    Parameters
    ----------
    angle_deg : (...) float [deg]

    Returns
    -------
    (...) float64 [rad]
    """
    return np.radians(np.asarray(angle_deg, dtype=np.float64))


def rad_to_deg(angle_rad: ArrayLike) -> np.ndarray:
    """Convert radians to degrees.

    Parameters
    ----------
    angle_rad : (...) float [rad]

    Returns
    -------
    (...) float64 [deg]
    """
    return np.degrees(np.asarray(angle_rad, dtype=np.float64))


def wrap_angle_rad(angle_rad: ArrayLike) -> np.ndarray:
    """Wrap angles into the half-open interval (-pi, pi].

    ``-pi`` maps to ``+pi`` so that a heading has exactly one representation.

    Parameters
    ----------
    angle_rad : (...) float [rad]

    Returns
    -------
    (...) float64 [rad], in (-pi, pi]
    """
    return _wrap_angle(np.asarray(angle_rad, dtype=np.float64))[()]


def _wrap_angle(angle_rad: np.ndarray | float) -> np.ndarray | float:
    # np.mod returns [0, 2*pi) for a positive divisor, so pi - mod(...) lies in (-pi, pi].
    return np.pi - np.mod(np.pi - angle_rad, 2.0 * np.pi)


wrap_angle_of_rad = jit(_wrap_angle)                 # one angle (kernels call this one)
