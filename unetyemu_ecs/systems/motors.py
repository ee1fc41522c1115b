"""ACTUATE phase, layer 1: per-motor thrust of every quadrotor, and its resultant on the body.

The paper's §2.1.1: the mixer layer (``controller: {mixer: ...}``, default ``x_quad_priority``:
X configuration, attitude-priority desaturation) has turned the collective thrust and the
normalised roll/pitch/yaw commands into a fraction of F_max per motor; this system adds the
optional first-order motor lag. Each motor's force acts along the body z axis at its motor's
position (roll and pitch torques arise from the lever arms) and yaw comes only from the rotor
reaction torques ``kappa * F_i`` with alternating spin directions; for the rigid body these are
exactly one force at the centre of mass and one torque (:mod:`..control.rotor_wrench`), which is
what goes to PyBullet, added to the body's ``force_cmd_enu_n`` / ``torque_cmd_enu_n_m``.

Ground effect (``motors.ground_effect``, :mod:`..control.ground_effect`, Cheeseman & Bennett 1955): near
a surface below it a rotor produces more thrust for the same command, ``T = k T_OGE`` with
``k = 1 / (1 - (R / 4z)^2 / (1 + (V / v_h)^2))``, ``z`` the height of each motor's hub above the static
scene's highest support under it (ground, road, roof, pad), ``R`` the drone's
:class:`~..components.flight.EnergyModel` ``rotor_radius_m`` (no EnergyModel: no ground effect), ``V``
the air's speed in the rotor plane (the drone's velocity relative to the wind) and ``v_h`` the hover
induced velocity of the motor's lagged thrust. Dynamic bodies (a package carried under the drone,
another drone, a car) are not surfaces. Only upright drones (body z axis pointing up) feel it. The
commands do not change: the controller sees more thrust per command near the ground, as a real one does.
The first-order lag acts on the out-of-ground-effect thrust ``T_OGE = motor_thrust_n / k``, so the lag's
time constant is the motor's, wherever the drone is.
"""

from __future__ import annotations

import esper
import numpy as np

from ..components.flight import EnergyModel, QuadrotorMotors
from ..control.ground_effect import (GROUND_EFFECT_CUTOFF_RADII, SurfaceIndex, ground_effect_factor,
                                     highest_top_near_m, surface_below_m, surface_index_from_shapes)
from ..control.mixer import motor_positions_flu_m
from ..control.rotor_power import hover_induced_velocity_m_s
from ..control.compiled import jit
from ..control.rotor_wrench import add_rotor_wrench_enu, rotor_torque_matrix_flu
from ..fleet import row_selector
from ..phases import Phase
from ..world import StepContext
from .fleet_system import FleetSystem
from .flight_state import MODE_DISARMED


class MotorSystem(FleetSystem):
    """Lag and apply the mixer's motor thrusts for every quadrotor in one pass.

    Phase: ACTUATE (order 20, after the mixer layer and the wind). Reads: fleet.motor_frac_cmd,
    flight_mode, motors_enabled, R_enu_flu, pack_voltage_v (``motors.rated_voltage_v``: the maximum
    thrust follows the pack, ``(V / V_rated)^2``, with the voltage of the previous step); for ground effect also pos_enu_m, vel_enu_m_s, wind_enu_m_s
    and the scene layout. Writes: fleet.motor_thrust_cmd_n, motor_thrust_n (applied, ground effect
    included), ground_effect_factor ((4,) per motor, 1 = none); adds the rotors'
    resultant force and torque to force_cmd_enu_n and torque_cmd_enu_n_m (applied in PHYSICS).
    """

    phase = Phase.ACTUATE
    order = 20
    requires = (QuadrotorMotors,)

    def __init__(self) -> None:
        super().__init__()
        self._surface_layout: object = None
        self._surface: SurfaceIndex | None = None

    def gather(self, ctx: StepContext) -> None:
        (comps,) = self.components
        self._f_max = np.array([c.max_thrust_per_motor_n for c in comps])
        rated = np.array([np.nan if c.rated_voltage_v is None else c.rated_voltage_v for c in comps])
        self._follows_pack = ~np.isnan(rated)                    # max thrust follows the pack voltage
        self._rated_v = np.where(self._follows_pack, rated, 1.0)
        self._kappa = np.array([c.yaw_moment_coeff_m for c in comps])
        tau = np.array([c.motor_tau_s for c in comps], dtype=float)
        self._alpha = np.where(tau > 0.0, 1.0 - np.exp(-ctx.dt_s / np.maximum(tau, 1e-12)), 1.0)   # lag per step
        arms = np.array([c.arm_length_m for c in comps])
        self._torque_matrix = rotor_torque_matrix_flu(motor_positions_flu_m(arms), self._kappa)   # (M, 3, 4)
        self._live = np.zeros(self.rows.size, dtype=bool)       # which drones' motors may turn (set each step)
        self._gather_ground_effect(ctx, comps, arms)

    def _gather_ground_effect(self, ctx: StepContext, comps: list[QuadrotorMotors], arms: np.ndarray) -> None:
        f = ctx.fleet
        energy = [esper.try_component(ent, EnergyModel) for ent in self.entities.tolist()]
        on = np.array([c.ground_effect and e is not None for c, e in zip(comps, energy)], dtype=bool)
        # a drone whose ground effect was just turned off keeps its lag state (the thrust out of ground effect)
        off_rows = self.rows[~on]
        f.motor_thrust_n[off_rows] /= f.ground_effect_factor[off_rows]
        f.ground_effect_factor[off_rows] = 1.0
        self._lag = bool(np.any(self._alpha < 1.0))        # without a lag the previous thrust does not matter
        ge_k = np.flatnonzero(on)                                             # positions in rows
        self._ge = ge_k.size > 0
        if not self._ge:
            return
        ge_energy = [energy[k] for k in ge_k.tolist()]
        self._ge_k = slice(None) if ge_k.size == on.size else ge_k
        self._ge_sel = row_selector(self.rows[ge_k])
        self._ge_dirty = True                                                 # factors may differ from 1
        radius = np.array([e.rotor_radius_m for e in ge_energy])
        self._ge_radius_m = radius
        self._ge_area_m2 = np.pi * radius ** 2
        self._ge_rows = self.rows[ge_k]
        self._ge_rho = np.array([ctx.services.air_density_kg_m3 if e.air_density_kg_m3 is None else e.air_density_kg_m3
                                 for e in ge_energy])
        self._ge_rotor_flu_m = motor_positions_flu_m(arms[ge_k])               # (G, 4, 3)
        layout = ctx.services.layout
        if layout is not self._surface_layout:                                 # the static scene: index it once
            self._surface = surface_index_from_shapes(s for obj in layout.objects for s in obj.shapes)
            self._surface_layout = layout
        top_m = float(np.max(self._surface.shapes[:, 7]))                    # -inf: no supports
        # above this body height no hub (within an arm of the centre) is within the cut-off of any support
        self._ge_gate_z_m = top_m + arms[ge_k] + GROUND_EFFECT_CUTOFF_RADII * radius

    def update(self, ctx: StepContext) -> None:
        f = ctx.fleet
        rows = self.rows
        lag_motor_thrusts(rows, self._f_max, self._follows_pack, self._rated_v, self._alpha, self._ge and self._lag,
                          f.flight_mode, f.motors_enabled, f.pack_voltage_v, f.motor_frac_cmd, f.motor_thrust_cmd_n,
                          f.motor_thrust_n, f.ground_effect_factor, self._live)
        if self._ge:
            factor = self._ground_effect_factor(ctx, self._live, f.motor_thrust_n[self.sel])
            if factor is not None:
                f.ground_effect_factor[self._ge_sel] = factor
                f.motor_thrust_n[self._ge_sel] *= factor
                self._ge_dirty = True
            elif self._ge_dirty:
                f.ground_effect_factor[self._ge_sel] = 1.0
                self._ge_dirty = False
        add_rotor_wrenches(rows, self._torque_matrix, f.motor_thrust_n, f.R_enu_flu, f.force_cmd_enu_n,
                           f.torque_cmd_enu_n_m)

    def _ground_effect_factor(self, ctx: StepContext, live: np.ndarray, thrust_oge_n: np.ndarray) -> np.ndarray | None:
        """(G, 4) factor of the drones with ground effect on (1 for rotors off, upside down or high up);
        None when it is 1 for all of them."""
        f = ctx.fleet
        pos_enu_m = f.pos_enu_m[self._ge_sel]
        low = pos_enu_m[:, 2] < self._ge_gate_z_m
        if not np.count_nonzero(low):
            return None
        R_enu_flu = f.R_enu_flu[self._ge_sel]
        active = np.flatnonzero(low & live[self._ge_k] & (R_enu_flu[:, 2, 2] > 0.0))   # thrust pointing up
        if active.size == 0:
            return None
        R_act = R_enu_flu[active]
        hubs_enu_m = pos_enu_m[active, None, :] + self._ge_rotor_flu_m[active] @ R_act.transpose(0, 2, 1)  # (A, 4, 3)
        # a cheap bound first (the highest support top in each hub's grid cell), then the hubs near a surface
        near = (hubs_enu_m[:, :, 2] - highest_top_near_m(self._surface, hubs_enu_m[:, :, :2])
                < GROUND_EFFECT_CUTOFF_RADII * self._ge_radius_m[active, None])
        a, m = np.nonzero(near)
        if a.size == 0:
            return None
        height_m = hubs_enu_m[a, m, 2] - surface_below_m(self._surface, hubs_enu_m[a, m])
        g = active[a]                                                         # positions among the G drones
        rows = self._ge_rows[g]
        air_flu_m_s = ((f.vel_enu_m_s[rows] - f.wind_enu_m_s[rows])[:, None, :] @ R_act[a])[:, 0, :]   # R^T v
        v_h_m_s = hover_induced_velocity_m_s(thrust_oge_n[self._ge_k][g, m], self._ge_rho[g], self._ge_area_m2[g])
        factor = np.ones((len(self._ge_radius_m), 4))
        factor[g, m] = ground_effect_factor(height_m, self._ge_radius_m[g],
                                            np.hypot(air_flu_m_s[:, 0], air_flu_m_s[:, 1]), v_h_m_s)
        return factor


@jit
def lag_motor_thrusts(rows, f_max_n, follows_pack, rated_v, alpha, out_of_ground_effect, flight_mode, motors_enabled,
                      pack_voltage_v, motor_frac_cmd, motor_thrust_cmd_n, motor_thrust_n, ground_effect_factor, live):
    """The commanded thrust of each motor of the drones in fleet ``rows`` (the mixer's fraction of F_max, F_max
    times ``(V / V_rated)^2`` where ``follows_pack`` and the pack reports a voltage) into ``motor_thrust_cmd_n``,
    and ``motor_thrust_n`` moved towards it by the first-order lag's ``alpha`` per step, from the thrust out of
    ground effect when ``out_of_ground_effect`` (the caller applies this step's factor). A disarmed drone, or
    one whose motors are disabled, gets zero at once; ``live`` (M,) says which are neither."""
    for k in range(rows.shape[0]):
        r = rows[k]
        on = flight_mode[r] != MODE_DISARMED and motors_enabled[r]
        live[k] = on
        f_max = f_max_n[k]
        volts = pack_voltage_v[r]
        if follows_pack[k] and volts > 0.0:
            f_max = f_max * (volts / rated_v[k]) ** 2
        scale = f_max if on else 0.0
        for j in range(4):
            cmd = motor_frac_cmd[r, j] * scale
            motor_thrust_cmd_n[r, j] = cmd
            lagged = motor_thrust_n[r, j]
            if out_of_ground_effect:
                lagged = lagged / ground_effect_factor[r, j]
            motor_thrust_n[r, j] = lagged + alpha[k] * (cmd - lagged) if on else 0.0


@jit
def add_rotor_wrenches(rows, torque_matrix_flu, motor_thrust_n, R_enu_flu, force_cmd_enu_n, torque_cmd_enu_n_m):
    """Add the rotors' resultant force and torque of the drones in fleet ``rows`` to the commanded ones
    (:func:`..control.rotor_wrench.add_rotor_wrench_enu`; ``torque_matrix_flu`` (M, 3, 4) in row order)."""
    for k in range(rows.shape[0]):
        r = rows[k]
        add_rotor_wrench_enu(motor_thrust_n[r], R_enu_flu[r], torque_matrix_flu[k], force_cmd_enu_n[r],
                             torque_cmd_enu_n_m[r])
