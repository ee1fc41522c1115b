"""The PX4-style attitude plugin (plugins/px4_attitude): its law alone, and in closed loop with the
built-in mixer and a pure-numpy rigid-body model of the project's quadrotor presets (no esper, no
PyBullet). Every loop runs a fixed number of 240 Hz steps, so nothing depends on machine speed.
"""

from __future__ import annotations

import dataclasses
import importlib.util
import sys
import typing

import numpy as np
import pytest
from numpy.testing import assert_allclose

from unetyemu_ecs.control.layers import Airframe, AttitudeSetpoint, DroneState
from unetyemu_ecs.control.mixer import SPIN_REACTION_SIGN, mix_x_quad, motor_positions_flu_m, torque_per_unit_cmd_flu_n_m
from unetyemu_ecs.frames import (R_from_quat_xyzw, euler_rpy_from_quat_xyzw, quat_multiply_xyzw,
                                 quat_xyzw_from_euler_rpy)
from unetyemu_ecs.units import GRAVITY_M_S2

from ..conftest import REPO_ROOT

# the plugin installed (pip install ./plugins/px4_attitude) or, in a fresh environment without it, its source tree
if importlib.util.find_spec("unetyemu_px4_attitude") is None:
    sys.path.insert(0, str(REPO_ROOT / "plugins" / "px4_attitude"))
from unetyemu_px4_attitude import MEMORY, PX4_ATTITUDE, Px4AttitudeParams, px4_attitude_law, torque_per_cmd_flu_n_m  # noqa: E402

DT_S = 1.0 / 240.0

# quadrotor presets (unetyemu_ecs/vehicles/params/quadrotor.toml): mass, F_max, arm, box half extents
PRESETS = {
    "small": dict(mass_kg=5.0, f_max_n=30.0, arm_m=0.24, half_m=(0.17, 0.17, 0.08)),
    "medium": dict(mass_kg=8.0, f_max_n=55.0, arm_m=0.354, half_m=(0.25, 0.25, 0.08)),
    "large": dict(mass_kg=12.0, f_max_n=85.0, arm_m=0.53, half_m=(0.375, 0.375, 0.10)),
}
YAW_MOMENT_COEFF_M = 0.016


def airframe_of(names: list[str]) -> Airframe:
    """Stacked airframes of the named presets (inertia of a uniform box, as PyBullet gives the body)."""
    m = np.array([PRESETS[n]["mass_kg"] for n in names])
    f_max = np.array([PRESETS[n]["f_max_n"] for n in names])
    h2 = np.array([PRESETS[n]["half_m"] for n in names]) ** 2
    inertia = m[:, None] / 3.0 * np.stack([h2[:, 1] + h2[:, 2], h2[:, 0] + h2[:, 2], h2[:, 0] + h2[:, 1]], axis=1)
    n = len(names)
    return Airframe(mass_kg=m, inertia_flu_kg_m2=inertia, max_thrust_per_motor_n=f_max,
                    arm_length_m=np.array([PRESETS[k]["arm_m"] for k in names]),
                    yaw_moment_coeff_m=np.full(n, YAW_MOMENT_COEFF_M), motor_tau_s=np.zeros(n),
                    torque_per_cmd_flu_n_m=torque_per_unit_cmd_flu_n_m(f_max, [PRESETS[k]["arm_m"] for k in names],
                                                                       np.full(n, YAW_MOMENT_COEFF_M)),
                    hover_thrust_frac=m * GRAVITY_M_S2 / (4.0 * f_max), max_tilt_rad=np.full(n, np.deg2rad(35.0)),
                    lim_climb_m_s=np.full(n, 8.0), lim_descent_m_s=np.full(n, 5.0),
                    lim_yaw_rate_rad_s=np.full(n, np.deg2rad(90.0)))


def stack(params: list[Px4AttitudeParams]) -> Px4AttitudeParams:
    """What the framework hands the law: every field an (N,) array."""
    return Px4AttitudeParams(**{f.name: np.array([getattr(p, f.name) for p in params], dtype=float)
                                for f in dataclasses.fields(Px4AttitudeParams)})


def initial_memory(n: int) -> dict[str, np.ndarray]:
    return {name: np.full((n, *tail), init, dtype=float) for name, (tail, init) in MEMORY.items()}


def setpoint(n: int, vz: float = 0.0, roll: float = 0.0, pitch: float = 0.0, yaw_rate: float = 0.0) -> AttitudeSetpoint:
    return AttitudeSetpoint(vz_m_s=np.full(n, vz), roll_rad=np.full(n, roll), pitch_rad=np.full(n, pitch),
                            yaw_rate_rad_s=np.full(n, yaw_rate))


def hover_state(n: int) -> DroneState:
    return DroneState(pos_enu_m=np.zeros((n, 3)), vel_enu_m_s=np.zeros((n, 3)), acc_enu_m_s2=np.zeros((n, 3)),
                      quat_enu_flu_xyzw=np.tile([0.0, 0.0, 0.0, 1.0], (n, 1)), rate_flu_rad_s=np.zeros((n, 3)))


class RigidBodyModel:
    """N free rigid bodies driven through the built-in mixer: attitude, body rates and vertical speed.

    Per step: motor thrusts from ``mix_x_quad`` (optionally with a first-order motor lag), torques
    ``r x F`` plus rotor reaction ``yaw_moment_coeff_m * thrust``, Euler's equations with the
    gyroscopic term, and the vertical force balance. Horizontal motion is left out.
    """

    def __init__(self, airframe: Airframe, motor_tau_s: float = 0.0) -> None:
        self.a = airframe
        n = airframe.mass_kg.size
        self.q = np.tile([0.0, 0.0, 0.0, 1.0], (n, 1))
        self.rate = np.zeros((n, 3))
        self.vz = np.zeros(n)
        self.az = np.zeros(n)
        self.motor_frac = np.tile(airframe.hover_thrust_frac[:, None], (1, 4))
        self.r_flu = motor_positions_flu_m(airframe.arm_length_m)       # (N, 4, 3)
        self.lag = 1.0 if motor_tau_s <= 0.0 else 1.0 - np.exp(-DT_S / motor_tau_s)

    def state(self) -> DroneState:
        n = self.vz.size
        vel = np.zeros((n, 3))
        vel[:, 2] = self.vz
        acc = np.zeros((n, 3))
        acc[:, 2] = self.az
        return DroneState(np.zeros((n, 3)), vel, acc, self.q.copy(), self.rate.copy())

    def step(self, thrust_frac: np.ndarray, torque_cmd: np.ndarray) -> None:
        cmd = mix_x_quad(thrust_frac, torque_cmd)
        self.motor_frac += self.lag * (cmd - self.motor_frac)
        f_n = self.motor_frac * self.a.max_thrust_per_motor_n[:, None]                    # (N, 4)
        forces = np.zeros(self.r_flu.shape)
        forces[:, :, 2] = f_n
        torque = np.cross(self.r_flu, forces).sum(axis=1)
        torque[:, 2] += self.a.yaw_moment_coeff_m * (f_n @ SPIN_REACTION_SIGN)
        inertia = self.a.inertia_flu_kg_m2
        rate_dot = (torque - np.cross(self.rate, inertia * self.rate)) / inertia
        self.rate = self.rate + rate_dot * DT_S
        half = 0.5 * self.rate * DT_S
        angle = np.linalg.norm(half, axis=1, keepdims=True)
        dq = np.concatenate([np.sinc(angle / np.pi) * half, np.cos(angle)], axis=1)
        self.q = quat_multiply_xyzw(self.q, dq)
        self.q /= np.linalg.norm(self.q, axis=1, keepdims=True)
        cos_tilt = R_from_quat_xyzw(self.q)[:, 2, 2]
        self.az = f_n.sum(axis=1) * cos_tilt / self.a.mass_kg - GRAVITY_M_S2
        self.vz = self.vz + self.az * DT_S


def fly(names: list[str], sp: AttitudeSetpoint, seconds: float, params: Px4AttitudeParams | None = None,
        motor_tau_s: float = 0.0) -> tuple[np.ndarray, RigidBodyModel, list[dict[str, np.ndarray]]]:
    """Fly the presets from level hover towards ``sp``; return roll [rad] per step (steps, N), the model
    and the memory after every step."""
    n = len(names)
    model = RigidBodyModel(airframe_of(names), motor_tau_s)
    p = stack([Px4AttitudeParams()] * n) if params is None else params
    memory = initial_memory(n)
    roll, memories = [], []
    for _ in range(int(round(seconds / DT_S))):
        cmd, memory = px4_attitude_law(sp, model.state(), model.a, p, memory, DT_S)
        model.step(cmd.thrust_frac, cmd.torque_cmd)
        roll.append(euler_rpy_from_quat_xyzw(model.q)[0])
        memories.append(memory)
    return np.array(roll), model, memories


def step_figures(y: np.ndarray, target: float) -> tuple[float, float, float]:
    """Rise time 10-90 % [s], overshoot [fraction of the step], 5 % settling time [s] of one response."""
    t = (np.arange(y.size) + 1) * DT_S
    rise = t[np.argmax(y >= 0.9 * target)] - t[np.argmax(y >= 0.1 * target)]
    overshoot = max(0.0, y.max() / target - 1.0)
    outside = np.flatnonzero(np.abs(y - target) > 0.05 * abs(target))
    settle = t[outside[-1] + 1] if outside.size else 0.0
    return rise, overshoot, settle


# -- the plugin as the framework sees it --------------------------------------------------------------------------
def test_plugin_is_an_attitude_controller_for_quadrotors_with_declared_memory():
    # GIVEN the entry point's object
    # THEN it is a ControllerPlugin for the attitude layer of quadrotors, its memory declared per name
    assert PX4_ATTITUDE.layer == "attitude"
    assert PX4_ATTITUDE.applies_to == frozenset({"quadrotor"})
    assert PX4_ATTITUDE.memory["rate_int_cmd"] == ((3,), 0.0)
    assert PX4_ATTITUDE.memory["vz_int_m_s2"] == ((), 0.0)


def test_every_parameter_is_a_float_with_a_range_that_contains_its_default():
    # GIVEN the parameter dataclass (the world-file schema)
    hints = typing.get_type_hints(Px4AttitudeParams, include_extras=True)
    for f in dataclasses.fields(Px4AttitudeParams):
        # THEN each field is an Annotated float with a lower and an upper bound around its default
        assert typing.get_origin(hints[f.name]) is typing.Annotated and hints[f.name].__origin__ is float, f.name
        bounds = {type(m).__name__: m.bound for m in hints[f.name].__metadata__}
        assert set(bounds) == {"Ge", "Le"}, f.name
        assert bounds["Ge"] <= f.default <= bounds["Le"], f.name


def test_torque_of_a_unit_command_matches_the_built_in_mixer():
    # GIVEN each preset at mid collective
    a = airframe_of(["small", "medium", "large"])
    r = motor_positions_flu_m(a.arm_length_m)
    for axis in range(3):
        cmd = np.zeros((3, 3))
        cmd[:, axis] = 0.5     # half a command keeps every motor inside [0, 1]: no desaturation
        # WHEN the mixer turns it into motor thrusts
        f_n = mix_x_quad(np.full(3, 0.5), cmd) * a.max_thrust_per_motor_n[:, None]
        forces = np.zeros(r.shape)
        forces[:, :, 2] = f_n
        torque = np.cross(r, forces).sum(axis=1)
        torque[:, 2] += a.yaw_moment_coeff_m * (f_n @ SPIN_REACTION_SIGN)
        # THEN the torque about that axis is half the law's torque per unit command (to rounding)
        assert_allclose(torque[:, axis], 0.5 * torque_per_cmd_flu_n_m(a)[:, axis], rtol=1e-12)


# -- static behaviour ---------------------------------------------------------------------------------------------
def test_level_hover_with_zero_setpoint_gives_hover_thrust_and_zero_torque():
    # GIVEN the three presets level and at rest, asked to hold
    names = ["small", "medium", "large"]
    a = airframe_of(names)
    # WHEN the law runs one step from its initial memory
    cmd, memory = px4_attitude_law(setpoint(3), hover_state(3), a, stack([Px4AttitudeParams()] * 3),
                                   initial_memory(3), DT_S)
    # THEN the collective is each airframe's hover thrust and no torque is asked for
    assert_allclose(cmd.thrust_frac, a.hover_thrust_frac, atol=1e-12)
    assert_allclose(cmd.torque_cmd, 0.0, atol=1e-12)
    assert_allclose(memory["rate_int_cmd"], 0.0, atol=1e-15)
    assert_allclose(memory["vz_int_m_s2"], 0.0, atol=1e-15)


def test_roll_setpoint_asks_for_positive_roll_torque_and_climb_for_more_thrust():
    # GIVEN a level drone asked for +10 deg roll (right side down) and a 1 m/s climb
    a = airframe_of(["medium"])
    cmd, _ = px4_attitude_law(setpoint(1, vz=1.0, roll=np.deg2rad(10.0)), hover_state(1), a,
                              stack([Px4AttitudeParams()]), initial_memory(1), DT_S)
    # THEN roll torque is positive, pitch and yaw none, and the collective is above hover
    assert cmd.torque_cmd[0, 0] > 0.0
    assert_allclose(cmd.torque_cmd[0, 1:], 0.0, atol=1e-12)
    assert cmd.thrust_frac[0] > a.hover_thrust_frac[0]


def test_roll_and_pitch_setpoints_are_relative_to_the_current_heading():
    # GIVEN the same level drone facing east, north-east, west and south
    yaws = np.array([0.0, 0.8, np.pi, -1.5])
    n = yaws.size
    state = dataclasses.replace(hover_state(n), quat_enu_flu_xyzw=quat_xyzw_from_euler_rpy(0.0, 0.0, yaws))
    # WHEN each is asked for 10 deg roll and 5 deg pitch
    cmd, _ = px4_attitude_law(setpoint(n, roll=np.deg2rad(10.0), pitch=np.deg2rad(5.0)), state,
                              airframe_of(["medium"] * n), stack([Px4AttitudeParams()] * n), initial_memory(n), DT_S)
    # THEN each gets the same body torques (the heading does not enter)
    assert_allclose(cmd.torque_cmd, np.tile(cmd.torque_cmd[0], (n, 1)), atol=1e-12)


# -- closed loop on the presets -----------------------------------------------------------------------------------
@pytest.mark.parametrize("motor_tau_s", [0.0, 0.03])
def test_ten_degree_roll_step_settles_within_five_percent_without_large_overshoot(motor_tau_s):
    # GIVEN the three presets hovering level (ideal motors, and motors with a 30 ms lag)
    names = ["small", "medium", "large"]
    target = np.deg2rad(10.0)
    # WHEN they are asked for 10 deg of roll for 2 s
    roll, _, _ = fly(names, setpoint(3, roll=target), 2.0, motor_tau_s=motor_tau_s)
    for k, name in enumerate(names):
        rise, overshoot, settle = step_figures(roll[:, k], target)
        # THEN each settles within 5 % in well under a second, overshooting by at most 10 %
        assert overshoot <= 0.10, (name, overshoot)
        assert settle <= 0.6, (name, settle)
        assert rise <= 0.3, (name, rise)
        assert abs(roll[-1, k] - target) <= 0.01 * target, name


def test_climb_step_settles_within_five_percent_with_little_overshoot():
    # GIVEN the presets hovering
    names = ["small", "medium", "large"]
    n = len(names)
    model = RigidBodyModel(airframe_of(names))
    params, memory, vz = stack([Px4AttitudeParams()] * n), initial_memory(n), []
    # WHEN asked to climb at 2 m/s for 6 s
    for _ in range(6 * 240):
        cmd, memory = px4_attitude_law(setpoint(n, vz=2.0), model.state(), model.a, params, memory, DT_S)
        model.step(cmd.thrust_frac, cmd.torque_cmd)
        vz.append(model.vz.copy())
    vz = np.array(vz)
    for k, name in enumerate(names):
        _, overshoot, settle = step_figures(vz[:, k], 2.0)
        # THEN each is within 5 % after 1 s, overshoots by at most 6 % and ends within 2 %
        assert overshoot <= 0.06, (name, overshoot)
        assert settle <= 1.0, (name, settle)
    assert_allclose(vz[-1], 2.0, rtol=0.02)


def test_yaw_rate_setpoint_is_tracked():
    # GIVEN the presets hovering
    names = ["small", "medium", "large"]
    rate_sp = np.deg2rad(45.0)
    # WHEN asked to turn at 45 deg/s for 6 s (the large frame has ~1 rad/s^2 of yaw authority)
    _, model, _ = fly(names, setpoint(3, yaw_rate=rate_sp), 6.0)
    # THEN each turns at 45 deg/s within 2 %, staying level
    assert_allclose(model.rate[:, 2], rate_sp, rtol=0.02)
    roll, pitch, _ = euler_rpy_from_quat_xyzw(model.q)
    assert np.all(np.abs(roll) < np.deg2rad(0.5)) and np.all(np.abs(pitch) < np.deg2rad(0.5))


def test_rate_integrator_stays_within_its_limit_while_the_output_saturates():
    # GIVEN the large preset asked for a yaw rate it cannot reach quickly, with a small integrator limit
    a = airframe_of(["large"])
    params = stack([Px4AttitudeParams(rate_int_lim=0.1)])
    memory = initial_memory(1)
    state = hover_state(1)
    sp = setpoint(1, yaw_rate=np.deg2rad(90.0))
    outputs, integrals = [], []
    # WHEN the law runs 5 s against a drone that does not turn (its yaw rate error never shrinks)
    for _ in range(1200):
        cmd, memory = px4_attitude_law(sp, state, a, params, memory, DT_S)
        outputs.append(cmd.torque_cmd[0, 2])
        integrals.append(memory["rate_int_cmd"][0, 2])
    # THEN the yaw command is saturated at 1 and the integrator never leaves +-0.1 nor moves while saturated
    assert_allclose(outputs, 1.0)
    assert np.all(np.abs(integrals) <= 0.1 + 1e-15)
    assert_allclose(integrals, integrals[0])


def test_rate_integrator_is_clamped_at_its_limit_when_the_output_is_not_saturated():
    # GIVEN a roll-rate error too small to saturate the output, held for 2 s (the integrator would
    # reach 0.05 in 0.3 s unclamped)
    a = airframe_of(["small"])
    params = stack([Px4AttitudeParams(rate_int_lim=0.05, rate_p_roll=0.0, rate_i_roll=100.0)])
    memory = initial_memory(1)
    state = dataclasses.replace(hover_state(1), rate_flu_rad_s=np.array([[-0.2, 0.0, 0.0]]))
    for _ in range(480):
        cmd, memory = px4_attitude_law(setpoint(1), state, a, params, memory, DT_S)
    # THEN the integrator sits at its limit and so does the roll command
    assert_allclose(memory["rate_int_cmd"][0, 0], 0.05, atol=1e-15)
    assert_allclose(cmd.torque_cmd[0, 0], 0.05, atol=1e-12)


def test_vertical_integrator_does_not_wind_up_while_thrust_is_saturated():
    # GIVEN a drone asked to climb at 8 m/s that does not move (thrust pinned at 1) for 2 s
    a = airframe_of(["large"])
    memory = initial_memory(1)
    for _ in range(480):
        cmd, memory = px4_attitude_law(setpoint(1, vz=8.0), hover_state(1), a, stack([Px4AttitudeParams()]),
                                       memory, DT_S)
    # THEN thrust is at full and the integrator has not grown
    assert_allclose(cmd.thrust_frac, 1.0)
    assert_allclose(memory["vz_int_m_s2"], 0.0, atol=1e-15)


# -- fleets ---------------------------------------------------------------------------------------------------------
def test_rows_with_mixed_parameters_match_the_same_drones_flown_alone():
    # GIVEN three presets with different gains, flown together and each alone
    names = ["small", "medium", "large"]
    each = [Px4AttitudeParams(roll_p=4.0, rate_p_roll=15.0), Px4AttitudeParams(),
            Px4AttitudeParams(roll_p=8.0, rate_i_roll=40.0, rate_d_roll=0.05, vz_p=3.0)]
    sp = setpoint(3, vz=0.5, roll=np.deg2rad(8.0), yaw_rate=0.3)
    roll_all, model_all, _ = fly(names, sp, 1.0, params=stack(each))
    for k, name in enumerate(names):
        roll_one, model_one, _ = fly([name], setpoint(1, vz=0.5, roll=np.deg2rad(8.0), yaw_rate=0.3), 1.0,
                                     params=stack([each[k]]))
        # THEN each row's trajectory is the lone drone's (to rounding)
        assert_allclose(roll_all[:, k], roll_one[:, 0], atol=1e-12)
        assert_allclose(model_all.vz[k], model_one.vz[0], atol=1e-12)
        assert_allclose(model_all.q[k], model_one.q[0], atol=1e-12)


def test_nan_in_one_rows_state_zeroes_that_row_only_and_keeps_its_memory():
    # GIVEN three drones mid-flight with memory, one of which reports a NaN body rate
    names = ["small", "medium", "large"]
    a = airframe_of(names)
    params = stack([Px4AttitudeParams()] * 3)
    state = dataclasses.replace(hover_state(3), rate_flu_rad_s=np.array([[0.1, -0.2, 0.05]] * 3),
                                quat_enu_flu_xyzw=np.tile(quat_xyzw_from_euler_rpy(0.05, -0.03, 1.0), (3, 1)))
    memory = initial_memory(3)
    memory["rate_int_cmd"][:] = [0.01, -0.02, 0.03]
    memory["vz_int_m_s2"][:] = 0.4
    sp = setpoint(3, vz=0.3, roll=0.1)
    clean, clean_mem = px4_attitude_law(sp, state, a, params, {k: v.copy() for k, v in memory.items()}, DT_S)
    bad_rate = state.rate_flu_rad_s.copy()
    bad_rate[1, 0] = np.nan
    # WHEN the law runs with the NaN in row 1
    cmd, new_mem = px4_attitude_law(sp, dataclasses.replace(state, rate_flu_rad_s=bad_rate), a, params,
                                    {k: v.copy() for k, v in memory.items()}, DT_S)
    # THEN rows 0 and 2 are exactly what they were without it
    for k in (0, 2):
        assert cmd.thrust_frac[k] == clean.thrust_frac[k]
        assert np.array_equal(cmd.torque_cmd[k], clean.torque_cmd[k])
        for name in MEMORY:
            assert np.array_equal(new_mem[name][k], clean_mem[name][k], equal_nan=True)
    # AND row 1 is commanded motors off, with no NaN anywhere, and keeps its memory
    assert cmd.thrust_frac[1] == 0.0 and np.all(cmd.torque_cmd[1] == 0.0)
    assert np.all(np.isfinite(cmd.thrust_frac)) and np.all(np.isfinite(cmd.torque_cmd))
    for name in MEMORY:
        assert np.array_equal(new_mem[name][1], memory[name][1], equal_nan=True)


def test_nan_setpoint_means_not_set_level_hold():
    # GIVEN a hovering drone whose setpoint is all NaN
    a = airframe_of(["small"])
    sp = AttitudeSetpoint(*(np.full(1, np.nan) for _ in range(4)))
    cmd, _ = px4_attitude_law(sp, hover_state(1), a, stack([Px4AttitudeParams()]), initial_memory(1), DT_S)
    # THEN it holds: hover thrust, no torque
    assert_allclose(cmd.thrust_frac, a.hover_thrust_frac, atol=1e-12)
    assert_allclose(cmd.torque_cmd, 0.0, atol=1e-12)


def test_non_positive_step_is_rejected_with_a_clear_error():
    # GIVEN dt = 0  THEN the law names the problem
    with pytest.raises(ValueError, match="dt_s must be > 0"):
        px4_attitude_law(setpoint(1), hover_state(1), airframe_of(["small"]), stack([Px4AttitudeParams()]),
                         initial_memory(1), 0.0)
