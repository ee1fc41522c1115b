"""Flight-stack cost: hovering fleets and the delivery scenario.

Run: python3 -m pytest benchmarks/test_bench_flight.py --benchmark-only --benchmark-columns=mean,stddev,rounds
Each "hover" benchmark measures one simulated second (240 physics steps) of the full phase loop
(motors, stabilizer, guidance, energy, payload, logs off) for N drones holding 10 m over a flat ground;
a mean under 1 s means that fleet runs faster than real time.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from unetyemu_ecs import Simulation, load_world_text
from unetyemu_ecs.config.world_file import load_world

WORLDS = Path(__file__).resolve().parent.parent / "worlds"


def _hover_world(n: int) -> str:
    side = int(np.ceil(np.sqrt(n)))
    lines = ["world: {name: bench_hover, physics_hz: 240, seed: 1}",
             "scene: {generator: none, ground_size_m: 400}",
             "vehicles:"]
    for i in range(n):
        x, y = -60 + 4.0 * (i % side), -60 + 4.0 * (i // side)
        lines.append(f"  - {{name: d{i}, type: quadrotor, preset: medium, pose: {{position_m: [{x}, {y}, 0.3]}}}}")
    return "\n".join(lines) + "\n"


@pytest.mark.parametrize("n_drones", [1, 10, 100])
def test_one_simulated_second_of_n_hovering_drones(benchmark, n_drones):
    sim = Simulation(load_world_text(_hover_world(n_drones)))
    try:
        for i in range(n_drones):
            x, y, _ = sim.position_enu_m(f"d{i}")
            sim.set_target(f"d{i}", x, y, 10.0)
        sim.run(duration=8.0)          # climbed and settled: measure steady hover
        benchmark.pedantic(lambda: sim.step(240), rounds=3, iterations=1)
        z = sim.fleet.pos_enu_m[[sim.row(f"d{i}") for i in range(n_drones)], 2]
        assert np.all(np.abs(z - 10.0) < 0.2), "the fleet must really be hovering while measured"
    finally:
        sim.close()


def test_ten_simulated_seconds_of_the_delivery_scenario(benchmark, tmp_path):
    """The shipped urban_delivery world (3 drones flying, 4 cars, city, 10 Hz CSV logs) from t = 0."""
    world = load_world(WORLDS / "urban_delivery.yaml")

    def run_ten_seconds():
        with Simulation(world, out_dir=tmp_path / "run") as sim:
            sim.run(duration=10.0)

    benchmark.pedantic(run_ten_seconds, rounds=3, iterations=1)
