"""Engine cost: city build time and physics-step cost against the number of bodies.

Run: python3 -m pytest benchmarks/test_bench_engine.py --benchmark-only --benchmark-columns=mean,stddev,rounds
Each "step" benchmark measures one simulated second (240 physics steps) of the full phase loop.
"""

from __future__ import annotations

import numpy as np
import pytest

from unetyemu_ecs import Simulation, load_world_text
from unetyemu_ecs.scene.config import UrbanParams
from unetyemu_ecs.scene.mesh import triangulate
from unetyemu_ecs.scene.urban import generate_urban


def _world_with_boxes(n: int, city: bool) -> str:
    lines = ["world: {name: bench, physics_hz: 240, seed: 1}",
             "scene: {generator: urban}" if city else "scene: {generator: none, ground_size_m: 400}",
             "packages:"]
    side = int(np.ceil(np.sqrt(n)))
    for i in range(n):
        x, y = -150 + 3.0 * (i % side), -150 + 3.0 * (i // side)
        # hovering boxes high above the city: falling bodies in free flight, no contacts
        lines.append(f"  - {{name: b{i}, mass_kg: 8.0, pose: {{position_m: [{x}, {y}, 500.0]}}}}")
    return "\n".join(lines) + "\n"


def test_generate_default_city(benchmark):
    benchmark(lambda: generate_urban(UrbanParams(), np.random.default_rng(7)))


def test_triangulate_default_city(benchmark):
    layout = generate_urban(UrbanParams(), np.random.default_rng(7))
    benchmark(lambda: triangulate(layout))


def test_build_default_city_in_pybullet(benchmark):
    world = load_world_text(_world_with_boxes(0, city=True))

    def build():
        Simulation(world).close()

    benchmark.pedantic(build, rounds=5, iterations=1)


@pytest.mark.parametrize("n_bodies", [1, 10, 100, 1000])
def test_one_simulated_second_with_n_free_bodies(benchmark, n_bodies):
    sim = Simulation(load_world_text(_world_with_boxes(n_bodies, city=True)))
    try:
        benchmark.pedantic(lambda: sim.step(240), rounds=3, iterations=1)
    finally:
        sim.close()
