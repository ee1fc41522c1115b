"""The `unetyemu` command line, run as a user would run it (a subprocess)."""

from __future__ import annotations

import csv
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

from ..conftest import REPO_ROOT, WORLDS


def unetyemu(*args: str, cwd: Path = REPO_ROOT, timeout: float = 300) -> subprocess.CompletedProcess:
    exe = shutil.which("unetyemu")
    cmd = [exe] if exe else [sys.executable, "-m", "unetyemu_ecs.cli"]
    return subprocess.run([*cmd, *args], cwd=cwd, capture_output=True, text=True, timeout=timeout)


def test_run_urban_delivery_headless_prints_summary_and_writes_logs(tmp_path):
    # WHEN the main scenario runs for 10 s as fast as possible
    out = tmp_path / "run"
    res = unetyemu("run", str(WORLDS / "urban_delivery.yaml"), "--duration", "10", "--rate", "max",
                   "--out", str(out))
    # THEN it succeeds and the summary names the time, the real-time factor and every vehicle
    assert res.returncode == 0, res.stderr
    assert "sim time 10.00 s" in res.stdout and "real-time factor" in res.stdout
    for name in ("drone1", "drone2", "drone3", "car1", "car2", "car3", "truck1", "package1"):
        assert name in res.stdout
    summary = json.loads((out / "summary.json").read_text())
    assert summary["steps"] == 2400 and summary["seed"] == 42
    # AND every vehicle has a CSV log at 10 Hz: a row at t=0 and one per 0.1 s
    for name in ("drone1", "truck1"):
        with open(out / f"{name}.csv", newline="") as fh:
            rows = list(csv.DictReader(fh))
        assert len(rows) == 101
        assert float(rows[-1]["time_s"]) == 10.0
    # AND drones log their motors, power and mission; cars do not
    with open(out / "drone1.csv", newline="") as fh:
        header = next(csv.reader(fh))
    assert {"thrust_fl_n", "power_w", "soc_frac", "remaining_time_s", "payload_kg", "mission_step"} <= set(header)
    with open(out / "truck1.csv", newline="") as fh:
        truck = list(csv.DictReader(fh))
    assert "thrust_fl_n" not in truck[0] and {"drive_mode", "throttle", "brake", "steer_deg"} <= set(truck[0])
    # AND the truck drives its route on the road (level, moving), while a parked car stays put
    assert truck[-1]["drive_mode"] == "route" and float(truck[-1]["x_m"]) - float(truck[0]["x_m"]) > 30.0
    assert abs(float(truck[-1]["z_m"]) - float(truck[0]["z_m"])) < 0.05
    with open(out / "car1.csv", newline="") as fh:
        car = list(csv.DictReader(fh))
    assert car[-1]["drive_mode"] == "parked" and abs(float(car[-1]["x_m"]) - float(car[0]["x_m"])) < 0.01
    # AND the summary reports each drone's mission, distance and energy
    d1 = next(e for e in summary["entities"] if e["name"] == "drone1")
    assert d1["mission"]["mission"] == "rooftop_delivery" and d1["energy_used_wh"] > 0 and d1["distance_m"] > 1
    assert "rooftop_delivery: running" in res.stdout


def test_validate_accepts_the_shipped_worlds():
    res = unetyemu("validate", *(str(p) for p in sorted(WORLDS.glob("*.yaml"))))
    assert res.returncode == 0, res.stderr
    assert res.stdout.count(": OK") == len(list(WORLDS.glob("*.yaml")))


def test_validate_on_a_broken_copy_prints_file_line_and_key_path_and_exits_2(tmp_path):
    # GIVEN the delivery world with a negative package mass
    text = (WORLDS / "urban_delivery.yaml").read_text()
    broken = tmp_path / "broken.yaml"
    broken.write_text(text.replace("mass_kg: 2.5", "mass_kg: -2.5"))
    line = next(i for i, l in enumerate(broken.read_text().splitlines(), 1) if "mass_kg: -2.5" in l)
    # WHEN validated
    res = unetyemu("validate", str(broken))
    # THEN the error names the file, the line and the key path, and the exit code is 2
    assert res.returncode == 2
    assert f"{broken}:{line}: packages[0].mass_kg: must be > 0, got -2.5" in res.stderr


def test_run_refuses_a_bad_world_without_starting(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("world: {physics_hz: 0}\n")
    res = unetyemu("run", str(bad), "--out", str(tmp_path / "out"))
    assert res.returncode == 2
    assert "world.physics_hz: must be >= 50" in res.stderr
    assert not (tmp_path / "out").exists()


def test_bad_cli_arguments_exit_2_with_a_reason(tmp_path):
    res = unetyemu("run", str(WORLDS / "empty.yaml"), "--rate", "fast")
    assert res.returncode == 2 and "expected a positive number or 'max'" in res.stderr
    res = unetyemu("run", str(WORLDS / "empty.yaml"), "--duration", "-3")
    assert res.returncode == 2 and "duration must be a positive" in res.stderr


def test_plugins_lists_the_builtin_components():
    res = unetyemu("plugins")
    assert res.returncode == 0
    assert "aero_drag" in res.stdout and "unetyemu_ecs.systems:" in res.stdout


def test_ctrl_c_ends_the_run_cleanly_keeping_logs_and_printing_the_summary(tmp_path):
    # GIVEN the main scenario running in real time (so that it is still running when interrupted)
    out = tmp_path / "run"
    exe = shutil.which("unetyemu")
    cmd = [exe] if exe else [sys.executable, "-m", "unetyemu_ecs.cli"]
    proc = subprocess.Popen([*cmd, "run", str(WORLDS / "urban_delivery.yaml"), "--rate", "1", "--quiet",
                             "--out", str(out)], cwd=REPO_ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    try:
        # wait until the first log rows exist, then let it run a couple of seconds more
        deadline = time.monotonic() + 120
        while not (out / "drone1.csv").exists() and time.monotonic() < deadline:
            time.sleep(0.2)
        time.sleep(3.0)
        # WHEN the user presses Ctrl-C
        proc.send_signal(signal.SIGINT)
        stdout, stderr = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            os.kill(proc.pid, signal.SIGKILL)
    # THEN it exits 130, prints the summary marked as interrupted, and keeps the rows written so far
    assert proc.returncode == 130, stderr
    assert "INTERRUPTED" in stdout and "drone1" in stdout
    summary = json.loads((out / "summary.json").read_text())
    assert summary["interrupted"] is True and 0.5 < summary["sim_time_s"] < 150.0
    with open(out / "drone1.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    # rows cover the simulated time up to the interruption, at 10 Hz, and the last row is complete
    assert len(rows) >= 10
    assert abs(float(rows[-1]["time_s"]) - summary["sim_time_s"]) <= 0.1 + 1e-9
    assert all(value != "" for value in rows[-1].values())


def test_a_bad_ros_domain_id_is_a_clear_error_not_a_traceback(tmp_path):
    env = {**os.environ, "ROS_DOMAIN_ID": "abc"}
    exe = shutil.which("unetyemu")
    cmd = [exe] if exe else [sys.executable, "-m", "unetyemu_ecs.cli"]
    res = subprocess.run([*cmd, "run", str(WORLDS / "empty.yaml"), "--ros2", "dds", "--duration", "0.1",
                          "--out", str(tmp_path / "r")], cwd=REPO_ROOT, capture_output=True, text=True, timeout=120, env=env)
    assert res.returncode == 1 and "ROS_DOMAIN_ID must be an integer" in res.stderr and "Traceback" not in res.stderr


def test_run_with_ros2_auto_says_which_backend_it_chose_and_rclpy_without_ros_is_a_clear_error(tmp_path):
    exe = shutil.which("unetyemu")
    cmd = [exe] if exe else [sys.executable, "-m", "unetyemu_ecs.cli"]
    env = {k: v for k, v in os.environ.items() if k not in ("CYCLONEDDS_URI", "ROS_DOMAIN_ID")}
    res = subprocess.run([*cmd, "run", str(WORLDS / "empty.yaml"), "--ros2", "auto", "--duration", "0.5",
                          "--out", str(tmp_path / "a")], cwd=REPO_ROOT, capture_output=True, text=True, timeout=120,
                         env=env)
    assert res.returncode == 0, res.stderr
    from unetyemu_ecs.transport.ros2.rclpy_backend import rclpy_available
    backend = "rclpy" if rclpy_available() else "dds"
    assert f"ROS 2: node /unetyemu_sim on the {backend} backend, ROS_DOMAIN_ID 0" in res.stderr
    if backend == "dds":
        assert "loopback only" in res.stderr
        res = subprocess.run([*cmd, "run", str(WORLDS / "empty.yaml"), "--ros2", "rclpy", "--duration", "0.1",
                              "--out", str(tmp_path / "r")], cwd=REPO_ROOT, capture_output=True, text=True,
                             timeout=120, env=env)
        assert res.returncode == 1 and "rclpy does not import" in res.stderr and "Traceback" not in res.stderr
