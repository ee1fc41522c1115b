"""ACTUATE phase: forces that act on bodies before the physics step."""

from __future__ import annotations

import esper
import numpy as np

from ..components.aero import AeroDrag
from ..control.aero import quadratic_drag_enu_n
from ..frames import R_from_quat_xyzw
from ..phases import Phase
from ..world import StepContext
from .rows import gather_rows


class AeroDragSystem(esper.Processor):
    """Add quadratic drag (relative to the local wind) to every body with :class:`AeroDrag`.

    Phase: ACTUATE, after wind systems (order 50). Reads: fleet.vel_enu_m_s, wind_enu_m_s,
    quat_enu_flu_xyzw. Writes: fleet.force_cmd_enu_n (adds).
    """

    phase = Phase.ACTUATE
    order = 50

    def __init__(self) -> None:
        self._seen_version = -1
        self._rows = np.empty(0, dtype=np.intp)

    def _gather(self) -> None:
        self._rows, comps = gather_rows(AeroDrag)
        self._cd = np.array([c.drag_coeff for c in comps])
        self._area = np.array([c.area_flu_m2 for c in comps]).reshape(-1, 3)
        self._rho = np.array([c.air_density_kg_m3 for c in comps])

    def process(self, ctx: StepContext) -> None:
        f = ctx.fleet
        if f.version != self._seen_version:
            self._gather()
            self._seen_version = f.version
        r = self._rows
        if r.size == 0:
            return
        v_rel = f.vel_enu_m_s[r] - f.wind_enu_m_s[r]
        f.force_cmd_enu_n[r] += quadratic_drag_enu_n(v_rel, R_from_quat_xyzw(f.quat_enu_flu_xyzw[r]),
                                                      self._cd, self._area, self._rho)
