"""Faults an independent physics audit found, each pinned by a test that failed before its fix."""

from __future__ import annotations

import numpy as np
import pytest

from unetyemu_ecs import ConfigError, Simulation, load_world_text
from unetyemu_ecs.components.flight import EnergyModel
from unetyemu_ecs.control.battery_ecm import energy_remaining_wh
from unetyemu_ecs.systems.flight_state import FlightMode
from unetyemu_ecs.vehicles.presets import preset, presets_for

from .test_flight import PICKUP_MISSION, _package, drone, flat_world, hover

G = 9.81


def test_manual_full_pitch_and_roll_at_full_throttle_tilts_at_most_the_limit_and_climbs():
    with Simulation(load_world_text(flat_world(drone("d1", "small")))) as sim:
        hover(sim, "d1", 10.0, 8.0)
        row = sim.row("d1")
        sim.teleop("d1", 1.0, 1.0, 1.0, 0.0)          # full climb, full forward, full right
        tilt_deg, z = [], []
        for _ in range(int(2.0 / sim.dt_s)):
            sim.step()
            tilt_deg.append(np.degrees(np.arccos(np.clip(sim.fleet.R_enu_flu[row, 2, 2], -1.0, 1.0))))
            z.append(sim.fleet.pos_enu_m[row, 2])
    assert max(tilt_deg) < 45.0 + 2.0          # the small preset's 45 deg (was ~59 deg)
    assert z[-1] > z[0] + 2.0                  # it climbs (it sank before)


def test_the_first_csv_row_obeys_the_same_energy_bookkeeping_as_every_other(tmp_path):
    import csv

    with Simulation(load_world_text(flat_world(drone("d1"))), out_dir=tmp_path) as sim:
        sim.set_target("d1", 0.0, 0.0, 5.0)
        sim.run(duration=1.0)
        model = sim.component("d1", EnergyModel)
    rows = list(csv.DictReader(open(tmp_path / "d1.csv", encoding="utf-8")))
    first = rows[0]
    assert float(first["time_s"]) == 0.0
    for row in rows:
        soc, power_w = float(row["soc_frac"]), float(row["power_w"])
        # energy held = the pack's open-circuit energy at its state of charge
        assert float(row["battery_wh"]) == pytest.approx(
            float(energy_remaining_wh(soc, model.design_capacity_ah, model.cells_series)), rel=1e-4)
        # the pack delivers the power drawn: terminal voltage x current
        assert float(row["pack_voltage_v"]) * float(row["pack_current_a"]) == pytest.approx(power_w, rel=2e-3)
        assert power_w >= 15.0                                              # at least the avionics' P0
        assert 0.0 < float(row["remaining_time_s"]) < 1e6                   # energy / (filtered) power
    # disarmed on the ground: P0 only, the full pack's energy, its remaining time at that power
    assert float(first["power_w"]) == pytest.approx(15.0)
    assert float(first["soc_frac"]) == 1.0
    assert float(first["remaining_time_s"]) == pytest.approx(float(first["battery_wh"]) * 3600.0 / 15.0, rel=1e-3)


@pytest.mark.parametrize("name", presets_for("quadrotor"))
def test_every_preset_has_thrust_to_weight_of_at_least_1_4_at_its_max_payload(name):
    p = preset("quadrotor", name)
    weight_n = (p["mass_kg"] + p["payload"]["max_payload_kg"]) * G
    assert 4 * p["motors"]["max_thrust_per_motor_n"] / weight_n >= 1.4     # large was 160 / 166.8 = 0.96


def test_the_large_preset_lifts_its_5_kg_max_payload_to_10_m():
    world = flat_world(drone("d1", "large", pose="{pad: home, offset_m: [-0.6, 0.0]}", components=PICKUP_MISSION),
                       packages=_package(5.0))
    with Simulation(load_world_text(world)) as sim:
        sim.run(until=40.0)
        status = sim.mission_status("d1")
        assert status["state"] == "running" and status["step_type"] == "idle", status   # it sat at 0.45 m
        assert sim.fleet.payload_kg[sim.row("d1")] == 5.0
        assert sim.position_enu_m("d1")[2] == pytest.approx(10.0, abs=0.3)


def test_a_drone_that_cannot_hover_its_max_payload_is_rejected_at_load_naming_the_numbers():
    comps = "      motors: {max_thrust_per_motor_n: 20.0}\n"           # the paper's small-drone motors on a medium
    with pytest.raises(ConfigError) as err:
        load_world_text(flat_world(drone("d1", "medium", components=comps)), file="w.yaml")
    text = str(err.value)
    assert "w.yaml:" in text and "vehicles[0].components.payload" in text
    assert "d1 cannot hover its max payload: 4 x 20 N = 80.0 N of thrust < (8 + 3) kg" in text


def test_a_takeoff_that_makes_no_progress_at_full_thrust_fails_with_insufficient_thrust_and_lands():
    comps = """      mission:
        name: up
        steps:
          - {type: takeoff, altitude_m: 10.0}
"""
    with Simulation(load_world_text(flat_world(drone("d1", "medium", components=comps)))) as sim:
        # motors worn to 19 N each: 76 N < 8 kg x g = 78.5 N (fault injection; the load check passed)
        sim.attach("d1", "motors", max_thrust_per_motor_n=19.0)
        sim.run(until=20.0)
        status = sim.mission_status("d1")
        assert status["state"] == "failed" and status["reason"] == "insufficient_thrust", status
        assert any("climb stalled" in message for _, name, message in sim.events if name == "d1")
        row = sim.row("d1")
        assert sim.fleet.flight_mode[row] == FlightMode.DISARMED      # it landed where it was and disarmed
        assert sim.position_enu_m("d1")[2] < 0.5
