"""The Python API refuses misuse with a clear error, as the README promises, and writes what a CLI run writes."""

from __future__ import annotations

import json

import numpy as np
import pytest

from unetyemu_ecs import Simulation, load_world_text
from unetyemu_ecs.app import SimulationClosedError

WORLD = """
world: {name: api, physics_hz: 240, seed: 5, log_hz: 10}
scene: {generator: none, ground_size_m: 200}
vehicles:
  - {name: d1, type: quadrotor, preset: small, pose: {position_m: [0, 0, 0.2]}, sensors: [imu, camera]}
  - {name: c1, type: car, preset: medium, pose: {position_m: [20, 0, 0.9]}}
"""


@pytest.fixture(scope="module")
def sim():
    with Simulation(load_world_text(WORLD)) as s:
        s.step(2)
        yield s


def test_an_unknown_vehicle_is_a_value_error_naming_the_vehicles_there_are(sim):
    for call in (lambda: sim.set_target("drone9", 1, 2, 3), lambda: sim.position_enu_m("drone9"),
                 lambda: sim.sensor("drone9", "imu"), lambda: sim.arm("drone9"), lambda: sim.mission_status("drone9")):
        with pytest.raises(ValueError, match=r"no vehicle or package named 'drone9' \(have: d1, c1\)"):
            call()


def test_asking_for_a_sensor_the_vehicle_does_not_carry_is_an_error_not_no_sample_yet(sim):
    with pytest.raises(ValueError, match=r"'d1' has no sensor 'sonar' \(it has: imu, camera, camera_info\)"):
        sim.sensor("d1", "sonar")
    with pytest.raises(ValueError, match="'c1' has no sensor 'imu'"):
        sim.sensor("c1", "imu")
    assert sim.sensor("d1", "imu") is not None          # a carried sensor answers


@pytest.mark.parametrize("n", [-5, 1.7, "3", True, None])
def test_step_takes_only_a_non_negative_whole_number_of_steps(sim, n):
    before = sim.step_count
    with pytest.raises(ValueError, match="n must be an integer >= 0"):
        sim.step(n)
    assert sim.step_count == before


def test_step_zero_and_numpy_integers_are_fine(sim):
    before = sim.step_count
    sim.step(0)
    sim.step(np.int64(2))
    assert sim.step_count == before + 2


@pytest.mark.parametrize("kwargs, message", [
    ({"duration": -1}, "duration must be > 0"),
    ({"duration": 0}, "duration must be > 0"),
    ({"duration": float("nan")}, "finite number"),
    ({"duration": float("inf")}, "finite number"),
    ({"duration": "10"}, "finite number"),
    ({"duration": 1e300}, "at most 604800 s"),
    ({"until": 0.0}, "before the current sim time"),
    ({"duration": 1.0, "rate": 0}, "rate must be"),
    ({"duration": 1.0, "rate": float("nan")}, "rate must be"),
])
def test_run_refuses_a_duration_or_rate_that_means_nothing(sim, kwargs, message):
    before = sim.step_count
    with pytest.raises(ValueError, match=message):
        sim.run(**kwargs)
    assert sim.step_count == before


@pytest.mark.parametrize("armed", ["yes", 1, None, "False"])
def test_arm_takes_true_or_false_only(sim, armed):
    for name in ("d1", "c1"):
        with pytest.raises(ValueError, match="armed must be True or False"):
            sim.arm(name, armed)


def test_booleans_are_not_numbers_for_commands(sim):
    with pytest.raises(ValueError, match="finite numbers"):
        sim.set_target("d1", True, 0.0, 5.0)
    with pytest.raises(ValueError, match="finite numbers"):
        sim.cmd_vel("c1", False, 0.0)


def test_every_call_after_close_raises_instead_of_doing_nothing():
    s = Simulation(load_world_text(WORLD))
    s.close()
    s.close()                                              # closing twice is fine
    for call in (lambda: s.step(), lambda: s.run(duration=1.0), lambda: s.set_target("d1", 1, 2, 3),
                 lambda: s.arm("d1"), lambda: s.teleop("d1", 0, 0, 0, 0), lambda: s.sensor("d1", "imu"),
                 lambda: s.position_enu_m("d1"), lambda: s.mission_status("d1"), lambda: s.transforms(),
                 lambda: s.summary()):
        with pytest.raises(SimulationClosedError, match="closed"):
            call()


def test_an_api_run_with_an_output_directory_writes_summary_json_like_the_cli(tmp_path):
    # GIVEN a simulation with logs
    with Simulation(load_world_text(WORLD), out_dir=tmp_path / "run") as s:
        s.run(duration=1.0)
        s.step(24)
    # THEN closing it wrote the summary of everything it ran, next to the CSV logs
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert summary["steps"] == 264 and summary["sim_time_s"] == pytest.approx(1.1)
    assert {e["name"] for e in summary["entities"]} == {"d1", "c1"}
    assert summary["logs"]["d1"].endswith("d1.csv") and (tmp_path / "run" / "d1.csv").exists()
    assert summary["wall_time_s"] > 0 and summary["interrupted"] is False


def test_commands_beyond_what_a_vehicle_can_do_are_refused(sim):
    with pytest.raises(ValueError, match=r"speed must be in \(0, 30\] m/s"):
        sim.set_target("d1", 10.0, 0.0, 5.0, speed=1e300)
    with pytest.raises(ValueError, match="within"):
        sim.cmd_vel("d1", 1e6, 0.0)
    with pytest.raises(ValueError, match="yaw rate"):
        sim.cmd_vel("c1", 1.0, 100.0)
    with pytest.raises(ValueError, match="expected mission text"):
        sim.load_mission("d1", 123)
    with pytest.raises(ValueError, match="laps must be an integer"):
        sim.drive_route("c1", [(1, 1), (5, 1), (5, 5)], loop=True, laps=2**70)


def test_a_seed_override_out_of_range_is_a_config_error_naming_it():
    from unetyemu_ecs import ConfigError

    for seed in (-1, 2**64, 1.5, True):
        with pytest.raises(ConfigError, match="world.seed: the seed override must be an integer"):
            load_world_text(WORLD, seed=seed)
