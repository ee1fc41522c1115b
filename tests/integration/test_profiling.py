"""Where a step's time goes: the per-system profile (``unetyemu run --profile``), the stress script's rows,
and the BLAS thread limit the simulation sets for itself."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest
from threadpoolctl import threadpool_info

from unetyemu_ecs import Simulation, load_world_text

from ..conftest import REPO_ROOT, WORLDS, unetyemu_command
from .test_flight import drone, flat_world


def test_profile_steps_times_every_system_of_every_step_in_phase_order():
    sim = Simulation(load_world_text(flat_world(drone("d1"))))
    try:
        sim.profile_steps()
        sim.step(240)
        profile = sim.step_profile
        rows = profile.rows()
    finally:
        sim.close()
    # THEN every step was timed, each system of the flight stack appears once, phases in running order
    assert profile.steps == 240
    names = [name for _, name, _, _ in rows]
    for system in ("PhysicsStepSystem", "MotorSystem", "NavigatorSystem", "StateReadbackSystem"):
        assert names.count(system) == 1
    order = ["COMMANDS", "MISSION", "GUIDANCE", "STABILIZE", "ACTUATE", "PHYSICS", "STATE", "PAYLOAD_ENERGY",
             "SENSORS", "OUTPUTS"]
    phases = [order.index(phase) for phase, _, _, _ in rows]
    assert phases == sorted(phases)
    assert sum(share for *_, share in rows) == pytest.approx(1.0)
    assert all(us > 0.0 for _, _, us, _ in rows)
    assert "step profile over 240 steps" in profile.table() and "(phase total)" in profile.table()


def test_unetyemu_run_profile_prints_the_table_and_writes_it_to_the_summary(tmp_path):
    res = subprocess.run([*unetyemu_command(), "run", str(WORLDS / "empty.yaml"), "--duration", "1", "--profile",
                          "--quiet", "--out", str(tmp_path / "out")], cwd=REPO_ROOT, capture_output=True, text=True,
                         timeout=120)
    assert res.returncode == 0, res.stderr
    assert "step profile over 240 steps" in res.stdout and "PhysicsStepSystem" in res.stdout
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["step_profile"]["steps"] == 240
    assert {"phase": "PHYSICS", "system": "PhysicsStepSystem"}.items() <= summary["step_profile"]["systems"][
        [s["system"] for s in summary["step_profile"]["systems"]].index("PhysicsStepSystem")].items()


def _blas_threads() -> list[int]:
    return [lib["num_threads"] for lib in threadpool_info() if lib["user_api"] == "blas"]


def test_the_simulation_limits_blas_to_one_thread_while_open_and_gives_the_limit_back():
    world = load_world_text("world: {name: t}\nscene: {generator: none, ground_size_m: 100}\n")
    before = _blas_threads()
    with Simulation(world):
        assert _blas_threads() and set(_blas_threads()) == {1}
    assert _blas_threads() == before
    with Simulation(world, blas_threads=None):
        assert _blas_threads() == before
    # two simulations open at once, closed in the order they were opened: BLAS ends as it was
    first, second = Simulation(world), Simulation(world)
    first.close()
    second.close()
    assert _blas_threads() == before
    with pytest.raises(ValueError, match=r"blas_threads must be None or an integer in \[1, 256\], got 0"):
        Simulation(world, blas_threads=0)


def test_the_stress_script_prints_one_row_per_case_with_rates_phases_and_memory():
    res = subprocess.run([sys.executable, str(REPO_ROOT / "benchmarks" / "stress.py"), "flight-1", "--seconds", "0.5",
                          "--rss-every", "0.25", "--json"], cwd=REPO_ROOT, capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr
    (row,) = [json.loads(line) for line in res.stdout.splitlines() if line.startswith("{")]
    assert row["case"] == "flight-1" and row["drones"] == 1 and row["sim_s"] == pytest.approx(0.5)
    assert row["rtf_wall"] > 0 and row["rtf_cpu"] > 0 and row["peak_rss_mb"] > 50
    assert row["phase_ms_per_step"]["PHYSICS"] > 0 and row["phase_ms_per_step"]["GUIDANCE"] > 0
    assert [t for t, _ in row["rss_mb_at_sim_s"]] == [0.0, 0.25, 0.5]                  # memory sampled as asked
    assert all(mb > 50 for _, mb in row["rss_mb_at_sim_s"])
    bad = subprocess.run([sys.executable, str(REPO_ROOT / "benchmarks" / "stress.py"), "flight-7"], cwd=REPO_ROOT,
                         capture_output=True, text=True, timeout=60)
    assert bad.returncode == 2 and "unknown case(s) flight-7" in bad.stderr


def test_the_stress_cases_run_as_pytest_benchmarks_and_print_the_scripts_rows():
    env = {**os.environ, "STRESS_SECONDS": "0.5"}
    res = subprocess.run([sys.executable, "-m", "pytest", "benchmarks/test_bench_stress.py", "-k", "flight-1]", "-s",
                          "-q", "-p", "no:cacheprovider", "--benchmark-disable"],
                         cwd=REPO_ROOT, capture_output=True, text=True, env=env, timeout=300)
    assert res.returncode == 0, res.stdout[-3000:] + res.stderr[-3000:]
    assert "1 passed, 18 deselected" in res.stdout
    (row,) = [line.split() for line in res.stdout.splitlines() if line.startswith("flight-1 ")]
    assert row[1] == "1" and float(row[2]) == 0.5 and float(row[3]) > 0 and float(row[-1]) > 50   # drones, sim s, rtf, MB
    env["STRESS_SECONDS"] = "-3"
    bad = subprocess.run([sys.executable, "-m", "pytest", "benchmarks/test_bench_stress.py", "-k", "flight-1]", "-q",
                          "-p", "no:cacheprovider", "--benchmark-disable"],
                         cwd=REPO_ROOT, capture_output=True, text=True, env=env, timeout=300)
    assert bad.returncode != 0 and "STRESS_SECONDS must be in [0.1, 3600], got -3.0" in bad.stdout


def test_the_side_by_side_script_measures_ours_and_names_where_the_peer_figures_come_from():
    res = subprocess.run([sys.executable, str(REPO_ROOT / "benchmarks" / "vs_gym_pybullet_drones.py"), "--drones", "1",
                          "--runs", "1", "--seconds", "0.5"],
                         cwd=REPO_ROOT, capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr
    lines = res.stdout.splitlines()
    peer_here = lines[0] == "peer: gym-pybullet-drones, measured in this run"
    assert peer_here or lines[0] == "peer: not installed: reference figures"
    drones, peer, ours, ratio = lines[2].replace("*", "").split()
    assert drones == "1" and float(ours) > 0
    assert float(ratio) == pytest.approx(float(ours) / float(peer), abs=0.006)       # printed to 2 decimals
    if not peer_here:
        assert float(peer) == 14.0 and "not in this run" in lines[-1]
