"""Quadratic aerodynamic drag, vectorised over a fleet."""

from __future__ import annotations

import numpy as np


def quadratic_drag_enu_n(vel_rel_enu_m_s: np.ndarray, R_enu_flu: np.ndarray, drag_coeff: np.ndarray,
                         area_flu_m2: np.ndarray, air_density_kg_m3: np.ndarray) -> np.ndarray:
    """Return the drag force on each body in ENU.

    Parameters
    ----------
    vel_rel_enu_m_s : (M, 3) [m/s], ENU, body velocity relative to the air
    R_enu_flu : (M, 3, 3), body FLU -> world ENU
    drag_coeff : (M,) [-]
    area_flu_m2 : (M, 3) [m^2], reference area facing each body axis
    air_density_kg_m3 : (M,) [kg/m^3]

    Returns
    -------
    (M, 3) [N], ENU: ``-0.5 rho C_d A_i |v| v_i`` per body axis, rotated back to ENU.
    """
    v_flu = np.einsum("mji,mj->mi", R_enu_flu, vel_rel_enu_m_s)
    v = np.asarray(vel_rel_enu_m_s, dtype=float)
    speed = np.sqrt(np.add.reduce(v * v, axis=1))     # np.linalg.norm(v, axis=1), as it computes it
    f_flu = -0.5 * (air_density_kg_m3 * drag_coeff * speed)[:, None] * area_flu_m2 * v_flu
    return np.einsum("mij,mj->mi", R_enu_flu, f_flu)
