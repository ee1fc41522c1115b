"""ACTUATE phase: forces that act on bodies before the physics step."""

from __future__ import annotations

import numpy as np

from ..components.aero import AeroDrag
from ..control.aero import add_quadratic_drag_enu_n
from ..control.compiled import jit
from ..phases import Phase
from ..world import StepContext
from .fleet_system import FleetSystem, stack_params


class AeroDragSystem(FleetSystem):
    """Add quadratic drag (relative to the local wind) to every body with :class:`AeroDrag`.

    Phase: ACTUATE, after wind systems (order 50). Reads: fleet.vel_enu_m_s, wind_enu_m_s,
    R_enu_flu; the world's air density unless the component sets one. Writes: fleet.force_cmd_enu_n (adds).
    """

    phase = Phase.ACTUATE
    order = 50
    requires = (AeroDrag,)

    def gather(self, ctx: StepContext) -> None:
        p = stack_params(self.components[0], AeroDrag)
        self._cd = p.drag_coeff
        self._area = np.ascontiguousarray(p.area_flu_m2.reshape(-1, 3))
        self._rho = np.where(np.isnan(p.air_density_kg_m3), ctx.services.air_density_kg_m3, p.air_density_kg_m3)

    def update(self, ctx: StepContext) -> None:
        f = ctx.fleet
        add_drag_forces(self.rows, self._cd, self._area, self._rho, f.vel_enu_m_s, f.wind_enu_m_s, f.R_enu_flu,
                        f.force_cmd_enu_n)


@jit
def add_drag_forces(rows, drag_coeff, area_flu_m2, air_density_kg_m3, vel_enu_m_s, wind_enu_m_s, R_enu_flu,
                    force_cmd_enu_n):
    """Add to ``force_cmd_enu_n`` the quadratic drag of the bodies in fleet ``rows`` (parameters in row order),
    relative to the wind at each (:func:`..control.aero.add_quadratic_drag_enu_n`)."""
    for k in range(rows.shape[0]):
        r = rows[k]
        add_quadratic_drag_enu_n(vel_enu_m_s[r] - wind_enu_m_s[r], R_enu_flu[r], drag_coeff[k], area_flu_m2[k],
                                 air_density_kg_m3[k], force_cmd_enu_n[r])
