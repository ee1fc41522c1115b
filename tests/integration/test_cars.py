"""Ground vehicles in PyBullet: braking, turning, routes, teleop, cmd_vel and collisions, checked against physics."""

from __future__ import annotations

import math

import numpy as np
import pybullet as p
import pytest

from unetyemu_ecs import Simulation, load_world_text
from unetyemu_ecs.components.car import CarBody, CarDynamics
from unetyemu_ecs.control.car import steer_limit_rad
from unetyemu_ecs.systems.car_state import DriveMode

G = 9.81
ROAD_FRICTION = 0.9          # the ground's friction coefficient; the tyre's 1.0 multiplies it


def world(vehicles: str, extra: str = "") -> str:
    return f"""
world: {{name: cars, physics_hz: 240, seed: 3}}
scene: {{generator: none, ground_size_m: 600}}
{extra}
vehicles:
{vehicles}
"""


def car(name: str, x: float = 0.0, y: float = 0.0, yaw_deg: float = 0.0, preset: str = "medium") -> str:
    z = {"medium": 0.9, "truck": 1.65}[preset]
    return (f"  - {{name: {name}, type: car, preset: {preset}, "
            f"pose: {{position_m: [{x}, {y}, {z}], yaw_deg: {yaw_deg}}}}}\n")


def speed(sim: Simulation, name: str) -> float:
    return float(sim.fleet.car_speed_m_s[sim.row(name)])


def accelerate_to(sim: Simulation, name: str, target_m_s: float) -> None:
    sim.drive(name, 1.0, 0.0, 0.0)
    for _ in range(240 * 30):
        sim.step()
        if speed(sim, name) >= target_m_s:
            return
    raise AssertionError(f"{name} did not reach {target_m_s} m/s")


def stopping_distance(sim: Simulation, name: str, brake: float) -> tuple[float, float]:
    """Brake from the current speed to rest; return (distance [m], initial speed [m/s])."""
    start, v0 = sim.position_enu_m(name).copy(), speed(sim, name)
    sim.drive(name, 0.0, brake, 0.0)
    for _ in range(240 * 30):
        sim.step()
        if speed(sim, name) < 0.01:
            break
    return float(np.linalg.norm(sim.position_enu_m(name)[:2] - start[:2])), v0


def braking_decel(dyn: CarDynamics, mass_kg: float, brake: float) -> float:
    """Deceleration implied by the brake torque and the friction: torque-limited below mu g.

    Four wheels each brake with ``brake T_max + C_rr m g r / 4``; the wheels' spin inertia (solid
    disc, 0.5 m r^2 each) adds to the mass that the brakes slow down.
    """
    r = dyn.wheel_radius_m
    torque = brake * dyn.max_brake_torque_n_m + dyn.rolling_resistance_coeff * mass_kg * G * r / 4.0
    m_eff = mass_kg + 4 * 0.5 * dyn.wheel_mass_kg
    return min(4.0 * torque / (r * m_eff), dyn.tyre_friction * ROAD_FRICTION * G)


@pytest.mark.parametrize("brake, regime", [(0.3, "brake torque"), (1.0, "tyre friction")])
def test_stopping_distance_from_10_m_s_matches_brake_torque_and_friction(brake, regime):
    with Simulation(load_world_text(world(car("c1")))) as sim:
        sim.run(duration=1.0)
        dyn = sim.component("c1", CarDynamics)
        mass = float(sim.definition_of("c1").params["mass_kg"])
        accelerate_to(sim, "c1", 10.0)
        dist, v0 = stopping_distance(sim, "c1", brake)
        expected = v0 ** 2 / (2.0 * braking_decel(dyn, mass, brake))
        assert dist == pytest.approx(expected, rel=0.10), regime
        # and the car stays upright and on its wheels
        roll_pitch = p.getEulerFromQuaternion(sim.attitude_enu_flu_xyzw("c1").tolist())[:2]
        assert max(abs(a) for a in roll_pitch) < math.radians(3)


def test_car_settles_on_its_suspension_at_the_static_ride_height_and_stays_there_asleep():
    with Simulation(load_world_text(world(car("c1")))) as sim:
        sim.run(duration=2.0)
        # the suspension preload makes zero deflection the static rest: the chassis sits where placed
        z_settled = sim.position_enu_m("c1")[2]
        assert z_settled == pytest.approx(0.9, abs=0.02)
        assert np.linalg.norm(sim.velocity_enu_m_s("c1")) < 1e-3
        # long after Bullet put it to sleep (and the actuation stopped sending it forces) it has not moved
        sim.run(duration=20.0)
        assert sim.position_enu_m("c1")[2] == pytest.approx(z_settled, abs=1e-4)


def test_a_20_m_radius_turn_at_5_m_s_holds_its_radius_and_the_steering_stays_within_its_limit():
    with Simulation(load_world_text(world(car("c1")))) as sim:
        sim.run(duration=1.0)
        sim.cmd_vel("c1", 5.0, 5.0 / 20.0)
        row = sim.row("c1")
        dyn = sim.component("c1", CarDynamics)
        joints = sim.component("c1", CarBody).joints
        xy, worst = [], 0.0
        for i in range(240 * 40):
            sim.step()
            limit = float(steer_limit_rad(np.array([speed(sim, "c1")]), np.deg2rad(dyn.max_steer_deg),
                                          dyn.steer_scale_at_50_m_s)[0])
            wheels = [p.getJointState(sim.fleet.body_id[row], j, physicsClientId=sim.physics.id)[0]
                      for j in joints.steering]
            worst = max(worst, max(abs(w) for w in wheels) - limit)
            if i >= 240 * 15:
                xy.append(sim.position_enu_m("c1")[:2].copy())
        xy = np.array(xy)
        # least-squares circle through the last 25 s of the track
        a = np.c_[2 * xy, np.ones(len(xy))]
        cx, cy, k = np.linalg.lstsq(a, (xy ** 2).sum(1), rcond=None)[0]
        radius = np.hypot(xy[:, 0] - cx, xy[:, 1] - cy)
        assert np.all(np.abs(radius - 20.0) < 1.0), (radius.min(), radius.max())
        assert speed(sim, "c1") == pytest.approx(5.0, abs=0.1)
        assert worst <= math.radians(0.5)


def test_steering_limit_shrinks_with_speed_even_for_an_impossible_yaw_rate():
    with Simulation(load_world_text(world(car("c1")))) as sim:
        sim.run(duration=1.0)
        sim.cmd_vel("c1", 20.0, 0.0)
        sim.run(duration=15.0)
        sim.cmd_vel("c1", 20.0, 3.0)           # asks for far more than the tyres can give
        row = sim.row("c1")
        dyn = sim.component("c1", CarDynamics)
        joints = sim.component("c1", CarBody).joints
        for _ in range(240):
            sim.step()
            limit = steer_limit_rad(np.array([speed(sim, "c1")]), np.deg2rad(dyn.max_steer_deg),
                                    dyn.steer_scale_at_50_m_s)[0]
            wheels = [p.getJointState(sim.fleet.body_id[row], j, physicsClientId=sim.physics.id)[0]
                      for j in joints.steering]
            assert max(abs(w) for w in wheels) <= limit + math.radians(0.5)
        assert limit < math.radians(25.0)           # 30 deg at rest, ~22 deg at 18-20 m/s


def test_full_throttle_never_exceeds_the_top_speed():
    with Simulation(load_world_text(world(car("c1")))) as sim:
        sim.run(duration=0.5)
        sim.drive("c1", 1.0, 0.0, 0.0)
        top = sim.component("c1", CarDynamics).top_speed_m_s
        fastest = 0.0
        for _ in range(40):
            sim.run(duration=1.0)
            fastest = max(fastest, speed(sim, "c1"))
        assert 0.9 * top < fastest <= top


def test_a_car_driven_into_a_parked_car_at_5_m_s_pushes_it_and_both_stay_upright():
    with Simulation(load_world_text(world(car("mover", x=-20.0) + car("parked", x=0.0)))) as sim:
        sim.run(duration=1.0)
        before = sim.position_enu_m("parked").copy()
        sim.cmd_vel("mover", 5.0, 0.0)
        sim.run(duration=8.0)
        # THEN there was an impact and the parked car (brakes on) was shoved forward
        impacts = [e for e in sim.events if e[2].startswith("impact with parked") or "impact with mover" in e[2]]
        assert impacts, sim.events
        assert sim.position_enu_m("parked")[0] - before[0] > 0.3
        for name in ("mover", "parked"):
            roll, pitch, _ = p.getEulerFromQuaternion(sim.attitude_enu_flu_xyzw(name).tolist())
            assert abs(roll) < math.radians(10) and abs(pitch) < math.radians(10), name


def test_a_drone_flying_into_a_parked_car_is_deflected_and_the_car_rocks():
    drone = "  - {name: d1, type: quadrotor, preset: medium, pose: {position_m: [-15.0, 0.0, 0.3]}}\n"
    with Simulation(load_world_text(world(car("parked") + drone))) as sim:
        sim.set_target("d1", -15.0, 0.0, 1.0)
        sim.run(duration=4.0)
        row = sim.row("parked")
        sim.set_target("d1", 15.0, 0.0, 1.0, speed=6.0)
        rocking = 0.0
        velocity_before = None
        for _ in range(240 * 4):
            sim.step()
            if sim.position_enu_m("d1")[0] < -3.5:
                velocity_before = sim.velocity_enu_m_s("d1").copy()
            rocking = max(rocking, float(np.linalg.norm(sim.fleet.rate_enu_rad_s[row, :2])))
        # THEN the drone hit the car's side and bounced: its course no longer points through the car
        assert any(e[1] == "d1" and "impact with parked" in e[2] for e in sim.events), sim.events
        assert velocity_before is not None and velocity_before[0] > 3.0
        assert sim.position_enu_m("d1")[0] < -2.0                 # it did not pass through the car
        # AND the car rocked on its suspension (roll/pitch rate), then settled upright
        assert rocking > 0.01
        roll, pitch, _ = p.getEulerFromQuaternion(sim.attitude_enu_flu_xyzw("parked").tolist())
        assert abs(roll) < math.radians(2) and abs(pitch) < math.radians(2)


def test_teleop_drives_forward_reverses_and_steers_left_as_documented():
    with Simulation(load_world_text(world(car("c1")))) as sim:
        sim.run(duration=0.5)
        sim.drive("c1", 0.5, 0.0, 0.0)
        sim.run(duration=3.0)
        assert speed(sim, "c1") > 2.0 and sim.position_enu_m("c1")[0] > 2.0        # forward = +x at yaw 0
        sim.drive("c1", 0.3, 0.0, 1.0)                                            # full left
        yaw0 = p.getEulerFromQuaternion(sim.attitude_enu_flu_xyzw("c1").tolist())[2]
        sim.run(duration=1.0)
        yaw1 = p.getEulerFromQuaternion(sim.attitude_enu_flu_xyzw("c1").tolist())[2]
        assert yaw1 - yaw0 > math.radians(10)                                      # turned CCW (left)
        sim.drive("c1", 0.0, 1.0, 0.0)
        sim.run(duration=4.0)
        assert abs(speed(sim, "c1")) < 0.05
        sim.drive("c1", -0.4, 0.0, 0.0)                                           # reverse
        sim.run(duration=2.0)
        assert speed(sim, "c1") < -1.0


def test_cmd_vel_holds_speed_forward_and_backward_and_switching_from_teleop_is_bumpless():
    with Simulation(load_world_text(world(car("c1")))) as sim:
        sim.run(duration=0.5)
        sim.drive("c1", 0.4, 0.0, 0.0)
        sim.run(duration=4.0)
        row = sim.row("c1")
        throttle_before = float(sim.fleet.car_throttle[row])
        v_before = speed(sim, "c1")
        sim.cmd_vel("c1", v_before, 0.0)      # take over at the current speed
        sim.step()
        assert sim.fleet.drive_mode[row] == DriveMode.VELOCITY
        assert float(sim.fleet.car_throttle[row]) == pytest.approx(throttle_before, abs=0.05)
        sim.cmd_vel("c1", 6.0, 0.0)
        sim.run(duration=10.0)
        assert speed(sim, "c1") == pytest.approx(6.0, abs=0.1)
        sim.cmd_vel("c1", -2.0, 0.0)
        sim.run(duration=12.0)
        assert speed(sim, "c1") == pytest.approx(-2.0, abs=0.1)
        sim.cmd_vel("c1", 0.0, 0.0)
        sim.run(duration=5.0)
        assert abs(speed(sim, "c1")) < 0.05


def test_set_target_drives_a_car_there_and_parks_it():
    with Simulation(load_world_text(world(car("c1")))) as sim:
        sim.run(duration=0.5)
        sim.set_target("c1", 40.0, 25.0, speed=6.0)
        sim.run(duration=30.0)
        assert np.linalg.norm(sim.position_enu_m("c1")[:2] - [40.0, 25.0]) < 2.0
        assert sim.fleet.drive_mode[sim.row("c1")] == DriveMode.PARKED
        assert any(who == "c1" and text == "route done" for _, who, text in sim.events)


def test_bad_car_commands_raise_and_drone_commands_on_a_car_are_rejected_without_stopping():
    drone = "  - {name: d1, type: quadrotor, preset: medium, pose: {position_m: [-15.0, 0.0, 0.3]}}\n"
    with Simulation(load_world_text(world(car("c1") + drone))) as sim:
        with pytest.raises(ValueError, match="brake"):
            sim.drive("c1", 0.5, 2.0, 0.0)
        with pytest.raises(ValueError, match="finite"):
            sim.cmd_vel("c1", float("nan"), 0.0)
        with pytest.raises(ValueError, match="not a car"):
            sim.drive("d1", 0.5, 0.0, 0.0)
        with pytest.raises(ValueError, match="not a drone"):
            sim.teleop("c1", 0.0, 0.0, 0.0, 0.0)
        with pytest.raises(ValueError, match="loop needs at least 3"):
            sim.drive_route("c1", [(10.0, 0.0), (20.0, 0.0)], loop=True)
        # a cmd_vel beyond the car's top speed (25 m/s) but within the API's range reaches the sim
        # (as from ROS 2) and is rejected there
        sim.cmd_vel("c1", 28.0, 0.0)
        sim.step(5)
        assert any(who == "c1" and "rejected cmd_vel" in text and "top speed" in text for _, who, text in sim.events)
        assert sim.fleet.drive_mode[sim.row("c1")] == DriveMode.PARKED


def test_a_car_driven_into_a_building_stops_at_its_wall_upright_and_the_impact_names_it():
    extra = "  buildings: [{center_m: [30.0, 0.0], size_m: [10.0, 20.0], height_m: 12.0}]"
    text = world(car("c1"), extra="").replace("scene: {generator: none, ground_size_m: 600}",
                                              "scene:\n  generator: none\n  ground_size_m: 600\n" + extra)
    with Simulation(load_world_text(text)) as sim:
        sim.run(duration=0.5)
        sim.cmd_vel("c1", 6.0, 0.0)
        sim.run(duration=8.0)
        impacts = [t for _, who, t in sim.events if who == "c1" and t.startswith("impact with building")]
        assert len(impacts) == 1, sim.events
        # the wall is at x = 25; the car's nose (2.25 m ahead of its centre) stops there
        assert sim.position_enu_m("c1")[0] == pytest.approx(25.0 - 2.25, abs=0.3)
        roll, pitch, _ = p.getEulerFromQuaternion(sim.attitude_enu_flu_xyzw("c1").tolist())
        assert abs(roll) < math.radians(5) and abs(pitch) < math.radians(5)


def test_a_two_lap_route_reports_each_lap_and_the_summary_says_two_laps():
    # GIVEN a car told to drive two laps round a 30 m square
    square = [(30.0, 0.0), (30.0, 30.0), (0.0, 30.0), (0.0, 0.0)]
    with Simulation(load_world_text(world(car("c1")))) as sim:
        sim.run(duration=0.5)
        sim.drive_route("c1", square, speed=6.0, loop=True, laps=2)
        # WHEN it has driven them and parked
        for _ in range(120):
            sim.run(duration=1.0)
            if sim.drive_status("c1")["route"] == "done":
                break
        # THEN it says two laps, each lap was an event, and the summary agrees
        assert sim.drive_status("c1") == {"mode": "parked", "route": "done", "laps": 2}
        laps = [text for _, who, text in sim.events if who == "c1" and text.startswith("route lap")]
        assert laps == ["route lap 1 done", "route lap 2 done"]
        car1 = next(e for e in sim.summary()["entities"] if e["name"] == "c1")
        assert car1["drive"]["laps"] == 2


def _settled_support(sim: Simulation, name: str, surface: str) -> tuple[float, float, float]:
    """(weight [N], normal force the ``surface`` class carries, normal force anything else carries) of a settled car."""
    cid = sim.physics.id
    below = next(b for b, cls in sim.static_body_ids.items() if cls.name == surface)
    body = int(sim.fleet.body_id[sim.row(name)])
    weight_n = G * sum(p.getDynamicsInfo(body, link, physicsClientId=cid)[0]
                       for link in range(-1, p.getNumJoints(body, physicsClientId=cid)))
    contacts = p.getContactPoints(bodyA=body, physicsClientId=cid)
    return (weight_n, sum(c[9] for c in contacts if c[2] == below), sum(c[9] for c in contacts if c[2] != below))


def test_a_car_parked_on_a_road_rests_on_the_road_2_mm_above_the_ground_and_the_road_carries_its_weight():
    # GIVEN a car parked on a city road (whose surface lies 2 mm above the ground plane) and one on bare ground
    from unetyemu_ecs.scene.primitives import ROAD_TOP_Z_M
    city = world("  - {name: c1, type: car, preset: medium, pose: {parking: parking_1}}\n").replace(
        "scene: {generator: none, ground_size_m: 600}",
        "scene: {generator: urban, urban: {blocks_x: 2, blocks_y: 2, block_size_m: 40, street_width_m: 12, "
        "building_height_m: [8, 12], start_pads: 1, target_pads: 0, roof_pads: 0, parking_spots: 1}}")
    heights = {}
    for text, name, surface in ((city, "c1", "ROAD"), (world(car("c2")), "c2", "GROUND")):
        with Simulation(load_world_text(text)) as sim:
            # WHEN it has settled
            sim.run(duration=3.0)
            # THEN the surface beneath carries the whole weight through the tyres, and nothing else any of it
            weight_n, carried_n, elsewhere_n = _settled_support(sim, name, surface)
            assert carried_n == pytest.approx(weight_n, rel=0.02), name
            assert elsewhere_n == pytest.approx(0.0, abs=1e-6), name
            heights[name] = float(sim.position_enu_m(name)[2])
    # and the car on the road rides the road's height higher than the one on bare ground
    assert heights["c1"] - heights["c2"] == pytest.approx(ROAD_TOP_Z_M, abs=5e-4)
