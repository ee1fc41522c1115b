"""PX4-style navigation on the flight stack, flown in PyBullet: land detector, home, arming checks,
auto-disarm, TAKEOFF, LAND, RTL, HOLD, stored missions, parameters (docs/architecture.md §7).

Every claim is read from the physics (positions, contact) and from the command results that MAVLink
and ROS 2 report from; nothing is mocked. Worlds are flat and small; flights are short.
"""

from __future__ import annotations

import numpy as np
import pytest

from unetyemu_ecs import Simulation, load_world_text
from unetyemu_ecs.transport.api import CommandStatus

from .test_flight import drone, flat_world


def make_sim(components: str = "", pose: str = "{position_m: [0.0, 0.0, 0.3]}") -> Simulation:
    sim = Simulation(load_world_text(flat_world(drone("d1", pose=pose, components=components))))
    sim.run(duration=1.0)           # settle on the ground
    return sim


def result(sim: Simulation, command_id: int):
    res = sim.command_result(command_id)
    assert res is not None, f"command {command_id} has no result"
    return res


def fly_up(sim: Simulation, alt_m: float) -> None:
    assert result_after(sim, sim.arm("d1")).status == CommandStatus.ACCEPTED
    assert result_after(sim, sim.takeoff("d1", alt_m)).status == CommandStatus.ACCEPTED
    run_until(sim, lambda: sim.nav_state("d1") == "HOLD", 30.0)


def result_after(sim: Simulation, command_id: int):
    sim.step()
    return result(sim, command_id)


def run_until(sim: Simulation, done, limit_s: float, every_s: float = 0.05) -> None:
    end = sim.sim_time_s + limit_s
    while not done():
        assert sim.sim_time_s < end, f"not done within {limit_s} s of sim time"
        sim.run(duration=every_s)


# -- land detector, home, nav_state of the existing commands ---------------------------------
def test_a_drone_resting_on_the_ground_is_on_ground_holds_and_has_its_home_there():
    # GIVEN a drone that settled on flat ground
    sim = make_sim()
    # THEN the land detector says ON_GROUND, the mode is HOLD (disarmed) and home is where it rests
    assert sim.landed_state("d1") == "ON_GROUND"
    assert sim.nav_state("d1") == "HOLD"
    assert not sim.is_armed("d1")
    home = sim.home_enu_m("d1")
    assert home is not None and np.linalg.norm(home[:2] - sim.position_enu_m("d1")[:2]) < 0.05


def test_a_drone_dropped_from_height_is_in_air_until_it_rests_on_the_ground():
    # GIVEN a disarmed drone released 3 m above the ground
    sim = Simulation(load_world_text(flat_world(drone("d1", pose="{position_m: [0.0, 0.0, 3.0]}"))))
    sim.run(duration=0.2)
    # THEN it is IN_AIR while falling, ON_GROUND once it rests
    assert sim.landed_state("d1") == "IN_AIR"
    run_until(sim, lambda: sim.landed_state("d1") == "ON_GROUND", 5.0)
    assert sim.position_enu_m("d1")[2] < 0.5


def test_nav_state_follows_target_velocity_stick_and_mission_commands():
    sim = make_sim()
    sim.set_target("d1", 0, 0, 3)
    sim.step()
    assert sim.nav_state("d1") == "GOTO"
    sim.cmd_vel("d1", 0.5, 0.0)
    sim.step()
    assert sim.nav_state("d1") == "OFFBOARD"
    sim.teleop("d1", 0.1, 0, 0, 0)
    sim.step()
    assert sim.nav_state("d1") == "MANUAL"
    sim.load_mission("d1", '[{"type": "idle", "duration_s": 30}]')
    sim.step(2)
    assert sim.nav_state("d1") == "MISSION" and sim.mission_state("d1") == "RUNNING"
    assert result_after(sim, sim.hold("d1")).status == CommandStatus.ACCEPTED
    assert sim.nav_state("d1") == "HOLD" and sim.mission_state("d1") == "PAUSED"


# -- arming ------------------------------------------------------------------------------------
def test_arming_with_5_percent_battery_is_refused_with_reason_low_battery():
    # GIVEN a drone whose battery is at 5 % (below its 10 % low-battery level)
    sim = make_sim(components="      energy: {initial_soc_frac: 0.05}\n")
    # WHEN it is asked to arm
    res = result_after(sim, sim.arm("d1"))
    # THEN the command is refused for the state, with the machine reason, and the motors stay off
    assert res.status == CommandStatus.REJECTED_STATE and res.reason == "low_battery"
    assert "battery" in res.text
    assert not sim.is_armed("d1")
    # AND forcing it arms anyway (PX4's 21196)
    assert result_after(sim, sim.arm("d1", force=True)).status == CommandStatus.ACCEPTED
    assert sim.is_armed("d1")


def test_disarming_in_the_air_is_refused_unless_forced():
    sim = make_sim()
    fly_up(sim, 3.0)
    res = result_after(sim, sim.arm("d1", False))
    assert res.status == CommandStatus.REJECTED_STATE and res.reason == "in_air"
    assert sim.is_armed("d1")
    assert result_after(sim, sim.arm("d1", False, force=True)).status == CommandStatus.ACCEPTED
    assert not sim.is_armed("d1")


def test_arming_sets_home_and_a_drone_that_never_takes_off_disarms_after_com_disarm_prflt():
    # GIVEN COM_DISARM_PRFLT = 1.5 s
    sim = make_sim()
    assert result_after(sim, sim.set_param("d1", "COM_DISARM_PRFLT", 1.5)).status == CommandStatus.ACCEPTED
    assert sim.get_param("d1", "COM_DISARM_PRFLT") == 1.5
    # WHEN it is armed and left on the ground
    armed_at = sim.sim_time_s
    assert result_after(sim, sim.arm("d1")).status == CommandStatus.ACCEPTED
    run_until(sim, lambda: not sim.is_armed("d1"), 5.0, every_s=1 / 240)
    # THEN it disarms itself 1.5 s after arming
    assert sim.sim_time_s - armed_at == pytest.approx(1.5, abs=0.05)
    assert any("COM_DISARM_PRFLT" in text for _, _, text in sim.events)


def test_takeoff_and_rtl_are_refused_with_state_reasons():
    sim = make_sim()
    res = result_after(sim, sim.takeoff("d1"))
    assert (res.status, res.reason) == (CommandStatus.REJECTED_STATE, "not_armed")
    sim.arm("d1")
    res = result_after(sim, sim.return_to_launch("d1"))
    assert (res.status, res.reason) == (CommandStatus.REJECTED_STATE, "landed")
    res = result_after(sim, sim.start_mission("d1"))
    assert (res.status, res.reason) == (CommandStatus.REJECTED_STATE, "no_mission")


def test_bad_values_are_refused_before_anything_is_queued():
    sim = make_sim()
    for call in (lambda: sim.takeoff("d1", float("nan")), lambda: sim.takeoff("d1", -3.0),
                 lambda: sim.set_param("d1", "MIS_TAKEOFF_ALT", 1e6), lambda: sim.set_param("d1", "NOPE", 1.0),
                 lambda: sim.set_nav_mode("d1", "CRUISE"), lambda: sim.change_speed("d1", 0.0),
                 lambda: sim.land("d1", (1e9, 0.0)), lambda: sim.arm("d1", "yes")):
        with pytest.raises(ValueError):
            call()
    assert sim.services.results == [] or all(r.kind != "takeoff" for r in sim.services.results)


# -- TAKEOFF, LAND, RTL ------------------------------------------------------------------------
def test_takeoff_without_an_altitude_hovers_at_mis_takeoff_alt():
    # GIVEN an armed drone on the ground (MIS_TAKEOFF_ALT 2.5 m, PX4's default)
    sim = make_sim()
    home_z = sim.home_enu_m("d1")[2]
    sim.arm("d1")
    # WHEN it is told to take off without an altitude
    assert result_after(sim, sim.takeoff("d1")).status == CommandStatus.ACCEPTED
    states = set()
    for _ in range(60):
        sim.run(duration=0.1)
        states.add(sim.landed_state("d1"))
    # THEN it reported TAKEOFF while climbing, then hovers at home + 2.5 m in HOLD
    assert "TAKEOFF" in states
    assert sim.nav_state("d1") == "HOLD"
    assert sim.landed_state("d1") == "IN_AIR"
    assert sim.position_enu_m("d1")[2] == pytest.approx(home_z + 2.5, abs=0.3)
    assert np.linalg.norm(sim.velocity_enu_m_s("d1")) < 0.3


def test_land_from_10_m_touches_down_reports_on_ground_and_disarms_2_s_later():
    # GIVEN a drone hovering 10 m up
    sim = make_sim()
    fly_up(sim, 10.0)
    assert sim.position_enu_m("d1")[2] > 9.5
    # WHEN it is told to land
    assert result_after(sim, sim.land("d1")).status == CommandStatus.ACCEPTED
    assert sim.nav_state("d1") == "LAND" and sim.landed_state("d1") == "LANDING"
    vz = []
    while sim.landed_state("d1") != "ON_GROUND":
        assert sim.sim_time_s < 60
        sim.step()
        vz.append((sim.position_enu_m("d1")[2], sim.velocity_enu_m_s("d1")[2]))
    touchdown = sim.sim_time_s
    # THEN it descended at MPC_Z_V_AUTO_DN (1.5 m/s) high up and MPC_LAND_SPEED (0.7 m/s) near the ground
    # (the velocity loop runs ~0.2 m/s past a 1.5 m/s descent limit)
    high = [-v for z, v in vz if 7.0 < z < 8.5]
    low = [-v for z, v in vz if 1.0 < z < 3.0]
    assert np.median(high) == pytest.approx(1.5, rel=0.2)
    assert np.median(low) == pytest.approx(0.7, rel=0.15)
    # AND it touched down where it was, and disarms COM_DISARM_LAND = 2 s after the land detector said so
    assert np.linalg.norm(sim.position_enu_m("d1")[:2]) < 0.5
    assert sim.is_armed("d1")
    run_until(sim, lambda: not sim.is_armed("d1"), 5.0, every_s=1 / 240)
    assert sim.sim_time_s - touchdown == pytest.approx(2.0, abs=0.05)
    assert sim.nav_state("d1") == "HOLD" and sim.landed_state("d1") == "ON_GROUND"


def test_rtl_climbs_to_rtl_return_alt_and_lands_within_1_m_of_home():
    # GIVEN RTL_RETURN_ALT 8 m, RTL_DESCEND_ALT 4 m and a drone 3 m up, 25 m from home
    sim = make_sim()
    home = sim.home_enu_m("d1")
    sim.set_param("d1", "RTL_RETURN_ALT", 8.0)
    sim.set_param("d1", "RTL_DESCEND_ALT", 4.0)
    fly_up(sim, 3.0)
    sim.set_target("d1", 25.0, 5.0, 3.0)
    run_until(sim, lambda: np.linalg.norm(sim.position_enu_m("d1") - (25.0, 5.0, 3.0)) < 0.5, 20.0)
    # WHEN it is told to return
    assert result_after(sim, sim.return_to_launch("d1")).status == CommandStatus.ACCEPTED
    assert sim.nav_state("d1") == "RTL"
    track = []
    while sim.is_armed("d1"):
        assert sim.sim_time_s < 120
        sim.run(duration=0.05)
        track.append(sim.position_enu_m("d1").copy())
    track = np.array(track)
    # THEN it climbed to home + 8 m before flying back (not higher), and the return leg flew at that height
    assert track[:, 2].max() == pytest.approx(home[2] + 8.0, abs=0.5)
    far = np.hypot(track[:, 0] - home[0], track[:, 1] - home[1]) > 5.0
    assert track[far & (np.arange(len(track)) > np.argmax(track[:, 2])), 2].min() > home[2] + 6.5
    # AND it landed within 1 m of home and disarmed
    assert np.linalg.norm(sim.position_enu_m("d1")[:2] - home[:2]) < 1.0
    assert sim.landed_state("d1") == "ON_GROUND" and sim.nav_state("d1") == "HOLD"


@pytest.mark.slow
def test_rtl_goes_to_the_closest_rally_point():
    sim = make_sim()
    sim.set_param("d1", "RTL_RETURN_ALT", 4.0)
    sim.set_param("d1", "RTL_DESCEND_ALT", 4.0)
    sim.set_rally_points("d1", [(20.0, 0.0, 0.0), (-80.0, 0.0, 0.0)])
    fly_up(sim, 4.0)
    sim.set_target("d1", 15.0, 0.0, 4.0)
    run_until(sim, lambda: sim.position_enu_m("d1")[0] > 14.5, 20.0)
    sim.return_to_launch("d1")
    run_until(sim, lambda: sim.landed_state("d1") == "ON_GROUND", 40.0)
    assert np.linalg.norm(sim.position_enu_m("d1")[:2] - (20.0, 0.0)) < 1.0


# -- missions ----------------------------------------------------------------------------------
MISSION = """{"name": "m", "steps": [
  {"type": "cruise", "waypoints": [{"x": 6, "y": 0, "z": 3}]},
  {"type": "return"}]}"""


def test_a_stored_mission_waits_then_takes_off_first_flies_and_returns_home():
    # GIVEN a mission stored on a drone on the ground (RTL heights small to keep it short)
    sim = make_sim()
    home = sim.home_enu_m("d1")
    sim.set_param("d1", "RTL_RETURN_ALT", 4.0)
    sim.set_param("d1", "RTL_DESCEND_ALT", 3.0)
    assert result_after(sim, sim.store_mission("d1", MISSION)).status == CommandStatus.ACCEPTED
    sim.run(duration=1.0)
    # THEN it is stored, not flown
    assert sim.mission_state("d1") == "STORED" and sim.landed_state("d1") == "ON_GROUND"
    # WHEN it is started
    sim.arm("d1")
    assert result_after(sim, sim.start_mission("d1")).status == CommandStatus.ACCEPTED
    assert sim.nav_state("d1") == "MISSION"
    sim.run(duration=1.5)
    # THEN it first climbs straight up (PX4's implicit takeoff) ...
    assert np.hypot(*sim.position_enu_m("d1")[:2]) < 0.3 and sim.position_enu_m("d1")[2] > 1.0
    # ... flies the waypoint, returns and lands at home, and the mission completes
    run_until(sim, lambda: sim.mission_state("d1") == "COMPLETED", 60.0, every_s=0.1)
    assert np.linalg.norm(sim.position_enu_m("d1")[:2] - home[:2]) < 1.0
    assert not sim.is_armed("d1") and sim.nav_state("d1") == "HOLD"
    assert any("mission step 0 (cruise) done" in text for _, _, text in sim.events)


@pytest.mark.slow
def test_pause_holds_and_resume_continues_the_mission():
    sim = make_sim()
    sim.load_mission("d1", '[{"type": "takeoff", "altitude_m": 3}, '
                           '{"type": "cruise", "waypoints": [{"x": 30, "y": 0, "z": 3}]}]')
    run_until(sim, lambda: sim.position_enu_m("d1")[0] > 5.0, 20.0)
    assert result_after(sim, sim.pause_mission("d1")).status == CommandStatus.ACCEPTED
    assert sim.mission_state("d1") == "PAUSED" and sim.nav_state("d1") == "HOLD"
    sim.run(duration=4.0)
    x = sim.position_enu_m("d1")[0]
    sim.run(duration=1.0)
    assert abs(sim.position_enu_m("d1")[0] - x) < 0.2
    assert result_after(sim, sim.pause_mission("d1", resume=True)).status == CommandStatus.ACCEPTED
    run_until(sim, lambda: sim.mission_state("d1") == "COMPLETED", 30.0)
    assert sim.position_enu_m("d1")[0] == pytest.approx(30.0, abs=0.5)


# -- flight parameters from the world file ---------------------------------------------------------
def test_world_file_flight_params_set_the_takeoff_altitude():
    # GIVEN a world file giving the drone MIS_TAKEOFF_ALT 4 m
    sim = make_sim(components="      flight_params: {MIS_TAKEOFF_ALT: 4.0, COM_DISARM_LAND: 1.0}\n")
    assert sim.get_param("d1", "MIS_TAKEOFF_ALT") == 4.0
    assert sim.get_param("d1", "RTL_RETURN_ALT") == 60.0          # the PX4 default where none is given
    home_z = sim.home_enu_m("d1")[2]
    # WHEN it takes off without an altitude
    sim.arm("d1")
    sim.takeoff("d1")
    run_until(sim, lambda: sim.nav_state("d1") == "HOLD" and sim.landed_state("d1") == "IN_AIR", 10.0)
    sim.run(duration=1.0)
    # THEN it hovers 4 m above home
    assert sim.position_enu_m("d1")[2] == pytest.approx(home_z + 4.0, abs=0.3)


@pytest.mark.parametrize("block, message", [
    ("{MIS_TAKEOFF_ALT: -1}", "flight_params.MIS_TAKEOFF_ALT: must be >= 0"),
    ("{NOPE: 1}", "flight_params.NOPE: unknown key"),
    ("{COM_OBL_RC_ACT: 1.5}", "flight_params.COM_OBL_RC_ACT: must be a whole number"),
    ("{RTL_RETURN_ALT: .nan}", "flight_params.RTL_RETURN_ALT: must be a finite number"),
])
def test_bad_world_file_flight_params_are_errors_naming_line_and_key(block, message):
    from unetyemu_ecs.config.schema import ConfigError

    with pytest.raises(ConfigError) as err:
        load_world_text(flat_world(drone("d1", components=f"      flight_params: {block}\n")))
    assert message in str(err.value)
    assert ":17: vehicles[0].components." in str(err.value)


# -- OFFBOARD ----------------------------------------------------------------------------------
def stream(sim: Simulation, seconds: float, **setpoint) -> None:
    """Send the same OFFBOARD setpoint at 10 Hz for ``seconds`` of sim time."""
    for _ in range(round(seconds / 0.1)):
        sim.offboard_setpoint("d1", **setpoint)
        sim.run(duration=0.1)


def heading(sim: Simulation) -> float:
    from unetyemu_ecs.frames import yaw_rad_from_quat_xyzw

    return float(yaw_rad_from_quat_xyzw(sim.attitude_enu_flu_xyzw("d1")))


def test_offboard_without_a_setpoint_stream_is_refused_with_reason_no_setpoint_stream():
    sim = make_sim()
    fly_up(sim, 3.0)
    res = result_after(sim, sim.set_nav_mode("d1", "OFFBOARD"))
    assert (res.status, res.reason) == (CommandStatus.REJECTED_STATE, "no_setpoint_stream")
    assert sim.nav_state("d1") == "HOLD"


def test_offboard_flies_position_enu_velocity_and_body_velocity_with_yaw_rate():
    # GIVEN a drone hovering 3 m up with an OFFBOARD stream running
    sim = make_sim()
    fly_up(sim, 3.0)
    start = sim.position_enu_m("d1").copy()
    sim.offboard_setpoint("d1", pos=(start[0] + 4.0, start[1], 4.0))
    sim.step()
    # WHEN it switches to OFFBOARD
    assert result_after(sim, sim.set_nav_mode("d1", "OFFBOARD")).status == CommandStatus.ACCEPTED
    assert sim.nav_state("d1") == "OFFBOARD"
    # THEN a position setpoint is flown to
    stream(sim, 6.0, pos=(start[0] + 4.0, start[1], 4.0))
    assert np.linalg.norm(sim.position_enu_m("d1") - (start[0] + 4.0, start[1], 4.0)) < 0.4
    # AND an ENU velocity setpoint (north 1.5 m/s) whatever the heading
    stream(sim, 3.0, vel_enu=(0.0, 1.5, 0.0))
    assert sim.velocity_enu_m_s("d1")[:2] == pytest.approx((0.0, 1.5), abs=0.25)
    # AND a body velocity with a yaw rate really turns the drone
    yaw0 = heading(sim)
    stream(sim, 3.0, vel_flu=(0.0, 0.0, 0.0), yaw_rate_rad_s=0.5)
    turned = (heading(sim) - yaw0 + np.pi) % (2 * np.pi) - np.pi
    assert turned == pytest.approx(1.5, abs=0.3)
    # AND a heading setpoint is held
    stream(sim, 4.0, vel_flu=(0.0, 0.0, 0.0), yaw_deg=0.0)
    assert abs(heading(sim)) < 0.1


@pytest.mark.parametrize("action, nav_after", [(0, "HOLD"), (4, "LAND")])
def test_offboard_stream_lapse_triggers_com_obl_rc_act_failsafe(action, nav_after):
    sim = make_sim()
    sim.set_param("d1", "COM_OBL_RC_ACT", action)
    fly_up(sim, 3.0)
    stream(sim, 0.3, vel_enu=(1.0, 0.0, 0.0))
    sim.set_nav_mode("d1", "OFFBOARD")
    stream(sim, 1.0, vel_enu=(1.0, 0.0, 0.0))
    assert sim.nav_state("d1") == "OFFBOARD"
    # WHEN the stream stops for longer than COM_OF_LOSS_T (1 s)
    last = sim.sim_time_s
    run_until(sim, lambda: sim.nav_state("d1") != "OFFBOARD", 3.0, every_s=1 / 240)
    # THEN the failsafe takes over one COM_OF_LOSS_T later, and says so
    assert sim.sim_time_s - last == pytest.approx(1.0, abs=0.15)
    assert sim.nav_state("d1") == nav_after
    assert any("offboard setpoints lost" in text for _, _, text in sim.events)


# -- parameters at run time, home, speed, termination, mission current ----------------------------
def test_terminate_stops_the_motors_in_the_air_and_the_drone_falls():
    sim = make_sim()
    fly_up(sim, 4.0)
    assert result_after(sim, sim.terminate("d1")).status == CommandStatus.ACCEPTED
    assert not sim.is_armed("d1")
    run_until(sim, lambda: sim.landed_state("d1") == "ON_GROUND", 5.0)
    assert sim.position_enu_m("d1")[2] < 0.5


@pytest.mark.slow
def test_rtl_flies_to_a_home_set_by_command():
    sim = make_sim()
    sim.set_param("d1", "RTL_RETURN_ALT", 4.0)
    sim.set_param("d1", "RTL_DESCEND_ALT", 4.0)
    fly_up(sim, 4.0)
    assert result_after(sim, sim.set_home("d1", (10.0, -5.0, 0.2))).status == CommandStatus.ACCEPTED
    assert sim.home_enu_m("d1") == pytest.approx((10.0, -5.0, 0.2))
    sim.return_to_launch("d1")
    run_until(sim, lambda: sim.landed_state("d1") == "ON_GROUND", 40.0)
    assert np.linalg.norm(sim.position_enu_m("d1")[:2] - (10.0, -5.0)) < 1.0


@pytest.mark.slow
def test_change_speed_slows_the_leg_being_flown():
    sim = make_sim()
    fly_up(sim, 3.0)
    sim.set_target("d1", 60.0, 0.0, 3.0, speed=8.0)
    sim.run(duration=5.0)
    assert sim.velocity_enu_m_s("d1")[0] > 6.5
    assert result_after(sim, sim.change_speed("d1", 2.0)).status == CommandStatus.ACCEPTED
    sim.run(duration=4.0)
    assert sim.velocity_enu_m_s("d1")[0] == pytest.approx(2.0, abs=0.3)


@pytest.mark.slow
def test_set_mission_current_skips_to_that_step():
    sim = make_sim()
    sim.store_mission("d1", '[{"type": "idle", "duration_s": 100}, {"type": "takeoff", "altitude_m": 2}]')
    sim.step()
    res = result_after(sim, sim.set_mission_current("d1", 5))
    assert res.status == CommandStatus.REJECTED_INVALID and "does not exist" in res.text
    assert result_after(sim, sim.set_mission_current("d1", 1)).status == CommandStatus.ACCEPTED
    sim.arm("d1")
    sim.start_mission("d1", 1)
    run_until(sim, lambda: sim.mission_state("d1") == "COMPLETED", 10.0)
    assert sim.position_enu_m("d1")[2] > 1.5


def test_gripper_grabs_the_package_in_reach_and_releases_it():
    sim = Simulation(load_world_text(flat_world(
        drone("d1"), packages="  - {name: parcel, mass_kg: 1.0, size_m: [0.4, 0.4, 0.3], "
                              "pose: {pad: home, offset_m: [3.0, 0.0]}}")))
    sim.run(duration=1.0)
    res = result_after(sim, sim.gripper("d1", False))
    assert (res.status, res.reason) == (CommandStatus.REJECTED_STATE, "empty")
    fly_up(sim, 2.0)
    pkg = sim.position_enu_m("parcel")
    # hover just above the package (the mission's grab height: package top + 0.1 m + half the airframe)
    sim.set_target("d1", pkg[0], pkg[1], pkg[2] + 0.15 + 0.1 + 0.06, speed=1.0)
    sim.run(duration=12.0)
    assert result_after(sim, sim.gripper("d1", True)).status == CommandStatus.ACCEPTED
    sim.run(duration=0.5)
    assert sim.fleet.payload_kg[sim.row("d1")] == 1.0
    assert result_after(sim, sim.gripper("d1", False)).status == CommandStatus.ACCEPTED
    sim.run(duration=0.5)
    assert sim.fleet.payload_kg[sim.row("d1")] == 0.0


# -- POSCTL / MANUAL, ORBIT, FOLLOW_TARGET, geofence -------------------------------------------------
def sticks(sim: Simulation, seconds: float, pitch=0.0, roll=0.0, throttle=0.5, yaw=0.0) -> None:
    for _ in range(round(seconds / 0.1)):
        sim.manual_control("d1", pitch, roll, throttle, yaw)
        sim.run(duration=0.1)


def test_posctl_flies_the_sticks_holds_when_centred_and_fails_safe_when_they_stop():
    sim = make_sim()
    sim.set_param("d1", "NAV_RCL_ACT", 3)           # land when the sticks stay lost
    sim.set_param("d1", "COM_FAIL_ACT_T", 1.0)
    fly_up(sim, 3.0)
    res = result_after(sim, sim.set_nav_mode("d1", "POSCTL"))
    assert (res.status, res.reason) == (CommandStatus.REJECTED_STATE, "no_manual_control")
    sticks(sim, 0.2)
    assert result_after(sim, sim.set_nav_mode("d1", "POSCTL")).status == CommandStatus.ACCEPTED
    # half forward stick: forward at half MPC_XY_VEL_MAX (6 m/s), capped by nothing else
    sticks(sim, 4.0, pitch=0.25)
    assert np.linalg.norm(sim.velocity_enu_m_s("d1")[:2]) == pytest.approx(3.0, abs=0.4)
    # centred: it brakes and holds
    sticks(sim, 4.0)
    x = sim.position_enu_m("d1").copy()
    sticks(sim, 1.0)
    assert np.linalg.norm(sim.position_enu_m("d1") - x) < 0.2
    # sticks lost: HOLD after COM_RC_LOSS_T, then NAV_RCL_ACT (land) after COM_FAIL_ACT_T
    run_until(sim, lambda: sim.nav_state("d1") == "HOLD", 2.0, every_s=1 / 240)
    run_until(sim, lambda: sim.nav_state("d1") == "LAND", 2.0, every_s=1 / 240)
    assert any("manual control lost" in text for _, _, text in sim.events)


@pytest.mark.slow
def test_orbit_circles_the_centre_at_the_radius_facing_it():
    sim = make_sim()
    fly_up(sim, 5.0)
    assert result_after(sim, sim.orbit("d1", (5.0, 0.0, 5.0), 5.0, 2.0)).status == CommandStatus.ACCEPTED
    assert sim.nav_state("d1") == "ORBIT"
    sim.run(duration=8.0)
    angles, radii = [], []
    for _ in range(40):
        sim.run(duration=0.25)
        p = sim.position_enu_m("d1")
        radii.append(np.hypot(p[0] - 5.0, p[1]))
        angles.append(np.arctan2(p[1], p[0] - 5.0))
        to_centre = np.arctan2(-p[1], 5.0 - p[0])
        assert abs((heading(sim) - to_centre + np.pi) % (2 * np.pi) - np.pi) < 0.3
    assert np.mean(radii) == pytest.approx(5.0, abs=0.5)
    swept = np.sum((np.diff(np.unwrap(angles))))
    assert swept == pytest.approx(-2.0 / 5.0 * 10.0, rel=0.2)      # clockwise at 2 m/s on r = 5 m for 10 s


@pytest.mark.slow
def test_follow_target_keeps_behind_a_moving_target_at_flw_tgt_dst_and_ht():
    sim = make_sim()
    sim.set_param("d1", "FLW_TGT_HT", 8.0)
    sim.set_param("d1", "FLW_TGT_DST", 5.0)
    fly_up(sim, 8.0)
    res = result_after(sim, sim.set_nav_mode("d1", "FOLLOW_TARGET"))
    assert (res.status, res.reason) == (CommandStatus.REJECTED_STATE, "no_target")
    target = np.array([0.0, 10.0, 0.0])
    vel = np.array([2.0, 0.0, 0.0])
    sim.follow_target_fix("d1", tuple(target), tuple(vel))
    sim.step()
    assert result_after(sim, sim.set_nav_mode("d1", "FOLLOW_TARGET")).status == CommandStatus.ACCEPTED
    for _ in range(200):
        target = target + vel * 0.1
        sim.follow_target_fix("d1", tuple(target), tuple(vel))
        sim.run(duration=0.1)
    p = sim.position_enu_m("d1")
    home_z = sim.home_enu_m("d1")[2]
    assert p[:2] == pytest.approx(target[:2] - (5.0, 0.0), abs=1.0)       # 5 m behind (course east)
    assert p[2] == pytest.approx(home_z + 8.0, abs=0.5)
    assert sim.velocity_enu_m_s("d1")[0] == pytest.approx(2.0, abs=0.3)


def test_geofence_breach_holds_and_arming_outside_is_refused():
    from unetyemu_ecs.navigation.geofence import Geofence

    sim = make_sim()
    fly_up(sim, 3.0)
    sim.set_geofence("d1", Geofence(inclusion_circles=((0.0, 0.0, 10.0),)))
    sim.set_target("d1", 30.0, 0.0, 3.0)
    run_until(sim, lambda: sim.nav_state("d1") == "HOLD", 15.0)
    sim.run(duration=3.0)
    assert 9.0 < np.hypot(*sim.position_enu_m("d1")[:2]) < 14.0
    assert any("geofence breached" in text for _, _, text in sim.events)
    # land outside, then arming there is refused
    sim.set_param("d1", "COM_DISARM_LAND", 0.5)
    sim.land("d1")
    run_until(sim, lambda: not sim.is_armed("d1"), 20.0)
    res = result_after(sim, sim.arm("d1"))
    assert (res.status, res.reason) == (CommandStatus.REJECTED_STATE, "outside_fence")


@pytest.mark.slow
def test_geofence_action_warning_only_warns_and_return_flies_home():
    from unetyemu_ecs.navigation.geofence import Geofence

    # GIVEN GF_ACTION 1 (warning): WHEN the drone flies out of a 10 m fence
    sim = make_sim()
    fly_up(sim, 3.0)
    sim.set_param("d1", "GF_ACTION", 1)
    sim.set_geofence("d1", Geofence(inclusion_circles=((0.0, 0.0, 10.0),)))
    sim.set_target("d1", 20.0, 0.0, 3.0)
    sim.run(duration=12.0)
    # THEN it warned and still flew to its target
    assert any("geofence breached" in text and "warning" in text for _, _, text in sim.events)
    assert np.hypot(*(sim.position_enu_m("d1")[:2] - [20.0, 0.0])) < 1.0 and sim.nav_state("d1") == "GOTO"
    # GIVEN GF_ACTION 3 (return): WHEN it breaches again; THEN it returns home and lands
    sim = make_sim()
    fly_up(sim, 3.0)
    sim.set_param("d1", "GF_ACTION", 3)
    sim.set_param("d1", "RTL_RETURN_ALT", 5.0)
    sim.set_geofence("d1", Geofence(inclusion_circles=((0.0, 0.0, 10.0),)))
    sim.set_target("d1", 20.0, 0.0, 3.0)
    run_until(sim, lambda: sim.nav_state("d1") == "RTL", 15.0)
    run_until(sim, lambda: sim.landed_state("d1") == "ON_GROUND", 60.0)
    assert np.hypot(*sim.position_enu_m("d1")[:2]) < 1.0


def test_the_navigators_arming_verdicts_for_the_whole_fleet_equal_the_arm_commands_check_drone_by_drone():
    import esper

    from unetyemu_ecs.components.body import FleetSlot
    from unetyemu_ecs.navigation.geofence import Geofence
    from unetyemu_ecs.navigation.params import FlightParams
    from unetyemu_ecs.navigation.state import NavRuntime
    from unetyemu_ecs.systems.flight_state import ArmBlock
    from unetyemu_ecs.systems.navigator import arm_block, arm_blocks, fence_active, fence_breach

    # GIVEN six drones: fine, low battery, overweight, motors off, outside their fence, in the air
    drones = "".join(drone(f"d{i}", pose=f"{{position_m: [{4.0 * i}, 0.0, {8.0 if i == 5 else 0.3}]}}")
                     for i in range(6))
    sim = Simulation(load_world_text(flat_world(drones)))
    sim.set_geofence("d4", Geofence(exclusion_circles=((16.0, 0.0, 2.0),)))
    sim.run(duration=1.0)                      # settled on the ground, d5 still falling
    f, row = sim.fleet, sim.row
    f.soc_frac[row("d1")], f.low_battery[row("d1")] = 0.05, True
    f.motors_enabled[row("d2")], f.payload_kg[row("d2")] = False, 50.0
    f.motors_enabled[row("d3")] = False
    # WHEN the navigator's fleet-wide verdict and the per-drone check are both asked
    with sim.ecs.active():
        items = esper.get_components(FleetSlot, NavRuntime, FlightParams)
        rows = np.array([slot.row for _, (slot, _, _) in items])
        why = [fence_breach(f, slot.row, nav, params) if fence_active(nav, params) else ""
               for _, (slot, nav, params) in items]
        together = arm_blocks(f, rows, why).tolist()
        one_by_one = [int(arm_block(f, ent, slot.row, nav, params)) for ent, (slot, nav, params) in items]
    # THEN they agree, and each drone is blocked for its own reason
    assert together == one_by_one
    verdict = dict(zip(rows.tolist(), together))
    expected = [ArmBlock.NONE, ArmBlock.LOW_BATTERY, ArmBlock.OVERWEIGHT, ArmBlock.MOTORS_DISABLED,
                ArmBlock.OUTSIDE_FENCE, ArmBlock.IN_AIR]
    assert [ArmBlock(verdict[row(f"d{i}")]) for i in range(6)] == expected
