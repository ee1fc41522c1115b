"""PAYLOAD_ENERGY phase: actuator-disk power per motor, battery energy, state of charge.

The paper's eq. 4 (actuator-disk / momentum theory, Mahony et al. 2012) in the form of docs/architecture.md §4,
``P_i = F_i^1.5 / (sqrt(2 rho A) eta)``, ``A = pi r^2``, ``P = sum_i P_i + P0``, evaluated on the
thrust each motor actually applied this step. A disarmed drone has zero thrust and so draws P0.
"""

from __future__ import annotations

import esper
import numpy as np

from ..components.flight import EnergyModel
from ..control.energy import rotor_power_w
from ..phases import Phase
from ..world import StepContext
from .flight_state import declare_flight_arrays
from .rows import gather_rows

J_PER_WH = 3600.0


class EnergySystem(esper.Processor):
    """Integrate power into battery energy for every drone with an :class:`EnergyModel`.

    Phase: PAYLOAD_ENERGY (order 50). Reads: fleet.motor_thrust_n, charging, charge_power_w.
    Writes: fleet.power_w, power_filt_w, energy_j, energy_used_j, soc_frac, remaining_time_s,
    low_battery, motors_enabled (False once the battery is empty).
    """

    phase = Phase.PAYLOAD_ENERGY
    order = 50

    def __init__(self) -> None:
        self._seen_version = -1
        self._rows = np.empty(0, dtype=np.intp)
        self._initialised: set[int] = set()

    def _gather(self, ctx: StepContext) -> None:
        f = ctx.fleet
        declare_flight_arrays(f)
        self._rows, comps = gather_rows(EnergyModel)
        self._area = np.array([np.pi * c.rotor_radius_m ** 2 for c in comps])
        self._rho = np.array([c.air_density_kg_m3 for c in comps])
        self._eta = np.array([c.efficiency for c in comps])
        self._p0 = np.array([c.p0_w for c in comps])
        self._cap_j = np.array([c.battery_wh * J_PER_WH for c in comps])
        self._low = np.array([c.low_battery_land_frac for c in comps])
        self._tau = np.array([c.remaining_time_tau_s for c in comps])
        entities = f.entity[self._rows]
        for k, (row, c) in enumerate(zip(self._rows.tolist(), comps)):
            if int(entities[k]) not in self._initialised:       # a new drone: full (or initial) battery
                f.energy_j[row] = c.initial_soc_frac * self._cap_j[k]
                f.energy_used_j[row] = 0.0
                f.soc_frac[row] = c.initial_soc_frac
                f.power_filt_w[row] = c.p0_w
                f.charge_power_w[row] = c.charge_power_w
                self._initialised.add(int(entities[k]))

    def process(self, ctx: StepContext) -> None:
        f = ctx.fleet
        if f.version != self._seen_version:
            self._gather(ctx)
            self._seen_version = f.version
        r = self._rows
        if r.size == 0:
            return
        power = rotor_power_w(f.motor_thrust_n[r], self._rho, self._area, self._eta).sum(axis=1) + self._p0
        f.power_w[r] = power
        a = 1.0 - np.exp(-ctx.dt_s / self._tau)
        f.power_filt_w[r] += a * (power - f.power_filt_w[r])
        charge = np.where(f.charging[r], f.charge_power_w[r], 0.0)
        energy = np.clip(f.energy_j[r] - power * ctx.dt_s + charge * ctx.dt_s, 0.0, self._cap_j)
        f.energy_j[r] = energy
        f.energy_used_j[r] += power * ctx.dt_s
        f.soc_frac[r] = energy / self._cap_j
        f.remaining_time_s[r] = energy / np.maximum(f.power_filt_w[r], 1e-9)
        f.low_battery[r] = f.soc_frac[r] < self._low
        empty = energy <= 0.0
        if empty.any():
            f.motors_enabled[r[empty]] = False
