"""Aerodynamic components."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated

from ..config.schema import Each, Ge, Le


@dataclass(frozen=True, slots=True, kw_only=True)
class AeroDrag:
    """Quadratic drag of a body in air, per body axis (FLU).

    ``F_flu = -0.5 * rho * drag_coeff * area_flu_m2 * |v_rel| * v_rel_flu`` with
    ``v_rel = v_body - v_wind`` (the wind is written by any wind system in ACTUATE).
    """

    # Ranges: bluff bodies have C_d up to ~2 (10 is a typo); areas up to 100 m^2 (a bus is ~10);
    # air from ~0.01 kg/m^3 (30 km up) to 2 (a cold, dense day at sea level is 1.4)
    drag_coeff: Annotated[float, Ge(0.0), Le(10.0)] = 1.0                             # C_d [-]
    area_flu_m2: Annotated[tuple[float, float, float], Each(Ge(0.0)), Each(Le(100.0))]  # frontal areas [m^2]
    air_density_kg_m3: Annotated[float, Ge(0.01), Le(2.0)] | None = None    # None: the world's air (ISA)
