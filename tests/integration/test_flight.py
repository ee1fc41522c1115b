"""The quadrotor flight stack in PyBullet: hover, payload, energy, limits, pursuit, modes.

Physics is checked against physics: hover thrust equals weight, hover power equals the
actuator-disk formula, a package raises both by what its mass implies.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from unetyemu_ecs import Simulation, load_world_text
from unetyemu_ecs.components.flight import GuidanceLimits
from unetyemu_ecs.control.atmosphere import isa_density_kg_m3
from unetyemu_ecs.control.energy import hover_power_w
from unetyemu_ecs.control.position import GuidanceGains
from unetyemu_ecs.scene.primitives import SceneClass
from unetyemu_ecs.systems.flight_state import FlightMode

G = 9.81


def flat_world(drones: str, packages: str = "", extra: str = "") -> str:
    return f"""
world: {{name: flight, physics_hz: 240, seed: 7}}
scene:
  generator: none
  ground_size_m: 300
  pads:
    - {{name: home, position_m: [0, 0]}}
    - {{name: away, position_m: [30, 0]}}
packages:
{packages or '  []'}
vehicles:
{drones}
{extra}
"""


def drone(name: str, preset: str = "medium", pose: str = "{position_m: [0.0, 0.0, 0.3]}", components: str = "",
          controller: str = "") -> str:
    text = f"  - name: {name}\n    type: quadrotor\n    preset: {preset}\n    pose: {pose}\n"
    if controller:
        text += f"    controller: {controller}\n"
    if components:
        text += "    components:\n" + components
    return text


def hover(sim: Simulation, name: str, z: float, settle_s: float) -> None:
    x, y, _ = sim.position_enu_m(name)
    sim.set_target(name, x, y, z)
    sim.run(duration=settle_s)


def measure(sim: Simulation, name: str, seconds: float) -> dict[str, np.ndarray]:
    """Record altitude, total thrust and power every step for ``seconds``."""
    row = sim.row(name)
    z, thrust, power, cmd = [], [], [], []
    for _ in range(int(round(seconds / sim.dt_s))):
        sim.step()
        f = sim.fleet
        z.append(f.pos_enu_m[row, 2])
        thrust.append(f.motor_thrust_n[row].sum())
        power.append(f.power_w[row])
        cmd.append(f.motor_thrust_cmd_n[row].copy())
    return {"z": np.array(z), "thrust": np.array(thrust), "power": np.array(power), "cmd": np.array(cmd)}


@pytest.fixture(scope="module")
def medium_hover():
    """A medium drone hovering at 10 m for 20 s, then measured for 5 s."""
    with Simulation(load_world_text(flat_world(drone("d1")))) as sim:
        hover(sim, "d1", 10.0, 20.0)
        yield sim, measure(sim, "d1", 5.0)


def test_medium_drone_holds_10_m_within_5_cm_after_settling(medium_hover):
    _, m = medium_hover
    assert np.max(np.abs(m["z"] - 10.0)) < 0.05


def test_hover_thrust_equals_weight_within_1_percent(medium_hover):
    _, m = medium_hover
    assert np.mean(m["thrust"]) == pytest.approx(8.0 * G, rel=0.01)


def test_hover_power_equals_the_actuator_disk_formula_within_1_percent(medium_hover):
    # P = 4 (mg/4)^1.5 / (sqrt(2 rho A) eta) + P0 with rho of the ISA at the world's 650 m (1.150 kg/m^3),
    # r 0.14 m, eta 0.9, P0 15 W: momentum theory with the real inflow is eq. 4 in hover
    _, m = medium_hover
    expected = hover_power_w(8.0, 4, G, float(isa_density_kg_m3(650.0)), 0.14, 0.90, 15.0)
    assert np.mean(m["power"]) == pytest.approx(expected, rel=0.01)


def test_the_papers_hover_actuator_disk_model_at_sea_level_air_gives_the_papers_hover_power():
    world = flat_world(drone("d1", components="      energy: {model: hover_actuator_disk, air_density_kg_m3: 1.225}\n"))
    with Simulation(load_world_text(world)) as sim:
        hover(sim, "d1", 10.0, 20.0)
        m = measure(sim, "d1", 3.0)
    assert np.mean(m["power"]) == pytest.approx(hover_power_w(8.0, 4, G, 1.225, 0.14, 0.90, 15.0), rel=0.01)


PICKUP_MISSION = """
      mission:
        name: lift
        steps:
          - {type: pickup, package: parcel}
          - {type: takeoff, altitude_m: 10.0}
          - {type: idle, duration_s: 60.0}
"""


def _package(mass: float) -> str:
    return f"  - {{name: parcel, mass_kg: {mass}, size_m: [0.4, 0.4, 0.3], pose: {{pad: home, offset_m: [1.0, 0.0]}}}}"


def test_picking_up_2_5_kg_raises_hover_thrust_by_its_weight_and_rotor_power_by_the_mass_ratio_to_1_5(
        medium_hover):
    # GIVEN the medium drone's unloaded hover (same gains, same everything)
    _, unloaded = medium_hover
    # WHEN it picks up a 2.5 kg package and hovers 10 m above the ground with it
    world = flat_world(drone("d1", components=PICKUP_MISSION), packages=_package(2.5))
    with Simulation(load_world_text(world)) as sim:
        sim.run(until=45.0)
        status = sim.mission_status("d1")
        assert status["state"] == "running" and status["step_type"] == "idle", status
        assert sim.fleet.payload_kg[sim.row("d1")] == 2.5
        loaded = measure(sim, "d1", 5.0)
    # THEN thrust rose by 2.5 g and rotor power by ((8 + 2.5) / 8) ** 1.5 (P0 excluded)
    assert np.mean(loaded["thrust"]) - np.mean(unloaded["thrust"]) == pytest.approx(2.5 * G, rel=0.02)
    ratio = (np.mean(loaded["power"]) - 15.0) / (np.mean(unloaded["power"]) - 15.0)
    assert ratio == pytest.approx(((8 + 2.5) / 8) ** 1.5, rel=0.02)
    # AND it still holds its altitude: the integrator took the load, no gain changed
    assert np.max(np.abs(loaded["z"] - np.mean(loaded["z"]))) < 0.05


def test_overweight_pickup_fails_and_the_drone_stays_down():
    # GIVEN a medium drone (max payload 3 kg) and a 4 kg package
    world = flat_world(drone("d1", components=PICKUP_MISSION), packages=_package(4.0))
    with Simulation(load_world_text(world)) as sim:
        # WHEN the mission runs for a while
        sim.run(until=30.0)
        status = sim.mission_status("d1")
        row = sim.row("d1")
        # THEN the pickup failed for being overweight, the motors are off and the drone is down
        assert status["state"] == "failed" and status["reason"] == "overweight"
        assert status["step_type"] == "pickup"
        assert not sim.fleet.motors_enabled[row]
        assert np.all(sim.fleet.motor_thrust_n[row] == 0.0)
        assert sim.position_enu_m("d1")[2] < 1.0


def test_disarmed_drone_on_the_ground_draws_only_p0():
    with Simulation(load_world_text(flat_world(drone("d1")))) as sim:
        sim.run(until=2.0)
        row = sim.row("d1")
        assert sim.fleet.flight_mode[row] == FlightMode.DISARMED
        assert sim.fleet.power_w[row] == pytest.approx(15.0)
        assert sim.fleet.energy_used_j[row] == pytest.approx(15.0 * 2.0, rel=1e-3)


def test_no_motor_command_leaves_0_to_f_max_during_aggressive_steps(rng):
    # GIVEN a small drone (F_max 30 N) hovering
    with Simulation(load_world_text(flat_world(drone("d1", preset="small")))) as sim:
        hover(sim, "d1", 10.0, 5.0)
        cmds = []
        # WHEN it is thrown at random far targets, each for 1.5 s, at high speed
        for _ in range(12):
            x, y = rng.uniform(-60, 60, 2)
            z = rng.uniform(2, 40)
            sim.set_target("d1", x, y, z, yaw_deg=float(rng.uniform(-180, 180)), speed=15.0)
            cmds.append(measure(sim, "d1", 1.5)["cmd"])
        cmds = np.concatenate(cmds)
    # THEN every motor command stayed within [0, F_max], and the limits were actually reached
    assert cmds.min() >= 0.0 and cmds.max() <= 30.0
    assert np.isclose(cmds, 0.0).any() or np.isclose(cmds, 30.0).any()


def _roll_rise_time(preset: str) -> float:
    """Rise time of roll after a roll-stick step at hover: time to 63.2 % of the final angle.

    The time-constant definition is used because the presets end up with different damping under
    the same gains (the large drone's lower torque-to-inertia ratio leaves it slightly
    underdamped), and a 10-90 % rise time rewards overshoot: it would call an oscillating
    response "faster".
    """
    with Simulation(load_world_text(flat_world(drone("d1", preset=preset)))) as sim:
        hover(sim, "d1", 20.0, 10.0)
        sim.teleop("d1", 0.0, 0.0, 0.0, 0.0)
        sim.run(duration=1.0)
        row = sim.row("d1")
        sim.teleop("d1", 0.0, 0.0, 0.5, 0.0)
        t0 = sim.sim_time_s
        t, roll = [], []
        for _ in range(int(2.0 / sim.dt_s)):
            sim.step()
            q = sim.fleet.quat_enu_flu_xyzw[row]
            roll.append(math.atan2(2 * (q[3] * q[0] + q[1] * q[2]), 1 - 2 * (q[0] ** 2 + q[1] ** 2)))
            t.append(sim.sim_time_s - t0)
    roll = np.abs(np.array(roll) - roll[0])
    final = np.mean(roll[-60:])
    assert final > math.radians(5)
    return t[int(np.argmax(roll >= 0.632 * final))]


def test_large_drone_rolls_slower_than_small_drone_with_the_same_gains():
    # The paper's observation, measured: less motor torque per unit of inertia => slower attitude. With
    # motors sized for a thrust-to-weight of 2 the large drone has 61 % of the small one's torque per
    # unit of inertia (the paper's motors: 43 %), and both loops are near their overdamped limit, where
    # the rise time tends to gain_rate_d / gain_att_p = 0.17 s whatever the airframe: the gap is small.
    small, large = _roll_rise_time("small"), _roll_rise_time("large")
    assert large > small


def test_pure_pursuit_flies_a_4_waypoint_route_within_half_a_metre_and_stops_on_the_last_point():
    mission = """
      mission:
        name: square
        cruise_speed: 3.0
        steps:
          - {type: takeoff, altitude_m: 10.0}
          - type: cruise
            waypoints:
              - {x: 20.0, y: 0.0, z: 10.0}
              - {x: 20.0, y: 20.0, z: 10.0}
              - {x: 0.0, y: 20.0, z: 10.0}
              - {x: 0.0, y: 40.0, z: 10.0}
          - {type: idle, duration_s: 30.0}
"""
    legs = np.array([[0, 0, 10], [20, 0, 10], [20, 20, 10], [0, 20, 10], [0, 40, 10]], dtype=float)
    with Simulation(load_world_text(flat_world(drone("d1", components=mission)))) as sim:
        row = sim.row("d1")
        while sim.mission_status("d1")["step_type"] != "cruise":
            sim.step()
        track, ys = [], []
        while sim.mission_status("d1")["step_type"] == "cruise":
            sim.step()
            p = sim.fleet.pos_enu_m[row]
            track.append(min(_dist_to_segment(p, a, b) for a, b in zip(legs[:-1], legs[1:])))
            ys.append(p[1])
        sim.run(duration=10.0)
        final = sim.position_enu_m("d1")
    assert max(track) < 0.5
    assert max(ys) - 40.0 < 0.3
    assert np.linalg.norm(final - legs[-1]) < 0.3


def _dist_to_segment(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
    d = b - a
    t = np.clip(np.dot(p - a, d) / np.dot(d, d), 0, 1)
    return float(np.linalg.norm(p - (a + t * d)))


def test_switching_from_auto_to_manual_at_hover_does_not_jump_thrust_or_attitude():
    with Simulation(load_world_text(flat_world(drone("d1")))) as sim:
        hover(sim, "d1", 10.0, 15.0)
        row = sim.row("d1")
        before = measure(sim, "d1", 0.5)
        sim.teleop("d1", 0.0, 0.0, 0.0, 0.0)
        after = measure(sim, "d1", 0.5)
        assert sim.fleet.flight_mode[row] == FlightMode.MANUAL
        # thrust continuous across the switch (well under 1 % of the weight)
        assert abs(after["thrust"][0] - before["thrust"][-1]) < 0.01 * 8.0 * G
        assert np.max(np.abs(after["z"] - 10.0)) < 0.1


def test_low_battery_ends_the_mission_and_lands():
    comps = """
      energy: {initial_soc_frac: 0.102, battery_wh: 20.0}
      mission:
        name: long
        steps:
          - {type: takeoff, altitude_m: 10.0}
          - {type: idle, duration_s: 300.0}
"""
    with Simulation(load_world_text(flat_world(drone("d1", components=comps)))) as sim:
        sim.run(until=60.0)
        status = sim.mission_status("d1")
        assert status["state"] == "failed" and status["reason"] == "low_battery"
        assert sim.fleet.flight_mode[sim.row("d1")] == FlightMode.DISARMED
        assert sim.position_enu_m("d1")[2] < 0.5


def test_recharge_on_a_pad_refills_the_battery_at_the_charger_power():
    comps = """
      energy: {initial_soc_frac: 0.5, charge_power_w: 10000.0, battery: ideal}
      mission:
        name: charge
        steps:
          - {type: recharge, target_soc_frac: 0.6}
"""
    with Simulation(load_world_text(flat_world(drone("d1", pose="{pad: home}", components=comps)))) as sim:
        sim.run(until=17.5)
        # 10 % of 500 Wh = 50 Wh at (10 000 - 15) W net takes 18.03 s: not yet...
        assert sim.mission_status("d1")["state"] != "completed"
        assert sim.fleet.soc_frac[sim.row("d1")] == pytest.approx(0.5 + 0.1 * 17.5 / 18.03, abs=0.002)
        sim.run(until=19.0)
        # ... and then done, at 60 %
        assert sim.mission_status("d1")["state"] == "completed"
        assert sim.fleet.soc_frac[sim.row("d1")] == pytest.approx(0.6, abs=0.002)


def test_bad_mission_is_rejected_whole_and_the_drone_keeps_hovering():
    from unetyemu_ecs import ConfigError

    with Simulation(load_world_text(flat_world(drone("d1")))) as sim:
        hover(sim, "d1", 10.0, 10.0)
        bad = '{"steps": [{"type": "takeoff"}, {"type": "cruise", "waypoints": [{"x": 1, "y": 2, "z": "high"}]}]}'
        with pytest.raises(ConfigError, match=r"steps\[1\]\.waypoints\[0\]\.z"):
            sim.load_mission("d1", bad)
        with pytest.raises(ConfigError, match="unknown pad 'nowhere'"):
            sim.load_mission("d1", '{"steps": [{"type": "land", "pad": "nowhere"}]}')
        sim.run(duration=2.0)
        assert sim.mission_status("d1") is None
        assert abs(sim.position_enu_m("d1")[2] - 10.0) < 0.1


def test_bad_api_commands_raise_and_change_nothing():
    with Simulation(load_world_text(flat_world(drone("d1")))) as sim:
        with pytest.raises(ValueError, match="finite"):
            sim.set_target("d1", float("nan"), 0, 10)
        with pytest.raises(ValueError, match=r"\[-1, 1\]"):
            sim.teleop("d1", 2.0, 0, 0, 0)
        with pytest.raises(KeyError, match="no vehicle"):
            sim.set_target("ghost", 0, 0, 10)
        sim.step(10)
        assert sim.fleet.flight_mode[sim.row("d1")] == FlightMode.DISARMED


def test_yaw_comes_from_rotor_reaction_torques_and_reaches_the_commanded_heading():
    with Simulation(load_world_text(flat_world(drone("d1")))) as sim:
        hover(sim, "d1", 10.0, 8.0)
        sim.set_target("d1", 0.0, 0.0, 10.0, yaw_deg=90.0)
        sim.run(duration=2.0)
        row = sim.row("d1")
        # 90° -> -150° is the short way round counter-clockwise (+120°): the CW-spinning motors
        # (FR, BL) push harder than the CCW ones (FL, BR) so that their reaction torque turns the body CCW
        sim.set_target("d1", 0.0, 0.0, 10.0, yaw_deg=-150.0)
        sim.step(24)
        thrust = sim.fleet.motor_thrust_n[row]
        assert thrust[1] + thrust[3] > thrust[0] + thrust[2]
        assert sim.fleet.rate_enu_rad_s[row][2] > 0.0          # and the body does turn CCW
        sim.run(duration=8.0)
        q = sim.attitude_enu_flu_xyzw("d1")
        yaw = math.degrees(math.atan2(2 * (q[3] * q[2] + q[0] * q[1]), 1 - 2 * (q[1] ** 2 + q[2] ** 2)))
        assert abs(yaw - (-150.0)) < 2.0
        assert abs(sim.position_enu_m("d1")[2] - 10.0) < 0.1


def test_motor_lag_makes_applied_thrust_follow_the_command_as_a_first_order_system():
    comps = "      motors: {motor_tau_s: 0.05}\n"
    with Simulation(load_world_text(flat_world(drone("d1", components=comps)))) as sim:
        sim.set_target("d1", 0.0, 0.0, 10.0)
        sim.step(2)          # step 0 applies the command, step 1 runs the first lagged motor update
        row = sim.row("d1")
        cmd = sim.fleet.motor_thrust_cmd_n[row].copy()
        applied = sim.fleet.motor_thrust_n[row].copy()
        alpha = 1.0 - math.exp(-sim.dt_s / 0.05)
        assert np.all(cmd > 0)
        assert np.all(applied < cmd)
        # two updates from zero: 1 - (1 - alpha)^2 of a (nearly) constant command
        assert applied.sum() == pytest.approx(cmd.sum() * (1 - (1 - alpha) ** 2), rel=0.05)


def test_several_pickups_and_deliveries_in_one_run():
    packages = "\n".join([
        "  - {name: p1, mass_kg: 1.0, size_m: [0.3, 0.3, 0.3], pose: {position_m: [1.0, 0.0, 0.25]}}",
        "  - {name: p2, mass_kg: 2.0, size_m: [0.3, 0.3, 0.3], pose: {position_m: [31.0, 0.0, 0.25]}}"])
    mission = """
      mission:
        name: swap
        cruise_speed: 6.0
        steps:
          - {type: pickup, package: p1}
          - {type: takeoff, altitude_m: 6.0}
          - {type: cruise, waypoints: [{x: 30.0, y: 5.0, z: 6.0}]}
          - {type: deliver, waypoints: [{x: 30.0, y: 5.0, z: 0.0}]}
          - {type: pickup, package: p2}
          - {type: takeoff, altitude_m: 6.0}
          - {type: cruise, waypoints: [{x: 0.0, y: 5.0, z: 6.0}]}
          - {type: deliver, waypoints: [{x: 0.0, y: 5.0, z: 0.0}]}
"""
    with Simulation(load_world_text(flat_world(drone("d1", components=mission), packages=packages))) as sim:
        while sim.sim_time_s < 120.0 and sim.mission_status("d1")["state"] != "completed":
            sim.run(duration=2.0)
        status = sim.mission_status("d1")
        assert status["state"] == "completed", sim.events
        # each package was carried to the other side and set down there
        p1, p2 = sim.position_enu_m("p1"), sim.position_enu_m("p2")
        assert np.linalg.norm(p1[:2] - [30.0, 5.0]) < 1.0 and p1[2] < 0.5
        assert np.linalg.norm(p2[:2] - [0.0, 5.0]) < 1.0 and p2[2] < 0.5
        assert sim.fleet.payload_kg[sim.row("d1")] == 0.0


def test_a_mixed_fleet_with_its_own_gains_flies_to_separate_targets_at_once():
    # GIVEN three drones of different presets, one with softer guidance gains, all in automatic mode together
    soft = "{position: {name: cascade_pid, params: {gain_vel_p: 1.2, gain_pos_p: 0.6}}}"
    drones = (drone("s", "small", "{position_m: [0.0, 0.0, 0.3]}")
              + drone("m", "medium", "{position_m: [5.0, 0.0, 0.3]}", controller=soft)
              + drone("l", "large", "{position_m: [10.0, 0.0, 0.3]}"))
    targets = {"s": (-10.0, 15.0, 8.0), "m": (20.0, 15.0, 12.0), "l": (10.0, -15.0, 6.0)}
    with Simulation(load_world_text(flat_world(drones))) as sim:
        for name, (x, y, z) in targets.items():
            sim.set_target(name, x, y, z)
        sim.run(duration=25.0)
        # THEN each arrives at its own target and holds it
        for name, target in targets.items():
            assert np.linalg.norm(sim.position_enu_m(name) - target) < 0.15, name
            assert np.linalg.norm(sim.velocity_enu_m_s(name)) < 0.1, name


def test_flying_into_a_building_is_reported_as_an_impact_naming_it_and_a_landing_is_not():
    # GIVEN a drone 20 m west of a 30 m tall building on flat ground
    world = """
world: {name: crash, physics_hz: 240, seed: 7}
scene:
  generator: none
  ground_size_m: 200
  buildings: [{center_m: [20.0, 0.0], size_m: [10.0, 10.0], height_m: 30.0}]
  pads: [{name: home, position_m: [0, 0]}]
vehicles:
""" + drone("d1")
    with Simulation(load_world_text(world)) as sim:
        # WHEN it takes off, lands and takes off again THEN none of that is an impact
        hover(sim, "d1", 10.0, 6.0)
        sim.set_target("d1", 0.0, 0.0, 0.0, speed=3.0)
        sim.run(duration=10.0)
        assert sim.position_enu_m("d1")[2] < 0.5
        hover(sim, "d1", 10.0, 6.0)
        assert sim.fleet.impacts[sim.row("d1")] == 0, sim.events
        # WHEN it is sent through the building at 6 m/s (and pressed against it for a second)
        sim.set_target("d1", 40.0, 0.0, 10.0, speed=6.0)
        sim.run(duration=4.0)
        # THEN exactly one impact is reported, naming the building and a point on its west face
        building = next(o for o in sim.layout.objects if o.cls == SceneClass.BUILDING)
        impacts = [e for e in sim.events if e[2].startswith("impact")]
        assert len(impacts) == 1 and sim.fleet.impacts[sim.row("d1")] == 1, impacts
        t, who, text = impacts[0]
        assert who == "d1" and f"impact with {building.name} at 6." in text
        x_hit = float(text.split("ENU (")[1].split(",")[0])
        assert x_hit == pytest.approx(15.0, abs=0.1)
        # AND the drone did not pass through the wall
        assert sim.position_enu_m("d1")[0] < 15.0


def test_cmd_vel_flies_the_body_frame_velocity_and_yaw_rate_and_holds_altitude():
    with Simulation(load_world_text(flat_world(drone("d1")))) as sim:
        hover(sim, "d1", 10.0, 8.0)
        # WHEN cmd_vel asks for 3 m/s forward and 1 m/s left (body frame), no yaw rate, no climb
        yaw0 = _yaw(sim, "d1")
        sim.cmd_vel("d1", 3.0, 0.0, left_m_s=1.0)
        sim.run(duration=6.0)
        # THEN the drone is in VELOCITY mode, flying that velocity turned into ENU by its heading
        assert sim.fleet.flight_mode[sim.row("d1")] == FlightMode.VELOCITY
        expect = np.array([3 * math.cos(yaw0) - math.sin(yaw0), 3 * math.sin(yaw0) + math.cos(yaw0)])
        v = sim.velocity_enu_m_s("d1")
        assert np.linalg.norm(v[:2] - expect) < 0.15 and abs(v[2]) < 0.1
        assert abs(sim.position_enu_m("d1")[2] - 10.0) < 0.3
        # WHEN it adds a yaw rate of 0.5 rad/s and a climb of 1 m/s
        sim.cmd_vel("d1", 3.0, 0.5, up_m_s=1.0)
        sim.run(duration=2.0)
        yaw_a = _yaw(sim, "d1")
        z_a = sim.position_enu_m("d1")[2]
        sim.run(duration=2.0)
        # THEN the heading turns at 0.5 rad/s, it climbs at 1 m/s and its velocity turns with the nose,
        # trailing it by about atan(yaw rate / velocity-loop gain) (a first-order loop chasing a turning setpoint)
        yaw_b = _yaw(sim, "d1")
        assert math.remainder(yaw_b - yaw_a, math.tau) == pytest.approx(1.0, abs=0.05)
        assert sim.position_enu_m("d1")[2] - z_a == pytest.approx(2.0, abs=0.1)
        v = sim.velocity_enu_m_s("d1")
        lag = math.remainder(yaw_b - math.atan2(v[1], v[0]), math.tau)
        assert lag == pytest.approx(math.atan(0.5 / GuidanceGains().gain_vel_p), abs=0.05)
        assert np.linalg.norm(v[:2]) == pytest.approx(3.0, abs=0.15)
        # WHEN cmd_vel is all zero THEN it stops (the velocity loop's integral of the drag it was
        # compensating decays over a few seconds) and hovers
        sim.cmd_vel("d1", 0.0, 0.0)
        sim.run(duration=8.0)
        assert np.linalg.norm(sim.velocity_enu_m_s("d1")) < 0.1


def test_cmd_vel_climb_and_yaw_rate_are_clamped_to_the_drone_limits():
    with Simulation(load_world_text(flat_world(drone("d1")))) as sim:
        hover(sim, "d1", 5.0, 6.0)
        sim.cmd_vel("d1", 0.0, 6.0, up_m_s=25.0)       # within the API's ranges, beyond the drone's limits
        sim.run(duration=3.0)
        f, row = sim.fleet, sim.row("d1")
        lim = sim.component("d1", GuidanceLimits)
        assert f.vz_sp_m_s[row] == pytest.approx(lim.lim_climb_m_s)
        assert f.yaw_rate_sp_rad_s[row] == pytest.approx(math.radians(lim.lim_yaw_rate_deg_s))
        with pytest.raises(ValueError, match="finite"):
            sim.cmd_vel("d1", math.nan, 0.0)


def _yaw(sim: Simulation, name: str) -> float:
    """The drone's ENU heading [rad] (its body x axis projected on the ground)."""
    x, y, z, w = sim.attitude_enu_flu_xyzw(name)
    return math.atan2(2 * (x * y + w * z), 1 - 2 * (y * y + z * z))
