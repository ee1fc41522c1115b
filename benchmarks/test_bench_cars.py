"""Ground-vehicle cost: cars driving and parked.

Run: python3 -m pytest benchmarks/test_bench_cars.py --benchmark-only --benchmark-columns=mean,stddev,rounds
Each benchmark measures one simulated second (240 physics steps of every phase) for N cars; a mean
under 1 s runs faster than real time.
"""

from __future__ import annotations

import numpy as np
import pytest

from unetyemu_ecs import Simulation, load_world_text


def _cars_world(n: int) -> str:
    lines = ["world: {name: bench_cars, physics_hz: 240, seed: 1}",
             "scene: {generator: none, ground_size_m: 600}",
             "vehicles:"]
    for i in range(n):
        x, y = -250.0 + 50.0 * (i % 10), -250.0 + 8.0 * (i // 10)
        lines.append(f"  - {{name: c{i}, type: car, preset: medium, pose: {{position_m: [{x}, {y}, 0.9]}}}}")
    return "\n".join(lines) + "\n"


@pytest.mark.parametrize("n_cars", [1, 10, 50])
def test_one_simulated_second_of_n_cars_driving(benchmark, n_cars):
    sim = Simulation(load_world_text(_cars_world(n_cars)))
    try:
        for i in range(n_cars):
            sim.cmd_vel(f"c{i}", 8.0, 0.05)          # gentle circles at 8 m/s
        sim.run(duration=5.0)
        benchmark.pedantic(lambda: sim.step(240), rounds=3, iterations=1)
        speeds = sim.fleet.car_speed_m_s[[sim.row(f"c{i}") for i in range(n_cars)]]
        assert np.all(np.abs(speeds - 8.0) < 0.5), "the cars must really be driving while measured"
    finally:
        sim.close()


@pytest.mark.parametrize("n_cars", [10, 50])
def test_one_simulated_second_of_n_parked_cars(benchmark, n_cars):
    sim = Simulation(load_world_text(_cars_world(n_cars)))
    try:
        sim.run(duration=4.0)                        # settled and asleep
        benchmark.pedantic(lambda: sim.step(240), rounds=3, iterations=1)
    finally:
        sim.close()
