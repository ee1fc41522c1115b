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
from typing import Annotated

import numpy as np

from ..config.schema import Ge, Gt, Le
from ..frames import euler_rpy_from_quat_xyzw
from ..units import GRAVITY_M_S2
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


def vertical_speed_to_thrust_frac(vz_sp_m_s: np.ndarray, vz_m_s: np.ndarray, acc_z_m_s2: np.ndarray,
                                  vz_int: np.ndarray, hover_thrust_frac: np.ndarray, cos_tilt: np.ndarray,
                                  dt_s: float, gains: StabilizerGains) -> tuple[np.ndarray, np.ndarray]:
    """Return ``(thrust_frac (N,), vz_int_new (N,))``.

    ``a_cmd = kp e + ki int(e) - kd a_z`` with ``e = vz_sp - vz`` [m/s]; ``thrust_frac =
    hover_thrust_frac (1 + a_cmd / g) / max(cos_tilt, cos 60deg)``. ``hover_thrust_frac`` is the
    *unloaded* drone's ``m g / (4 F_max)``: extra load is taken up by the integral, never by
    changing parameters. Anti-windup: the integral is clamped to ``lim_vz_int_m_s`` and frozen
    while the output is saturated in the direction the error pushes.
    """
    err = vz_sp_m_s - vz_m_s
    tilt = np.maximum(cos_tilt, MIN_COS_TILT)

    def output(integral: np.ndarray) -> np.ndarray:
        a_cmd = gains.gain_vz_p * err + gains.gain_vz_i * integral - gains.gain_vz_d * acc_z_m_s2
        return hover_thrust_frac * (1.0 + a_cmd / GRAVITY_M_S2) / tilt

    trial = np.minimum(np.maximum(vz_int + err * dt_s, -gains.lim_vz_int_m_s), gains.lim_vz_int_m_s)
    u = output(trial)
    thrust = np.minimum(np.maximum(u, 0.0), 1.0)
    if np.count_nonzero(thrust != u):          # some output saturated (or NaN): it may be winding up
        winding = ((u > 1.0) & (err > 0.0)) | ((u < 0.0) & (err < 0.0))
        if np.count_nonzero(winding):
            trial = np.where(winding, vz_int, trial)
            thrust = np.minimum(np.maximum(output(trial), 0.0), 1.0)
    return thrust, trial


def attitude_to_torque_cmd(roll_sp_rad: np.ndarray, pitch_sp_rad: np.ndarray, yaw_rate_sp_rad_s: np.ndarray,
                           roll_rad: np.ndarray, pitch_rad: np.ndarray, rate_flu_rad_s: np.ndarray,
                           gains: StabilizerGains) -> np.ndarray:
    """Return normalised ``[roll, pitch, yaw]`` torque commands (N, 3), clipped to [-1, 1].

    rate_flu_rad_s : (N, 3) [rad/s] measured body rates, FLU
    """
    # written column by column into one (N, 3) array, through its transpose so that a scalar gain and an (N,)
    # gain broadcast alike: u_roll = kp (roll_sp - roll) - kd p, u_pitch likewise, u_yaw = k_yaw (r_sp - r)
    rate_t = rate_flu_rad_s.T
    u = np.empty((rate_t.shape[1], 3))
    u_t = u.T
    np.subtract(roll_sp_rad, roll_rad, out=u_t[0])
    np.subtract(pitch_sp_rad, pitch_rad, out=u_t[1])
    u_rp = u_t[:2]
    np.multiply(gains.gain_att_p, u_rp, out=u_rp)
    np.subtract(u_rp, gains.gain_rate_d * rate_t[:2], out=u_rp)
    u_yaw = u_t[2]
    np.subtract(yaw_rate_sp_rad_s, rate_t[2], out=u_yaw)
    np.multiply(gains.gain_yaw_rate_p, u_yaw, out=u_yaw)
    np.maximum(u, -1.0, out=u)
    return np.minimum(u, 1.0, out=u)


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

    Returns ``(vz_sp_m_s, roll_sp_rad, pitch_sp_rad, yaw_rate_sp_rad_s)``, each (N,).
    """
    s = np.clip(np.nan_to_num(np.asarray(stick, dtype=float).reshape(-1, 4)), -1.0, 1.0)
    vz_sp = np.where(s[:, 0] >= 0.0, s[:, 0] * lim_climb_m_s, s[:, 0] * lim_descent_m_s)
    length = np.hypot(s[:, 1], s[:, 2])
    tilt = np.minimum(length, 1.0) * lim_tilt_rad                        # total tilt [rad]
    # thrust axis along (tan(tilt) * direction, 1) in the heading frame (forward, right, up)
    k = np.tan(tilt) / np.maximum(length, 1e-12)
    pitch = np.arctan(k * s[:, 1])
    roll = np.arctan(k * s[:, 2] * np.cos(pitch))
    return vz_sp, roll, pitch, s[:, 3] * lim_yaw_rate_rad_s


def angle_rate_pd_law(sp: AttitudeSetpoint, state: DroneState, airframe: Airframe, params: StabilizerGains,
                      memory: dict[str, np.ndarray], dt_s: float) -> tuple[ThrustTorqueCommand, dict[str, np.ndarray]]:
    """The built-in attitude layer ``angle_rate_pd`` (the paper's layer 2): AttitudeSetpoint ->
    ThrustTorqueCommand, by :func:`vertical_speed_to_thrust_frac` (memory ``vz_int_m_s``) and
    :func:`attitude_to_torque_cmd`."""
    roll, pitch, _ = euler_rpy_from_quat_xyzw(state.quat_enu_flu_xyzw)
    cos_tilt = np.cos(roll) * np.cos(pitch)
    thrust, vz_int = vertical_speed_to_thrust_frac(sp.vz_m_s, state.vel_enu_m_s[:, 2], state.acc_enu_m_s2[:, 2],
                                                   memory["vz_int_m_s"], airframe.hover_thrust_frac, cos_tilt,
                                                   dt_s, params)
    torque = attitude_to_torque_cmd(sp.roll_rad, sp.pitch_rad, sp.yaw_rate_rad_s, roll, pitch, state.rate_flu_rad_s,
                                    params)
    return ThrustTorqueCommand(thrust, torque), {"vz_int_m_s": vz_int}
