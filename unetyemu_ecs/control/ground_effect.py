"""Ground effect on rotor thrust, and the static surface below each rotor; pure and vectorised.

The law (Cheeseman & Bennett, "The effect of the ground on a helicopter rotor in forward flight",
ARC R&M 3021, 1955): a rotor of radius ``R`` whose disk is ``z`` above a surface produces, at the
same power, ``T_IGE / T_OGE = 1 / (1 - (R / (4 z))^2)`` in hover. Their method of images replaces
the ground by a mirror source of the rotor's inflow; in forward flight the wake is swept back at
``tan(theta) = V / v_i`` and the image's effect falls by ``cos^2(theta)``:
``T_IGE / T_OGE = 1 / (1 - (R / (4 z))^2 / (1 + (V / v_i)^2))``. Here ``V`` is the air's speed in the
disk plane and ``v_i`` the induced velocity, taken as the hover value ``v_h = sqrt(T / (2 rho A))``
of the rotor's out-of-ground-effect thrust (:func:`..control.rotor_power.hover_induced_velocity_m_s`).
For the simulator the factor multiplies the thrust each motor produces for its command.

Limits (ours):

- the formula diverges at ``z = R/4``; heights are clamped to ``z >= R/2``
  (:data:`GROUND_EFFECT_MIN_HEIGHT_RADII`), where the factor is 4/3, the cap commonly used with this
  model: measured thrust ratios stay finite close to the ground (for small rotors and whole
  multirotors: Sanchez-Cuevas, Heredia & Ollero, "Characterization of the aerodynamic ground effect
  and its influence in multirotor control", Int. J. Aerospace Eng. 2017, 1823056; they also find
  that a multirotor gains more than its single rotors would very close to the ground -- not
  modelled). A medium drone standing on the ground has its hubs 0.08 m (0.57 R) up: factor 1.24;
- above ``z = 4 R`` (two rotor diameters, :data:`GROUND_EFFECT_CUTOFF_RADII`) the factor is exactly 1:
  the formula gives 1.0039 there, so the cut is a 0.4 % step in thrust. It bounds which rotors need a
  surface look-up at all, which keeps large fleets cheap;
- the rotor's own rotation (``omega x r``) is left out of ``V``, and the height is measured
  vertically from the hub (a tilted disk is treated as level).

The surface below: :class:`SurfaceIndex` holds the static scene's supports (boxes yawed about z and
upright cylinders; spheres -- tree crowns -- are not supports, as in
:meth:`..scene.primitives.SceneLayout.support_at`) in a uniform x/y grid, so that the highest top
under each of P points costs O(P x shapes per cell) instead of O(P x all shapes).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Iterable

import numpy as np

GROUND_EFFECT_MIN_HEIGHT_RADII = 0.5     # z >= R/2: factor 4/3
GROUND_EFFECT_CUTOFF_RADII = 4.0         # z >= 4 R: factor 1 (the formula gives 1.0039)
_EDGE_EPS_M = 1e-9                        # a point on a footprint's edge is covered (as SceneLayout.support_at)
_MAX_CELLS_PER_AXIS = 256
_MIN_CELL_M = 0.5


def ground_effect_factor(height_m: np.ndarray, rotor_radius_m: np.ndarray, inplane_speed_m_s: np.ndarray = 0.0,
                         induced_velocity_m_s: np.ndarray = np.inf, *,
                         min_height_radii: float = GROUND_EFFECT_MIN_HEIGHT_RADII,
                         cutoff_radii: float = GROUND_EFFECT_CUTOFF_RADII) -> np.ndarray:
    """Return ``T_IGE / T_OGE`` (>= 1) of rotors ``height_m`` above the surface below them.

    Parameters
    ----------
    height_m : (...) float [m], rotor disk above the surface below it (any value: clamped to
        ``min_height_radii * R``; NaN or +inf -- no surface below -- gives 1)
    rotor_radius_m : (...) float [m], broadcast with ``height_m``
    inplane_speed_m_s : (...) float [m/s], air speed in the disk plane (0: the hover form)
    induced_velocity_m_s : (...) float [m/s], the rotor's induced velocity (inf: the hover form)
    min_height_radii : the clamp, ``z >= min_height_radii * R`` (must exceed 1/4)
    cutoff_radii : at and above ``z = cutoff_radii * R`` the factor is 1

    Returns
    -------
    (...) float, ``1 / (1 - (R / 4z)^2 / (1 + (V / v_i)^2))``; 1 where ``V > 0`` and ``v_i = 0``
    (no wake to reflect)
    """
    if min_height_radii <= 0.25:
        raise ValueError(f"min_height_radii {min_height_radii:g} must exceed 1/4 (the formula diverges at z = R/4)")
    radius = np.asarray(rotor_radius_m, dtype=float)
    height = np.asarray(height_m, dtype=float)
    ratio_sq = np.square(radius / (4.0 * np.maximum(height, min_height_radii * radius)))
    speed_sq = np.square(inplane_speed_m_s)
    advance_sq = speed_sq / np.maximum(np.square(induced_velocity_m_s), 1e-300)   # (V / v_i)^2; v_i = 0, V > 0: huge
    factor = 1.0 / (1.0 - ratio_sq / (1.0 + advance_sq))
    return np.where(height < cutoff_radii * radius, factor, 1.0)           # NaN height compares False: 1


@dataclass(frozen=True, slots=True)
class SurfaceIndex:
    """The static supports of a scene (boxes yawed about z, upright cylinders) in a uniform x/y grid.

    Attributes
    ----------
    shapes : (K + 1, 8) float64, one row per support: ``[r2_m2, x_m, y_m, a_m, b_m, cos_yaw, sin_yaw, top_m]``:
        a point is covered when ``|local x| <= a``, ``|local y| <= b`` (the half extents of a box along its
        own axes, edge tolerance included; a cylinder's radius, yaw 0) and ``dx^2 + dy^2 <= r2`` (a
        cylinder's radius squared; inf for a box); the last row covers nothing (the padding of ``cell_table``)
    origin_m : (2,) float64 [m], ENU x/y of the grid's lower corner
    inv_cell_m : float [1/m], one over the edge of a (square) cell
    max_ij : (2,) float64, the highest cell index along x and y (``nx - 1``, ``ny - 1``); the grid has an
        empty border of one cell all round, where every point outside it falls
    strides : (2,) intp, cell index ``= ix * strides[0] + iy`` (``strides = (ny, 1)``)
    cell_table : (C, S) int32, the supports whose x/y bounding box meets each cell, padded with K;
        S is the most supports meeting one cell (4 in the default generated city)
    cell_max_top_m : (C,) float64 [m], highest top of the supports meeting each cell (-inf: none)
    """

    shapes: np.ndarray
    origin_m: np.ndarray
    inv_cell_m: float
    max_ij: np.ndarray
    strides: np.ndarray
    cell_table: np.ndarray
    cell_max_top_m: np.ndarray


def build_surface_index(boxes: np.ndarray, cylinders: np.ndarray) -> SurfaceIndex:
    """Index the supports of a scene.

    Parameters
    ----------
    boxes : (Kb, 6) float [m, rad], ``[x_m, y_m, half_x_m, half_y_m, yaw_rad, top_m]``
    cylinders : (Kc, 4) float [m], ``[x_m, y_m, radius_m, top_m]``
    """
    boxes = np.asarray(boxes, dtype=float).reshape(-1, 6)
    cyls = np.asarray(cylinders, dtype=float).reshape(-1, 4)
    c, s = np.cos(boxes[:, 4]), np.sin(boxes[:, 4])
    shapes = np.concatenate([
        np.column_stack([np.full(len(boxes), np.inf), boxes[:, 0], boxes[:, 1], boxes[:, 2] + _EDGE_EPS_M,
                         boxes[:, 3] + _EDGE_EPS_M, c, s, boxes[:, 5]]),
        np.column_stack([cyls[:, 2] ** 2, cyls[:, 0], cyls[:, 1], cyls[:, 2], cyls[:, 2],
                         np.ones(len(cyls)), np.zeros(len(cyls)), cyls[:, 3]])])
    n_shapes = len(shapes)
    nothing = np.array([[-1.0, 0.0, 0.0, -1.0, -1.0, 1.0, 0.0, -np.inf]])   # covers no point
    if n_shapes == 0:
        return SurfaceIndex(nothing, np.zeros(2), 1.0, np.zeros(2), np.array([1, 1], dtype=np.intp),
                            np.zeros((1, 1), dtype=np.int32), np.full(1, -np.inf))
    # x/y half extents of each support's bounding box (a yawed box: |c| a + |s| b, |s| a + |c| b)
    ext_x = np.abs(shapes[:, 5]) * shapes[:, 3] + np.abs(shapes[:, 6]) * shapes[:, 4] + _EDGE_EPS_M
    ext_y = np.abs(shapes[:, 6]) * shapes[:, 3] + np.abs(shapes[:, 5]) * shapes[:, 4] + _EDGE_EPS_M
    lo = np.array([np.min(shapes[:, 1] - ext_x), np.min(shapes[:, 2] - ext_y)])
    hi = np.array([np.max(shapes[:, 1] + ext_x), np.max(shapes[:, 2] + ext_y)])
    cell = max(float(np.max(hi - lo)) / _MAX_CELLS_PER_AXIS, _MIN_CELL_M)
    lo = lo - cell                                                         # an empty border of one cell
    n = np.maximum(np.ceil((hi - lo) / cell).astype(int), 1) + 2
    # the cells each support's bounding box spans, as (cell, support) pairs sorted by cell
    i0 = np.clip(np.floor((shapes[:, 1] - ext_x - lo[0]) / cell).astype(int), 1, n[0] - 2)
    i1 = np.clip(np.floor((shapes[:, 1] + ext_x - lo[0]) / cell).astype(int), 1, n[0] - 2)
    j0 = np.clip(np.floor((shapes[:, 2] - ext_y - lo[1]) / cell).astype(int), 1, n[1] - 2)
    j1 = np.clip(np.floor((shapes[:, 2] + ext_y - lo[1]) / cell).astype(int), 1, n[1] - 2)
    pairs_cell, pairs_shape = [], []
    for k in range(n_shapes):             # once per scene
        ii, jj = np.meshgrid(np.arange(i0[k], i1[k] + 1), np.arange(j0[k], j1[k] + 1), indexing="ij")
        pairs_cell.append((ii * n[1] + jj).ravel())
        pairs_shape.append(np.full(ii.size, k))
    cells = np.concatenate(pairs_cell)
    owners = np.concatenate(pairs_shape)
    order = np.argsort(cells, kind="stable")
    cells, owners = cells[order], owners[order]
    n_cells = int(n[0] * n[1])
    counts = np.bincount(cells, minlength=n_cells)
    start = np.cumsum(counts) - counts
    table = np.full((n_cells, int(counts.max())), n_shapes, dtype=np.int32)
    table[cells, np.arange(cells.size) - start[cells]] = owners
    max_top = np.full(n_cells, -np.inf)
    np.maximum.at(max_top, cells, shapes[owners, 7])
    return SurfaceIndex(np.concatenate([shapes, nothing]), lo, 1.0 / cell, (n - 1).astype(float),
                        np.array([n[1], 1], dtype=np.intp), table, max_top)


def surface_index_from_shapes(shapes: Iterable[object]) -> SurfaceIndex:
    """Index every :class:`~..scene.primitives.Box` and :class:`~..scene.primitives.Cylinder` of ``shapes``
    (duck-typed on their attributes; anything else, e.g. a Sphere, is not a support)."""
    boxes, cyls = [], []
    for s in shapes:
        if hasattr(s, "half_extents_m"):
            boxes.append((s.center_enu_m[0], s.center_enu_m[1], s.half_extents_m[0], s.half_extents_m[1],
                          s.yaw_rad, s.center_enu_m[2] + s.half_extents_m[2]))
        elif hasattr(s, "half_height_m"):
            cyls.append((s.center_enu_m[0], s.center_enu_m[1], s.radius_m, s.center_enu_m[2] + s.half_height_m))
    return build_surface_index(np.array(boxes, dtype=float).reshape(-1, 6), np.array(cyls, dtype=float).reshape(-1, 4))


def cells_of(index: SurfaceIndex, xy_m: np.ndarray) -> np.ndarray:
    """Return the grid cell of each ENU x/y point (..., 2) [m]; a cell of the empty border outside the grid."""
    ij = np.fmin(np.fmax((xy_m - index.origin_m) * index.inv_cell_m, 0.0), index.max_ij)   # NaN: 0
    return ij.astype(np.intp) @ index.strides


def highest_top_near_m(index: SurfaceIndex, xy_m: np.ndarray) -> np.ndarray:
    """Return an upper bound [m] of the support tops under each x/y point (..., 2): its cell's highest top
    (-inf outside the grid). Cheap: one look-up per point."""
    return index.cell_max_top_m[cells_of(index, xy_m)]


def surface_below_m(index: SurfaceIndex, points_enu_m: np.ndarray) -> np.ndarray:
    """Return the top z [m] of the highest support under each point and not above it; -inf where none.

    The same footprint test as :meth:`..scene.primitives.SceneLayout.support_at` (edges count as
    covered; spheres are not supports), restricted to tops at or below the point, so that a wall or a
    roof beside a rotor is not taken for the ground under it.

    Parameters
    ----------
    points_enu_m : (P, 3) float [m], ENU
    """
    pts = np.asarray(points_enu_m, dtype=float).reshape(-1, 3)
    sh = index.shapes[index.cell_table[cells_of(index, pts[:, :2])]]      # (P, S, 8) the supports near each point
    dx, dy = pts[:, 0, None] - sh[..., 1], pts[:, 1, None] - sh[..., 2]
    cos, sin = sh[..., 5], sh[..., 6]
    # inside the (yawed) box; a cylinder: inside the square around it and the circle
    covered = ((np.abs(cos * dx + sin * dy) <= sh[..., 3]) & (np.abs(cos * dy - sin * dx) <= sh[..., 4])
               & (dx * dx + dy * dy <= sh[..., 0]))
    top = sh[..., 7]
    return np.max(np.where(covered & (top <= pts[:, 2, None] + _EDGE_EPS_M), top, -np.inf), axis=1)


__all__ = ["GROUND_EFFECT_CUTOFF_RADII", "GROUND_EFFECT_MIN_HEIGHT_RADII", "SurfaceIndex", "build_surface_index",
           "cells_of", "ground_effect_factor", "highest_top_near_m", "surface_below_m", "surface_index_from_shapes"]
