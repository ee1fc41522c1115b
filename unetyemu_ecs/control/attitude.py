"""Layer 2 (the paper's §2.1.2): vertical speed, pitch/roll and yaw-rate loops, vectorised.

- Altitude: PID on vertical speed with tilt compensation and anti-windup -> collective thrust.
- Pitch/roll: rate-PD, ``u = gain_att_p * (angle_sp - angle) - gain_rate_d * rate`` (angle error
  proportional, measured body rate as the derivative, Mueller & D'Andrea 2014).
- Yaw: proportional on the yaw-rate error.

Outputs are normalised: the collective as a fraction of 4 F_max and the torques as mixer commands
(see ``mixer.py``). Because the same default gains act through each airframe's own F_max, arm and
inertia, a large drone answers more slowly than a small one — the paper's observation.

Every gain argument may be a scalar or an (N,) array (a fleet with mixed gains).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import Annotated

import numpy as np

from ..config.schema import Ge, Gt, Le
from ..frames import euler_rpy_of_quat_xyzw
from ..units import GRAVITY_M_S2
from .compiled import at, float_rows, gain_arg, jit, rows_arg
from .layers import Airframe, AttitudeSetpoint, DroneState, ThrustTorqueCommand

MIN_COS_TILT = float(np.cos(np.deg2rad(60.0)))   # tilt compensation stops growing beyond 60 deg


@dataclass(frozen=True, kw_only=True)
class StabilizerGains:
    """Gains of the built-in attitude controller ``angle_rate_pd`` (``controller: {attitude: {name:
    angle_rate_pd, params: {...}}}``), the same default for every preset.

    Sources: pitch/roll 0.02 per degree and 0.2 are the paper's reference values (its Unity project); the
    vertical-speed PID is ours (in SI, on vertical acceleration), tuned for a 240 Hz loop to hold
    hover within 5 cm without overshooting a climb.
    """

    # Ranges: gains within 1000 (the defaults are 0.05-4; beyond, a 240 Hz loop diverges); clamp within 10 g
    gain_vz_p: Annotated[float, Ge(0.0), Le(1_000.0)] = 4.0          # [1/s] vertical-speed error -> acceleration
    gain_vz_i: Annotated[float, Ge(0.0), Le(1_000.0)] = 2.0          # [1/s^2]
    gain_vz_d: Annotated[float, Ge(0.0), Le(1_000.0)] = 0.05         # [-] on measured vertical acceleration
    lim_vz_int_m_s: Annotated[float, Gt(0.0), Le(100.0)] = 4.0     # integral clamp: covers +/- 0.8 g of extra load
    gain_att_p: Annotated[float, Ge(0.0), Le(1_000.0)] = 1.146       # [1/rad] (the paper's 0.02 per degree)
    gain_rate_d: Annotated[float, Ge(0.0), Le(1_000.0)] = 0.2        # [s/rad]
    gain_yaw_rate_p: Annotated[float, Ge(0.0), Le(1_000.0)] = 1.0    # [s/rad]

    @cached_property
    def kernel_args(self) -> tuple:
        """The gains as the compiled laws take them (:func:`~.compiled.gain_arg`), in the order of the fields:
        worked out once per (frozen) object."""
        return (gain_arg(self.gain_vz_p), gain_arg(self.gain_vz_i), gain_arg(self.gain_vz_d),
                gain_arg(self.lim_vz_int_m_s), gain_arg(self.gain_att_p), gain_arg(self.gain_rate_d),
                gain_arg(self.gain_yaw_rate_p))


def vertical_speed_to_thrust_frac(vz_sp_m_s: np.ndarray, vz_m_s: np.ndarray, acc_z_m_s2: np.ndarray,
                                  vz_int: np.ndarray, hover_thrust_frac: np.ndarray, cos_tilt: np.ndarray,
                                  dt_s: float, gains: StabilizerGains) -> tuple[np.ndarray, np.ndarray]:
    """Return ``(thrust_frac (N,), vz_int_new (N,))``.

    ``a_cmd = kp e + ki int(e) - kd a_z`` with ``e = vz_sp - vz`` [m/s]; ``thrust_frac =
    hover_thrust_frac (1 + a_cmd / g) / max(cos_tilt, cos 60deg)``. ``hover_thrust_frac`` is the
    *unloaded* drone's ``m g / (4 F_max)``: extra load is taken up by the integral, never by
    changing parameters. Anti-windup: the integral is clamped to ``lim_vz_int_m_s`` and frozen
    while the output is saturated in the direction the error pushes. Compiled, drone by drone
    (:func:`vertical_speed_thrust_of`).
    """
    values = (vz_sp_m_s, vz_m_s, acc_z_m_s2, vz_int, hover_thrust_frac, cos_tilt)
    args = rows_arg(*values, n=max(np.size(v) for v in values))
    return _vertical_speed_thrusts(*args, float(dt_s), *_vz_gains(gains))


@jit
def vertical_speed_thrust_of(vz_sp_m_s, vz_m_s, acc_z_m_s2, vz_int, hover_thrust_frac, cos_tilt, dt_s, gain_vz_p,
                             gain_vz_i, gain_vz_d, lim_vz_int_m_s):
    """:func:`vertical_speed_to_thrust_frac` of one drone: ``(thrust_frac, vz_int_new)``."""
    err = vz_sp_m_s - vz_m_s
    tilt = max(cos_tilt, MIN_COS_TILT)

    def output(integral):
        a_cmd = gain_vz_p * err + gain_vz_i * integral - gain_vz_d * acc_z_m_s2
        return hover_thrust_frac * (1.0 + a_cmd / GRAVITY_M_S2) / tilt

    trial = min(max(vz_int + err * dt_s, -lim_vz_int_m_s), lim_vz_int_m_s)
    u = output(trial)
    thrust = min(max(u, 0.0), 1.0)
    if thrust != u and ((u > 1.0 and err > 0.0) or (u < 0.0 and err < 0.0)):   # saturated the way e pushes
        trial = vz_int
        thrust = min(max(output(trial), 0.0), 1.0)
    return thrust, trial


@jit
def _vertical_speed_thrusts(vz_sp_m_s, vz_m_s, acc_z_m_s2, vz_int, hover_thrust_frac, cos_tilt, dt_s, gain_vz_p,
                            gain_vz_i, gain_vz_d, lim_vz_int_m_s):
    n = vz_sp_m_s.shape[0]
    thrust, integral = np.empty(n), np.empty(n)
    for k in range(n):
        thrust[k], integral[k] = vertical_speed_thrust_of(
            vz_sp_m_s[k], vz_m_s[k], acc_z_m_s2[k], vz_int[k], hover_thrust_frac[k], cos_tilt[k], dt_s,
            at(gain_vz_p, k), at(gain_vz_i, k), at(gain_vz_d, k), at(lim_vz_int_m_s, k))
    return thrust, integral


def attitude_to_torque_cmd(roll_sp_rad: np.ndarray, pitch_sp_rad: np.ndarray, yaw_rate_sp_rad_s: np.ndarray,
                           roll_rad: np.ndarray, pitch_rad: np.ndarray, rate_flu_rad_s: np.ndarray,
                           gains: StabilizerGains) -> np.ndarray:
    """Return normalised ``[roll, pitch, yaw]`` torque commands (N, 3), clipped to [-1, 1]:
    ``u_roll = kp (roll_sp - roll) - kd p``, ``u_pitch`` likewise, ``u_yaw = k_yaw (r_sp - r)``.

    rate_flu_rad_s : (N, 3) [rad/s] measured body rates, FLU. Compiled, drone by drone
    (:func:`attitude_torque_cmd_into`).
    """
    rate = np.asarray(rate_flu_rad_s, dtype=float).reshape(-1, 3)
    args = rows_arg(roll_sp_rad, pitch_sp_rad, yaw_rate_sp_rad_s, roll_rad, pitch_rad, n=rate.shape[0])
    return _attitude_torque_cmds(*args, rate, *_attitude_gains(gains))


@jit
def attitude_torque_cmd_into(roll_sp_rad, pitch_sp_rad, yaw_rate_sp_rad_s, roll_rad, pitch_rad, rate_flu_rad_s,
                             gain_att_p, gain_rate_d, gain_yaw_rate_p, torque_cmd):
    """:func:`attitude_to_torque_cmd` of one drone, into ``torque_cmd`` (3,)."""
    u_roll = gain_att_p * (roll_sp_rad - roll_rad) - gain_rate_d * rate_flu_rad_s[0]
    u_pitch = gain_att_p * (pitch_sp_rad - pitch_rad) - gain_rate_d * rate_flu_rad_s[1]
    u_yaw = gain_yaw_rate_p * (yaw_rate_sp_rad_s - rate_flu_rad_s[2])
    torque_cmd[0] = min(max(u_roll, -1.0), 1.0)
    torque_cmd[1] = min(max(u_pitch, -1.0), 1.0)
    torque_cmd[2] = min(max(u_yaw, -1.0), 1.0)


@jit
def _attitude_torque_cmds(roll_sp_rad, pitch_sp_rad, yaw_rate_sp_rad_s, roll_rad, pitch_rad, rate_flu_rad_s,
                          gain_att_p, gain_rate_d, gain_yaw_rate_p):
    u = np.empty((roll_sp_rad.shape[0], 3))
    for k in range(roll_sp_rad.shape[0]):
        attitude_torque_cmd_into(roll_sp_rad[k], pitch_sp_rad[k], yaw_rate_sp_rad_s[k], roll_rad[k], pitch_rad[k],
                                 rate_flu_rad_s[k], at(gain_att_p, k), at(gain_rate_d, k), at(gain_yaw_rate_p, k), u[k])
    return u


def _vz_gains(g: StabilizerGains) -> tuple:
    return g.kernel_args[:4]


def _attitude_gains(g: StabilizerGains) -> tuple:
    return g.kernel_args[4:]


def manual_to_setpoints(stick: np.ndarray, lim_tilt_rad: np.ndarray, lim_climb_m_s: np.ndarray,
                        lim_descent_m_s: np.ndarray, lim_yaw_rate_rad_s: np.ndarray
                        ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Map teleop sticks ``[throttle, pitch, roll, yaw]`` (N, 4) in [-1, 1] to stabilizer setpoints.

    - throttle: vertical speed, +1 climbs at ``lim_climb``, -1 descends at ``lim_descent``, 0 holds;
    - pitch and roll together tilt the thrust axis: +1 pitch = forward = nose down, +1 roll = move
      right = right side down. The (pitch, roll) stick is a vector (clipped to the unit circle) whose
      direction is the direction of the tilt and whose length times ``lim_tilt`` is the *total* tilt,
      as PX4's stabilized mode does, so full pitch and full roll together tilt ``lim_tilt``
      diagonally, not ~60 deg; one stick alone gives its Euler angle ``stick * lim_tilt`` exactly;
    - yaw: +1 = turn left (CCW) at ``lim_yaw_rate``.

    Returns ``(vz_sp_m_s, roll_sp_rad, pitch_sp_rad, yaw_rate_sp_rad_s)``, each (N,). Compiled, drone by
    drone (:func:`manual_setpoints_of`).
    """
    s = float_rows(stick, 4)
    n = s.shape[0]
    out = np.empty((4, n))
    _manual_setpoints(s, *rows_arg(lim_tilt_rad, lim_climb_m_s, lim_descent_m_s, lim_yaw_rate_rad_s, n=n), out)
    return out[0], out[1], out[2], out[3]


@jit
def _stick(x):
    """A stick axis: NaN 0, then clipped to [-1, 1] (numpy's nan_to_num then clip, infinities included)."""
    return 0.0 if np.isnan(x) else min(1.0, max(-1.0, x))


@jit
def manual_setpoints_of(stick, lim_tilt_rad, lim_climb_m_s, lim_descent_m_s, lim_yaw_rate_rad_s):
    """:func:`manual_to_setpoints` of one drone's sticks (4,): ``(vz_sp, roll_sp, pitch_sp, yaw_rate_sp)``."""
    throttle, pitch_stick = _stick(stick[0]), _stick(stick[1])
    roll_stick, yaw_stick = _stick(stick[2]), _stick(stick[3])
    vz_sp = throttle * lim_climb_m_s if throttle >= 0.0 else throttle * lim_descent_m_s
    length = np.hypot(pitch_stick, roll_stick)
    tilt = min(length, 1.0) * lim_tilt_rad                              # total tilt [rad]
    # thrust axis along (tan(tilt) * direction, 1) in the heading frame (forward, right, up)
    k = np.tan(tilt) / max(length, 1e-12)
    pitch = np.arctan(k * pitch_stick)
    roll = np.arctan(k * roll_stick * np.cos(pitch))
    return vz_sp, roll, pitch, yaw_stick * lim_yaw_rate_rad_s


@jit
def _manual_setpoints(stick, lim_tilt_rad, lim_climb_m_s, lim_descent_m_s, lim_yaw_rate_rad_s, out):
    for k in range(stick.shape[0]):
        out[0, k], out[1, k], out[2, k], out[3, k] = manual_setpoints_of(
            stick[k], lim_tilt_rad[k], lim_climb_m_s[k], lim_descent_m_s[k], lim_yaw_rate_rad_s[k])


def angle_rate_pd_law(sp: AttitudeSetpoint, state: DroneState, airframe: Airframe, params: StabilizerGains,
                      memory: dict[str, np.ndarray], dt_s: float) -> tuple[ThrustTorqueCommand, dict[str, np.ndarray]]:
    """The built-in attitude layer ``angle_rate_pd`` (the paper's layer 2): AttitudeSetpoint ->
    ThrustTorqueCommand, by :func:`vertical_speed_to_thrust_frac` (memory ``vz_int_m_s``) and
    :func:`attitude_to_torque_cmd` at the roll and pitch of the drones' attitude (one compiled loop)."""
    thrust, torque, vz_int = _angle_rate_pd(
        *rows_arg(sp.vz_m_s, sp.roll_rad, sp.pitch_rad, sp.yaw_rate_rad_s, n=state.pos_enu_m.shape[0]),
        state.quat_enu_flu_xyzw, state.vel_enu_m_s, state.acc_enu_m_s2, state.rate_flu_rad_s, memory["vz_int_m_s"],
        airframe.hover_thrust_frac, float(dt_s), *params.kernel_args)
    return ThrustTorqueCommand(thrust, torque), {"vz_int_m_s": vz_int}


@jit
def _angle_rate_pd(vz_sp_m_s, roll_sp_rad, pitch_sp_rad, yaw_rate_sp_rad_s, quat_enu_flu_xyzw, vel_enu_m_s,
                   acc_enu_m_s2, rate_flu_rad_s, vz_int, hover_thrust_frac, dt_s, gain_vz_p, gain_vz_i, gain_vz_d,
                   lim_vz_int_m_s, gain_att_p, gain_rate_d, gain_yaw_rate_p):
    n = vz_sp_m_s.shape[0]
    thrust, torque, integral = np.empty(n), np.empty((n, 3)), np.empty(n)
    for k in range(n):
        roll, pitch, _ = euler_rpy_of_quat_xyzw(quat_enu_flu_xyzw[k])
        thrust[k], integral[k] = vertical_speed_thrust_of(
            vz_sp_m_s[k], vel_enu_m_s[k, 2], acc_enu_m_s2[k, 2], vz_int[k], hover_thrust_frac[k],
            np.cos(roll) * np.cos(pitch), dt_s, at(gain_vz_p, k), at(gain_vz_i, k), at(gain_vz_d, k),
            at(lim_vz_int_m_s, k))
        attitude_torque_cmd_into(roll_sp_rad[k], pitch_sp_rad[k], yaw_rate_sp_rad_s[k], roll, pitch, rate_flu_rad_s[k],
                                 at(gain_att_p, k), at(gain_rate_d, k), at(gain_yaw_rate_p, k), torque[k])
    return thrust, torque, integral
