"""Dryden turbulence (MIL-F-8785C low-altitude model) and the 1-cosine discrete gust, vectorised.

Sources
-------
- MIL-F-8785C, *Flying Qualities of Piloted Airplanes* (5 Nov 1980), §3.7 "Atmospheric
  disturbances": the Dryden spectra, the low-altitude (h < 1000 ft) scales and intensities and the
  discrete gust; repeated in MIL-HDBK-1797 (19 Dec 1997), whose Dryden form instead writes the
  transverse spectra with ``2 L`` (``2 L_w = h``, ``L_u = 2 L_v``); the spectra are the same, and
  this module uses the 8785C lengths ``L_w = h``, ``L_u = L_v`` throughout.
- MathWorks Aerospace Blockset, "Dryden Wind Turbulence Model (Continuous)" and "(Discrete)"
  (https://www.mathworks.com/help/aeroblks/drydenwindturbulencemodelcontinuous.html): the same
  forming filters, the low-altitude range (below 1000 ft), W20 = 15 / 30 / 45 kt for light /
  moderate / severe turbulence, and the frozen-field (Taylor) limitation.
- 14 CFR 25.341(a)(2): the full "1-cosine" gust ``U = (U_ds/2)(1 - cos(pi s/H))``, 0 <= s <= 2H.

Low-altitude parameters (h = height above ground in **feet**, clamped to 10..1000 ft)::

    sigma_w = 0.1 W20,   sigma_u = sigma_v = sigma_w / (0.177 + 0.000823 h)^0.4
    L_w = h,             L_u = L_v = h / (0.177 + 0.000823 h)^1.2

W20 is the mean wind speed 20 ft (6.1 m) above ground; the sigma_w / W20 ratio carries any unit,
and the lengths are converted to metres. L_w = h vanishes at the ground, so below 10 ft the 10 ft
values are held, as implementations of the standard do. Above 1000 ft the standard blends towards
its isotropic medium-altitude model; drones fly far lower, so the 1000 ft values are held instead.

Forming filters (Taylor's frozen turbulence: the body sweeps a frozen field at speed V, so a
spatial frequency Omega becomes a time frequency omega = V Omega)::

    H_u(s) = sigma_u sqrt(2 L_u / (pi V)) / (1 + T_u s)                           T = L / V
    H_v(s) = sigma_v sqrt(L_v / (pi V)) (1 + sqrt(3) T_v s) / (1 + T_v s)^2       (same for w)

Realisation. Each filter is run on a *normalised* state of unit stationary variance and scaled by
sigma at the output. With ``a = V / L`` the states obey::

    x_u'  = -a x_u + sqrt(2a) xi                         u = sigma_u x_u
    x_1'  = -a x_1 + sqrt(2a) xi,   x_2' = a (x_1 - x_2)  v = sigma_v (sqrt(3) x_1 + (1 - sqrt(3)) x_2) / sqrt(2)

whose transfer functions are the spec's up to the constant its white-noise convention absorbs
(the spectra are one-sided, ``sigma^2 = int_0^inf Phi dOmega``); here it is fixed by requiring
the output variance to be sigma^2. The stationary covariance of (x_1, x_2) is [[1, 1/2], [1/2, 1/2]] for *every*
``a``, so a body that speeds up, climbs or changes W20 keeps exactly the right variance with no
transient. Each step uses the exact discretisation (zero-order hold of the coefficients over dt):
``Phi = exp(A dt)`` in closed form and the noise covariance ``Q = P - Phi P Phi^T``, so the
variance is sigma^2 at any step size (240 Hz or 100 Hz alike); forward-Euler difference equations
(``u_k+1 = (1 - V dt / L) u_k + sqrt(2 V dt / L) sigma_u eta_k``) are right only for ``dt << L / V``.

Convection speed and axes (choices of this module, not of the standard):
- V = max(|v_body - w_mean|, ``min_convection_speed_m_s``): a body moving through the air sees
  the field at its airspeed; a drone hovering in wind sees it carried past at the mean wind speed.
  The floor keeps ``L / V`` finite for a hover in calm air, where the field is then nearly frozen.
- u lies along the *horizontal mean wind*, v horizontal to its left, w up (ENU). At low altitude
  sigma_u = sigma_v and L_u = L_v, so the horizontal axes differ only in spectral shape; tying
  them to the mean wind rather than to each body's path keeps the turbulence vector from turning
  as a drone manoeuvres. With no horizontal mean wind (below 1 mm/s) u points east.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated

import numpy as np
from numpy.typing import ArrayLike

from ..config.schema import Ge, Gt, Le

M_PER_FT = 0.3048                       # international foot (1959), exact
M_S_PER_KNOT = 1852.0 / 3600.0          # international nautical mile per hour, exact
W20_LIGHT_M_S = 15.0 * M_S_PER_KNOT     # MIL-F-8785C light turbulence: 7.7 m/s at 20 ft
W20_MODERATE_M_S = 30.0 * M_S_PER_KNOT  # moderate: 15.4 m/s
W20_SEVERE_M_S = 45.0 * M_S_PER_KNOT    # severe: 23.1 m/s
HEIGHT_MIN_FT = 10.0                    # low-altitude formulas floor (3.05 m); L_w = h -> 0 at the ground
HEIGHT_MAX_FT = 1000.0                  # low-altitude model ceiling (304.8 m)
DRYDEN_STATE_SIZE = 5                   # normalised filter states per body: x_u, x_v1, x_v2, x_w1, x_w2
_CALM_WIND_M_S = 1e-3                   # horizontal mean wind below which u points east
_SQRT3 = np.sqrt(3.0)

__all__ = ["M_PER_FT", "M_S_PER_KNOT", "W20_LIGHT_M_S", "W20_MODERATE_M_S", "W20_SEVERE_M_S",
           "DRYDEN_STATE_SIZE", "DrydenParams", "dryden_sigma_and_scale", "dryden_axes_enu",
           "dryden_stationary_state", "dryden_step", "one_minus_cosine_gust_m_s", "gust_enu_m_s"]


@dataclass(frozen=True, kw_only=True)
class DrydenParams:
    """Parameters of the low-altitude Dryden turbulence (one set for the whole world)."""

    # W20 in 0..50 m/s: MIL-F-8785C's severe turbulence is 23 m/s (45 kt); 50 m/s is a category-3
    # hurricane. sigma_w = 0.1 W20, so a wanted vertical intensity sigma_w is W20 = 10 sigma_w.
    wind_speed_20ft_m_s: Annotated[float, Ge(0.0), Le(50.0)]
    # floor on the speed the field is swept past a body; 1 m/s is below any flown airspeed and above
    # a hover's drift. Range: positive (L/V finite) up to 10 m/s (above that it would override real flight).
    min_convection_speed_m_s: Annotated[float, Gt(0.0), Le(10.0)] = 1.0


def dryden_sigma_and_scale(height_agl_m: ArrayLike, wind_speed_20ft_m_s: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """Return the MIL-F-8785C low-altitude intensities and scale lengths.

    Parameters
    ----------
    height_agl_m : (M,) [m], height above ground; clamped to 10..1000 ft (3.05..304.8 m)
    wind_speed_20ft_m_s : scalar or (M,) [m/s], mean wind speed 20 ft above ground (W20)

    Returns
    -------
    sigma_uvw_m_s : (M, 3) [m/s], intensities (sigma_u, sigma_v, sigma_w)
    scale_uvw_m : (M, 3) [m], scale lengths (L_u, L_v, L_w)
    """
    h_ft = np.clip(np.asarray(height_agl_m, dtype=np.float64) / M_PER_FT, HEIGHT_MIN_FT, HEIGHT_MAX_FT)
    k = 0.177 + 0.000823 * h_ft
    sigma_w = 0.1 * np.broadcast_to(np.asarray(wind_speed_20ft_m_s, dtype=np.float64), h_ft.shape)
    sigma_uv = sigma_w / k ** 0.4
    scale_uv_m = h_ft / k ** 1.2 * M_PER_FT
    return (np.stack([sigma_uv, sigma_uv, sigma_w], axis=-1),
            np.stack([scale_uv_m, scale_uv_m, h_ft * M_PER_FT], axis=-1))


def dryden_axes_enu(mean_wind_enu_m_s: np.ndarray) -> np.ndarray:
    """Return ``R_enu_uvw`` (M, 3, 3): columns are the u (along the horizontal mean wind), v (left of it)
    and w (up) turbulence axes in ENU; u is east where the horizontal mean wind is below 1 mm/s."""
    horiz = np.asarray(mean_wind_enu_m_s, dtype=np.float64)[:, :2]
    speed = np.linalg.norm(horiz, axis=1, keepdims=True)
    e_u = np.where(speed > _CALM_WIND_M_S, horiz / np.maximum(speed, _CALM_WIND_M_S), [1.0, 0.0])
    R = np.zeros((horiz.shape[0], 3, 3))
    R[:, :2, 0] = e_u
    R[:, 0, 1], R[:, 1, 1] = -e_u[:, 1], e_u[:, 0]   # z x e_u
    R[:, 2, 2] = 1.0
    return R


def dryden_stationary_state(count: int, rng: np.random.Generator) -> np.ndarray:
    """Draw (count, 5) normalised filter states from their stationary distribution (no start-up transient)."""
    n = rng.standard_normal((count, DRYDEN_STATE_SIZE))
    x = n.copy()
    x[:, 2] = 0.5 * (n[:, 1] + n[:, 2])     # Cholesky factor of [[1, 1/2], [1/2, 1/2]] is [[1, 0], [1/2, 1/2]]
    x[:, 4] = 0.5 * (n[:, 3] + n[:, 4])
    return x


def _second_order_step(x1: np.ndarray, x2: np.ndarray, theta: np.ndarray, n1: np.ndarray, n2: np.ndarray):
    """Advance one normalised second-order Dryden filter exactly by ``theta = a dt`` (all (M,))."""
    decay = np.exp(-theta)
    q11 = -np.expm1(-2.0 * theta)                       # Q = P - Phi P Phi^T, P = [[1, 1/2], [1/2, 1/2]]
    q12 = 0.5 * q11 - theta * decay ** 2
    q22 = 0.5 * q11 - theta * (1.0 + theta) * decay ** 2
    l11 = np.sqrt(q11)
    l21 = q12 / l11
    l22 = np.sqrt(np.maximum(q22 - l21 ** 2, 0.0))     # q22 ~ theta^3 / 1.5: clamp rounding below zero
    return decay * x1 + l11 * n1, decay * (theta * x1 + x2) + l21 * n1 + l22 * n2


def dryden_step(state: np.ndarray, height_agl_m: np.ndarray, mean_wind_enu_m_s: np.ndarray,
                vel_enu_m_s: np.ndarray, dt_s: float, rng: np.random.Generator,
                params: DrydenParams) -> tuple[np.ndarray, np.ndarray]:
    """Advance the turbulence of M bodies by one step and return it in ENU.

    Parameters
    ----------
    state : (M, 5) float64 [-], normalised filter states: ``dryden_stationary_state`` for turbulence
        at full strength from the first step, or zeros for turbulence that builds up over ~L / V
    height_agl_m : (M,) [m], height above ground
    mean_wind_enu_m_s : (M, 3) [m/s], ENU, mean wind at each body (sets the u axis and V)
    vel_enu_m_s : (M, 3) [m/s], ENU, body velocity
    dt_s : step [s], > 0
    rng : seeded generator; draws one (M, 5) standard normal array per call
    params : W20 and the convection-speed floor

    Returns
    -------
    state : (M, 5) the advanced states (the input is not modified)
    turbulence_enu_m_s : (M, 3) [m/s], ENU, to add to the mean wind
    """
    if dt_s <= 0.0:
        raise ValueError("dt_s must be positive")
    sigma, scale_m = dryden_sigma_and_scale(height_agl_m, params.wind_speed_20ft_m_s)
    speed = np.maximum(np.linalg.norm(np.asarray(vel_enu_m_s) - mean_wind_enu_m_s, axis=1),
                       params.min_convection_speed_m_s)
    theta = speed[:, None] * dt_s / scale_m                  # (M, 3): dt / T for u, v, w
    n = rng.standard_normal((state.shape[0], DRYDEN_STATE_SIZE))
    new = np.empty_like(state)
    decay_u = np.exp(-theta[:, 0])
    new[:, 0] = decay_u * state[:, 0] + np.sqrt(-np.expm1(-2.0 * theta[:, 0])) * n[:, 0]
    new[:, 1], new[:, 2] = _second_order_step(state[:, 1], state[:, 2], theta[:, 1], n[:, 1], n[:, 2])
    new[:, 3], new[:, 4] = _second_order_step(state[:, 3], state[:, 4], theta[:, 2], n[:, 3], n[:, 4])
    shaped = np.stack([new[:, 0],
                       (_SQRT3 * new[:, 1] + (1.0 - _SQRT3) * new[:, 2]) / np.sqrt(2.0),
                       (_SQRT3 * new[:, 3] + (1.0 - _SQRT3) * new[:, 4]) / np.sqrt(2.0)], axis=1)
    return new, np.einsum("mij,mj->mi", dryden_axes_enu(mean_wind_enu_m_s), sigma * shaped)


def one_minus_cosine_gust_m_s(dist_m: ArrayLike, amplitude_m_s: ArrayLike, length_m: ArrayLike) -> np.ndarray:
    """Return the 1-cosine gust speed [m/s] a distance ``dist_m`` [m] into the gust.

    ``(V_m / 2)(1 - cos(pi x / d_m))`` for 0 <= x <= 2 d_m, else 0: it rises to ``amplitude_m_s``
    (V_m) at x = ``length_m`` (d_m, MIL-F-8785C's gust length, 14 CFR 25.341's gradient H) and falls
    back to zero at 2 d_m. MIL-F-8785C (and MathWorks' "Discrete Wind Gust Model" block) define the
    rise over d_m and then hold V_m; the discrete gust may be "used singly or in multiples", and this
    is the rise followed by its mirror image: the full 1-cosine gust of 14 CFR 25.341(a)(2).
    """
    x = np.asarray(dist_m, dtype=np.float64)
    d = np.asarray(length_m, dtype=np.float64)
    if not np.all(d > 0.0):
        raise ValueError("the gust length (or rise time) must be positive")
    inside = (x >= 0.0) & (x <= 2.0 * d)
    return np.where(inside, 0.5 * np.asarray(amplitude_m_s) * (1.0 - np.cos(np.pi * x / d)), 0.0)


def gust_enu_m_s(t_s: ArrayLike, start_s: ArrayLike, amplitude_m_s: ArrayLike, rise_time_s: ArrayLike,
                 dir_enu: ArrayLike) -> np.ndarray:
    """Return the 1-cosine gust velocity (..., 3) [m/s] in ENU at time ``t_s``.

    The gust starts at ``start_s`` [s], peaks at ``amplitude_m_s`` [m/s] ``rise_time_s`` [s] later and is
    over after ``2 rise_time_s``; ``dir_enu`` (..., 3) is the direction it blows toward (normalised
    here). In time the spatial form needs no speed: a body crossing the gust at V has
    ``x = V (t - start)`` and ``d_m = V rise_time``, so ``x / d_m = (t - start) / rise_time``.
    """
    direction = np.asarray(dir_enu, dtype=np.float64)
    norm = np.linalg.norm(direction, axis=-1, keepdims=True)
    if np.any(norm == 0.0):
        raise ValueError("dir_enu must be non-zero")
    speed = one_minus_cosine_gust_m_s(np.asarray(t_s, dtype=np.float64) - start_s, amplitude_m_s, rise_time_s)
    return speed[..., None] * direction / norm
