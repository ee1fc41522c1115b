"""Aerodynamic components."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated

from ..config.schema import Each, Ge, Gt


@dataclass(frozen=True, slots=True, kw_only=True)
class AeroDrag:
    """Quadratic drag of a body in air, per body axis (FLU).

    ``F_flu = -0.5 * rho * drag_coeff * area_flu_m2 * |v_rel| * v_rel_flu`` with
    ``v_rel = v_body - v_wind`` (the wind is written by any wind system in ACTUATE).
    """

    drag_coeff: Annotated[float, Ge(0.0)] = 1.0                                        # C_d [-]
    area_flu_m2: Annotated[tuple[float, float, float], Each(Ge(0.0))]                 # frontal areas [m^2]
    air_density_kg_m3: Annotated[float, Gt(0.0)] = 1.225                               # ISA sea level
