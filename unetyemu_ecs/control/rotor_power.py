"""Rotor power from momentum theory with the real inflow (climb, descent, forward flight), vectorised.

Per rotor of disk area ``A`` producing thrust ``T`` in air of density ``rho``, with the air meeting
the disk at ``V_c`` along the rotor axis (positive when the rotor moves up its axis: climb, or the
axial part of forward flight with the disk tilted into the wind) and ``V_h`` in the disk plane:

- hover induced velocity ``v_h = sqrt(T / (2 rho A))``;
- Glauert's momentum theory for the normal working state (climb, hover, forward flight, slow
  descent): the total inflow ``u = V_c + v_i`` solves ``u = V_c + v_h^2 / sqrt(V_h^2 + u^2)``
  (Leishman, "Principles of Helicopter Aerodynamics", 2nd ed., 2006, §2.13 and §5.3; solved by
  Newton's method on ``u > 0``);
- descent: momentum theory has no valid solution in the vortex-ring state (roughly
  ``-2 v_h < V_c < 0`` with little in-plane speed). There we take the induced velocity from
  Leishman's empirical fit to measured axial-descent data (ibid. ch. 2, the vortex-ring and
  turbulent-wake states: ``v_i / v_h = k + k1 x + k2 x^2 + k3 x^3 + k4 x^4`` for ``-2 <= x <= 0``,
  ``x = V_c / v_h``, k = 1.15, k1..k4 = -1.125, -1.372, -1.718, -0.655), shifted linearly so
  that it meets momentum theory at both ends (``v_i = v_h`` in hover, the windmill-brake state's
  ``v_i = -V_c/2 - sqrt(V_c^2/4 - v_h^2)`` at ``x = -2``); beyond ``x = -2`` the windmill-brake
  solution holds. The vortex ring fades with in-plane speed: its correction to momentum theory is
  added with weight ``max(0, 1 - V_h / v_h)`` (the ring is blown away once the in-plane speed
  reaches about ``v_h``, cf. Wolkovitch's boundary). A descent with in-plane speed steeper than
  ``V_c = -v_h^2 / V_h`` has no normal-working-state solution: the air flows up through the disk
  (windmill-brake state, Glauert's other root);
- power to the shaft ``T (V_c + v_i)`` (induced plus climb power; in forward flight with a tilted
  disk ``T V_c`` is the fuselage's parasite power), plus the *increase* of blade profile power
  with advance ratio ``mu = V_h / V_tip``: ``P_0h * 4.65 mu^2`` with ``P_0h = (sigma C_d0 / 8) rho
  A V_tip^3`` (Leishman ch. 5, forward-flight profile power). The hover profile power is part of the overall efficiency
  ``eta`` of the paper's eq. 4, so that in hover this reduces *exactly* to eq. 4:
  ``P = T^1.5 / (sqrt(2 rho A) eta)``. Electrical power is the shaft power over ``eta``, never
  negative (the ESCs do not regenerate).
"""

from __future__ import annotations

import numpy as np

from .compiled import jit, ufunc

# Leishman (2006) ch. 2: empirical induced velocity in axial descent, v_i / v_h as a polynomial of V_c / v_h
_VRS_FIT = (1.15, -1.125, -1.372, -1.718, -0.655)
PROFILE_MU2_FACTOR = 4.65     # profile power grows as (1 + 4.65 mu^2) (Leishman ch. 5)
_NEWTON_STEPS = 6             # from a cold start: converged to ~1e-12 (tests)
_WARM_NEWTON_STEPS = 2        # from the previous step's root
_BISECTION_STEPS = 48
_NEGLIGIBLE_DESCENT_FRAC = 1e-4    # a descent slower than this x v_h changes v_i by < 1e-4 v_h: no ring


def hover_induced_velocity_m_s(thrust_n: np.ndarray, air_density_kg_m3: np.ndarray,
                               disk_area_m2: np.ndarray) -> np.ndarray:
    """``v_h = sqrt(T / (2 rho A))`` [m/s] (negative thrust counts as zero)."""
    return hover_induced_velocity_of_loading_m_s(np.maximum(thrust_n, 0.0), 2.0 * air_density_kg_m3 * disk_area_m2)


def hover_induced_velocity_of_loading_m_s(thrust_pos_n: np.ndarray, two_rho_area_kg_m: np.ndarray) -> np.ndarray:
    """``v_h = sqrt(T / (2 rho A))`` [m/s] of a thrust ``T >= 0`` with ``2 rho A`` given (a constant of the rotor)."""
    return np.sqrt(thrust_pos_n / two_rho_area_kg_m)


def _glauert_inflow_scalar(v_axial_m_s: float, v_inplane_m_s: float, v_h_m_s: float, guess_m_s: float) -> float:
    """Glauert's total inflow of one rotor (:func:`glauert_inflow_m_s`; ``guess_m_s`` NaN: none)."""
    vh2 = v_h_m_s * v_h_m_s
    vin2 = v_inplane_m_s * v_inplane_m_s
    if v_axial_m_s * v_inplane_m_s < -vh2:                  # no positive root: windmill-brake state, bisection
        lo, hi = v_axial_m_s, 0.0                             # F(lo) < 0 < F(hi)
        for _ in range(_BISECTION_STEPS):
            mid = 0.5 * (lo + hi)
            if mid - v_axial_m_s - vh2 / np.sqrt(vin2 + mid * mid) > 0.0:
                hi = mid
            else:
                lo = mid
        return 0.5 * (lo + hi)
    if guess_m_s > 0.05 * v_h_m_s:                           # the previous step's root, a plausible inflow
        u, steps = guess_m_s, _WARM_NEWTON_STEPS
    else:                                                    # a first step, or a root near u = 0: from cold
        half = 0.5 * v_axial_m_s
        u, steps = half + np.sqrt(half * half + vh2 * vh2 / (vh2 + vin2 + 1e-12)), _NEWTON_STEPS
    for _ in range(steps):
        r2 = vin2 + u * u + 1e-12
        r = np.sqrt(r2)
        u = max(u - (u - v_axial_m_s - vh2 / r) / (1.0 + vh2 * u / (r2 * r)), 1e-9)
    return u


glauert_inflow_scalar_m_s = jit(_glauert_inflow_scalar)
_glauert_inflow_ufunc = ufunc("f8(f8, f8, f8, f8)")(_glauert_inflow_scalar)


def glauert_inflow_m_s(v_axial_m_s: np.ndarray, v_inplane_m_s: np.ndarray, v_h_m_s: np.ndarray,
                        guess_m_s: np.ndarray | None = None) -> np.ndarray:
    """Total inflow ``u = V_c + v_i`` of Glauert's relation ``u = V_c + v_h^2 / sqrt(V_h^2 + u^2)``.

    The normal working state's root ``u > 0`` (Newton's method) where it exists; in a descent steeper
    than ``V_c = -v_h^2 / V_h`` there is none and the air flows up through the disk: the root in
    ``(V_c, 0)`` (the windmill-brake state, by bisection). Both roots meet at ``u = 0`` on that
    boundary, so the result is continuous. Newton starts from ``guess_m_s`` where it is a plausible
    inflow (the previous step's root, ``> 0.05 v_h``: two iterations then suffice), else from the axial
    closed form with the in-plane speed folded into ``v_h`` (exact without in-plane speed). Any
    broadcastable shapes; compiled per rotor (:func:`glauert_inflow_scalar_m_s` is the kernels' form).
    """
    return _glauert_inflow_ufunc(v_axial_m_s, v_inplane_m_s, v_h_m_s, np.nan if guess_m_s is None else guess_m_s)


def _descent_induced_scalar(v_axial_m_s: float, v_h_m_s: float) -> float:
    """Induced velocity of one rotor in axial descent (``V_c < 0``): the vortex-ring fit for ``-2 <= x < 0``,
    the windmill-brake state below, both meeting momentum theory at ``x = 0`` and ``x = -2``."""
    vh = max(v_h_m_s, 1e-9)
    x = v_axial_m_s / vh
    if x <= -2.0:
        half = -0.5 * v_axial_m_s
        return half - np.sqrt(max(half * half - vh * vh, 0.0))
    k0, k1, k2, k3, k4 = _VRS_FIT
    fit = k0 + x * (k1 + x * (k2 + x * (k3 + x * k4)))
    fit_at_minus2 = k0 - 2 * k1 + 4 * k2 - 8 * k3 + 16 * k4
    ring = fit - (k0 - 1.0) - (fit_at_minus2 - (k0 - 1.0) - 1.0) * (-x / 2.0)   # 1 at x = 0 and at x = -2
    return ring * vh


descent_induced_scalar_m_s = jit(_descent_induced_scalar)


def _vortex_ring_correction_scalar(v_axial_m_s: float, v_inplane_m_s: float, v_h_m_s: float) -> float:
    """:func:`vortex_ring_correction_m_s` of one rotor."""
    if not v_axial_m_s < -_NEGLIGIBLE_DESCENT_FRAC * v_h_m_s:
        return 0.0
    weight = min(max(1.0 - v_inplane_m_s / max(v_h_m_s, 1e-9), 0.0), 1.0)
    if not weight > 0.0:
        return 0.0
    half = 0.5 * v_axial_m_s                                               # V_c < 0 here
    axial_momentum = -half + np.sqrt(half * half + v_h_m_s * v_h_m_s)     # closed form of Glauert without V_h
    return weight * (descent_induced_scalar_m_s(v_axial_m_s, v_h_m_s) - axial_momentum)


vortex_ring_correction_scalar_m_s = jit(_vortex_ring_correction_scalar)
vortex_ring_correction_m_s = ufunc("f8(f8, f8, f8)")(_vortex_ring_correction_scalar)
vortex_ring_correction_m_s.__doc__ = """What descent adds to Glauert's inflow [m/s]: the difference between the
axial-descent curve and momentum theory in axial flight, with weight ``max(0, 1 - V_h / v_h)``: zero at
``V_c = 0`` (continuous with climb at any in-plane speed), the whole axial curve without in-plane speed; zero
where the rotor descends slower than ``1e-4 v_h`` (the correction would be < 1e-4 v_h). A ufunc:
``vortex_ring_correction_m_s(v_axial_m_s, v_inplane_m_s, v_h_m_s)``, any broadcastable shapes."""


def rotor_inflow_m_s(thrust_n: np.ndarray, v_axial_m_s: np.ndarray, v_inplane_m_s: np.ndarray,
                     air_density_kg_m3: np.ndarray, disk_area_m2: np.ndarray) -> np.ndarray:
    """Total inflow ``u = V_c + v_i`` [m/s] through each rotor (scalars or any matching shapes; see the
    module docstring): :func:`glauert_inflow_m_s` plus :func:`vortex_ring_correction_m_s`.

    v_axial_m_s : air velocity along the rotor axis, positive when the rotor climbs into it [m/s]
    v_inplane_m_s : speed of the air in the disk plane (>= 0) [m/s]
    """
    v_axial_m_s = np.asarray(v_axial_m_s, dtype=float)
    v_inplane_m_s = np.asarray(v_inplane_m_s, dtype=float)
    v_h = hover_induced_velocity_m_s(np.asarray(thrust_n, dtype=float), air_density_kg_m3, disk_area_m2)
    return glauert_inflow_m_s(v_axial_m_s, v_inplane_m_s, v_h) + vortex_ring_correction_m_s(v_axial_m_s,
                                                                                             v_inplane_m_s, v_h)


def induced_velocity_m_s(thrust_n: np.ndarray, v_axial_m_s: np.ndarray, v_inplane_m_s: np.ndarray,
                         air_density_kg_m3: np.ndarray, disk_area_m2: np.ndarray) -> np.ndarray:
    """Induced velocity ``v_i`` [m/s] of each rotor: :func:`rotor_inflow_m_s` less the axial air speed."""
    return rotor_inflow_m_s(thrust_n, v_axial_m_s, v_inplane_m_s, air_density_kg_m3, disk_area_m2) \
        - np.asarray(v_axial_m_s, dtype=float)


def shaft_power_from_inflow_w(thrust_n: np.ndarray, inflow_m_s: np.ndarray, v_inplane_m_s: np.ndarray,
                              profile_hover_w: np.ndarray, tip_speed_m_s: np.ndarray) -> np.ndarray:
    """``T u + P_0h 4.65 (V_h / V_tip)^2`` [W]: induced and climb power plus the profile power's growth."""
    return shaft_power_of_positive_thrust_w(np.maximum(thrust_n, 0.0), inflow_m_s, v_inplane_m_s,
                                            profile_hover_w * PROFILE_MU2_FACTOR, tip_speed_m_s)


def shaft_power_of_positive_thrust_w(thrust_pos_n: np.ndarray, inflow_m_s: np.ndarray, v_inplane_m_s: np.ndarray,
                                     profile_mu2_w: np.ndarray, tip_speed_m_s: np.ndarray) -> np.ndarray:
    """:func:`shaft_power_from_inflow_w` [W] of a thrust ``T >= 0`` with ``profile_mu2_w = P_0h 4.65`` given (a
    constant of the rotor): ``T u + profile_mu2_w (V_h / V_tip)^2``."""
    mu = v_inplane_m_s / tip_speed_m_s
    return thrust_pos_n * inflow_m_s + profile_mu2_w * mu * mu


def rotor_shaft_power_w(thrust_n: np.ndarray, v_axial_m_s: np.ndarray, v_inplane_m_s: np.ndarray,
                        air_density_kg_m3: np.ndarray, disk_area_m2: np.ndarray, profile_hover_w: np.ndarray,
                        tip_speed_m_s: np.ndarray) -> np.ndarray:
    """Shaft power [W] of each rotor beyond hover profile power: ``T (V_c + v_i) + P_0h 4.65 (V_h / V_tip)^2``.

    Negative where the rotor extracts energy from the air (windmill brake state); callers clamp.
    """
    u = rotor_inflow_m_s(thrust_n, v_axial_m_s, v_inplane_m_s, air_density_kg_m3, disk_area_m2)
    return shaft_power_from_inflow_w(thrust_n, u, v_inplane_m_s, profile_hover_w, tip_speed_m_s)


def profile_hover_power_w(solidity: np.ndarray, blade_drag_coeff: np.ndarray, air_density_kg_m3: np.ndarray,
                          disk_area_m2: np.ndarray, tip_speed_m_s: np.ndarray) -> np.ndarray:
    """Blade profile power of a rotor in hover, ``(sigma C_d0 / 8) rho A V_tip^3`` [W] (Leishman ch. 2)."""
    return solidity * blade_drag_coeff / 8.0 * air_density_kg_m3 * disk_area_m2 * tip_speed_m_s ** 3


def climb_to_hover_power_ratio(v_climb_m_s: np.ndarray, v_h_m_s: np.ndarray) -> np.ndarray:
    """Textbook axial-climb power ratio ``P_c / P_h = V_c/(2 v_h) + sqrt((V_c/(2 v_h))^2 + 1)``
    (Leishman ch. 2, axial climb)."""
    half = np.asarray(v_climb_m_s) / (2.0 * np.asarray(v_h_m_s))
    return half + np.sqrt(half * half + 1.0)
