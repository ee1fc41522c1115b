"""One step of every drone's rotor power and battery, compiled (the energy system's kernel).

The laws are those of :mod:`.rotor_power` (momentum theory with the real inflow), :mod:`.energy` (the
paper's actuator disk) and :mod:`.battery_ecm` (the equivalent-circuit LiPo pack), or the paper's ideal
energy bucket; this module only runs them per drone and per rotor in one compiled loop, reading and
writing the fleet's arrays in place (:mod:`.compiled`: NumPy on arrays of a few elements costs a
microsecond per operation, and one drone's step took about 100 of them).

Per-drone constants live in one structured array of :data:`ENERGY_PARAMS` (see
:func:`energy_params`); ``rows`` are the drones' fleet rows, in the same order.
"""

from __future__ import annotations

import numpy as np

from .battery_ecm import (_ocv_integral_of_clipped_v, _ocv_of_clipped_v, advance_pack, clipped_soc_and_exp,
                          pack_current_for_power_a, terminal_from_ocv_v)
from .compiled import jit
from .energy import actuator_disk_power_w
from .rotor_power import (glauert_inflow_scalar_m_s, hover_induced_velocity_of_loading_m_s,
                          shaft_power_of_positive_thrust_w, vortex_ring_correction_scalar_m_s)

J_PER_WH = 3600.0

# the laws compiled for the scalars of one rotor or one pack (the same functions NumPy callers use)
_advance_pack = jit(advance_pack)
_terminal_from_ocv_v = jit(terminal_from_ocv_v)
_pack_current_for_power_a = jit(pack_current_for_power_a)
_clipped_soc_and_exp = jit(clipped_soc_and_exp)
_ocv_of_clipped = jit(_ocv_of_clipped_v)
_ocv_integral_of_clipped = jit(_ocv_integral_of_clipped_v)
_actuator_disk_power_w = jit(actuator_disk_power_w)
_hover_induced_velocity_of_loading_m_s = jit(hover_induced_velocity_of_loading_m_s)
_shaft_power_of_positive_thrust_w = jit(shaft_power_of_positive_thrust_w)

ENERGY_PARAMS = np.dtype([
    # power
    ("momentum", np.bool_),              # momentum theory with the real inflow (else the paper's eq. 4 on thrust)
    ("two_rho_area_kg_m", np.float64),   # 2 rho A of one rotor
    ("efficiency", np.float64),          # eta: shaft power / electrical power
    ("p0_w", np.float64),                # power of everything but the rotors
    ("profile_mu2_w", np.float64),       # P_0h 4.65: profile power's growth with advance ratio squared
    ("tip_speed_m_s", np.float64),
    # battery
    ("lipo", np.bool_),                  # the equivalent-circuit pack (else the ideal bucket)
    ("cells", np.float64),               # in series
    ("r0_pack_ohm", np.float64),
    ("r1_pack_ohm", np.float64),
    ("rc_decay", np.float64),            # e^(-dt/tau) of the RC pair over one step (battery_ecm.rc_decay)
    ("rc_rise", np.float64),             # 1 - rc_decay
    ("capacity_eff_as", np.float64),     # effective capacity [A s]
    ("cells_capacity_ah", np.float64),   # cells x effective capacity [Ah]: open-circuit energy per volt of OCV
    ("cutoff_pack_v", np.float64),       # the motors stop below this terminal voltage
    ("ideal_capacity_j", np.float64),    # the ideal bucket's energy when full
    ("ideal_pack_v", np.float64),        # the ideal bucket's voltage (cells x 3.7 V)
    ("low_battery_frac", np.float64),    # SOC below which low_battery is set
    ("filter_gain", np.float64),         # 1 - e^(-dt/tau) of the remaining-time power filter over one step
], align=True)


def energy_params(m: int) -> np.ndarray:
    """(m,) zeroed :data:`ENERGY_PARAMS` records for the caller to fill."""
    return np.zeros(m, dtype=ENERGY_PARAMS)


@jit
def drone_power_w(p, axial_per_rate_m, row, motor_thrust_n, ground_effect_factor, vel_enu_m_s, wind_enu_m_s,
                  R_enu_flu, rate_flu_rad_s, glauert_inflow_m_s):
    """Electrical power [W] of the drone in fleet ``row`` (its :data:`ENERGY_PARAMS` record ``p``): its
    rotors' over eta, plus P0, evaluated on the thrust out of ground effect (near the ground the same power
    lifts more). Momentum model: each rotor's axial air speed is the body's velocity relative to the air
    along its z axis plus the rotor's own from the roll and pitch rates (``axial_per_rate_m`` (2, 4):
    ``[w_x, w_y] @`` it), the in-plane one the body's (the yaw rate's in-plane ``w x r`` is left out: at most
    a few tenths of a m/s, second order in its effect on power); Glauert's root is kept in
    ``glauert_inflow_m_s[row]`` as the next step's start."""
    total_w = 0.0
    if p.momentum:
        vx = vel_enu_m_s[row, 0] - wind_enu_m_s[row, 0]
        vy = vel_enu_m_s[row, 1] - wind_enu_m_s[row, 1]
        vz = vel_enu_m_s[row, 2] - wind_enu_m_s[row, 2]
        R = R_enu_flu[row]
        fwd = R[0, 0] * vx + R[1, 0] * vy + R[2, 0] * vz         # R^T v: the air's velocity in body FLU
        left = R[0, 1] * vx + R[1, 1] * vy + R[2, 1] * vz
        up = R[0, 2] * vx + R[1, 2] * vy + R[2, 2] * vz
        v_inplane = np.sqrt(fwd * fwd + left * left)
        wx, wy = rate_flu_rad_s[row, 0], rate_flu_rad_s[row, 1]
        for j in range(4):
            thrust_pos = max(motor_thrust_n[row, j] / ground_effect_factor[row, j], 0.0)   # negative counts as zero
            v_axial = up + wx * axial_per_rate_m[0, j] + wy * axial_per_rate_m[1, j]
            v_h = _hover_induced_velocity_of_loading_m_s(thrust_pos, p.two_rho_area_kg_m)
            root = glauert_inflow_scalar_m_s(v_axial, v_inplane, v_h, glauert_inflow_m_s[row, j])
            glauert_inflow_m_s[row, j] = root
            inflow = root + vortex_ring_correction_scalar_m_s(v_axial, v_inplane, v_h)
            shaft_w = _shaft_power_of_positive_thrust_w(thrust_pos, inflow, v_inplane, p.profile_mu2_w,
                                                        p.tip_speed_m_s)
            total_w += max(shaft_w, 0.0) / p.efficiency                  # the ESCs do not regenerate
    else:
        for j in range(4):
            total_w += _actuator_disk_power_w(motor_thrust_n[row, j] / ground_effect_factor[row, j],
                                              p.two_rho_area_kg_m, p.efficiency)
    return total_w + p.p0_w


@jit
def fleet_power_w(rows, params, axial_per_rate_m, motor_thrust_n, ground_effect_factor, vel_enu_m_s, wind_enu_m_s,
                  R_enu_flu, rate_flu_rad_s, glauert_inflow_m_s):
    """(M,) [W] :func:`drone_power_w` of the drones in ``rows`` (``params`` and ``axial_per_rate_m`` (M, 2, 4)
    in the same order)."""
    power_w = np.empty(rows.shape[0])
    for k in range(rows.shape[0]):
        power_w[k] = drone_power_w(params[k], axial_per_rate_m[k], rows[k], motor_thrust_n, ground_effect_factor,
                                   vel_enu_m_s, wind_enu_m_s, R_enu_flu, rate_flu_rad_s, glauert_inflow_m_s)
    return power_w


@jit
def energy_step(rows, params, axial_per_rate_m, dt_s, motor_thrust_n, ground_effect_factor, vel_enu_m_s,
                wind_enu_m_s, R_enu_flu, rate_flu_rad_s, glauert_inflow_m_s, charging, charge_power_w, soc_frac,
                pack_v_rc_v, power_w, power_filt_w, pack_current_a, pack_voltage_v, energy_j, energy_used_j,
                remaining_time_s, low_battery, motors_enabled):
    """Advance the drones in ``rows`` by ``dt_s``: their power (:func:`drone_power_w`), less a charger's
    while ``charging``, drawn from the pack over the step; every fleet array named is written in place at
    those rows (``motors_enabled`` only cleared, where the pack cut off: below its cut-off voltage or empty).

    LiPo pack: the current that delivers the power at the terminal (:func:`.battery_ecm.pack_current_for_power_a`
    at the open-circuit voltage of the SOC and the RC pair's voltage at the step's start), SOC and RC pair
    after the step (:func:`.battery_ecm.advance_pack`), the terminal voltage and the open-circuit energy left
    at the new SOC. Ideal bucket: energy less the power over the step, within [0, capacity], at its fixed
    voltage. Remaining time is the energy left over the filtered power.
    """
    for k in range(rows.shape[0]):
        row = rows[k]
        p = params[k]
        power = drone_power_w(p, axial_per_rate_m[k], row, motor_thrust_n, ground_effect_factor, vel_enu_m_s,
                              wind_enu_m_s, R_enu_flu, rate_flu_rad_s, glauert_inflow_m_s)
        power_w[row] = power
        power_filt_w[row] += p.filter_gain * (power - power_filt_w[row])
        net_w = power - charge_power_w[row] if charging[row] else power
        soc = soc_frac[row]
        if p.lipo:
            s, exp_term = _clipped_soc_and_exp(soc)
            current, _limited = _pack_current_for_power_a(net_w, p.cells * _ocv_of_clipped(s, exp_term),
                                                          pack_v_rc_v[row], p.r0_pack_ohm)
            soc, v_rc = _advance_pack(soc, pack_v_rc_v[row], current, dt_s, p.capacity_eff_as, p.rc_decay,
                                      p.rc_rise, p.r1_pack_ohm)
            s, exp_term = _clipped_soc_and_exp(soc)
            volts = _terminal_from_ocv_v(p.cells * _ocv_of_clipped(s, exp_term), v_rc, current, p.r0_pack_ohm)
            energy = p.cells_capacity_ah * _ocv_integral_of_clipped(s, exp_term) * J_PER_WH
            cut = volts < p.cutoff_pack_v or soc <= 0.0
            pack_v_rc_v[row] = v_rc
        else:
            left_j = min(max(soc * p.ideal_capacity_j - net_w * dt_s, 0.0), p.ideal_capacity_j)
            soc = left_j / p.ideal_capacity_j
            current, volts = net_w / p.ideal_pack_v, p.ideal_pack_v
            energy = soc * p.ideal_capacity_j
            cut = soc <= 0.0
        soc_frac[row] = soc
        pack_current_a[row] = current
        pack_voltage_v[row] = volts
        energy_j[row] = energy
        energy_used_j[row] += power * dt_s
        remaining_time_s[row] = energy / max(power_filt_w[row], 1e-9)
        low_battery[row] = soc < p.low_battery_frac
        if cut:
            motors_enabled[row] = False


__all__ = ["ENERGY_PARAMS", "drone_power_w", "energy_params", "energy_step", "fleet_power_w"]
