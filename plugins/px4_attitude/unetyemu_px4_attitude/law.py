"""PX4-style attitude layer: tilt-prioritised quaternion attitude P, body-rate PID, vertical-speed PI(D).

One pure law over N drones, modelled on three PX4 (PX4/PX4-Autopilot, v1.14) classes:

- ``src/modules/mc_att_control/AttitudeControl/AttitudeControl.cpp`` -- quaternion attitude
  control after Brescianini, Hehn & D'Andrea, "Nonlinear Quadrocopter Attitude Control" (ETH
  Zurich, 2013): the shortest rotation that brings the current thrust axis onto the desired one
  (the *reduced* attitude) is corrected in full, the remaining rotation about the thrust axis only
  by ``yaw_weight``; the error quaternion's vector part times the P gains gives the body-rate
  setpoint, the yaw-rate setpoint is fed forward, every axis is limited.
- ``src/lib/rate_control/rate_control.cpp`` -- body-rate PID with the D term on the measured
  angular acceleration (no derivative kick on setpoint steps), an integrator limit, the
  "I-term factor" that integrates less for large rate errors, and no integration towards a
  saturated output.
- ``src/modules/mc_pos_control/PositionControl/PositionControl.cpp`` -- the vertical part of
  ``_velocityControl`` / ``_accelerationControl``: PID on vertical speed -> vertical acceleration
  -> collective ``hover_thrust (1 + a / g)`` projected onto the body axis, integrator limited and
  frozen while the thrust is saturated in the direction the error pushes.

Differences from PX4, all because our inputs differ:

- The setpoint gives roll, pitch and a yaw *rate* (``AttitudeSetpoint``), so the desired attitude
  takes the drone's *current* yaw and the yaw rate is fed forward about the body z axis (PX4 feeds
  its Euler yaw rate forward about the world z axis).
- Gains act in angular acceleration, not in PX4's normalised torque, so one set of defaults flies
  every airframe: ``torque_cmd = I * alpha / tau_1`` where ``tau_1`` is the torque a command of 1
  produces with the built-in mixer (``unetyemu_ecs/control/mixer.py``, motor order FL, FR, BR, BL
  at ``arm / sqrt 2`` from each body axis, ``MIX_X`` = 1/2 x the paper's eq. 2):

  * roll: a command ``u`` adds ``+u/2 F_max`` on FL, BL (y = +arm/sqrt 2) and ``-u/2 F_max`` on FR,
    BR, so ``tau_x = 4 (u/2) F_max arm / sqrt 2 = sqrt 2 F_max arm u``: at mid collective, u = 1
    drives the left motors to F_max and the right ones to 0. Pitch is the same about y.
  * yaw: ``+-u/2 F_max`` on each motor with the sign of its reaction torque (``SPIN_REACTION_SIGN``),
    each reacting ``yaw_moment_coeff_m x thrust``, so ``tau_z = 2 yaw_moment_coeff_m F_max u``.

  Rate integrators are kept in that normalised torque, so ``rate_int_lim`` means what PX4's
  ``MC_RR_INT_LIM`` means (a fraction of full torque).
- The mixer's saturation is not reported back to the attitude layer, so the rate integrator
  stops on this law's own output limit of +-1 only (PX4 also stops on the allocator's flags).
- A row whose state has a NaN (or a zero quaternion) gets thrust 0 and torque 0 -- what the
  built-in mixer does with a NaN command -- and keeps its memory unchanged, as PX4's
  ``updateIntegral`` does not propagate invalid values; other rows are unaffected. NaN in a
  setpoint means "not set": level attitude, zero vertical speed, zero yaw rate.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated

import numpy as np

try:
    from unetyemu_ecs.plugin_api import (GRAVITY_M_S2, Airframe, AttitudeSetpoint, DroneState, Ge, Le,
                                         R_from_quat_xyzw, ThrustTorqueCommand, quat_conjugate_xyzw,
                                         quat_multiply_xyzw, quat_xyzw_from_euler_rpy)
except ImportError as exc:  # pragma: no cover - depends on the environment
    raise ImportError("unetyemu-px4-attitude is a plugin of the unetyemu_ecs simulator: install it into the "
                      "environment that has unetyemu_ecs (.venv/bin/pip install ./plugins/px4_attitude from the "
                      f"simulator's repository) ({exc})") from exc

I_FACTOR_RATE_RAD_S = float(np.deg2rad(400.0))   # PX4 rate_control.cpp: I gain fades out for larger rate errors


@dataclass(frozen=True, kw_only=True)
class Px4AttitudeParams:
    """Gains and limits of the PX4-style attitude layer (``controller: {attitude: {name: px4_attitude,
    params: {...}}}``); PX4's parameter name in brackets where there is one.

    Rate-loop gains are in angular acceleration (rad/s^2 per rad/s, per rad, per rad/s^2), not in
    PX4's normalised torque, so the defaults fit every preset (the law scales by each airframe's
    inertia and torque authority). Defaults: attitude loop, yaw weight, rate limits, integrator
    limits and tilt compensation are PX4 v1.14's defaults; the rate PID and the vertical-speed gains
    are ours, tuned on the small/medium/large quadrotor presets at 240 Hz (the package README gives
    the step responses).
    """

    # attitude loop: rate setpoint per rad of attitude error [1/s]; above ~30 a 240 Hz loop with the
    # rate loop below stops being damped, 0 disables the axis
    roll_p: Annotated[float, Ge(0.0), Le(30.0)] = 6.5               # [MC_ROLL_P]
    pitch_p: Annotated[float, Ge(0.0), Le(30.0)] = 6.5              # [MC_PITCH_P]
    yaw_p: Annotated[float, Ge(0.0), Le(30.0)] = 2.8                # [MC_YAW_P]
    yaw_weight: Annotated[float, Ge(0.0), Le(1.0)] = 0.4            # [MC_YAW_WEIGHT] share of the yaw error corrected
    # body-rate limits [deg/s]; 1800 deg/s (5 rev/s) is beyond any multicopter's flips
    max_rate_roll_pitch_deg_s: Annotated[float, Ge(1.0), Le(1800.0)] = 220.0   # [MC_ROLLRATE_MAX, MC_PITCHRATE_MAX]
    max_rate_yaw_deg_s: Annotated[float, Ge(1.0), Le(1800.0)] = 200.0          # [MC_YAWRATE_MAX]
    # rate PID -> angular acceleration: P [1/s], I [1/s^2], D [-] (on measured angular acceleration);
    # P beyond 120 1/s (the 240 Hz loop's Nyquist rate in rad/s x 0.16) oscillates at the loop rate
    rate_p_roll: Annotated[float, Ge(0.0), Le(120.0)] = 20.0
    rate_p_pitch: Annotated[float, Ge(0.0), Le(120.0)] = 20.0
    rate_p_yaw: Annotated[float, Ge(0.0), Le(120.0)] = 10.0
    rate_i_roll: Annotated[float, Ge(0.0), Le(1000.0)] = 20.0
    rate_i_pitch: Annotated[float, Ge(0.0), Le(1000.0)] = 20.0
    rate_i_yaw: Annotated[float, Ge(0.0), Le(1000.0)] = 5.0
    rate_d_roll: Annotated[float, Ge(0.0), Le(1.0)] = 0.0
    rate_d_pitch: Annotated[float, Ge(0.0), Le(1.0)] = 0.0
    rate_d_yaw: Annotated[float, Ge(0.0), Le(1.0)] = 0.0
    # rate integrator limit as a fraction of full torque command [-]
    rate_int_lim: Annotated[float, Ge(0.0), Le(1.0)] = 0.3           # [MC_RR_INT_LIM, MC_PR_INT_LIM, MC_YR_INT_LIM]
    # low-pass on the measured angular acceleration that feeds the D term [Hz]
    rate_d_cutoff_hz: Annotated[float, Ge(1.0), Le(1000.0)] = 30.0  # [IMU_DGYRO_CUTOFF]
    # vertical speed PID -> vertical acceleration: P [1/s], I [1/s^2], D [-] (on measured acceleration).
    # PX4's 4 / 2 overshoot a climb step by 8 % and take 2.4 s to settle within 5 % on every preset
    # (the integrator's zero at -I/P sits on the slow closed-loop pole); 5 / 1.5 gives 5 % and 0.5 s
    vz_p: Annotated[float, Ge(0.0), Le(100.0)] = 5.0                # [MPC_Z_VEL_P_ACC, default 4]
    vz_i: Annotated[float, Ge(0.0), Le(100.0)] = 1.5                # [MPC_Z_VEL_I_ACC, default 2]
    vz_d: Annotated[float, Ge(0.0), Le(1.0)] = 0.0                  # [MPC_Z_VEL_D_ACC]
    # vertical integrator limit [m/s^2]: PX4 holds it within 1 g; 2 g covers any payload a preset lifts
    vz_int_lim_m_s2: Annotated[float, Ge(0.0), Le(20.0)] = 9.81
    # tilt compensation 1 / cos(tilt) stops growing beyond this tilt [deg] (60 deg: at most x 2)
    max_tilt_comp_deg: Annotated[float, Ge(0.0), Le(80.0)] = 60.0


MEMORY = {
    "rate_int_cmd": ((3,), 0.0),          # rate integrators, FLU, in normalised torque command [-]
    "vz_int_m_s2": ((), 0.0),             # vertical-speed integrator [m/s^2]
    "rate_prev_flu_rad_s": ((3,), np.nan),   # last step's measured body rate; NaN = none yet (no D kick)
    "ang_acc_flu_rad_s2": ((3,), 0.0),    # low-passed measured angular acceleration (D term input)
}


def torque_per_cmd_flu_n_m(airframe: Airframe) -> np.ndarray:
    """Return the torque (N, 3) [N m] about FLU x, y, z that a torque command of 1 produces.

    The layer's convention, given by the simulator in the airframe: ``sqrt 2 F_max arm`` for roll
    and pitch, ``2 yaw_moment_coeff_m F_max`` for yaw (derivation in the module docstring).
    """
    return np.asarray(airframe.torque_per_cmd_flu_n_m, dtype=float).reshape(-1, 3)


def _finite_or(x: np.ndarray, fill: float) -> np.ndarray:
    x = np.asarray(x, dtype=float)
    return np.where(np.isfinite(x), x, fill)


def px4_attitude_law(sp: AttitudeSetpoint, state: DroneState, airframe: Airframe, params: Px4AttitudeParams,
                     memory: dict[str, np.ndarray], dt_s: float) -> tuple[ThrustTorqueCommand, dict[str, np.ndarray]]:
    """Return the thrust/torque command of N drones and their new memory.

    Parameters
    ----------
    sp : roll/pitch setpoints [rad], yaw-rate setpoint [rad/s] about body z, vertical speed [m/s], each (N,)
    state : measured state; uses ``quat_enu_flu_xyzw`` (N, 4), ``rate_flu_rad_s`` (N, 3),
        ``vel_enu_m_s[:, 2]`` and ``acc_enu_m_s2[:, 2]``
    airframe : inertia, F_max, arm, yaw moment coefficient, hover thrust fraction, each (N,) / (N, 3)
    params : :class:`Px4AttitudeParams` with every field an (N,) array
    memory : ``MEMORY``'s names -> (N, ...) arrays
    dt_s : step [s], > 0

    Returns
    -------
    ThrustTorqueCommand with ``thrust_frac`` (N,) in [0, 1] and ``torque_cmd`` (N, 3) in [-1, 1];
    the new memory (same names and shapes).
    """
    if not dt_s > 0.0:
        raise ValueError(f"px4_attitude: dt_s must be > 0, got {dt_s!r}")
    p = params
    q_raw = np.asarray(state.quat_enu_flu_xyzw, dtype=float).reshape(-1, 4)
    rate_raw = np.asarray(state.rate_flu_rad_s, dtype=float).reshape(-1, 3)
    vz_raw = np.asarray(state.vel_enu_m_s, dtype=float).reshape(-1, 3)[:, 2]
    az_raw = np.asarray(state.acc_enu_m_s2, dtype=float).reshape(-1, 3)[:, 2]
    q_norm = np.linalg.norm(np.nan_to_num(q_raw), axis=1)
    valid = (np.all(np.isfinite(q_raw), axis=1) & (q_norm > 1e-9) & np.all(np.isfinite(rate_raw), axis=1)
             & np.isfinite(vz_raw) & np.isfinite(az_raw))
    # invalid rows compute on benign stand-ins (no NaN warnings) and are masked at the end
    q = np.where(valid[:, None], q_raw, [0.0, 0.0, 0.0, 1.0])
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    rate = np.where(valid[:, None], rate_raw, 0.0)
    vz = np.where(valid, vz_raw, 0.0)
    az = np.where(valid, az_raw, 0.0)

    roll_sp = _finite_or(sp.roll_rad, 0.0)
    pitch_sp = _finite_or(sp.pitch_rad, 0.0)
    yaw_rate_sp = _finite_or(sp.yaw_rate_rad_s, 0.0)
    vz_sp = _finite_or(sp.vz_m_s, 0.0)

    # -- attitude: tilt-prioritised quaternion P (AttitudeControl::update) ----------------------
    R_enu_flu = R_from_quat_xyzw(q)
    yaw = np.arctan2(R_enu_flu[:, 1, 0], R_enu_flu[:, 0, 0])
    q_sp = quat_xyzw_from_euler_rpy(roll_sp, pitch_sp, yaw)
    e_z = R_enu_flu[:, :, 2]
    e_z_sp = R_from_quat_xyzw(q_sp)[:, :, 2]
    # shortest rotation (world frame) taking the thrust axis e_z onto e_z_sp: xyzw = (e_z x e_z_sp, 1 + e_z . e_z_sp)
    q_tilt = np.concatenate([np.cross(e_z, e_z_sp), 1.0 + np.sum(e_z * e_z_sp, axis=1, keepdims=True)], axis=1)
    tilt_norm = np.linalg.norm(q_tilt, axis=1, keepdims=True)
    opposite = tilt_norm[:, 0] < 1e-6     # thrust axes opposite: no unique shortest rotation, use the full setpoint
    q_tilt = q_tilt / np.where(opposite[:, None], 1.0, tilt_norm)
    q_red = np.where(opposite[:, None], q_sp, quat_multiply_xyzw(q_tilt, q))
    # what is left of the setpoint after the reduced attitude is a rotation about the thrust axis
    q_dyaw = quat_multiply_xyzw(quat_conjugate_xyzw(q_red), q_sp)
    q_dyaw = np.where(q_dyaw[:, 3:4] < 0.0, -q_dyaw, q_dyaw)
    half_yaw = p.yaw_weight * np.arctan2(q_dyaw[:, 2], q_dyaw[:, 3])   # half of the weighted angle
    q_yaw_w = np.stack([np.zeros_like(half_yaw), np.zeros_like(half_yaw), np.sin(half_yaw), np.cos(half_yaw)], axis=1)
    q_err = quat_multiply_xyzw(quat_conjugate_xyzw(q), quat_multiply_xyzw(q_red, q_yaw_w))
    q_err = np.where(q_err[:, 3:4] < 0.0, -q_err, q_err)
    err_att_flu = 2.0 * q_err[:, :3]      # sin(angle/2)-scaled axis, FLU [rad]
    # PX4 divides the yaw gain by the yaw weight so that yaw_p sets the yaw response
    yaw_p = np.where(p.yaw_weight > 1e-4, p.yaw_p / np.maximum(p.yaw_weight, 1e-4), p.yaw_p)
    gain_att = np.stack(np.broadcast_arrays(p.roll_p, p.pitch_p, yaw_p), axis=1)
    rate_sp = err_att_flu * gain_att
    rate_sp[:, 2] += yaw_rate_sp
    lim_rate = np.deg2rad(np.stack(np.broadcast_arrays(p.max_rate_roll_pitch_deg_s, p.max_rate_roll_pitch_deg_s,
                                                       p.max_rate_yaw_deg_s), axis=1))
    rate_sp = np.clip(rate_sp, -lim_rate, lim_rate)

    # -- body rates: PID in angular acceleration, integrator in torque command (RateControl) -----
    rate_prev = np.asarray(memory["rate_prev_flu_rad_s"], dtype=float).reshape(-1, 3)
    acc_filt = np.asarray(memory["ang_acc_flu_rad_s2"], dtype=float).reshape(-1, 3)
    rate_int = np.asarray(memory["rate_int_cmd"], dtype=float).reshape(-1, 3)
    has_prev = np.all(np.isfinite(rate_prev), axis=1)
    raw_acc = np.where(has_prev[:, None], (rate - np.where(has_prev[:, None], rate_prev, 0.0)) / dt_s, acc_filt)
    rc_s = 1.0 / (2.0 * np.pi * np.asarray(p.rate_d_cutoff_hz, dtype=float))
    a_lp = (dt_s / (dt_s + rc_s)).reshape(-1, 1)
    acc_filt_new = acc_filt + a_lp * (raw_acc - acc_filt)

    inertia = np.asarray(airframe.inertia_flu_kg_m2, dtype=float).reshape(-1, 3)
    tau_1 = torque_per_cmd_flu_n_m(airframe)
    # command per rad/s^2; an axis with no authority (e.g. yaw_moment_coeff_m = 0) gets no command
    cmd_per_acc = np.divide(inertia, tau_1, out=np.zeros_like(inertia), where=tau_1 > 0.0)
    kp = np.stack(np.broadcast_arrays(p.rate_p_roll, p.rate_p_pitch, p.rate_p_yaw), axis=1)
    ki = np.stack(np.broadcast_arrays(p.rate_i_roll, p.rate_i_pitch, p.rate_i_yaw), axis=1)
    kd = np.stack(np.broadcast_arrays(p.rate_d_roll, p.rate_d_pitch, p.rate_d_yaw), axis=1)
    rate_err = rate_sp - rate
    torque_raw = cmd_per_acc * (kp * rate_err - kd * acc_filt_new) + rate_int
    # anti-windup: never integrate towards an output that is already past its limit
    winding = ((torque_raw > 1.0) & (rate_err > 0.0)) | ((torque_raw < -1.0) & (rate_err < 0.0))
    i_factor = np.maximum(0.0, 1.0 - (rate_err / I_FACTOR_RATE_RAD_S) ** 2)
    lim_int = np.asarray(p.rate_int_lim, dtype=float).reshape(-1, 1)
    rate_int_new = np.where(winding, rate_int,
                            np.clip(rate_int + i_factor * ki * cmd_per_acc * rate_err * dt_s, -lim_int, lim_int))
    torque_cmd = np.clip(torque_raw, -1.0, 1.0)

    # -- vertical speed: PID -> acceleration -> collective (PositionControl) ---------------------
    vz_int = np.asarray(memory["vz_int_m_s2"], dtype=float).reshape(-1)
    vz_err = vz_sp - vz
    acc_sp_z = p.vz_p * vz_err + vz_int - p.vz_d * az
    cos_tilt = np.maximum(R_enu_flu[:, 2, 2], np.cos(np.deg2rad(p.max_tilt_comp_deg)))
    hover = np.asarray(airframe.hover_thrust_frac, dtype=float).reshape(-1)
    thrust_raw = hover * (1.0 + acc_sp_z / GRAVITY_M_S2) / cos_tilt
    saturated = ((thrust_raw >= 1.0) & (vz_err >= 0.0)) | ((thrust_raw <= 0.0) & (vz_err <= 0.0))
    vz_int_new = np.where(saturated, vz_int,
                          np.clip(vz_int + p.vz_i * vz_err * dt_s, -p.vz_int_lim_m_s2, p.vz_int_lim_m_s2))
    thrust_frac = np.clip(thrust_raw, 0.0, 1.0)

    # -- rows with an invalid state: motors off, memory untouched --------------------------------
    ok = valid[:, None]
    new_memory = {
        "rate_int_cmd": np.where(ok, rate_int_new, rate_int),
        "vz_int_m_s2": np.where(valid, vz_int_new, vz_int),
        "rate_prev_flu_rad_s": np.where(ok, rate, rate_prev),
        "ang_acc_flu_rad_s2": np.where(ok, acc_filt_new, acc_filt),
    }
    command = ThrustTorqueCommand(thrust_frac=np.where(valid, thrust_frac, 0.0),
                                  torque_cmd=np.where(ok, torque_cmd, 0.0))
    return command, new_memory


__all__ = ["MEMORY", "Px4AttitudeParams", "px4_attitude_law", "torque_per_cmd_flu_n_m"]
