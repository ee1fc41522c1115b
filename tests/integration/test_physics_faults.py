"""Faults an independent physics audit found, each pinned by a test that failed before its fix."""

from __future__ import annotations

import numpy as np
import pytest

from unetyemu_ecs import Simulation, load_world_text

from .test_flight import drone, flat_world, hover


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
    rows = list(csv.DictReader(open(tmp_path / "d1.csv", encoding="utf-8")))
    first = rows[0]
    assert float(first["time_s"]) == 0.0
    for row in rows:
        battery_wh, power_w, soc = float(row["battery_wh"]), float(row["power_w"]), float(row["soc_frac"])
        assert battery_wh == pytest.approx(500.0 * soc, rel=1e-4)          # energy held = capacity x SOC
        assert power_w >= 15.0                                              # at least the avionics' P0
        remaining = float(row["remaining_time_s"])
        assert 0.0 < remaining < 1e6                                         # energy / (filtered) power
    assert float(first["power_w"]) == pytest.approx(15.0)                   # disarmed on the ground: P0 only
    assert float(first["remaining_time_s"]) == pytest.approx(500.0 * 3600.0 / 15.0, rel=1e-3)
