"""A sweep from start to table: check every run's world, reuse finished runs, run the rest on Ray,
keep each run's outputs in its own directory, and write the table and the plot.

The sweep directory::

    sweep.json              what was swept: the world file (and its SHA-256), parameters, seeds, duration
    results.csv             one row per ended run: parameters, seed, status, figures, error
    <figure>_vs_<key>.png   the chosen figure against the chosen parameter (mean +/- std over seeds);
                            <figure>_over_seeds.png, its histogram, for a sweep of seeds alone
    runs/<run id>/          each run's summary.json, vehicle CSV logs and run.json (status, figures, error)

``run.json`` is written last: a run with ``status: ok`` there is finished, and a resumed sweep skips
it. Failed, timed-out and unfinished runs run again on resume.
"""

from __future__ import annotations

import json
import shutil
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TextIO

from ..config.yaml_source import load_yaml_text
from .figures import NUMERIC_FIGURES, run_figures
from .overrides import apply_overrides
from .isolation import (IsolationError, check_mavlink_instances, check_ros2_domains, instances_per_slot,
                        mavlink_overrides, ros2_domain)
from .plan import RunSpec, SweepPlan, explain_invalid, resolve_run, validate_plan
from .progress import SweepProgress
from .table import plot_figure, plot_histogram, write_csv
from .worker import RunOutcome, RunTask

SWEEP_FILE = "sweep.json"
RESULTS_FILE = "results.csv"
RUN_FILE = "run.json"
TABLE_EVERY_S = 5.0         # the CSV is rewritten at most this often while runs come in (and at the end)
MIN_GRACE_S = 30.0          # a run's worker is killed this long after its own time limit at the latest


class SweepError(ValueError):
    """The sweep cannot start: invalid worlds, a bad option, or an output directory that does not fit."""


@dataclass(frozen=True)
class SweepOptions:
    """How to run a sweep (``unetyemu sweep`` switches)."""

    workers: int | None = None          # slots (one core each); None: every core (local) or every CPU (cluster)
    address: str | None = None          # an existing Ray cluster; None: start a local one
    duration_s: float | None = None     # sim time per run; None: the world file's duration_s
    timeout_s: float | None = None      # wall time per run before it is stopped and reported; None: no limit
    vehicle: str | None = None          # figures of this vehicle; None: the world's totals
    plot: str = "energy_used_wh"        # the figure to plot ...
    against: str | None = None          # ... against this parameter (None: the first)
    ros2: str = "off"                   # ROS 2 in every run (each worker slot on its own domain)
    mavlink: bool = False               # MAVLink endpoints on every drone (each slot on its own instances)
    resume: bool = False                # continue the sweep in out_dir


@dataclass
class SweepResult:
    out_dir: Path
    rows: list[dict[str, Any]]
    csv_path: Path
    plot_path: Path | None
    skipped: int = 0                    # finished by an earlier session of this sweep
    unfinished: list[str] = field(default_factory=list)   # run ids not run or cut short by a stop
    cluster: str = ""
    cluster_start_s: float = 0.0        # wall time to start or reach the Ray cluster
    running_s: float = 0.0              # wall time from the first run handed out to the last one ended
    ran: int = 0                        # runs that ended in this session (any status)

    @property
    def runs_per_minute(self) -> float | None:
        """Throughput of this session's runs once the cluster was up."""
        return 60.0 * self.ran / self.running_s if self.ran and self.running_s > 0 else None

    def count(self, status: str) -> int:
        return sum(1 for r in self.rows if r["status"] == status)

    @property
    def interrupted(self) -> bool:
        return bool(self.unfinished)


def _sweep_record(plan: SweepPlan, options: SweepOptions) -> dict[str, Any]:
    return {"world_file": plan.world_file, "world_sha256": plan.world_sha256, "duration_s": options.duration_s,
            "parameters": [{"key": p.key, "values": list(p.texts)} for p in plan.parameters],
            "seeds": list(plan.seeds), "runs": len(plan.runs), "ros2": options.ros2, "mavlink": options.mavlink,
            "updated": time.strftime("%Y-%m-%dT%H:%M:%S")}


def _write_json(path: Path, data: dict[str, Any]) -> None:
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(data, indent=2, default=str) + "\n", encoding="utf-8")
    tmp.replace(path)


def finished_runs(out_dir: Path, plan: SweepPlan, options: SweepOptions) -> dict[str, dict[str, Any]]:
    """Check that ``out_dir`` can hold this sweep (a new one is created, empty); return the runs an
    earlier session of it finished (resume).

    Raises
    ------
    SweepError
        It is not a directory, holds files but no sweep, holds a sweep but ``resume`` is off, or holds one
        of other world-file contents or duration (its runs would not be the same runs).
    """
    record = out_dir / SWEEP_FILE
    try:
        if out_dir.exists() and not out_dir.is_dir():
            raise SweepError(f"--out {out_dir}: exists and is not a directory")
        if not record.exists():
            if out_dir.is_dir() and any(out_dir.iterdir()):
                raise SweepError(f"--out {out_dir}: holds files that are not a sweep; choose a new or empty directory")
            if options.resume:
                raise SweepError(f"--resume: {out_dir} holds no sweep to resume ({SWEEP_FILE} is missing)")
            out_dir.mkdir(parents=True, exist_ok=True)      # writable? (empty until every check has passed)
            return {}
        if not options.resume:
            raise SweepError(f"--out {out_dir}: holds a sweep already; pass --resume to finish it, or choose a new "
                             "directory")
        before = json.loads(record.read_text(encoding="utf-8"))
    except OSError as exc:
        raise SweepError(f"--out {out_dir}: {exc.strerror or exc}") from None
    except ValueError as exc:           # not JSON
        raise SweepError(f"{record}: cannot be read ({exc}); it is not a sweep this version wrote") from None
    if not isinstance(before, dict):
        raise SweepError(f"{record}: not a sweep record (a JSON object); it is not a sweep this version wrote")
    if before.get("world_sha256") != plan.world_sha256:
        raise SweepError(f"{record}: the sweep ran {before.get('world_file')!r} with other contents than "
                         f"{plan.world_file!r} has now; its runs would not be comparable (start a new sweep)")
    if before.get("duration_s") != options.duration_s:
        raise SweepError(f"{record}: the sweep ran for --duration {before.get('duration_s')}, not "
                         f"{options.duration_s}; resume it with the same duration")
    finished = {}
    for run in plan.runs:
        path = out_dir / "runs" / run.run_id / RUN_FILE
        try:
            info = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, ValueError):
            continue
        if isinstance(info, dict) and info.get("status") == "ok" and (path.parent / "summary.json").is_file():
            finished[run.run_id] = info
    return finished


def claim_out_dir(out_dir: Path, plan: SweepPlan, options: SweepOptions) -> None:
    """Create the sweep's directory and write ``sweep.json`` (after every check has passed)."""
    try:
        (out_dir / "runs").mkdir(parents=True, exist_ok=True)
        _write_json(out_dir / SWEEP_FILE, _sweep_record(plan, options))
    except OSError as exc:
        raise SweepError(f"--out {out_dir}: cannot write there: {exc.strerror or exc}") from None


def _row(run: RunSpec, status: str, error: str, figures: dict[str, Any] | None) -> dict[str, Any]:
    row: dict[str, Any] = {"run": run.run_id, "status": status}
    row.update({key: text for key, _v, text in run.values})
    row["seed"] = run.seed
    row.update(figures or {})
    row["error"] = error.strip().splitlines()[0] if error.strip() else ""
    return row


def _figures(run_dir: Path, vehicle: str | None) -> dict[str, Any] | None:
    """The table's figures from a run's summary.json; None when it is missing, unreadable, or lacks the vehicle."""
    try:
        summary = json.loads((run_dir / "summary.json").read_text(encoding="utf-8"))
        return run_figures(summary, vehicle)
    except (OSError, ValueError, KeyError, TypeError):
        return None


def _store(out_dir: Path, run: RunSpec, outcome: RunOutcome, task: RunTask | None, options: SweepOptions) -> dict[str, Any]:
    """Write a run's files and its run.json (last); return its table row."""
    run_dir = out_dir / "runs" / run.run_id
    if run_dir.exists():
        shutil.rmtree(run_dir)
    run_dir.mkdir(parents=True)
    for name, data in outcome.files.items():
        target = (run_dir / name).resolve()
        if run_dir.resolve() not in target.parents:      # a file name from a worker never leaves the run's folder
            continue
        target.parent.mkdir(parents=True, exist_ok=True)
        target.write_bytes(data)
    figures = _figures(run_dir, options.vehicle) if outcome.summary is not None else None
    info = {"run": run.run_id, "status": outcome.status, "error": outcome.error,
            "parameters": {key: text for key, _v, text in run.values}, "seed": run.seed, "figures": figures,
            "host": outcome.host, "pid": outcome.pid, "task_wall_s": round(outcome.wall_s, 3),
            "started_unix_s": round(outcome.started_unix_s, 3) if outcome.started_unix_s else None,
            "ros2_domain": task.ros2_domain if task else None,
            "mavlink_instances": {".".join(map(str, path)): v for path, v in (task.overrides if task else ())
                                  if path[-2:] == ("mavlink", "instance")}}
    _write_json(run_dir / RUN_FILE, info)
    return _row(run, outcome.status, outcome.error, figures)


def _check_options(plan: SweepPlan, options: SweepOptions) -> None:
    if options.plot not in NUMERIC_FIGURES:
        raise SweepError(f"--plot {options.plot}: not a figure of the table (one of {', '.join(NUMERIC_FIGURES)})")
    keys = [p.key for p in plan.parameters]
    if options.against is not None and options.against not in keys:
        raise SweepError(f"--against {options.against}: not a swept parameter ({', '.join(keys) or 'none given'})")
    if options.vehicle is not None:                 # in every combination: a --set may rename vehicles
        seen: set[str] = set()
        for run in plan.runs:
            if run.combination in seen:
                continue
            seen.add(run.combination)
            names = [e.name for e in resolve_run(plan, run).vehicles]
            if options.vehicle not in names:
                where = f" with {', '.join(f'{k}={t}' for k, _v, t in run.values)}" if run.values else ""
                raise SweepError(f"--vehicle {options.vehicle}: no such vehicle in {plan.world_file}{where} "
                                 f"(vehicles: {', '.join(names)})")


def run_sweep(plan: SweepPlan, out_dir: str | Path, options: SweepOptions = SweepOptions(),
              stream: TextIO | None = None, should_stop: Callable[[], bool] = lambda: False,
              quiet: bool = False) -> SweepResult:
    """Run every run of ``plan`` not finished before, on Ray; write the table and the plot.

    Raises
    ------
    SweepError
        Before anything runs: a parameter combination gives an invalid world (every error, each traced
        to its ``--set``), a bad option, or an unusable output directory.
    RayUnavailable
        Ray is missing or the cluster cannot be reached.
    """
    from . import ray_runner

    stream = stream if stream is not None else sys.stderr
    out_dir = Path(out_dir)
    bad = validate_plan(plan)
    if bad:
        raise SweepError(explain_invalid(plan, bad))
    _check_options(plan, options)
    finished = finished_runs(out_dir, plan, options)
    rows: dict[str, dict[str, Any]] = {}
    for run in plan.runs:
        if run.run_id in finished:
            rows[run.run_id] = _row(run, "ok", "", _figures(out_dir / "runs" / run.run_id, options.vehicle))
    todo = [run for run in plan.runs if run.run_id not in finished]
    keys = [p.key for p in plan.parameters]
    csv_path = out_dir / RESULTS_FILE
    ordered = lambda: [rows[r.run_id] for r in plan.runs if r.run_id in rows]     # noqa: E731
    unfinished: list[RunSpec] = []
    cluster_text = ""
    first_domain = 0
    if options.ros2 != "off":                       # the first worker's domain, read as the ROS 2 transport reads it
        from ..transport.ros2.dds_backend import Ros2Error, domain_from_env

        try:
            first_domain = domain_from_env()
        except Ros2Error as exc:
            raise SweepError(str(exc)) from None
    cluster_start_s = running_s = 0.0
    ran = 0
    doc, _src = load_yaml_text(plan.world_text, plan.world_file)
    combos = {r.combination: r.overrides for r in todo}
    # MAVLink endpoints from --mavlink, the world file or a --set: each worker's runs on their own instances
    isolate_mavlink = options.mavlink or any(instances_per_slot(apply_overrides(doc, list(o)), forced=False) > 0
                                             for o in combos.values())
    claimed = False
    if not todo:
        claim_out_dir(out_dir, plan, options)
        claimed = True
    elif should_stop():                             # stopped while the worlds were checked: nothing written
        unfinished = list(todo)
    else:
        t0 = time.perf_counter()
        cluster = ray_runner.connect(options.workers, options.address)
        cluster_start_s = time.perf_counter() - t0
        cluster_text = cluster.description
        try:
            try:
                if options.ros2 != "off":
                    check_ros2_domains(first_domain, cluster.workers)
                if isolate_mavlink:
                    for overrides in combos.values():
                        check_mavlink_instances(apply_overrides(doc, list(overrides)), options.mavlink,
                                                cluster.workers)
            except IsolationError as exc:
                raise SweepError(str(exc)) from None
            claim_out_dir(out_dir, plan, options)
            claimed = True
            tasks: dict[str, RunTask] = {}

            def make_task(run: RunSpec, slot: int) -> RunTask:
                applied = apply_overrides(doc, list(run.overrides)) if isolate_mavlink else doc
                extra = mavlink_overrides(applied, slot, options.mavlink) if isolate_mavlink else ()
                task = RunTask(run.run_id, plan.world_file, plan.world_text, (*run.overrides, *extra), run.seed,
                               options.duration_s, options.timeout_s, options.ros2,
                               ros2_domain(first_domain, slot) if options.ros2 != "off" else None, options.mavlink)
                tasks[run.run_id] = task
                return task

            progress = None if quiet else SweepProgress(stream, len(plan.runs), skipped=len(finished))
            if not quiet:
                stream.write(f"sweep of {len(plan.runs)} runs ({len(finished)} finished before) on {cluster_text}; "
                             f"outputs in {out_dir}\n")
                stream.flush()
            counts = {"ok": 0, "failed": 0}
            last_table = [time.monotonic()]

            def on_outcome(run: RunSpec, outcome: RunOutcome) -> None:
                rows[run.run_id] = _store(out_dir, run, outcome, tasks.get(run.run_id), options)
                counts["ok" if outcome.status == "ok" else "failed"] += 1
                if outcome.status != "ok" and progress is not None:
                    first = outcome.error.strip().splitlines()[0] if outcome.error.strip() else ""
                    progress.note(f"run {run.label}: {outcome.status.upper()}: {first}")
                if time.monotonic() - last_table[0] >= TABLE_EVERY_S:
                    write_csv(csv_path, keys, ordered())
                    last_table[0] = time.monotonic()

            def tick(running: int) -> None:
                if progress is not None:
                    progress.update(counts["ok"], running, counts["failed"])

            hard = None if options.timeout_s is None else options.timeout_s + max(MIN_GRACE_S, 0.5 * options.timeout_s)
            t0 = time.perf_counter()
            unfinished = ray_runner.run_all(cluster, todo, make_task, on_outcome, should_stop, tick, hard)
            running_s = time.perf_counter() - t0
            ran = len(todo) - len(unfinished)
            if progress is not None:
                progress.update(counts["ok"], 0, counts["failed"], force=True)
                progress.done()
        finally:
            ray_runner.disconnect(cluster)
    plot_path = None
    table_rows = ordered()
    if not claimed:
        return SweepResult(out_dir, table_rows, csv_path, None, len(finished), [r.run_id for r in unfinished])
    try:
        write_csv(csv_path, keys, table_rows)
        if keys and any(r["status"] == "ok" for r in table_rows):
            against = options.against or keys[0]
            plot_path = plot_figure(out_dir / f"{options.plot}_vs_{against}.png", table_rows, keys, options.plot,
                                    against, title=plan.world_name)
        elif any(r["status"] == "ok" for r in table_rows):           # seeds only: a Monte-Carlo campaign
            plot_path = plot_histogram(out_dir / f"{options.plot}_over_seeds.png", table_rows, options.plot,
                                       title=plan.world_name)
    except OSError as exc:
        raise SweepError(f"cannot write the table or plot in {out_dir}: {exc.strerror or exc} (the runs' own "
                         "outputs are under runs/)") from None
    return SweepResult(out_dir, table_rows, csv_path, plot_path, len(finished), [r.run_id for r in unfinished],
                       cluster_text, cluster_start_s, running_s, ran)


__all__ = ["SweepError", "SweepOptions", "SweepResult", "claim_out_dir", "finished_runs", "run_sweep"]
