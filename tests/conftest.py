"""Shared fixtures: a seeded RNG, paths, and a helper that writes world files."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

# ROS 2 tests talk to their peers on loopback: outside a network namespace the simulator's DDS
# participant is confined to it (its default range joins multicast on the host's interface). The
# discovery tests run their own participants in `unshare -n` with the variable of their choice.
os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")

# Each pytest-xdist worker (gw0, gw1, ...) runs its simulators and ROS 2 peers on a DDS domain of its
# own (ROS_DOMAIN_ID 20 + worker number), so two ROS 2 tests running at once on two workers never
# see each other's vehicles; the peers in tests/ros2_peer and tests/fastdds_peer read the same variable.
_WORKER = os.environ.get("PYTEST_XDIST_WORKER", "")
if _WORKER.startswith("gw") and _WORKER[2:].isdigit():
    os.environ.setdefault("ROS_DOMAIN_ID", str(20 + int(_WORKER[2:])))

REPO_ROOT = Path(__file__).resolve().parents[1]
WORLDS = REPO_ROOT / "worlds"

_WARM_UP_WORLD = """world: {name: warm_up, physics_hz: 240, seed: 1}
scene: {generator: none, ground_size_m: 100}
vehicles:
  - {name: d1, type: quadrotor, preset: medium, pose: {position_m: [0, 0, 0.2]}}
"""


def pytest_configure(config: pytest.Config) -> None:
    """Compile the simulator's kernels before any test runs (in the controller, before pytest-xdist starts its
    workers): numba caches them in ``__pycache__``, so on a fresh checkout no test, and no process a test starts,
    waits the seconds the first compile takes."""
    if hasattr(config, "workerinput"):
        return
    from unetyemu_ecs import Simulation, load_world_text

    with Simulation(load_world_text(_WARM_UP_WORLD), ros2="off") as sim:
        sim.set_target("d1", 2.0, 0.0, 2.0)
        sim.run(duration=0.2)


def pip_install_plugin(plugin_dir: Path, target: Path) -> Path:
    """pip-install the plugin package ``plugin_dir`` into the private directory ``target`` (no
    dependencies, no network), as a user would install it; return ``target``."""
    subprocess.run([sys.executable, "-m", "pip", "install", "--quiet", "--no-deps", "--no-build-isolation",
                    "--target", str(target), str(plugin_dir)], check=True, capture_output=True, timeout=300)
    return target


def run_python_with_site(site: Path, code: str, timeout_s: float = 300.0) -> subprocess.CompletedProcess:
    """Run ``code`` in a fresh interpreter with ``site`` (a pip ``--target`` directory) first on its path."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(site), str(REPO_ROOT), env.get("PYTHONPATH", "")])
    return subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True,
                          timeout=timeout_s, cwd=REPO_ROOT)


def unetyemu_command() -> list[str]:
    """How to run the ``unetyemu`` CLI of the interpreter running the tests: the console script next to
    it (the venv's ``.venv/bin/unetyemu``), never another one found on PATH; else ``python -m``."""
    script = Path(sys.executable).with_name("unetyemu")
    return [str(script)] if script.exists() else [sys.executable, "-m", "unetyemu_ecs.cli"]


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(1234)


@pytest.fixture
def write_world(tmp_path: Path):
    """Write dedented YAML to a file in ``tmp_path`` and return its path."""

    def _write(text: str, name: str = "world.yaml") -> Path:
        path = tmp_path / name
        path.write_text(textwrap.dedent(text).lstrip("\n"), encoding="utf-8")
        return path

    return _write
