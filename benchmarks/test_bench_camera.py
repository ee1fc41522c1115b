"""Camera cost: ms per frame of our ray-cast RGB and depth cameras against PyBullet's TinyRenderer
(the CPU renderer PyBullet offers) for the same view of the default city, in the same run: the
measurement behind the renderer choice (see unetyemu_ecs/sensors/camera.py).

Run: python3 -m pytest benchmarks/test_bench_camera.py --benchmark-only --benchmark-columns=mean,stddev,rounds
"""

from __future__ import annotations

import numpy as np
import pybullet as p
import pytest

from unetyemu_ecs import Simulation, load_world_text
from unetyemu_ecs.sensors.camera import DepthCameraSystem, RgbCameraSystem

RESOLUTIONS = [(320, 240), (640, 480)]


def _world(width: int, height: int, key: str) -> str:
    return ("world: {name: bench_cam, physics_hz: 240, seed: 42}\nscene: {generator: urban}\nvehicles:\n"
            "  - {name: d1, type: quadrotor, preset: medium, pose: {position_m: [0.0, -60.0, 15.0]},"
            f" components: {{{key}: {{width: {width}, height: {height}, mount_rpy_deg: [0.0, 20.0, 90.0]}}}}}}\n")


@pytest.mark.parametrize("width, height", RESOLUTIONS)
@pytest.mark.parametrize("kind", ["camera", "depth_camera"])
def test_raycast_camera_frame(benchmark, kind, width, height):
    sim = Simulation(load_world_text(_world(width, height, kind)))
    try:
        sim.step(1)
        cls = RgbCameraSystem if kind == "camera" else DepthCameraSystem
        system = next(s for s in sim.ecs.systems if type(s) is cls)
        ctx = sim._context()

        def frame():
            sim.services.sensors.this_step.clear()          # as every step does
            ctx.services.camera_casts.clear()               # a new frame: cast again (not the view shared this step)
            with sim.ecs.active():
                system.measure(ctx, system.sensors, sim.sim_time_s)

        benchmark.pedantic(frame, rounds=5, iterations=1, warmup_rounds=1)
        assert sim.sensor("d1", kind).width == width
    finally:
        sim.close()


@pytest.mark.parametrize("width, height", RESOLUTIONS)
def test_pybullet_tinyrenderer_frame(benchmark, width, height):
    """The alternative: PyBullet's CPU renderer, RGB + depth buffer of the same view."""
    sim = Simulation(load_world_text(_world(width, height, "camera")))
    try:
        eye = [0.0, -60.0, 15.0]
        view = p.computeViewMatrix(eye, [0.0, -60.0 + np.cos(np.deg2rad(20.0)), 15.0 - np.sin(np.deg2rad(20.0))],
                                   [0, 0, 1], physicsClientId=sim.physics.id)
        vfov = np.degrees(2 * np.arctan(np.tan(np.deg2rad(45.0)) * height / width))
        proj = p.computeProjectionMatrixFOV(vfov, width / height, 0.1, 200.0, physicsClientId=sim.physics.id)

        def frame():
            p.getCameraImage(width, height, view, proj, renderer=p.ER_TINY_RENDERER, physicsClientId=sim.physics.id)

        benchmark.pedantic(frame, rounds=3, iterations=1, warmup_rounds=1)
    finally:
        sim.close()
