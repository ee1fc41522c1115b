"""PAYLOAD_ENERGY phase: rotor power per motor, the battery pack, state of charge, remaining time.

Power (``energy.model``):

- ``momentum`` (default): each rotor's power from momentum theory with the air's real velocity
  through its disk -- the drone's velocity relative to the wind plus the rotor's own velocity from
  the body rates, split into the axial part (climb / descent) and the in-plane part (forward
  flight) -- :func:`..control.rotor_power.rotor_shaft_power_w`, over the efficiency eta. In hover
  it is the paper's eq. 4 exactly;
- ``hover_actuator_disk``: the paper's eq. 4 on the thrust alone, ``P_i = F_i^1.5 / (sqrt(2 rho A) eta)``.

``P = sum_i P_i + P0``, evaluated on the thrust each motor applied this step (a disarmed drone
draws P0). The battery (``energy.battery``) is an equivalent-circuit LiPo pack (``lipo``,
:mod:`..control.battery_ecm`: the pack delivers P at its terminal voltage, which sags by I R0 at
once and by the RC pair over its time constant; the motors stop below the cut-off voltage or when
empty) or the paper's ideal energy bucket (``ideal``).
"""

from __future__ import annotations

import math

import esper
import numpy as np

from ..components.flight import LIPO_CELL_NOMINAL_V, EnergyModel, QuadrotorMotors
from ..control.battery_ecm import cell_ocv_v, energy_remaining_wh, pack_current_for_power_a, step_pack
from ..control.energy import rotor_power_w
from ..control.mixer import motor_positions_flu_m
from ..control.rotor_power import (glauert_inflow_m_s, hover_induced_velocity_m_s, profile_hover_power_w,
                                   shaft_power_from_inflow_w, vortex_ring_correction_m_s)
from ..phases import Phase
from ..world import StepContext
from .fleet_system import FleetSystem

J_PER_WH = 3600.0


def _column(items: list[EnergyModel], name: str) -> np.ndarray:
    return np.array([getattr(c, name) for c in items], dtype=float)


class EnergySystem(FleetSystem):
    """Power and battery of every drone with an :class:`EnergyModel`.

    Phase: PAYLOAD_ENERGY (order 50). Reads: fleet.motor_thrust_n, ground_effect_factor, vel_enu_m_s,
    wind_enu_m_s, R_enu_flu, rate_flu_rad_s, charging, charge_power_w. Writes: fleet.power_w,
    power_filt_w, energy_j (left), energy_used_j (delivered to the loads), soc_frac, remaining_time_s,
    low_battery, pack_voltage_v, pack_current_a, pack_v_rc_v, glauert_inflow_m_s (the solver's next
    start), motors_enabled (False once the pack cuts off).

    A drone's battery starts at ``initial_soc_frac`` the first time the system sees it; an
    :class:`EnergyModel` replaced later changes the power from the next step on and keeps the charge.
    """

    phase = Phase.PAYLOAD_ENERGY
    order = 50
    requires = (EnergyModel,)

    def __init__(self) -> None:
        super().__init__()
        self._initialised: set[int] = set()      # entities whose battery has been filled

    def gather(self, ctx: StepContext) -> None:
        comps: list[EnergyModel] = self.components[0]
        col = lambda name: _column(comps, name)  # noqa: E731
        self._area = np.pi * col("rotor_radius_m") ** 2
        rho = col("air_density_kg_m3")
        self._rho = np.where(np.isnan(rho), ctx.services.air_density_kg_m3, rho)
        self._eta = col("efficiency")
        self._p0 = col("p0_w")
        self._low = col("low_battery_land_frac")
        self._tau = col("remaining_time_tau_s")
        self._filter_dt_s, self._filter_gain = math.nan, np.zeros_like(self._tau)   # the filter's gain per step
        # power model
        self._momentum = np.array([c.model == "momentum" for c in comps])
        self._any_momentum, self._all_momentum = bool(self._momentum.any()), bool(self._momentum.all())
        self._tip_speed = col("tip_speed_m_s")[:, None]
        self._profile_hover_w = profile_hover_power_w(col("rotor_solidity"), col("blade_drag_coeff"), self._rho,
                                                      self._area, col("tip_speed_m_s"))[:, None]
        arms = []
        for ent in self.entities.tolist():
            motors = esper.try_component(ent, QuadrotorMotors)
            arms.append(motors.arm_length_m if motors is not None else 0.0)
        pos = motor_positions_flu_m(np.array(arms))                                  # (M, 4, 3), z = 0
        # a rotor's axial velocity from the body rates, (w x r)_z = w_x r_y - w_y r_x: [w_x, w_y] @ this
        self._axial_per_rate = np.stack([pos[:, :, 1], -pos[:, :, 0]], axis=1)     # (M, 2, 4) [m]
        self._rho_col, self._area_col, self._eta_col = self._rho[:, None], self._area[:, None], self._eta[:, None]
        # battery
        self._lipo = np.array([c.battery == "lipo" for c in comps])
        self._any_lipo, self._all_lipo = bool(self._lipo.any()), bool(self._lipo.all())
        self._cells = col("cells_series")
        self._capacity_eff_ah = np.array([c.capacity_ah for c in comps])
        self._r0 = self._cells * col("cell_r0_ohm")
        self._r1 = self._cells * col("cell_r1_ohm")
        self._rc_tau = col("rc_tau_s")
        self._cutoff_v = self._cells * col("cell_cutoff_v")
        self._ideal_cap_j = col("battery_wh") * J_PER_WH
        self._ideal_v = self._cells * LIPO_CELL_NOMINAL_V
        new = [k for k, ent in enumerate(self.entities.tolist()) if ent not in self._initialised]
        if new:
            self._fill(ctx, np.array(new, dtype=np.intp), comps)

    def _fill(self, ctx: StepContext, k: np.ndarray, comps: list[EnergyModel]) -> None:
        """A new drone's battery: charged to ``initial_soc_frac``, at rest, drawing what its motors draw now."""
        f = ctx.fleet
        rows = self.rows[k]
        soc = np.array([comps[i].initial_soc_frac for i in k.tolist()])
        f.soc_frac[rows] = soc
        f.pack_v_rc_v[rows] = 0.0
        f.energy_used_j[rows] = 0.0
        f.charge_power_w[rows] = [comps[i].charge_power_w for i in k.tolist()]
        f.energy_j[rows] = self._energy_j(soc, k)
        power = self._power_w(f, rows, k)
        f.power_w[rows] = f.power_filt_w[rows] = power      # what it draws now (P0 on the ground)
        ocv = self._cells[k] * cell_ocv_v(soc)
        current = np.where(self._lipo[k], pack_current_for_power_a(power, ocv, 0.0, self._r0[k])[0],
                           power / self._ideal_v[k])
        f.pack_current_a[rows] = current
        f.pack_voltage_v[rows] = np.where(self._lipo[k], ocv - current * self._r0[k], self._ideal_v[k])
        f.remaining_time_s[rows] = f.energy_j[rows] / np.maximum(power, 1e-9)
        f.low_battery[rows] = soc < self._low[k]
        self._initialised.update(self.entities[k].tolist())

    def _energy_j(self, soc: np.ndarray, k: np.ndarray | slice) -> np.ndarray:
        """Energy left [J] at ``soc``: the open-circuit energy down to empty (lipo) or capacity x SOC (ideal)."""
        if not self._any_lipo:
            return soc * self._ideal_cap_j[k]
        lipo = energy_remaining_wh(soc, self._capacity_eff_ah[k], self._cells[k]) * J_PER_WH
        return lipo if self._all_lipo else np.where(self._lipo[k], lipo, soc * self._ideal_cap_j[k])

    def _power_w(self, f, rows: np.ndarray | slice, k: np.ndarray | slice = slice(None)) -> np.ndarray:
        """Electrical power [W] of drones ``rows`` (parameters ``k``): rotors over eta, plus P0."""
        # the power of the thrust out of ground effect: near the ground the same power lifts more
        thrust = f.motor_thrust_n[rows] / f.ground_effect_factor[rows]
        rho, area, eta = self._rho[k], self._area[k], self._eta[k]
        if self._all_momentum:
            rotors = self._momentum_power_w(f, rows, k, thrust)
        else:
            rotors = rotor_power_w(thrust, rho, area, eta)
            if self._any_momentum:
                rotors = np.where(self._momentum[k][:, None], self._momentum_power_w(f, rows, k, thrust), rotors)
        return rotors.sum(axis=1) + self._p0[k]

    def _momentum_power_w(self, f, rows: np.ndarray | slice, k: np.ndarray | slice, thrust: np.ndarray) -> np.ndarray:
        """(M, 4) [W] electrical power of each rotor from momentum theory with the air through its disk.

        Axial: the body's velocity relative to the air along its z axis plus each rotor's own from the
        roll and pitch rates; in-plane: the body's (the yaw rate's in-plane ``w x r`` is left out: at most
        a few tenths of a m/s, second order in the in-plane speed's effect on power).
        """
        v_rel_enu = f.vel_enu_m_s[rows] - f.wind_enu_m_s[rows]
        v_flu = (v_rel_enu[:, None, :] @ f.R_enu_flu[rows])[:, 0, :]                 # R^T v: body FLU
        v_axial = v_flu[:, 2:3] + (f.rate_flu_rad_s[rows][:, None, :2] @ self._axial_per_rate[k])[:, 0, :]
        v_inplane = np.sqrt(v_flu[:, 0:1] * v_flu[:, 0:1] + v_flu[:, 1:2] * v_flu[:, 1:2])    # (M, 1)
        v_h = hover_induced_velocity_m_s(thrust, self._rho_col[k], self._area_col[k])
        root = glauert_inflow_m_s(v_axial, v_inplane, v_h, guess_m_s=f.glauert_inflow_m_s[rows])
        f.glauert_inflow_m_s[rows] = root
        inflow = root + vortex_ring_correction_m_s(v_axial, v_inplane, v_h)
        shaft = shaft_power_from_inflow_w(thrust, inflow, v_inplane, self._profile_hover_w[k], self._tip_speed[k])
        return np.maximum(shaft, 0.0) / self._eta_col[k]          # the ESCs do not regenerate

    def update(self, ctx: StepContext) -> None:
        f = ctx.fleet
        r = self.sel
        dt = ctx.dt_s
        power = self._power_w(f, r)
        f.power_w[r] = power
        if dt != self._filter_dt_s:
            self._filter_dt_s, self._filter_gain = dt, 1.0 - np.exp(-dt / self._tau)
        f.power_filt_w[r] += self._filter_gain * (power - f.power_filt_w[r])
        charging = f.charging[r]
        net_w = power - np.where(charging, f.charge_power_w[r], 0.0) if charging.any() else power
        soc = f.soc_frac[r]
        cut = np.zeros(soc.shape, dtype=bool)
        if self._any_lipo:
            ocv = self._cells * cell_ocv_v(soc)
            current, _limited = pack_current_for_power_a(net_w, ocv, f.pack_v_rc_v[r], self._r0)
            pack = step_pack(soc, f.pack_v_rc_v[r], current, dt, self._capacity_eff_ah, self._r0, self._r1,
                             self._rc_tau, self._cells)
            lipo_soc, volts = pack.soc_frac, pack.terminal_v
            cut = self._lipo & ((volts < self._cutoff_v) | (lipo_soc <= 0.0))
            f.pack_v_rc_v[r] = pack.v_rc_v
        if not self._all_lipo:
            ideal_energy = np.minimum(np.maximum(soc * self._ideal_cap_j - net_w * dt, 0.0), self._ideal_cap_j)
            ideal_soc = ideal_energy / self._ideal_cap_j
            ideal_current = net_w / self._ideal_v
        if self._all_lipo:
            soc, f.pack_current_a[r], f.pack_voltage_v[r] = lipo_soc, current, volts
        elif not self._any_lipo:
            soc, f.pack_current_a[r], f.pack_voltage_v[r] = ideal_soc, ideal_current, self._ideal_v
            cut = ideal_soc <= 0.0
        else:
            lipo = self._lipo
            soc = np.where(lipo, lipo_soc, ideal_soc)
            f.pack_current_a[r] = np.where(lipo, current, ideal_current)
            f.pack_voltage_v[r] = np.where(lipo, volts, self._ideal_v)
            cut |= ~lipo & (ideal_soc <= 0.0)
        f.soc_frac[r] = soc
        energy = self._energy_j(soc, slice(None))
        f.energy_j[r] = energy
        f.energy_used_j[r] += power * dt
        f.remaining_time_s[r] = energy / np.maximum(f.power_filt_w[r], 1e-9)
        f.low_battery[r] = soc < self._low
        if cut.any():
            f.motors_enabled[self.rows[cut]] = False
