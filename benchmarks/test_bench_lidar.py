"""LiDAR cost: the full pipeline (rays in the world frame, static + moving-body casts, points in the
sensor frame, PointCloud2) for N drones in the default city, next to a bare ``cast_rays`` of the same
number of rays on the same static scene, measured in the same run.

Run: python3 -m pytest benchmarks/test_bench_lidar.py --benchmark-only --benchmark-columns=mean,stddev,rounds
Rays per second are in each result's extra_info (``--benchmark-verbose`` or ``--benchmark-json``; from the
mean) and printed at the end of the run, for the pipeline and the bare cast alike from the best of 7 rounds
taken in turns (a bare cast, a pipeline tick, ...), with the pipeline's share of the bare cast's rate.
"""

from __future__ import annotations

import time

import numpy as np
import pytest

from unetyemu_ecs import Simulation, load_world_text
from unetyemu_ecs.sensors.lidar import LidarSystem, ray_directions_sensor

from bench_worlds import city_with_lidar_drones  # noqa: E402  (benchmarks/ is on sys.path)

RAYS_PER_SCAN = 360 * 16
RESULTS: dict[str, float] = {}


@pytest.fixture(scope="module", autouse=True)
def _report():
    yield
    for name, rate in RESULTS.items():
        print(f"\n{name}: {rate / 1e6:.2f} Mrays/s")
    for name, rate in RESULTS.items():
        if name.startswith("pipeline"):
            bare = RESULTS[name.replace("pipeline", "bare cast_rays")]
            print(f"\n{name}: {100 * rate / bare:.0f} % of the bare cast")


@pytest.mark.parametrize("n_drones", [1, 30, 60, 100])
def test_lidar_pipeline_for_n_drones(benchmark, n_drones):
    sim = Simulation(load_world_text(city_with_lidar_drones(n_drones)))
    try:
        sim.step(1)
        lidar = next(s for s in sim.ecs.systems if isinstance(s, LidarSystem))
        ctx = sim._context()

        def one_tick():
            sim.services.sensors.this_step.clear()          # as every step does: last step's samples are gone
            with sim.ecs.active():
                lidar.measure(ctx, lidar.sensors, sim.sim_time_s)

        benchmark.pedantic(one_tick, rounds=5, iterations=1, warmup_rounds=1)
        rays = n_drones * RAYS_PER_SCAN
        benchmark.extra_info["rays_per_s"] = rays / benchmark.stats.stats.mean
        assert sim.sensor("d0", "lidar").width > 0.2 * RAYS_PER_SCAN       # it really sees the city

        # the bare cast of the same rays on the same static scene, in turns with more pipeline ticks (so that
        # both see the same machine): best of 7 of each
        import open3d as o3d

        dirs, _ = ray_directions_sensor(lidar.sensors[0].spec)
        rays_np = np.hstack([np.repeat(sim.fleet.pos_enu_m[[s.row for s in lidar.sensors]], len(dirs), axis=0),
                             np.tile(dirs, (n_drones, 1))]).astype(np.float32)
        tensor = o3d.core.Tensor(rays_np)
        best_bare = best_pipeline = np.inf
        for _ in range(7):
            t0 = time.perf_counter()
            lidar.world.static.cast_rays(tensor, nthreads=0)
            t1 = time.perf_counter()
            one_tick()
            best_bare, best_pipeline = min(best_bare, t1 - t0), min(best_pipeline, time.perf_counter() - t1)
        benchmark.extra_info["bare_cast_rays_per_s"] = rays / best_bare
        benchmark.extra_info["pipeline_share_of_bare_cast"] = best_bare / best_pipeline
        RESULTS[f"pipeline, {n_drones} drones"] = rays / best_pipeline
        RESULTS[f"bare cast_rays, {n_drones} drones"] = rays / best_bare
    finally:
        sim.close()
