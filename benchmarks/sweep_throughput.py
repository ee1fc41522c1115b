"""Sweep throughput on a local Ray cluster: runs per minute with 1 and with 2 workers (one core each).

    python3 benchmarks/sweep_throughput.py [--runs 24] [--duration 20] [--rounds 1]

Each case is one sweep of ``--runs`` runs of worlds/parcel_sweep.yaml (package masses x seeds,
``--duration`` simulated seconds each), through the same :func:`run_sweep` as ``unetyemu sweep``.
Printed per case: runs per minute once the cluster is up (first run handed out to last run ended),
the same including the cluster's start, the mean wall time of one run, and the speed-up over 1 worker.
The pytest-benchmark version is ``benchmarks/test_bench_sweep.py``.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from unetyemu_ecs.sweep import SweepOptions, build_plan, parse_set, run_sweep  # noqa: E402

WORLD = REPO / "worlds" / "parcel_sweep.yaml"
MASSES_KG = ("0.25", "0.5", "0.75", "1.0")


@dataclass
class Throughput:
    workers: int
    runs: int
    runs_per_min: float             # once the cluster is up
    runs_per_min_total: float       # including the cluster's start
    run_wall_s: float               # mean wall time of one run's simulation
    cluster_start_s: float


def measure(workers: int, runs: int = 12, duration_s: float = 20.0) -> Throughput:
    """One sweep of ``runs`` runs (masses x seeds) on ``workers`` workers; its throughput."""
    seeds = -(-runs // len(MASSES_KG))
    plan = build_plan(WORLD, [parse_set("packages.parcel.mass_kg=" + ",".join(MASSES_KG))], seeds=seeds)
    plan = type(plan)(plan.world_file, plan.world_text, plan.world_sha256, plan.parameters, plan.seeds,
                      plan.runs[:runs])
    with tempfile.TemporaryDirectory(prefix="sweep-bench-") as tmp:
        t0 = time.perf_counter()
        result = run_sweep(plan, Path(tmp) / "sweep", SweepOptions(workers=workers, duration_s=duration_s),
                           quiet=True)
        total_s = time.perf_counter() - t0
    if result.count("ok") != runs:
        bad = [r for r in result.rows if r["status"] != "ok"]
        raise RuntimeError(f"{len(bad)} runs did not finish: {bad[:2]}")
    return Throughput(workers, runs, result.runs_per_minute or 0.0, 60.0 * runs / total_s,
                      statistics.mean(float(r["wall_time_s"]) for r in result.rows), result.cluster_start_s)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=24)
    parser.add_argument("--duration", type=float, default=20.0, help="simulated seconds per run")
    parser.add_argument("--rounds", type=int, default=1, help="interleaved rounds of (1 worker, 2 workers)")
    args = parser.parse_args(argv)
    found: dict[int, list[Throughput]] = {1: [], 2: []}
    for _ in range(args.rounds):
        for workers in (1, 2):
            found[workers].append(measure(workers, args.runs, args.duration))
    print(f"{args.runs} runs of {WORLD.name}, {args.duration:g} s simulated each; median of {args.rounds} round(s)")
    print(f"{'workers':>7} {'runs/min':>9} {'incl. start':>11} {'s/run':>6} {'start s':>7} {'speed-up':>8}")
    base = statistics.median(t.runs_per_min for t in found[1])
    for workers, results in found.items():
        rate = statistics.median(t.runs_per_min for t in results)
        total = statistics.median(t.runs_per_min_total for t in results)
        per_run = statistics.median(t.run_wall_s for t in results)
        start = statistics.median(t.cluster_start_s for t in results)
        print(f"{workers:>7} {rate:>9.1f} {total:>11.1f} {per_run:>6.2f} {start:>7.1f} {rate / base:>7.2f}x")
    return 0


if __name__ == "__main__":
    sys.exit(main())
