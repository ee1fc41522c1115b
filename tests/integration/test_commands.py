"""Commands as a robot driver treats them: streams lapse, targets stay in the world and warn about
walls in the way, and live commands win over the world file's script."""

from __future__ import annotations

import numpy as np
import pytest

from unetyemu_ecs import Simulation, load_world_text
from unetyemu_ecs.sensors.messages import msg_type
from unetyemu_ecs.systems.car_state import DriveMode
from unetyemu_ecs.systems.flight_state import FlightMode
from unetyemu_ecs.transport.ros2.inbound import CommandContext, to_command

WORLD = """
world: {name: commands, physics_hz: 240, seed: 9}
scene:
  generator: none
  ground_size_m: 300
  buildings: [{center_m: [60, 0], size_m: [20, 20], height_m: 30}]
vehicles:
  - {name: d1, type: quadrotor, preset: small, pose: {position_m: [0, 0, 0.2]}%s}
  - {name: c1, type: car, preset: medium, pose: {position_m: [0, 40, 0.9]}}
"""


def apply_command(sim: Simulation, vehicle: str, kind: str, topic_kind: str, msg, hold_s: float | None = None) -> int:
    """What the ROS 2 transport does with one sample of a command topic: build the command, submit it."""
    context = CommandContext(sim.layout, tuple(sim.package_names))
    return sim.inbox.submit(to_command(context, vehicle, kind, topic_kind, msg, hold_s))


def make(extra: str = "", timeout: str = "") -> Simulation:
    return Simulation(load_world_text(WORLD % (extra + timeout)))


def twist(x: float = 0.0, z: float = 0.0, yaw_rate: float = 0.0):
    Vector3, Twist = msg_type("geometry_msgs/msg/Vector3"), msg_type("geometry_msgs/msg/Twist")
    return Twist(linear=Vector3(x=x, y=0.0, z=z), angular=Vector3(x=0.0, y=0.0, z=yaw_rate))


def float_array(values: list[float]):
    Layout = msg_type("std_msgs/msg/MultiArrayLayout")
    return msg_type("std_msgs/msg/Float32MultiArray")(layout=Layout(dim=[], data_offset=0),
                                                      data=np.array(values, dtype=np.float32))


def events_of(sim: Simulation, name: str) -> list[str]:
    return [text for _, who, text in sim.events if who == name]


def test_a_ros_cmd_vel_that_stops_arriving_lapses_after_the_command_timeout_and_the_drone_hovers():
    with make() as sim:
        assert sim.command_timeout_s("d1") == 0.5                      # the documented default
        # GIVEN a drone climbing on one cmd_vel from ROS 2 (as a 3 s teleop burst that then stops)
        apply_command(sim, "d1", "quadrotor", "cmd_vel", twist(z=3.0), hold_s=sim.command_timeout_s("d1"))
        sim.run(duration=0.4)
        assert sim.fleet.flight_mode[sim.row("d1")] == FlightMode.VELOCITY
        # WHEN no new command arrives for longer than the timeout
        sim.run(duration=3.0)
        # THEN the drone holds where it was when the command lapsed: it stopped climbing within ~1 m
        row = sim.row("d1")
        assert sim.fleet.flight_mode[row] == FlightMode.AUTO
        assert sim.position_enu_m("d1")[2] < 3.0
        assert abs(sim.velocity_enu_m_s("d1")[2]) < 0.3
        assert any("cmd_vel timed out" in t and "holding position" in t for t in events_of(sim, "d1"))


def test_a_steady_stream_keeps_flying_and_a_zero_timeout_holds_forever():
    with make(timeout=", command_timeout_s: 0") as sim:
        assert sim.command_timeout_s("d1") == 0.0
        apply_command(sim, "d1", "quadrotor", "cmd_vel", twist(z=2.0), hold_s=sim.command_timeout_s("d1") or None)
        sim.run(duration=3.0)
        assert sim.fleet.flight_mode[sim.row("d1")] == FlightMode.VELOCITY
        assert sim.position_enu_m("d1")[2] > 3.0
    with make() as sim:
        for _ in range(15):                                           # 0.2 s apart < 0.5 s timeout
            apply_command(sim, "d1", "quadrotor", "cmd_vel", twist(z=2.0), hold_s=0.5)
            sim.run(duration=0.2)
        assert sim.fleet.flight_mode[sim.row("d1")] == FlightMode.VELOCITY
        assert not any("timed out" in t for t in events_of(sim, "d1"))


def test_a_car_whose_teleop_stops_arriving_brakes_to_a_stop():
    with make() as sim:
        sim.run(duration=0.5)
        sim.drive("c1", 0.6, 0.0, 0.3, hold_s=2.0)                     # a stream that stops after one message
        sim.run(duration=2.0)
        assert float(sim.fleet.car_speed_m_s[sim.row("c1")]) > 2.0
        sim.run(duration=6.0)
        assert sim.fleet.drive_mode[sim.row("c1")] == DriveMode.VELOCITY
        assert abs(float(sim.fleet.car_speed_m_s[sim.row("c1")])) < 0.2
        assert any("teleop timed out" in t and "braking" in t for t in events_of(sim, "c1"))


def test_targets_outside_the_world_are_refused_from_python_and_from_ros():
    with make() as sim:
        with pytest.raises(ValueError, match=r"outside the world, which spans x in \[-150, 150\] m"):
            sim.set_target("d1", 1e9, 0.0, 10.0)
        with pytest.raises(ValueError, match=r"z must be in \[0, 10000\] m"):
            sim.set_target("d1", 10.0, 0.0, 50000.0)
        with pytest.raises(ValueError, match="outside the world"):
            apply_command(sim, "c1", "car", "target", float_array([0, 1e9, 0, 0, 5]))
        with pytest.raises(ValueError, match="outside the world"):
            sim.drive_route("c1", [(10.0, 0.0), (900.0, 0.0)])
        sim.set_target("d1", 100.0, -100.0, 20.0)                     # inside: fine


def test_a_target_behind_a_building_is_flown_but_warned_about_first():
    with make() as sim:
        sim.step(1)
        # WHEN the drone is sent straight through the 30 m building at x = 50..70
        sim.set_target("d1", 100.0, 0.0, 10.0)
        sim.step(1)
        # THEN a warning names the building and where the path enters it
        warnings = [t for t in events_of(sim, "d1") if t.startswith("warning")]
        assert len(warnings) == 1 and "building" in warnings[0], warnings
        assert "ENU (49.8, 0.0," in warnings[0] or "ENU (49.7, 0.0," in warnings[0], warnings[0]
        # AND a target with a clear line of flight (over the roof) has none
        sim.set_target("d1", 0.0, 100.0, 10.0)
        sim.step(1)
        assert len([t for t in events_of(sim, "d1") if t.startswith("warning")]) == 1


def test_a_live_command_stops_the_world_files_teleop_script_for_good():
    script = ", components: {teleop_script: {keyframes: [{t_s: 2.0, stick: [0.5, 0, 0, 0]}]}}"
    with make(extra=script) as sim:
        sim.run(duration=0.5)
        # GIVEN a mission loaded live (as over ROS 2) before the script's keyframe at 2 s
        sim.load_mission("d1", '{"name": "hop", "steps": [{"type": "takeoff", "altitude_m": 6}, '
                               '{"type": "idle", "duration_s": 20}]}')
        # WHEN the script's time comes
        sim.run(duration=3.0)
        # THEN the mission still runs (the script did not cancel it) and the script stopped
        assert sim.mission_status("d1")["state"] == "running"
        assert sim.fleet.flight_mode[sim.row("d1")] == FlightMode.AUTO
        assert any(t.startswith("teleop_script stopped") for t in events_of(sim, "d1"))
        assert not any("cancelled" in t for t in events_of(sim, "d1"))


def test_ros2_arm_and_nav_mode_topics_take_off_and_land_a_drone_and_refuse_unknown_modes():
    String, Bool = msg_type("std_msgs/msg/String"), msg_type("std_msgs/msg/Bool")
    with make() as sim:
        # GIVEN a drone on the ground; WHEN /d1/arm (true) and then /d1/nav_mode "takeoff" arrive
        armed = apply_command(sim, "d1", "quadrotor", "arm", Bool(data=True))
        sim.step()
        takeoff = apply_command(sim, "d1", "quadrotor", "nav_mode", String(data="takeoff"))
        sim.run(duration=6.0)
        # THEN both were accepted (source ros2) and the drone hovers at home + MIS_TAKEOFF_ALT (2.5 m)
        assert sim.command_result(armed).ok and sim.command_result(takeoff).ok
        assert sim.command_result(takeoff).source == "ros2"
        home_z = sim.home_enu_m("d1")[2]
        assert sim.position_enu_m("d1")[2] == pytest.approx(home_z + 2.5, abs=0.3)
        # WHEN "land" follows; THEN it lands and disarms by itself
        apply_command(sim, "d1", "quadrotor", "nav_mode", String(data="land"))
        sim.run(duration=12.0)
        assert sim.landed_state("d1") == "ON_GROUND" and not sim.is_armed("d1")
        # AND an unknown mode, or a mode for a car, is refused before it becomes a command
        with pytest.raises(ValueError, match="mode must be one of HOLD, TAKEOFF"):
            apply_command(sim, "d1", "quadrotor", "nav_mode", String(data="warp"))
        with pytest.raises(ValueError, match="navigation modes are for drones"):
            apply_command(sim, "c1", "car", "nav_mode", String(data="takeoff"))
