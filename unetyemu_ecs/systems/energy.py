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
empty) or the paper's ideal energy bucket (``ideal``). One compiled loop over the drones,
:func:`..control.energy_step.energy_step`, runs those laws each step.
"""

from __future__ import annotations

import esper
import numpy as np

from ..components.flight import LIPO_CELL_NOMINAL_V, EnergyModel, QuadrotorMotors
from ..control.battery_ecm import cell_ocv_and_integral_v, pack_current_for_power_a, rc_decay
from ..control.energy_step import J_PER_WH, energy_params, energy_step, fleet_power_w
from ..control.mixer import motor_positions_flu_m
from ..control.rotor_power import PROFILE_MU2_FACTOR, profile_hover_power_w
from ..phases import Phase
from ..world import StepContext
from .fleet_system import FleetSystem


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
        area = np.pi * col("rotor_radius_m") ** 2
        rho = col("air_density_kg_m3")
        rho = np.where(np.isnan(rho), ctx.services.air_density_kg_m3, rho)
        self._tau = col("remaining_time_tau_s")
        self._rc_tau = col("rc_tau_s")
        p = self._params = energy_params(len(comps))
        p["momentum"] = [c.model == "momentum" for c in comps]
        p["two_rho_area_kg_m"] = 2.0 * rho * area
        p["efficiency"] = col("efficiency")
        p["p0_w"] = col("p0_w")
        p["profile_mu2_w"] = PROFILE_MU2_FACTOR * profile_hover_power_w(col("rotor_solidity"), col("blade_drag_coeff"),
                                                                         rho, area, col("tip_speed_m_s"))
        p["tip_speed_m_s"] = col("tip_speed_m_s")
        arms = []
        for ent in self.entities.tolist():
            motors = esper.try_component(ent, QuadrotorMotors)
            arms.append(motors.arm_length_m if motors is not None else 0.0)
        pos = motor_positions_flu_m(np.array(arms))                                  # (M, 4, 3), z = 0
        # a rotor's axial velocity from the body rates, (w x r)_z = w_x r_y - w_y r_x: [w_x, w_y] @ this
        self._axial_per_rate = np.ascontiguousarray(np.stack([pos[:, :, 1], -pos[:, :, 0]], axis=1))   # (M, 2, 4) [m]
        p["lipo"] = [c.battery == "lipo" for c in comps]
        cells = col("cells_series")
        capacity_eff_ah = np.array([c.capacity_ah for c in comps])
        p["cells"] = cells
        p["r0_pack_ohm"] = cells * col("cell_r0_ohm")
        p["r1_pack_ohm"] = cells * col("cell_r1_ohm")
        p["capacity_eff_as"] = 3600.0 * capacity_eff_ah
        p["cells_capacity_ah"] = cells * capacity_eff_ah
        p["cutoff_pack_v"] = cells * col("cell_cutoff_v")
        p["ideal_capacity_j"] = col("battery_wh") * J_PER_WH
        p["ideal_pack_v"] = cells * LIPO_CELL_NOMINAL_V
        p["low_battery_frac"] = col("low_battery_land_frac")
        self._set_step_constants(1.0)      # replaced on the first step (dt unknown here)
        new = [k for k, ent in enumerate(self.entities.tolist()) if ent not in self._initialised]
        if new:
            self._fill(ctx, np.array(new, dtype=np.intp), comps)

    def _set_step_constants(self, dt_s: float) -> None:
        """The constants of a step of ``dt_s``: the remaining-time filter's gain, the RC pair's decay and rise."""
        self._dt_s = dt_s
        self._params["filter_gain"] = 1.0 - np.exp(-dt_s / self._tau)
        self._params["rc_decay"], self._params["rc_rise"] = rc_decay(dt_s, self._rc_tau)

    def _fill(self, ctx: StepContext, k: np.ndarray, comps: list[EnergyModel]) -> None:
        """A new drone's battery: charged to ``initial_soc_frac``, at rest, drawing what its motors draw now."""
        f = ctx.fleet
        rows = self.rows[k]
        p = self._params[k]
        lipo, ideal_v = p["lipo"], p["ideal_pack_v"]
        soc = np.array([comps[i].initial_soc_frac for i in k.tolist()])
        f.soc_frac[rows] = soc
        f.pack_v_rc_v[rows] = 0.0
        f.energy_used_j[rows] = 0.0
        f.charge_power_w[rows] = [comps[i].charge_power_w for i in k.tolist()]
        cell_ocv, cell_ocv_integral = cell_ocv_and_integral_v(soc)
        f.energy_j[rows] = np.where(lipo, p["cells_capacity_ah"] * cell_ocv_integral * J_PER_WH, soc * p["ideal_capacity_j"])
        power = fleet_power_w(rows, p, self._axial_per_rate[k], f.motor_thrust_n, f.ground_effect_factor,
                              f.vel_enu_m_s, f.wind_enu_m_s, f.R_enu_flu, f.rate_flu_rad_s, f.glauert_inflow_m_s)
        f.power_w[rows] = f.power_filt_w[rows] = power      # what it draws now (P0 on the ground)
        ocv = p["cells"] * cell_ocv
        current = np.where(lipo, pack_current_for_power_a(power, ocv, 0.0, p["r0_pack_ohm"])[0], power / ideal_v)
        f.pack_current_a[rows] = current
        f.pack_voltage_v[rows] = np.where(lipo, ocv - current * p["r0_pack_ohm"], ideal_v)
        f.remaining_time_s[rows] = f.energy_j[rows] / np.maximum(power, 1e-9)
        f.low_battery[rows] = soc < p["low_battery_frac"]
        self._initialised.update(self.entities[k].tolist())

    def update(self, ctx: StepContext) -> None:
        f = ctx.fleet
        if ctx.dt_s != self._dt_s:
            self._set_step_constants(ctx.dt_s)
        energy_step(self.rows, self._params, self._axial_per_rate, ctx.dt_s, f.motor_thrust_n, f.ground_effect_factor,
                    f.vel_enu_m_s, f.wind_enu_m_s, f.R_enu_flu, f.rate_flu_rad_s, f.glauert_inflow_m_s, f.charging,
                    f.charge_power_w, f.soc_frac, f.pack_v_rc_v, f.power_w, f.power_filt_w, f.pack_current_a,
                    f.pack_voltage_v, f.energy_j, f.energy_used_j, f.remaining_time_s, f.low_battery,
                    f.motors_enabled)


