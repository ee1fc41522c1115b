"""``unetyemu sweep`` on a real local Ray cluster (started by the command, 2 workers on loopback): the
table against the runs' own summaries, runs that raise, die or overrun reported while the others
finish, resume, Ctrl-C, per-worker ROS 2 domains, and bad input refused before anything starts."""

from __future__ import annotations

import csv
import json
import os
import re
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pytest

from ..conftest import REPO_ROOT, WORLDS, pip_install_plugin, unetyemu_command

pytest.importorskip("ray")

PLUGIN_DIR = REPO_ROOT / "tests" / "plugins" / "fault_injection"
RAY = str(Path(sys.executable).with_name("ray")) if Path(sys.executable).with_name("ray").exists() else "ray"
SWEEP_TIMEOUT_S = 300
# the sweeps' per-run wall-clock limit where one run stalls on purpose: the healthy 2-s runs take about
# 0.5 s of wall time, so this leaves them a margin of 30x for a loaded machine
STALL_TIMEOUT_S = 15


@pytest.fixture(scope="module")
def env(tmp_path_factory):
    """The environment of a user who installed the fault-injection test plugin (the driver and the Ray
    workers it starts both see it)."""
    site = pip_install_plugin(PLUGIN_DIR, tmp_path_factory.mktemp("fault_site"))
    out = dict(os.environ)
    out["PYTHONPATH"] = os.pathsep.join([str(site), str(REPO_ROOT), out.get("PYTHONPATH", "")])
    return out


def sweep(env, *args, timeout=SWEEP_TIMEOUT_S, cwd=None):
    return subprocess.run([*unetyemu_command(), "sweep", *map(str, args)], env=env, capture_output=True, text=True,
                          timeout=timeout, cwd=cwd or REPO_ROOT)


def table(out: Path) -> list[dict[str, str]]:
    with (out / "results.csv").open(newline="") as f:
        return list(csv.DictReader(f))


def run_info(out: Path, row: dict[str, str]) -> dict:
    return json.loads((out / "runs" / row["run"] / "run.json").read_text())


def test_a_2x2x2_sweep_tables_what_each_run_summarised(env, tmp_path):
    out = tmp_path / "sweep"
    # WHEN 2 masses x 2 presets x 2 seeds run on two workers
    res = sweep(env, WORLDS / "parcel_sweep.yaml", "--set", "packages.parcel.mass_kg=0.5,1.5",
                "--set", "vehicles.drone1.preset=medium,large", "--seeds", 2, "--workers", 2, "--duration", 8,
                "--out", out)
    assert res.returncode == 0, res.stderr
    rows = table(out)
    # THEN there is one row per run, each run in its own directory
    assert len(rows) == 8 and len({r["run"] for r in rows}) == 8
    assert {(r["packages.parcel.mass_kg"], r["vehicles.drone1.preset"], r["seed"]) for r in rows} == {
        (m, p, s) for m in ("0.5", "1.5") for p in ("medium", "large") for s in ("1", "2")}
    for row in rows:
        # AND every figure is what the run's own summary.json says
        summary = json.loads((out / "runs" / row["run"] / "summary.json").read_text())
        drone = next(e for e in summary["entities"] if e["name"] == "drone1")
        parcel = next(e for e in summary["entities"] if e["name"] == "parcel")
        assert row["status"] == "ok" and summary["seed"] == int(row["seed"])
        assert drone["preset"] == row["vehicles.drone1.preset"]
        assert float(row["energy_used_wh"]) == pytest.approx(drone["energy_used_wh"], abs=1e-4)
        assert float(row["distance_m"]) == pytest.approx(drone["distance_m"], abs=1e-3)
        assert int(row["impacts"]) == drone["impacts"] + parcel["impacts"] == 0
        assert row["mission"] == drone["mission"]["state"] + f" (step {drone['mission']['step'] + 1}/" \
                                                            f"{drone['mission']['steps']})"
        assert float(row["sim_time_s"]) == pytest.approx(8.0, abs=0.02) == summary["sim_time_s"]
        assert float(row["wall_time_s"]) == summary["wall_time_s"]
        assert float(row["real_time_factor"]) == summary["real_time_factor"]
        assert (out / "runs" / row["run"] / "drone1.csv").is_file()
        assert run_info(out, row)["status"] == "ok"
    # AND the parameters reached the physics: the heavier parcel costs more energy on every drone and seed
    energy = {(r["packages.parcel.mass_kg"], r["vehicles.drone1.preset"], r["seed"]): float(r["energy_used_wh"])
              for r in rows}
    for (mass, preset, seed), wh in energy.items():
        if mass == "1.5":
            assert wh > energy[("0.5", preset, seed)]
    # AND the runs were spread over both workers, and the table was printed and plotted
    assert len({run_info(out, r)["pid"] for r in rows}) == 2
    assert sum(line.startswith("ok ") for line in res.stdout.splitlines()) == 8
    assert "8 of 8 runs finished" in res.stdout
    plot = out / "energy_used_wh_vs_packages.parcel.mass_kg.png"
    assert plot.read_bytes()[:4] == b"\x89PNG"


def test_one_run_in_this_process_reports_ok_timeout_or_failed_with_its_files():
    from unetyemu_ecs.sweep import RunTask, execute_run

    text = (WORLDS / "parcel_sweep.yaml").read_text()
    ok = execute_run(RunTask("a", "parcel_sweep.yaml", text, ((("packages", 0, "mass_kg"), 0.5),), 3, 1.0, None))
    assert ok.status == "ok" and ok.summary["seed"] == 3 and ok.summary["sim_time_s"] == pytest.approx(1.0)
    assert {"summary.json", "drone1.csv"} <= set(ok.files) and ok.error == ""
    slow = execute_run(RunTask("b", "parcel_sweep.yaml", text, (), 1, 40.0, 0.3))
    assert slow.status == "timeout" and slow.summary["sim_time_s"] < 40.0 and "summary.json" in slow.files
    bad = execute_run(RunTask("c", "parcel_sweep.yaml", text, ((("packages", 0, "mass_kg"), -1.0),), 1, 1.0, None))
    assert bad.status == "failed" and bad.summary is None and bad.files == {}
    assert bad.error.startswith("ConfigError: parcel_sweep.yaml:") and "mass_kg: must be > 0" in bad.error


def _faulty_world(tmp_path: Path) -> Path:
    path = tmp_path / "faulty.yaml"
    path.write_text((WORLDS / "parcel_sweep.yaml").read_text() + "\nsystems:\n  fault: {at_s: 1000.0, stall_s: 0.2}\n")
    return path


def test_runs_that_raise_die_or_overrun_are_reported_the_others_finish_and_resume_skips_finished(env, tmp_path):
    world, out = _faulty_world(tmp_path), tmp_path / "sweep"
    args = ["--set", "systems.fault.how=raise,exit,stall", "--set", "systems.fault.at_s=1.0,1000",
            "--workers", 2, "--duration", 2, "--timeout", STALL_TIMEOUT_S, "--out", out, "--quiet"]
    # WHEN a sweep has a run that raises, one whose process dies and one that stalls past its timeout
    res = sweep(env, world, *args)
    # THEN each is reported with its parameters and error, the three healthy runs finish, exit 1
    assert res.returncode == 1, res.stderr
    rows = {(r["systems.fault.how"], r["systems.fault.at_s"]): r for r in table(out)}
    assert len(rows) == 6
    assert all(rows[(how, "1000")]["status"] == "ok" for how in ("raise", "exit", "stall"))
    assert rows[("raise", "1.0")]["status"] == "failed"
    assert rows[("raise", "1.0")]["error"].startswith("RuntimeError: injected fault at t=1.00 s")
    assert rows[("exit", "1.0")]["status"] == "failed"
    assert rows[("exit", "1.0")]["error"].startswith("the worker process died")
    assert rows[("stall", "1.0")]["status"] == "timeout"
    assert rows[("stall", "1.0")]["error"].startswith(f"stopped after {STALL_TIMEOUT_S} s of wall time at sim time")
    assert "3 of 6 runs finished, 2 failed, 1 timed out" in res.stdout
    assert f"failed: {rows[('raise', '1.0')]['run']}: RuntimeError: injected fault" in res.stdout
    # the run that raised kept what it logged up to the fault; the stalled one its summary
    assert (out / "runs" / rows[("raise", "1.0")]["run"] / "drone1.csv").is_file()
    assert json.loads((out / "runs" / rows[("stall", "1.0")]["run"] / "summary.json").read_text())["interrupted"]
    finished = {key: run_info(out, r) for key, r in rows.items() if r["status"] == "ok"}

    # WHEN the sweep is resumed with a second seed
    res = sweep(env, world, *args, "--resume", "--seeds", 2)
    # THEN the finished runs are not run again; the failed ones and the new seed's runs are
    assert res.returncode == 1, res.stderr
    assert "6 of 12 runs finished (3 in an earlier session)" in res.stdout
    again = {(r["systems.fault.how"], r["systems.fault.at_s"], r["seed"]): r for r in table(out)}
    assert len(again) == 12
    for (how, at_s), info in finished.items():
        assert run_info(out, again[(how, at_s, "1")]) == info              # untouched: same pid, same figures
    assert {r["status"] for k, r in again.items() if k[1] == "1.0"} == {"failed", "timeout"}
    assert sum(r["status"] == "ok" for r in again.values()) == 6


def test_ctrl_c_keeps_finished_runs_and_resume_runs_only_the_rest(env, tmp_path):
    out = tmp_path / "sweep"
    args = [WORLDS / "parcel_sweep.yaml", "--set", "packages.parcel.mass_kg=0.5,1.0", "--seeds", 2,
            "--workers", 1, "--duration", 6, "--out", out]
    proc = subprocess.Popen([*unetyemu_command(), "sweep", *map(str, args)], env=env, cwd=REPO_ROOT,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + SWEEP_TIMEOUT_S
        while not list(out.glob("runs/*/run.json")) and time.monotonic() < deadline and proc.poll() is None:
            time.sleep(0.2)
        # WHEN Ctrl-C arrives after the first run finished
        proc.send_signal(signal.SIGINT)
        stdout, stderr = proc.communicate(timeout=60)
    finally:
        proc.kill()
    # THEN the sweep stops at once with 130, keeps the finished run(s) in its table and says how to go on
    assert proc.returncode == 130, stderr
    rows = table(out)
    assert 1 <= len(rows) < 4 and all(r["status"] == "ok" for r in rows)
    assert "runs not finished; finish them with: unetyemu sweep" in stderr and "--resume" in stderr
    kept = {r["run"]: run_info(out, r) for r in rows}
    # WHEN it is resumed
    res = sweep(env, *args, "--resume", "--quiet")
    # THEN only the rest run
    assert res.returncode == 0, res.stderr
    rows = table(out)
    assert len(rows) == 4 and all(r["status"] == "ok" for r in rows)
    assert f"4 of 4 runs finished ({len(kept)} in an earlier session)" in res.stdout
    for run, info in kept.items():
        assert json.loads((out / "runs" / run / "run.json").read_text()) == info


def test_with_ros2_each_worker_publishes_on_its_own_domain(env, tmp_path):
    out = tmp_path / "sweep"
    first = int(env.get("ROS_DOMAIN_ID", "0") or 0)
    res = sweep(env, WORLDS / "parcel_sweep.yaml", "--set", "packages.parcel.mass_kg=0.5,1.0", "--workers", 2,
                "--duration", 2, "--ros2", "dds", "--out", out, "--quiet")
    assert res.returncode == 0, res.stderr
    domains = set()
    for row in table(out):
        info = run_info(out, row)
        ros2 = json.loads((out / "runs" / row["run"] / "summary.json").read_text())["transports"]["ros2"]
        assert ros2["domain_id"] == info["ros2_domain"] and ros2["published"] > 0
        domains.add(ros2["domain_id"])
    assert domains == {first, first + 1}


def test_with_mavlink_each_worker_binds_its_own_px4_instance(env, tmp_path):
    from .mavlink_client import free_ports

    # GIVEN a drone with a MAVLink endpoint (on free ports, so that no other test's endpoint is in the way)
    ports = free_ports(n_drones=2)
    world = tmp_path / "mavlink.yaml"
    world.write_text((WORLDS / "parcel_sweep.yaml").read_text().replace(
        "      battery: {}\n",
        f"      battery: {{}}\n      mavlink: {{instance: 0, api_local_base: {ports['api_local']}, "
        f"api_remote_base: {ports['api_remote']}, gcs_local_base: {ports['gcs_local']}, "
        f"gcs_remote: {ports['gcs_remote']}}}\n"))
    out = tmp_path / "sweep"
    # WHEN two runs go at once on two workers
    res = sweep(env, world, "--set", "packages.parcel.mass_kg=0.5,1.0", "--workers", 2, "--duration", 4,
                "--out", out, "--quiet")
    # THEN each bound its own instance's ports (the same ports twice would have failed the second run)
    assert res.returncode == 0, res.stderr
    rows = table(out)
    infos = [run_info(out, r) for r in rows]
    endpoints = [json.loads((out / "runs" / r["run"] / "summary.json").read_text())["transports"]["mavlink"]["drone1"]
                 for r in rows]
    instances = sorted(next(iter(i["mavlink_instances"].values())) for i in infos)
    assert instances == [0, 1]
    assert sorted(e["ports"]["api"][0] for e in endpoints) == [ports["api_local"], ports["api_local"] + 1]
    assert sorted(e["system_id"] for e in endpoints) == [1, 2]
    # AND they did run at the same time, in two processes
    assert len({i["pid"] for i in infos}) == 2
    first, second = sorted(infos, key=lambda i: i["started_unix_s"])
    assert second["started_unix_s"] < first["started_unix_s"] + first["task_wall_s"]


def test_bad_input_is_refused_before_anything_starts(env, tmp_path):
    out = tmp_path / "sweep"
    world = WORLDS / "parcel_sweep.yaml"
    # an invalid combination: file, line and --set named; no Ray, no directory
    res = sweep(env, world, "--set", "packages.parcel.mass_kg=1.0,-2", "--out", out)
    assert res.returncode == 2
    line = next(i for i, t in enumerate(world.read_text().splitlines(), 1) if "mass_kg: 1.0" in t)
    assert f"parcel_sweep.yaml:{line}: packages[0].mass_kg: must be > 0, got -2.0" in res.stderr
    assert "(from --set packages.parcel.mass_kg=-2)" in res.stderr and not out.exists()
    # a key that names nothing, a malformed --set, a vehicle or figure that does not exist
    for args, words in ((["--set", "vehicles.drone7.preset=small"], "no item named 'drone7' in vehicles"),
                        (["--set", "packages.parcel.mass_kg"], "expected KEY.PATH=VALUE"),
                        (["--vehicle", "truck9"], "--vehicle truck9: no such vehicle"),
                        (["--set", "packages.parcel.mass_kg=1", "--plot", "colour"], "--plot colour: not a figure"),
                        (["--set", "vehicles.drone1.name=drone1,d2", "--vehicle", "drone1"],
                         "--vehicle drone1: no such vehicle in"),
                        (["--resume"], "--resume needs --out"),
                        (["--seeds", "0"], "argument --seeds: must be from 1")):
        res = sweep(env, world, *args, *(["--out", out] if "--resume" not in args else []))
        assert res.returncode == 2 and words in res.stderr, (args, res.stderr)
        assert not out.exists()
    # an output directory that cannot be made
    res = sweep(env, world, "--out", "/dev/null/sweep")
    assert res.returncode == 2 and "--out /dev/null/sweep: Not a directory" in res.stderr
    # a directory that holds something else, or a sweep of a world file changed since
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    res = sweep(env, world, "--out", out)
    assert res.returncode == 2 and "holds files that are not a sweep" in res.stderr
    (out / "notes.txt").unlink()
    (out / "sweep.json").write_text(json.dumps({"world_sha256": "0" * 64, "world_file": "old.yaml",
                                                "duration_s": None}))
    res = sweep(env, world, "--out", out)
    assert res.returncode == 2 and "pass --resume to finish it" in res.stderr
    res = sweep(env, world, "--out", out, "--resume")
    assert res.returncode == 2 and "with other contents than" in res.stderr


def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def test_a_sweep_runs_on_an_existing_cluster_given_by_address(env, tmp_path):
    # GIVEN a Ray head started with `ray start` (the README's cluster recipe, on one machine)
    port = _free_port()
    ray_tmp = tempfile.mkdtemp(prefix="ray", dir="/tmp")       # Ray's socket paths must stay short
    head = subprocess.Popen([RAY, "start", "--head", "--port", str(port), "--num-cpus", "2",
                             "--include-dashboard", "false", "--disable-usage-stats", "--temp-dir", ray_tmp,
                             "--block"], env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        ready = subprocess.run([RAY, "status", "--address", f"127.0.0.1:{port}"], env={**env, "RAY_AUTH_MODE": "token"},
                               capture_output=True, text=True, timeout=120)
        deadline = time.monotonic() + 120
        while ready.returncode != 0 and time.monotonic() < deadline and head.poll() is None:
            time.sleep(1)
            ready = subprocess.run([RAY, "status", "--address", f"127.0.0.1:{port}"],
                                   env={**env, "RAY_AUTH_MODE": "token"}, capture_output=True, text=True, timeout=120)
        assert ready.returncode == 0, ready.stdout + ready.stderr
        out = tmp_path / "sweep"
        # WHEN the sweep is pointed at it (token authentication, as Ray's clusters have by default)
        res = sweep({**env, "RAY_AUTH_MODE": "token"}, WORLDS / "parcel_sweep.yaml",
                    "--set", "packages.parcel.mass_kg=0.5,1.0", "--duration", 2, "--address", f"127.0.0.1:{port}",
                    "--out", out, "--quiet")
        # THEN it uses that cluster's CPUs and the outputs come back here
        assert res.returncode == 0, res.stderr
        assert f"on Ray cluster at 127.0.0.1:{port} (2 CPUs), 2 workers" in res.stdout
        assert [r["status"] for r in table(out)] == ["ok", "ok"]
        assert all((out / "runs" / r["run"] / "summary.json").is_file() for r in table(out))
    finally:
        head.terminate()                    # `ray start --block` stops the processes it started
        try:
            head.wait(timeout=60)
        except subprocess.TimeoutExpired:
            head.kill()
        shutil.rmtree(ray_tmp, ignore_errors=True)


@pytest.mark.slow
def test_the_readme_worked_example_runs_as_written(env, tmp_path):
    readme = (REPO_ROOT / "README.md").read_text()
    command = re.search(r"^```sh\n(unetyemu sweep worlds/parcel_sweep\.yaml [^\n]*)\n```", readme, re.M).group(1)
    (tmp_path / "worlds").symlink_to(WORLDS)
    args = command.split()[2:]
    res = sweep(env, *args, cwd=tmp_path, timeout=1800)
    assert res.returncode == 0, res.stderr
    out = tmp_path / args[args.index("--out") + 1]
    rows = table(out)
    assert len(rows) == 3 * 4 * 5 and all(r["status"] == "ok" for r in rows)
    # the small drone cannot lift more than 1 kg; every other case delivers without touching anything
    for r in rows:
        heavy = float(r["packages.parcel.mass_kg"]) > 1.0
        expected = "failed at step 1: overweight" if heavy and r["vehicles.drone1.preset"] == "small" else "completed"
        assert r["mission"] == expected and r["impacts"] == "0"
    assert (out / "energy_used_wh_vs_packages.parcel.mass_kg.png").is_file()
