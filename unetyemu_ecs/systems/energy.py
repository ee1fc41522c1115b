"""PAYLOAD_ENERGY phase: actuator-disk power per motor, battery energy, state of charge.

The paper's eq. 4 (actuator-disk / momentum theory, Mahony et al. 2012) in the form of docs/architecture.md §4,
``P_i = F_i^1.5 / (sqrt(2 rho A) eta)``, ``A = pi r^2``, ``P = sum_i P_i + P0``, evaluated on the
thrust each motor actually applied this step. A disarmed drone has zero thrust and so draws P0.
"""

from __future__ import annotations

import math

import numpy as np

from ..components.flight import EnergyModel
from ..control.energy import rotor_power_w
from ..phases import Phase
from ..world import StepContext
from .fleet_system import FleetSystem, stack_params

J_PER_WH = 3600.0


class EnergySystem(FleetSystem):
    """Integrate power into battery energy for every drone with an :class:`EnergyModel`.

    Phase: PAYLOAD_ENERGY (order 50). Reads: fleet.motor_thrust_n, charging, charge_power_w.
    Writes: fleet.power_w, power_filt_w, energy_j, energy_used_j, soc_frac, remaining_time_s,
    low_battery, motors_enabled (False once the battery is empty).

    A drone's battery starts at ``initial_soc_frac`` the first time the system sees it; an
    :class:`EnergyModel` replaced later (other rotors, avionics power, capacity) changes the power
    from the next step on and keeps the energy the battery holds.
    """

    phase = Phase.PAYLOAD_ENERGY
    order = 50
    requires = (EnergyModel,)

    def __init__(self) -> None:
        super().__init__()
        self._initialised: set[int] = set()      # entities whose battery has been filled

    def gather(self, ctx: StepContext) -> None:
        f = ctx.fleet
        p = stack_params(self.components[0], EnergyModel)
        self._area = np.pi * p.rotor_radius_m ** 2
        self._rho = p.air_density_kg_m3
        self._eta = p.efficiency
        self._p0 = p.p0_w
        self._cap_j = p.battery_wh * J_PER_WH
        self._low = p.low_battery_land_frac
        self._tau = p.remaining_time_tau_s
        self._filter_dt_s, self._filter_gain = math.nan, np.zeros_like(self._tau)   # the filter's gain per step
        for k, (row, ent) in enumerate(zip(self.rows.tolist(), self.entities.tolist())):
            if ent not in self._initialised:       # a new drone: full (or initial) battery
                f.energy_j[row] = p.initial_soc_frac[k] * self._cap_j[k]
                f.energy_used_j[row] = 0.0
                f.soc_frac[row] = p.initial_soc_frac[k]
                f.charge_power_w[row] = p.charge_power_w[k]
                power = float(rotor_power_w(f.motor_thrust_n[row:row + 1], self._rho[k:k + 1], self._area[k:k + 1],
                                            self._eta[k:k + 1]).sum()) + p.p0_w[k]
                f.power_w[row] = f.power_filt_w[row] = power       # what it draws now (P0 on the ground)
                f.remaining_time_s[row] = f.energy_j[row] / max(power, 1e-9)
                f.low_battery[row] = f.soc_frac[row] < self._low[k]
                self._initialised.add(ent)

    def update(self, ctx: StepContext) -> None:
        f = ctx.fleet
        r = self.sel
        dt = ctx.dt_s
        power = rotor_power_w(f.motor_thrust_n[r], self._rho, self._area, self._eta).sum(axis=1) + self._p0
        f.power_w[r] = power
        if dt != self._filter_dt_s:
            self._filter_dt_s, self._filter_gain = dt, 1.0 - np.exp(-dt / self._tau)
        f.power_filt_w[r] += self._filter_gain * (power - f.power_filt_w[r])
        charging = f.charging[r]
        energy = f.energy_j[r] - power * dt
        if charging.any():
            energy += np.where(charging, f.charge_power_w[r], 0.0) * dt
        energy = np.minimum(np.maximum(energy, 0.0), self._cap_j)
        f.energy_j[r] = energy
        f.energy_used_j[r] += power * dt
        soc = energy / self._cap_j
        f.soc_frac[r] = soc
        f.remaining_time_s[r] = energy / np.maximum(f.power_filt_w[r], 1e-9)
        f.low_battery[r] = soc < self._low
        empty = energy <= 0.0
        if empty.any():
            f.motors_enabled[self.rows[empty]] = False
