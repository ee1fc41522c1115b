"""The stress cases of ``benchmarks/stress.py`` as pytest-benchmarks: every case (flight 1-1000 drones, LiDAR
10-100 drones with ROS 2 off and on, 1 and 5 cameras at two resolutions, the delivery scenario) in its own
interpreter, as the script runs it.

Run: python3 -m pytest benchmarks/test_bench_stress.py --benchmark-only -s
     STRESS_SECONDS=5 python3 -m pytest benchmarks/test_bench_stress.py --benchmark-only -s -k "flight or lidar-60"

The benchmark's own time is the whole case (start-up, world building, settling, then ``STRESS_SECONDS``
simulated seconds, default 2); the figures to compare are those of the measured interval alone, in each
result's ``extra_info`` (``--benchmark-json``) and printed at the end as ``stress.py`` prints them: real-time
factor per wall and per CPU second, ms per step of every phase, peak resident memory of the case's process.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

import pytest

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from stress import CASES, SECONDS_MAX, SECONDS_MIN, format_row, header, run_case_isolated  # noqa: E402

ROWS: dict[str, dict] = {}


def _seconds() -> float:
    raw = os.environ.get("STRESS_SECONDS", "2")
    try:
        seconds = float(raw)
    except ValueError:
        raise pytest.UsageError(f"STRESS_SECONDS must be a number of simulated seconds, got {raw!r}") from None
    if not SECONDS_MIN <= seconds <= SECONDS_MAX:
        raise pytest.UsageError(f"STRESS_SECONDS must be in [{SECONDS_MIN:g}, {SECONDS_MAX:g}], got {seconds}")
    return seconds


@pytest.fixture(scope="module", autouse=True)
def _report():
    yield
    if ROWS:
        print("\n" + header())
        for case in CASES:
            if case in ROWS:
                print(format_row(ROWS[case]))


@pytest.mark.parametrize("case", CASES)
def test_stress_case(benchmark, case):
    seconds = _seconds()
    row = benchmark.pedantic(run_case_isolated, args=(case, seconds), rounds=1, iterations=1)
    assert row["case"] == case and abs(row["sim_s"] - seconds) < 0.01, row      # it simulated what was asked
    assert row["rtf_wall"] > 0 and row["rtf_cpu"] > 0 and row["peak_rss_mb"] > 0
    benchmark.extra_info.update(row)
    ROWS[case] = row
