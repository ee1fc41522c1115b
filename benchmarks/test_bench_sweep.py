"""Sweep throughput: runs per minute of ``unetyemu sweep`` on a local Ray cluster with 1 and 2 workers.

Run: python3 -m pytest benchmarks/test_bench_sweep.py --benchmark-only --benchmark-columns=median,min,max,rounds
Each round is one sweep of 24 runs of worlds/parcel_sweep.yaml (20 simulated seconds each), cluster
start included in the timed round; runs per minute once the cluster is up, and the 2-worker speed-up,
are in extra_info and printed at the end. The plain script is ``benchmarks/sweep_throughput.py``.
"""

from __future__ import annotations

import contextlib

import pytest

from sweep_throughput import measure  # noqa: E402  (benchmarks/ is on sys.path)

pytest.importorskip("ray")

RUNS, DURATION_S = 24, 20.0
RESULTS: dict[int, float] = {}


@pytest.fixture(scope="module", autouse=True)
def _report(request):
    yield
    if len(RESULTS) < 2:
        return
    lines = [f"{w} worker{'s' * (w != 1)}: {rate:5.1f} runs/min ({rate / RESULTS[1]:.2f}x)" for w, rate in RESULTS.items()]
    capture = request.config.pluginmanager.get_plugin("capturemanager")
    with capture.global_and_fixture_disabled() if capture is not None else contextlib.nullcontext():
        print(f"\n\nsweep throughput, {RUNS} runs of {DURATION_S:g} s (cluster up)\n" + "\n".join(lines), flush=True)


@pytest.mark.parametrize("workers", [1, 2])
def test_sweep_runs_per_minute(benchmark, workers):
    found = []
    benchmark.pedantic(lambda: found.append(measure(workers, RUNS, DURATION_S)), rounds=1, iterations=1)
    t = found[-1]
    RESULTS[workers] = t.runs_per_min
    benchmark.extra_info.update(runs_per_min=round(t.runs_per_min, 2), runs_per_min_total=round(t.runs_per_min_total, 2),
                                run_wall_s=round(t.run_wall_s, 3), cluster_start_s=round(t.cluster_start_s, 2))
