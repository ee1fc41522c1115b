"""The paper's delivery scenario end to end (worlds/urban_delivery.yaml), its logs and plots."""

from __future__ import annotations

import csv
import dataclasses
import filecmp

import numpy as np
import pytest

from unetyemu_ecs import Simulation, load_world
from unetyemu_ecs.cli import main as cli_main
from unetyemu_ecs.components.car import CarRoute
from unetyemu_ecs.control.atmosphere import isa_density_kg_m3
from unetyemu_ecs.control.rotor_power import rotor_shaft_power_w
from unetyemu_ecs.sensors.base import SensorSpec

from ..conftest import WORLDS

WORLD = WORLDS / "urban_delivery.yaml"


def without_sensors(path=WORLD):
    """The world of ``path`` with its sensors taken off: they only read the state, so flights, drives,
    payloads and logs are the same, at a third of the cost (the sensors of this world are tested by
    test_ros2_dds.py, which runs it with all of them)."""
    world = load_world(path)
    bare = tuple(dataclasses.replace(e, components={k: c for k, c in e.components.items()
                                                    if not isinstance(c, SensorSpec)}) for e in world.entities)
    return dataclasses.replace(world, entities=bare)


def _rows(path) -> list[dict[str, str]]:
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


@pytest.fixture(scope="module")
def delivery_run(tmp_path_factory):
    """Run the scenario (at most its 150 s simulated) until both missions and the truck's route are done
    and 2 s more have passed (about 112 s), and keep its outputs."""
    out = tmp_path_factory.mktemp("delivery")
    with Simulation(without_sensors(), out_dir=out) as sim:
        route = sim.component("truck1", CarRoute)
        waypoints = np.array([[w.x, w.y] for w in route.waypoints])
        nearest = np.full(len(waypoints), np.inf)            # closest the truck came to each waypoint
        all_done_s = None
        while sim.sim_time_s < 150.0 - 1e-9 and (all_done_s is None or sim.sim_time_s < all_done_s + 2.0):
            sim.step()
            nearest = np.minimum(nearest, np.linalg.norm(waypoints - sim.position_enu_m("truck1")[:2], axis=1))
            if all_done_s is None and sim.step_count % 240 == 0 and sim.drive_status("truck1")["route"] == "done" \
                    and all((sim.mission_status(d) or {}).get("state") == "completed" for d in ("drone1", "drone2")):
                all_done_s = sim.sim_time_s
        result = {
            "status": {name: sim.mission_status(name) for name in ("drone1", "drone2")},
            "package": sim.position_enu_m("package1"),
            "roof": sim.layout.pads["roof_1"],
            "drone1": sim.position_enu_m("drone1"),
            "home": sim.layout.pads["start_1"],
            "drone3_z": sim.position_enu_m("drone3")[2],
            "events": sim.events,
            "impacts": [e for e in sim.events if e[2].startswith("impact")],
            "truck_nearest_m": nearest,
            "truck_events": [text for _, who, text in sim.events if who == "truck1"],
        }
    return out, result


def test_delivery_mission_completes_and_the_package_ends_on_the_rooftop_pad(delivery_run):
    _, r = delivery_run
    assert r["status"]["drone1"]["state"] == "completed", r["events"]
    pad = r["roof"]
    # the package rests on the pad: within the pad's square, its bottom on the pad top
    assert np.all(np.abs(r["package"][:2] - pad.center_enu_m[:2]) < pad.size_m / 2)
    assert r["package"][2] == pytest.approx(pad.center_enu_m[2] + 0.15, abs=0.05)
    # and drone 1 is back home
    assert np.linalg.norm(r["drone1"][:2] - r["home"].center_enu_m[:2]) < 1.5


def test_the_shipped_routes_clear_every_building_and_tree(delivery_run):
    # the rooftop route detours around a 56 m tower that stands on the straight line
    assert delivery_run[1]["impacts"] == []


def test_the_truck_completes_its_block_route_within_1_5_m_of_every_waypoint(delivery_run):
    _, r = delivery_run
    assert "route done" in r["truck_events"]                   # two laps, then parked at its first waypoint
    assert np.all(r["truck_nearest_m"] < 1.5), r["truck_nearest_m"]


def test_target_sequence_drone_completes_and_teleop_drone_hovers(delivery_run):
    _, r = delivery_run
    assert r["status"]["drone2"]["state"] == "completed", r["events"]
    assert r["drone3_z"] > 5.0


def test_csv_shows_the_power_step_at_pickup_and_back_after_delivery(delivery_run):
    out, _ = delivery_run
    rows = _rows(out / "drone1.csv")
    # steady level cruise (the scenario hardly hovers still: its few slow samples are transients), loaded
    # out to the roof and empty back: thrust is about the weight
    cruise = {True: [], False: []}
    for row in rows:
        if row["mode"] == "auto" and row["mission_step_type"] == "cruise" and float(row["speed_m_s"]) > 6.0 \
                and abs(float(row["vz_m_s"])) < 0.3:
            cruise[float(row["payload_kg"]) > 0].append((float(row["power_w"]), float(row["speed_m_s"])))
    assert len(cruise[True]) > 50 and len(cruise[False]) > 50
    (loaded, v_loaded), (empty, v_empty) = (np.median(np.array(cruise[k]), axis=0) for k in (True, False))
    # rotor power (the total less the 15 W of avionics) from momentum theory in forward flight (Glauert):
    # between the hover law (mass ratio^1.5 = 1.50) and the fast-flight limit (mass ratio^2 = 1.72), plus
    # the 2.5 kg package's own drag (a 0.4 x 0.3 m face, C_d 1.05) times the speed, over eta
    rho, area, eta = float(isa_density_kg_m3(650.0)), np.pi * 0.14 ** 2, 0.90
    rotors = [float(rotor_shaft_power_w(np.array([m * 9.81 / 4]), np.array([0.0]), np.array([v]), rho, area, 0.0,
                                        120.0)[0]) * 4 / eta for m, v in ((10.5, v_loaded), (8.0, v_empty))]
    package_drag_w = 0.5 * rho * 1.05 * 0.4 * 0.3 * v_loaded ** 3 / eta
    expected = (rotors[0] + package_drag_w) / rotors[1]
    assert 1.50 < (loaded - 15.0) / (empty - 15.0) < 1.72
    assert (loaded - 15.0) / (empty - 15.0) == pytest.approx(expected, rel=0.03)
    kinds = {row["mission_step_type"] for row in rows}
    assert {"pickup", "takeoff", "cruise", "land", "deliver"} <= kinds


def test_same_world_and_seed_twice_give_identical_csv_files(tmp_path):
    # 10 s: the pickup, the takeoffs, the truck's start and the teleop script are all in it
    for run in ("a", "b"):
        with Simulation(without_sensors(), out_dir=tmp_path / run) as sim:
            sim.run(until=10.0)
    for name in ("drone1", "drone2", "drone3", "truck1"):
        assert filecmp.cmp(tmp_path / "a" / f"{name}.csv", tmp_path / "b" / f"{name}.csv", shallow=False)


def test_plot_writes_one_png_per_vehicle_from_a_run(delivery_run, capsys):
    out, _ = delivery_run
    assert cli_main(["plot", str(out)]) == 0
    for name in ("drone1", "drone2", "drone3", "truck1", "car1"):
        png = out / f"{name}.png"
        assert png.exists() and png.stat().st_size > 20_000
    assert not (out / "package1.png").exists()


def test_plot_of_a_directory_without_vehicle_logs_is_bad_input(tmp_path, capsys):
    assert cli_main(["plot", str(tmp_path)]) == 2
    assert "no vehicle logs" in capsys.readouterr().err
