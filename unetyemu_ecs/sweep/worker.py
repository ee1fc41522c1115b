"""One run of a sweep, as a worker process executes it: build, run, summarise, hand the outputs back.

Nothing here imports Ray: :func:`execute_run` is a plain function (tested on its own), which the Ray
actor of :mod:`unetyemu_ecs.sweep.ray_runner` calls. The run writes into a temporary directory on the
worker's machine and returns its files as bytes, so a cluster's nodes need no shared file system: the
sweep's driver writes them under its own output directory.
"""

from __future__ import annotations

import os
import socket
import tempfile
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..config.schema import Path as KeyPath

MAX_RETURNED_BYTES = 256 << 20      # a run's logs come back up to this size; beyond it only summary.json


@dataclass(frozen=True)
class RunTask:
    """Everything a worker needs for one run (picklable, no open resources)."""

    run_id: str
    world_file: str                                 # for messages and relative paths in the world
    world_text: str
    overrides: tuple[tuple[KeyPath, Any], ...]      # the run's parameters plus the slot's MAVLink instances
    seed: int
    duration_s: float | None                        # None: the world file's duration_s
    timeout_s: float | None                         # wall-clock limit of the run itself (None: none)
    ros2: str = "off"                               # off / dds / rclpy / auto
    ros2_domain: int | None = None
    mavlink: bool = False                           # drones have MAVLink endpoints (instances set by overrides)


@dataclass
class RunOutcome:
    """What came of one run: ``status`` ok / timeout / failed / cancelled, its summary and output files."""

    run_id: str
    status: str
    error: str = ""
    summary: dict[str, Any] | None = None
    files: dict[str, bytes] = field(default_factory=dict)
    host: str = ""
    pid: int = 0
    wall_s: float = 0.0                             # the whole task: build, run, close
    started_unix_s: float = 0.0                     # when the worker began it (its clock)


def _collect(out: Path) -> tuple[dict[str, bytes], str]:
    paths = sorted(p for p in out.rglob("*") if p.is_file())
    total = sum(p.stat().st_size for p in paths)
    if total > MAX_RETURNED_BYTES:
        paths = [p for p in paths if p.name == "summary.json"]
        note = f"outputs of {total / 2**20:.0f} MiB exceed {MAX_RETURNED_BYTES >> 20} MiB: only summary.json kept"
    else:
        note = ""
    return {str(p.relative_to(out)): p.read_bytes() for p in paths}, note


def execute_run(task: RunTask) -> RunOutcome:
    """Run ``task`` to the end of its duration (or its timeout) at full speed; never raises for the run's
    own failures: they come back as ``status="failed"`` with the error and whatever the run had written."""
    from ..app import Simulation
    from ..config.world_file import resolve_world
    from ..config.yaml_source import load_yaml_text
    from .overrides import apply_overrides

    t0 = time.perf_counter()
    outcome = RunOutcome(task.run_id, "failed", host=socket.gethostname(), pid=os.getpid(), started_unix_s=time.time())
    with tempfile.TemporaryDirectory(prefix="unetyemu-sweep-") as tmp:
        out = Path(tmp) / "run"
        try:
            doc, src = load_yaml_text(task.world_text, task.world_file)
            world = resolve_world(apply_overrides(doc, list(task.overrides)), src, seed=task.seed)
            if task.ros2_domain is not None:
                os.environ["ROS_DOMAIN_ID"] = str(task.ros2_domain)
            timed_out = False
            sim = Simulation(world, out_dir=out, ros2=task.ros2, mavlink=task.mavlink, blas_threads=1,
                             raycast_threads=1)
            try:
                def watch(sim_s: float, end_s: float, wall_s: float) -> None:
                    nonlocal timed_out
                    if task.timeout_s is not None and wall_s > task.timeout_s:
                        timed_out = True
                        sim.stop()

                duration = task.duration_s if task.duration_s is not None else world.spec.world.duration_s
                sim.run(duration=duration, rate=None, progress=watch, progress_interval_s=0.25)
                outcome.summary = sim.summary()
            finally:
                sim.close()                         # writes summary.json, closes the logs
            if timed_out:
                outcome.status = "timeout"
                outcome.error = (f"stopped after {task.timeout_s:g} s of wall time at sim time "
                                 f"{outcome.summary['sim_time_s']:.2f} s")
            elif outcome.summary["interrupted"]:    # a stop signal reached the worker: the sweep is stopping
                outcome.status = "cancelled"
                outcome.error = "interrupted before its end"
            else:
                outcome.status = "ok"
        except Exception as exc:                    # the run's own failure: reported, the sweep goes on
            outcome.status = "failed"
            outcome.error = f"{type(exc).__name__}: {exc}\n{traceback.format_exc(limit=-8)}".strip()
        if out.is_dir():
            outcome.files, note = _collect(out)
            if note:
                outcome.error = (outcome.error + "\n" + note).strip()
    outcome.wall_s = time.perf_counter() - t0
    return outcome


class SweepWorker:
    """The body of a Ray actor: one per worker slot, running one run at a time."""

    def __init__(self, slot: int) -> None:
        self.slot = slot        # its BLAS and OpenMP pools start at one thread (ray_runner.WORKER_ENV)

    def run(self, task: RunTask) -> RunOutcome:
        return execute_run(task)


__all__ = ["RunOutcome", "RunTask", "SweepWorker", "execute_run"]
