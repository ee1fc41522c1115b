"""STABILIZE phase, layer 2: setpoints -> collective thrust and normalised roll/pitch/yaw torques.

The paper's §2.1.2: vertical-speed PID with tilt compensation and anti-windup, pitch/roll rate-PD
(angle error P, measured body rate D), yaw-rate P. Manual (teleop sticks) and automatic (guidance)
modes both produce the same setpoints (vertical speed, roll, pitch, yaw rate) into the same loops
with the same integrator state, so switching between them causes no jump.
"""

from __future__ import annotations

import esper
import numpy as np

from ..components.body import RigidBody
from ..components.flight import GuidanceLimits, QuadrotorMotors
from ..control.attitude import StabilizerGains, attitude_to_torque_cmd, manual_to_setpoints, vertical_speed_to_thrust_frac
from ..frames import euler_rpy_from_quat_xyzw
from ..phases import Phase
from ..units import GRAVITY_M_S2
from ..world import StepContext
from .flight_state import FlightMode, declare_flight_arrays
from .rows import gather_rows, stack_params


class StabilizerSystem(esper.Processor):
    """Run the layer-2 loops of every armed drone in one pass.

    Phase: STABILIZE. Reads: flight_mode, stick (MANUAL rows), vz_sp_m_s/roll_sp_rad/pitch_sp_rad/
    yaw_rate_sp_rad_s (AUTO rows, from guidance), attitude, body rates, vertical velocity and
    acceleration. Writes: thrust_frac_sp, torque_cmd, vz_int_m_s (and the setpoints of MANUAL rows).
    """

    phase = Phase.STABILIZE
    order = 0

    def __init__(self) -> None:
        self._seen_version = -1
        self._rows = np.empty(0, dtype=np.intp)

    def _gather(self, ctx: StepContext) -> None:
        declare_flight_arrays(ctx.fleet)
        self._rows, gains = gather_rows(StabilizerGains)
        ents = ctx.fleet.entity[self._rows]
        motors = [esper.component_for_entity(int(e), QuadrotorMotors) for e in ents]
        limits = [esper.component_for_entity(int(e), GuidanceLimits) for e in ents]
        mass = np.array([esper.component_for_entity(int(e), RigidBody).mass_kg for e in ents])
        # Nominal hover fraction of the unloaded drone: a payload is left to the integrator.
        self._hover_frac = mass * GRAVITY_M_S2 / (4.0 * np.array([m.max_thrust_per_motor_n for m in motors]))
        self._gains = stack_params(gains, StabilizerGains)
        self._lim_tilt = np.deg2rad([lim.max_tilt_deg for lim in limits])
        self._lim_climb = np.array([lim.lim_climb_m_s for lim in limits])
        self._lim_descent = np.array([lim.lim_descent_m_s for lim in limits])
        self._lim_yaw_rate = np.deg2rad([lim.lim_yaw_rate_deg_s for lim in limits])

    def process(self, ctx: StepContext) -> None:
        f = ctx.fleet
        if f.version != self._seen_version:
            self._gather(ctx)
            self._seen_version = f.version
        r = self._rows
        if r.size == 0:
            return
        mode = f.flight_mode[r]
        manual = mode == FlightMode.MANUAL
        if manual.any():
            rm = r[manual]
            vz_sp, roll_sp, pitch_sp, yaw_rate_sp = manual_to_setpoints(
                f.stick[rm], self._lim_tilt[manual], self._lim_climb[manual], self._lim_descent[manual],
                self._lim_yaw_rate[manual])
            f.vz_sp_m_s[rm] = vz_sp
            f.roll_sp_rad[rm] = roll_sp
            f.pitch_sp_rad[rm] = pitch_sp
            f.yaw_rate_sp_rad_s[rm] = yaw_rate_sp
        roll, pitch, _ = euler_rpy_from_quat_xyzw(f.quat_enu_flu_xyzw[r])
        cos_tilt = np.cos(roll) * np.cos(pitch)
        thrust, vz_int = vertical_speed_to_thrust_frac(
            f.vz_sp_m_s[r], f.vel_enu_m_s[r, 2], f.acc_enu_m_s2[r, 2], f.vz_int_m_s[r], self._hover_frac, cos_tilt,
            ctx.dt_s, self._gains)
        torque = attitude_to_torque_cmd(f.roll_sp_rad[r], f.pitch_sp_rad[r], f.yaw_rate_sp_rad_s[r], roll, pitch,
                                        f.rate_flu_rad_s[r], self._gains)
        armed = mode != FlightMode.DISARMED
        f.thrust_frac_sp[r] = np.where(armed, thrust, 0.0)
        f.torque_cmd[r] = np.where(armed[:, None], torque, 0.0)
        f.vz_int_m_s[r] = np.where(armed, vz_int, 0.0)
