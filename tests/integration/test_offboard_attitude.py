"""OFFBOARD attitude + thrust (PX4's SET_ATTITUDE_TARGET) flown in PyBullet: the commanded collective
thrust and tilt are what the physics does with them — Newton's second law, no altitude hold."""

from __future__ import annotations

import math

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mavlink2

from unetyemu_ecs import Simulation, load_world_text
from unetyemu_ecs.components.body import RigidBody
from unetyemu_ecs.components.flight import QuadrotorMotors
from unetyemu_ecs.frames import quat_xyzw_from_euler_rpy, quat_xyzw_to_wxyz
from unetyemu_ecs.transport.api import CommandStatus
from unetyemu_ecs.units import GRAVITY_M_S2

from .mavlink_client import Client, free_ports, wait_for, world_text
from .test_navigation import fly_up, heading, make_sim, result_after, run_until

MAIN_OFFBOARD = 6


def hover_thrust(sim: Simulation, name: str = "d1") -> float:
    """Collective thrust that carries the drone's weight: m g / (4 F_max)."""
    mass = sim.component(name, RigidBody).mass_kg
    return mass * GRAVITY_M_S2 / (4.0 * sim.component(name, QuadrotorMotors).max_thrust_per_motor_n)


def stream(sim: Simulation, seconds: float, **setpoint) -> None:
    """The same attitude setpoint at 20 Hz for ``seconds`` of sim time."""
    for _ in range(round(seconds / 0.05)):
        sim.offboard_attitude("d1", **setpoint)
        sim.run(duration=0.05)


def acceleration_enu(sim: Simulation, seconds: float, settle_s: float = 0.0, **setpoint) -> np.ndarray:
    """Mean acceleration [m/s^2, ENU] over ``seconds`` of streaming ``setpoint``, after ``settle_s`` of
    streaming it for the attitude loop to get there."""
    stream(sim, settle_s, **setpoint)
    v0, t0 = sim.velocity_enu_m_s("d1").copy(), sim.sim_time_s
    stream(sim, seconds, **setpoint)
    return (sim.velocity_enu_m_s("d1") - v0) / (sim.sim_time_s - t0)


def enter_offboard_attitude(sim: Simulation, thrust: float, **setpoint) -> None:
    """From HOLD, brake to a standstill, then switch to OFFBOARD with an attitude stream running."""
    sim.hold("d1")
    run_until(sim, lambda: np.linalg.norm(sim.velocity_enu_m_s("d1")) < 0.02, 20.0)
    sim.offboard_attitude("d1", 0.0, 0.0, thrust, **setpoint)
    sim.step()
    assert result_after(sim, sim.set_nav_mode("d1", "OFFBOARD")).status == CommandStatus.ACCEPTED
    stream(sim, 0.3, roll_deg=0.0, pitch_deg=0.0, thrust=thrust, **setpoint)       # motors settle (lag)


def test_hover_thrust_holds_a_level_drone_and_25_percent_more_climbs_at_a_quarter_g():
    # GIVEN a drone hovering 10 m up, switched to OFFBOARD attitude at its hover thrust m g / (4 F_max)
    sim = make_sim()
    fly_up(sim, 10.0)
    hover = hover_thrust(sim)
    enter_offboard_attitude(sim, hover)
    assert sim.nav_state("d1") == "OFFBOARD"
    # THEN level at hover thrust it neither climbs nor sinks (weight = thrust) ...
    assert acceleration_enu(sim, 2.0, roll_deg=0.0, pitch_deg=0.0, thrust=hover) == pytest.approx(
        (0.0, 0.0, 0.0), abs=0.05)
    # ... AND 1.25 x hover thrust accelerates it upwards at (T - m g) / m = 0.25 g
    a = acceleration_enu(sim, 1.0, roll_deg=0.0, pitch_deg=0.0, thrust=1.25 * hover)
    assert a[2] == pytest.approx(0.25 * GRAVITY_M_S2, rel=0.1)
    assert np.hypot(a[0], a[1]) < 0.05


def test_a_10_degree_nose_down_tilt_accelerates_forward_at_g_tan_10_degrees_and_the_heading_is_held():
    # GIVEN a drone hovering 10 m up facing north, in OFFBOARD attitude
    sim = make_sim()
    fly_up(sim, 10.0)
    hover = hover_thrust(sim)
    sim.set_target("d1", *sim.position_enu_m("d1"), yaw_deg=90.0)
    run_until(sim, lambda: abs(heading(sim) - math.pi / 2) < 0.02, 20.0)
    enter_offboard_attitude(sim, hover, yaw_deg=90.0)
    # WHEN it pitches 10 deg nose down with the thrust whose vertical part carries its weight
    a = acceleration_enu(sim, 1.0, 0.5, roll_deg=0.0, pitch_deg=10.0, thrust=hover / math.cos(math.radians(10.0)),
                         yaw_deg=90.0)
    # THEN it accelerates north (its nose) at g tan 10 deg = 1.73 m/s^2 at constant height
    assert a[1] == pytest.approx(GRAVITY_M_S2 * math.tan(math.radians(10.0)), rel=0.1)
    assert abs(a[0]) < 0.1 and abs(a[2]) < 0.15
    # AND a 10 deg roll to the right (right side down) accelerates it east, its right
    stream(sim, 1.0, roll_deg=0.0, pitch_deg=-10.0, thrust=hover / math.cos(math.radians(10.0)), yaw_deg=90.0)
    a = acceleration_enu(sim, 1.0, 0.5, roll_deg=10.0, pitch_deg=0.0, thrust=hover / math.cos(math.radians(10.0)),
                         yaw_deg=90.0)
    assert a[0] == pytest.approx(GRAVITY_M_S2 * math.tan(math.radians(10.0)), rel=0.15)
    assert abs(heading(sim) - math.pi / 2) < 0.05


def test_a_heading_and_a_yaw_rate_turn_the_drone_and_a_lapsed_stream_falls_back_to_hold():
    sim = make_sim()
    fly_up(sim, 10.0)
    hover = hover_thrust(sim)
    enter_offboard_attitude(sim, hover)
    # WHEN the attitude setpoint asks for heading 120 deg, then a yaw rate of 0.5 rad/s
    stream(sim, 4.0, roll_deg=0.0, pitch_deg=0.0, thrust=hover, yaw_deg=120.0)
    assert heading(sim) == pytest.approx(math.radians(120.0), abs=0.05)
    yaw0 = heading(sim)
    stream(sim, 2.0, roll_deg=0.0, pitch_deg=0.0, thrust=hover, yaw_rate_rad_s=0.5)
    turned = (heading(sim) - yaw0 + math.pi) % (2 * math.pi) - math.pi
    assert turned == pytest.approx(1.0, abs=0.2)
    # AND when the stream stops for COM_OF_LOSS_T the drone holds its position (COM_OBL_RC_ACT 0)
    run_until(sim, lambda: sim.nav_state("d1") != "OFFBOARD", 3.0, every_s=1 / 240)
    assert sim.nav_state("d1") == "HOLD"
    sim.run(duration=5.0)
    assert np.linalg.norm(sim.velocity_enu_m_s("d1")) < 0.2


@pytest.mark.parametrize("bad, message", [
    (dict(roll_deg=0.0, pitch_deg=0.0, thrust=1.5), "thrust must be a number in [0, 1]"),
    (dict(roll_deg=0.0, pitch_deg=0.0, thrust=math.nan), "thrust must be a number in [0, 1]"),
    (dict(roll_deg=85.0, pitch_deg=0.0, thrust=0.5), "roll_deg must be a number in [-80, 80]"),
    (dict(roll_deg=0.0, pitch_deg=math.inf, thrust=0.5), "pitch_deg must be a number in [-80, 80]"),
    (dict(roll_deg=0.0, pitch_deg=0.0, thrust=0.5, yaw_deg=0.0, yaw_rate_rad_s=0.1), "a yaw or a yaw rate, not both"),
])
def test_an_attitude_setpoint_out_of_range_is_refused_by_name(bad, message):
    sim = make_sim()
    with pytest.raises(ValueError) as err:
        sim.offboard_attitude("d1", **bad)
    assert message in str(err.value) and "offboard_attitude('d1')" in str(err.value)


# -- over MAVLink: SET_ATTITUDE_TARGET from a pymavlink peer ------------------------------------
def attitude_target(roll_ned_deg: float, pitch_ned_deg: float, yaw_ned_deg: float, thrust: float,
                    type_mask: int = 0b0000_0111) -> mavlink2.MAVLink_set_attitude_target_message:
    """MAVSDK's set_attitude: q of FRD in NED (w, x, y, z), body rates ignored (type_mask 7)."""
    q = quat_xyzw_to_wxyz(quat_xyzw_from_euler_rpy(math.radians(roll_ned_deg), math.radians(pitch_ned_deg),
                                                   math.radians(yaw_ned_deg)))
    return mavlink2.MAVLink_set_attitude_target_message(0, 1, 1, type_mask, [float(x) for x in q], 0.0, 0.0, 0.0,
                                                        thrust)


def rejected(sim: Simulation) -> int:
    return sim.transport_counters()["mavlink"]["d1"]["setpoints_rejected"]


def test_set_attitude_target_over_mavlink_flies_offboard_and_rate_only_setpoints_are_refused(tmp_path):
    # GIVEN a drone with a MAVLink endpoint hovering 10 m up, and a pymavlink peer on its API link
    ports = free_ports(1)
    sim = Simulation(load_world_text(world_text(ports, n_drones=1)), out_dir=tmp_path / "out")
    api = Client(ports["api_remote"], ports["api_local"])
    try:
        sim.run(duration=1.0)
        fly_up(sim, 10.0)
        sim.run(duration=3.0)
        hover = hover_thrust(sim)
        # WHEN it streams SET_ATTITUDE_TARGET (pitch -10 deg NED = nose down, heading 90 deg NED = east, the
        # way it faces) and switches to OFFBOARD with SET_MODE, as MAVSDK's set_attitude + offboard.start do
        assert abs(heading(sim)) < 0.05
        tilted = attitude_target(0.0, -10.0, 90.0, hover / math.cos(math.radians(10.0)))
        for _ in range(4):
            api.send(tilted)
            sim.flush_transports(5.0)
            sim.run(duration=0.05)
        api.send(mavlink2.MAVLink_set_mode_message(1, 1 | 128, MAIN_OFFBOARD << 16))
        v0, t0, hb = None, 0.0, None
        for k in range(40):                                   # 2 s at 20 Hz
            api.send(tilted)
            sim.flush_transports(5.0)
            sim.run(duration=0.05)
            if k == 10:
                v0, t0 = sim.velocity_enu_m_s("d1").copy(), sim.sim_time_s
            api.poll()                                        # heartbeats (1 Hz) while the stream is alive
            hb = hb or api.take("HEARTBEAT", lambda m: (m.custom_mode >> 16) & 0xFF == MAIN_OFFBOARD)
        a = (sim.velocity_enu_m_s("d1") - v0) / (sim.sim_time_s - t0)
        # THEN the drone is in OFFBOARD (and says so in its heartbeat), faces east and accelerates east at
        # g tan 10 deg at constant height
        assert sim.nav_state("d1") == "OFFBOARD"
        sim.flush_transports(5.0)
        api.poll()
        hb = hb or api.take("HEARTBEAT", lambda m: (m.custom_mode >> 16) & 0xFF == MAIN_OFFBOARD)
        assert hb is not None
        assert heading(sim) == pytest.approx(0.0, abs=0.05)
        assert a[0] == pytest.approx(GRAVITY_M_S2 * math.tan(math.radians(10.0)), rel=0.15)
        assert abs(a[1]) < 0.1
        assert abs(a[2]) < 0.2
        # AND a body-rate-only setpoint (attitude ignored), a NaN thrust and an un-normalisable q are
        # counted as refused setpoints, the first said once in a STATUSTEXT
        api.send(attitude_target(0.0, 0.0, 0.0, hover, type_mask=0b1000_0000))
        api.send(attitude_target(0.0, 0.0, 0.0, math.nan))
        api.send(mavlink2.MAVLink_set_attitude_target_message(0, 1, 1, 7, [0.0, 0.0, 0.0, 0.0], 0, 0, 0, hover))
        text = wait_for(sim, api, "STATUSTEXT", lambda m: "SET_ATTITUDE_TARGET" in m.text, steps=240)
        assert text is not None and text.text == "SET_ATTITUDE_TARGET needs q and thrust (no rates)"
        run_until(sim, lambda: sim.flush_transports(5.0) and rejected(sim) >= 3, 2.0)
        assert rejected(sim) == 3, sim.transport_counters()["mavlink"]
    finally:
        api.close()
        sim.close()
