"""Quadratic aerodynamic drag, per body and over a fleet."""

from __future__ import annotations

import numpy as np

from .compiled import jit


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
    v = np.ascontiguousarray(vel_rel_enu_m_s, dtype=float)
    m = v.shape[0]
    force = np.zeros((m, 3))
    _add_quadratic_drags_enu_n(v, np.ascontiguousarray(R_enu_flu, dtype=float),
                               np.broadcast_to(np.asarray(drag_coeff, dtype=float), (m,)),
                               np.ascontiguousarray(np.broadcast_to(area_flu_m2, (m, 3)), dtype=float),
                               np.broadcast_to(np.asarray(air_density_kg_m3, dtype=float), (m,)), force)
    return force


@jit
def add_quadratic_drag_enu_n(vel_rel_enu_m_s, R_enu_flu, drag_coeff, area_flu_m2, air_density_kg_m3, force_enu_n):
    """Add to ``force_enu_n`` (3,) one body's drag ``-0.5 rho C_d A_i |v| v_i`` per body axis ``i`` (``v_i`` of
    ``R^T v``), rotated back to ENU (kernels call this; :func:`quadratic_drag_enu_n` for arrays)."""
    v0, v1, v2 = vel_rel_enu_m_s[0], vel_rel_enu_m_s[1], vel_rel_enu_m_s[2]
    k = -0.5 * (air_density_kg_m3 * drag_coeff * np.sqrt(v0 * v0 + v1 * v1 + v2 * v2))
    for i in range(3):                                                  # body axis i
        f_i = k * area_flu_m2[i] * (R_enu_flu[0, i] * v0 + R_enu_flu[1, i] * v1 + R_enu_flu[2, i] * v2)
        for j in range(3):
            force_enu_n[j] += R_enu_flu[j, i] * f_i


@jit
def _add_quadratic_drags_enu_n(vel_rel_enu_m_s, R_enu_flu, drag_coeff, area_flu_m2, air_density_kg_m3, force_enu_n):
    for k in range(vel_rel_enu_m_s.shape[0]):
        add_quadratic_drag_enu_n(vel_rel_enu_m_s[k], R_enu_flu[k], drag_coeff[k], area_flu_m2[k],
                                 air_density_kg_m3[k], force_enu_n[k])


__all__ = ["add_quadratic_drag_enu_n", "quadratic_drag_enu_n"]
