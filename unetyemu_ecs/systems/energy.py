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
from ..control.battery_ecm import (advance_pack, cell_ocv_and_integral_v, cell_ocv_v, energy_remaining_wh,
                                   pack_current_for_power_a, rc_decay, terminal_from_ocv_v)
from ..control.energy import rotor_power_w
from ..control.mixer import motor_positions_flu_m
from ..control.rotor_power import (PROFILE_MU2_FACTOR, glauert_inflow_m_s, hover_induced_velocity_of_loading_m_s,
                                   profile_hover_power_w, shaft_power_of_positive_thrust_w,
                                   vortex_ring_correction_m_s)
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
        # per-step constants of dt (set on the first step and whenever dt changes): the filter's gain, the RC pair's
        # decay and rise (:func:`..control.battery_ecm.rc_decay`)
        self._filter_dt_s, self._filter_gain = math.nan, np.zeros_like(self._tau)
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
        self._two_rho_area_col = 2.0 * self._rho_col * self._area_col                    # (M, 1) [kg/m]
        self._profile_mu2_w = self._profile_hover_w * PROFILE_MU2_FACTOR                # (M, 1) [W]
        # battery
        self._lipo = np.array([c.battery == "lipo" for c in comps])
        self._any_lipo, self._all_lipo = bool(self._lipo.any()), bool(self._lipo.all())
        self._cells = col("cells_series")
        self._capacity_eff_ah = np.array([c.capacity_ah for c in comps])
        self._r0 = self._cells * col("cell_r0_ohm")
        self._r1 = self._cells * col("cell_r1_ohm")
        self._rc_tau = col("rc_tau_s")
        self._rc_decay, self._rc_rise = rc_decay(1.0, self._rc_tau)     # replaced on the first step (dt unknown here)
        self._capacity_eff_as = 3600.0 * self._capacity_eff_ah
        self._cells_capacity_ah = self._cells * self._capacity_eff_ah     # energy_remaining_wh's cells x capacity
        # the pack OCV [V] the last step left at the SOC it left (None: none yet, or the rows changed)
        self._ocv_soc_frac: np.ndarray | None = None
        self._ocv_pack_v = np.zeros_like(self._cells)
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
        if self._all_momentum:
            rotors = self._momentum_power_w(f, rows, k, thrust)
        else:
            rotors = rotor_power_w(thrust, self._rho[k], self._area[k], self._eta[k])
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
        thrust_pos = np.maximum(thrust, 0.0)                                         # negative thrust counts as zero
        v_h = hover_induced_velocity_of_loading_m_s(thrust_pos, self._two_rho_area_col[k])
        root = glauert_inflow_m_s(v_axial, v_inplane, v_h, guess_m_s=f.glauert_inflow_m_s[rows])
        f.glauert_inflow_m_s[rows] = root
        inflow = root + vortex_ring_correction_m_s(v_axial, v_inplane, v_h)
        shaft = shaft_power_of_positive_thrust_w(thrust_pos, inflow, v_inplane, self._profile_mu2_w[k],
                                                 self._tip_speed[k])
        return np.maximum(shaft, 0.0) / self._eta_col[k]          # the ESCs do not regenerate

    def _pack_ocv_v(self, soc: np.ndarray) -> np.ndarray:
        """``cells OCV(soc)`` [V]: the value the last step computed while the SOC is still the one it left."""
        if self._ocv_soc_frac is not None and (soc == self._ocv_soc_frac).all():
            return self._ocv_pack_v
        return self._cells * cell_ocv_v(soc)

    def update(self, ctx: StepContext) -> None:
        f = ctx.fleet
        r = self.sel
        dt = ctx.dt_s
        power = self._power_w(f, r)
        f.power_w[r] = power
        if dt != self._filter_dt_s:
            self._filter_dt_s, self._filter_gain = dt, 1.0 - np.exp(-dt / self._tau)
            self._rc_decay, self._rc_rise = rc_decay(dt, self._rc_tau)
        f.power_filt_w[r] += self._filter_gain * (power - f.power_filt_w[r])
        charging = f.charging[r]
        net_w = power - np.where(charging, f.charge_power_w[r], 0.0) if charging.any() else power
        soc = f.soc_frac[r]
        if self._any_lipo:         # step_pack, its OCV at the new SOC shared with the energy left and the next step
            v_rc = f.pack_v_rc_v[r]
            current, _limited = pack_current_for_power_a(net_w, self._pack_ocv_v(soc), v_rc, self._r0)
            lipo_soc, v_rc = advance_pack(soc, v_rc, current, dt, self._capacity_eff_as, self._rc_decay,
                                          self._rc_rise, self._r1)
            cell_ocv, cell_ocv_integral = cell_ocv_and_integral_v(lipo_soc)
            pack_ocv = self._cells * cell_ocv
            volts = terminal_from_ocv_v(pack_ocv, v_rc, current, self._r0)
            self._ocv_soc_frac, self._ocv_pack_v = lipo_soc, pack_ocv
            cut = (volts < self._cutoff_v) | (lipo_soc <= 0.0)
            if not self._all_lipo:
                cut &= self._lipo
            f.pack_v_rc_v[r] = v_rc
        if not self._all_lipo:
            ideal_energy = np.minimum(np.maximum(soc * self._ideal_cap_j - net_w * dt, 0.0), self._ideal_cap_j)
            ideal_soc = ideal_energy / self._ideal_cap_j
            ideal_current = net_w / self._ideal_v
        if self._all_lipo:
            soc, f.pack_current_a[r], f.pack_voltage_v[r] = lipo_soc, current, volts
            energy = self._cells_capacity_ah * cell_ocv_integral * J_PER_WH    # energy_remaining_wh at lipo_soc
        else:
            if not self._any_lipo:
                soc, f.pack_current_a[r], f.pack_voltage_v[r] = ideal_soc, ideal_current, self._ideal_v
                cut = ideal_soc <= 0.0
            else:
                lipo = self._lipo
                soc = np.where(lipo, lipo_soc, ideal_soc)
                f.pack_current_a[r] = np.where(lipo, current, ideal_current)
                f.pack_voltage_v[r] = np.where(lipo, volts, self._ideal_v)
                cut |= ~lipo & (ideal_soc <= 0.0)
            energy = self._energy_j(soc, slice(None))
        f.soc_frac[r] = soc
        f.energy_j[r] = energy
        f.energy_used_j[r] += power * dt
        f.remaining_time_s[r] = energy / np.maximum(f.power_filt_w[r], 1e-9)
        f.low_battery[r] = soc < self._low
        if cut.any():
            f.motors_enabled[self.rows[cut]] = False
