"""The `unetyemu` command line, run as a user would run it (a subprocess)."""

from __future__ import annotations

import csv
import json
import os
import shutil
import signal
import subprocess
import time
from pathlib import Path

import pytest

from ..conftest import REPO_ROOT, WORLDS, unetyemu_command


def unetyemu(*args: str, cwd: Path = REPO_ROOT, timeout: float = 300) -> subprocess.CompletedProcess:
    cmd = unetyemu_command()
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
    res = unetyemu("run", str(WORLDS / "empty.yaml"), "--mavlink", "--mavlink-bind", "localhost:14540")
    assert res.returncode == 2 and "'localhost:14540' is not an IP address" in res.stderr


def test_plugins_lists_the_builtin_components():
    res = unetyemu("plugins")
    assert res.returncode == 0
    assert "aero_drag" in res.stdout and "unetyemu_ecs.systems:" in res.stdout
    # AND the transports group, with ROS 2, the recorder and the live views behind the same seam as any other
    transports = res.stdout.split("unetyemu_ecs.transports:")[1]
    for name in ("mavlink", "ros2", "record", "foxglove", "view"):
        assert f"  {name} " in transports, name


def _csv_rows(path: Path) -> int:
    try:
        with open(path, newline="") as fh:
            return max(0, sum(1 for _ in fh) - 1)
    except FileNotFoundError:
        return 0


def _start_and_stop(tmp_path: Path, signals: list[signal.Signals], gap_s: float = 0.05):
    """Run the main scenario in real time; once 12 log rows are written (1.1 s of sim time, however slow
    the machine), send ``signals`` ``gap_s`` apart; return (process, stdout, stderr, out dir)."""
    out = tmp_path / "run"
    cmd = unetyemu_command()
    proc = subprocess.Popen([*cmd, "run", str(WORLDS / "urban_delivery.yaml"), "--rate", "1", "--quiet",
                             "--out", str(out)], cwd=REPO_ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    try:
        deadline = time.monotonic() + 300                  # a hang guard, not a speed expectation
        while _csv_rows(out / "drone1.csv") < 12 and proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.1)
        for k, sig in enumerate(signals):
            if k:
                time.sleep(gap_s)
            proc.send_signal(sig)
        stdout, stderr = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            os.kill(proc.pid, signal.SIGKILL)
    return proc, stdout, stderr, out


def _assert_clean_stop(proc, stdout: str, stderr: str, out: Path, code: int) -> None:
    # exits with 128 + the signal, prints the summary marked as interrupted, keeps the rows written so far
    assert proc.returncode == code, stderr
    assert "INTERRUPTED" in stdout and "drone1" in stdout and "Traceback" not in stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["interrupted"] is True and 1.0 < summary["sim_time_s"] < 150.0
    with open(out / "drone1.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    # rows cover the simulated time up to the interruption, at 10 Hz, and the last row is complete
    assert len(rows) >= 12
    assert abs(float(rows[-1]["time_s"]) - summary["sim_time_s"]) <= 0.1 + 1e-9
    assert all(value != "" for value in rows[-1].values())


def test_ctrl_c_ends_the_run_cleanly_keeping_logs_and_printing_the_summary(tmp_path):
    _assert_clean_stop(*_start_and_stop(tmp_path, [signal.SIGINT]), code=130)


@pytest.mark.parametrize("sig, code", [(signal.SIGTERM, 143), (signal.SIGHUP, 129)])
def test_sigterm_and_sighup_stop_the_run_like_ctrl_c(tmp_path, sig, code):
    # `timeout`, `docker stop`, systemd and `ros2 launch` send SIGTERM; a closed terminal SIGHUP
    _assert_clean_stop(*_start_and_stop(tmp_path, [sig]), code=code)


def test_two_ctrl_c_50_ms_apart_still_end_with_130_and_a_summary(tmp_path):
    _assert_clean_stop(*_start_and_stop(tmp_path, [signal.SIGINT, signal.SIGINT], gap_s=0.05), code=130)


def test_run_refuses_to_overwrite_an_earlier_run_or_an_empty_out(tmp_path):
    # GIVEN a directory that holds an earlier run's files
    earlier = tmp_path / "earlier"
    earlier.mkdir()
    (earlier / "summary.json").write_text("{}")
    res = unetyemu("run", str(WORLDS / "empty.yaml"), "--duration", "0.1", "--out", str(earlier))
    assert res.returncode == 2 and "already holds files" in res.stderr and "--overwrite" in res.stderr
    assert (earlier / "summary.json").read_text() == "{}"
    res = unetyemu("run", str(WORLDS / "empty.yaml"), "--duration", "0.1", "--out", str(earlier), "--overwrite")
    assert res.returncode == 0, res.stderr
    assert json.loads((earlier / "summary.json").read_text())["steps"] == 24
    # AND an empty --out is an argument error, not "write into the current directory"
    res = unetyemu("run", str(WORLDS / "empty.yaml"), "--duration", "0.1", "--out", "", cwd=tmp_path)
    assert res.returncode == 2 and "must not be empty" in res.stderr
    assert list(tmp_path.iterdir()) == [earlier]


def test_default_output_directories_never_collide(tmp_path):
    shutil.copy(WORLDS / "empty.yaml", tmp_path / "empty.yaml")
    for _ in range(2):
        res = unetyemu("run", "empty.yaml", "--duration", "0.1", cwd=tmp_path)
        assert res.returncode == 0, res.stderr
    runs = sorted((tmp_path / "runs").iterdir())
    assert len(runs) == 2 and all((r / "summary.json").exists() for r in runs)


def test_version_and_numbers_out_of_range_are_clear(tmp_path):
    res = unetyemu("--version")
    assert res.returncode == 0 and res.stdout.startswith("unetyemu_ecs ")
    for args, message in ((["--duration", "1e308"], "up to 604800"), (["--rate", "1e-9"], "between 0.01 and 1000"),
                          (["--seed", "-1"], "seed must be"), (["--duration", "nan"], "duration must be")):
        res = unetyemu("run", str(WORLDS / "empty.yaml"), *args, "--out", str(tmp_path / "x"))
        assert res.returncode == 2 and message in res.stderr and "Traceback" not in res.stderr, (args, res.stderr)


def test_gui_without_a_display_says_so_instead_of_an_x_error(tmp_path):
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    cmd = unetyemu_command()
    res = subprocess.run([*cmd, "run", str(WORLDS / "empty.yaml"), "--gui", "--duration", "0.1",
                          "--out", str(tmp_path / "g")], cwd=REPO_ROOT, capture_output=True, text=True, timeout=120,
                         env=env)
    assert res.returncode == 1 and "needs a display" in res.stderr and "xvfb-run" in res.stderr


def test_plugins_shows_what_the_presets_give_instead_of_required():
    res = unetyemu("plugins")
    motors = res.stdout[res.stdout.index("  motors "):]
    line = next(l for l in motors.splitlines() if "max_thrust_per_motor_n" in l)
    assert "per preset:" in line and "small 30.0" in line and "(required)" not in line
    energy = res.stdout[res.stdout.index("  energy "):]
    assert "battery_wh: number = 500.0 (from the vehicle preset)" in energy


def test_plugins_into_a_closed_pipe_is_quiet():
    cmd = " ".join(unetyemu_command())
    res = subprocess.run(f"{cmd} plugins | head -1", shell=True, cwd=REPO_ROOT, capture_output=True, text=True,
                         timeout=120)
    assert "Traceback" not in res.stderr and "BrokenPipe" not in res.stderr


def test_a_bad_ros_domain_id_is_a_clear_error_not_a_traceback(tmp_path):
    env = {**os.environ, "ROS_DOMAIN_ID": "abc"}
    cmd = unetyemu_command()
    res = subprocess.run([*cmd, "run", str(WORLDS / "empty.yaml"), "--ros2", "dds", "--duration", "0.1",
                          "--out", str(tmp_path / "r")], cwd=REPO_ROOT, capture_output=True, text=True, timeout=120, env=env)
    assert res.returncode == 1 and "ROS_DOMAIN_ID must be an integer" in res.stderr and "Traceback" not in res.stderr


def test_run_with_ros2_auto_says_which_backend_it_chose_and_rclpy_without_ros_is_a_clear_error(tmp_path):
    cmd = unetyemu_command()
    env = {k: v for k, v in os.environ.items() if k not in ("CYCLONEDDS_URI", "ROS_DOMAIN_ID")}
    res = subprocess.run([*cmd, "run", str(WORLDS / "empty.yaml"), "--ros2", "auto", "--duration", "0.5",
                          "--out", str(tmp_path / "a")], cwd=REPO_ROOT, capture_output=True, text=True, timeout=120,
                         env=env)
    assert res.returncode == 0, res.stderr
    from unetyemu_ecs.transport.ros2.rclpy_backend import rclpy_available
    backend = "rclpy" if rclpy_available() else "dds"
    assert f"ROS 2: node /unetyemu_sim on the {backend} backend, ROS_DOMAIN_ID 0" in res.stderr
    if backend == "dds":
        assert "loopback only (ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST)" in res.stderr   # as tests/conftest.py sets
        res = subprocess.run([*cmd, "run", str(WORLDS / "empty.yaml"), "--ros2", "rclpy", "--duration", "0.1",
                              "--out", str(tmp_path / "r")], cwd=REPO_ROOT, capture_output=True, text=True,
                             timeout=120, env=env)
        assert res.returncode == 1 and "rclpy does not import" in res.stderr and "Traceback" not in res.stderr


def test_teleop_refuses_a_name_that_cannot_be_a_vehicle():
    res = unetyemu("teleop", "drone 1; rm")
    assert res.returncode == 2 and "is not a vehicle name" in res.stderr and "Traceback" not in res.stderr


def test_plot_of_a_killed_run_plots_what_it_can_and_names_the_skipped_line(tmp_path):
    # GIVEN a run whose drone log lost the end of its last row (SIGKILL while writing)
    out = tmp_path / "run"
    res = unetyemu("run", str(WORLDS / "empty.yaml"), "--duration", "0.1", "--out", str(out))
    assert res.returncode == 0, res.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["pads"] == {}                       # the empty world has none; the city names its pads
    log = out / "d1.csv"
    (out / "d1.csv").write_text("time_s,x_m,y_m,z_m\n0.0,0,0,1\n0.1,0,0,1.1\n0.2,0,0,1.")
    # WHEN it is plotted
    res = unetyemu("plot", str(out))
    # THEN the readable rows are plotted and the damaged line is named on stderr
    assert res.returncode == 0, res.stderr
    assert str(log.with_suffix(".png")) in res.stdout
    assert "warning:" in res.stderr and "line 4" in res.stderr and "Traceback" not in res.stderr
