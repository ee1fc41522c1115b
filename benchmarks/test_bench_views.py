"""What watching costs: the delivery scenario's real-time factor with the recorder, the Foxglove server
and the built-in web view, each with a live consumer and with a stalled one (issue target: each costs
less than 10 % of the real-time factor, and a stalled consumer nothing).

Every variant builds worlds/urban_delivery.yaml afresh, lets it run 1 simulated second (servers up,
the client subscribed, serialisers built), then times RUN_S simulated seconds as fast as it goes. A
stalled client stops reading after that first second; the run goes on STALL_SETTLE_S simulated
seconds (its socket's buffers fill, the server notices) before the timed part: what is measured is
what a client that stays stalled costs.
The variants run interleaved, ROUNDS times, so that a busy machine slows them alike; the figure is
each one's median real-time factor against the median of the runs without any consumer. Consumers
are separate processes (benchmarks/view_client.py), as a real Foxglove or browser is:

    plain            no transport
    record           --record (the recorder's worker process writes the bag)
    foxglove-idle    --foxglove, nobody connected (what serving costs before anyone watches)
    foxglove         --foxglove with a client subscribed to every channel, reading
    foxglove-stalled the same client, which stops reading after the first simulated second
    view-idle        --view, no page open
    view             --view with a page that selects drone3 and asks for every LiDAR cloud, reading
    view-stalled     the same page, which stops reading after the first simulated second

Run: python3 -m pytest benchmarks/test_bench_views.py --benchmark-only -s   (about 10 minutes on 2 cores)
"""

from __future__ import annotations

import json
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pytest

from unetyemu_ecs import Simulation, load_world

ROOT = Path(__file__).resolve().parent.parent
CLIENT = Path(__file__).resolve().parent / "view_client.py"
RUN_S = 10.0
STALL_SETTLE_S = 5.0
ROUNDS = 3
VARIANTS = ("plain", "record", "foxglove-idle", "foxglove", "foxglove-stalled", "view-idle", "view", "view-stalled")


def run_variant(variant: str, scratch: Path) -> dict:
    """Build, warm up and time one variant; its real-time factor and the consumer's counts."""
    kind = variant.split("-")[0]
    options = {"record": {"record": scratch / f"bag-{time.time_ns()}"}, "foxglove": {"foxglove": 0},
               "view": {"view": 0}}.get(kind, {})
    client = None
    with Simulation(load_world(ROOT / "worlds" / "urban_delivery.yaml"), **options) as sim:
        if kind in ("foxglove", "view") and not variant.endswith("idle"):
            url = sim.transports[kind].url
            url = url if kind == "foxglove" else url.replace("http://", "ws://") + "ws"
            client = subprocess.Popen([sys.executable, str(CLIENT), kind, url]
                                      + (["--stall"] if variant.endswith("stalled") else []),
                                      stdout=subprocess.PIPE, text=True)
            assert client.stdout.readline().strip() == "ready"
        try:
            sim.run(duration=1.0)
            if variant.endswith("stalled"):
                client.send_signal(signal.SIGUSR1)
                assert client.stdout.readline().strip() == "stalled"
                sim.run(duration=STALL_SETTLE_S)
            stats = sim.run(duration=RUN_S)
            sim.flush_transports(60.0)
            counters = sim.transport_counters().get(kind, {})
        finally:
            got = {}
            if client is not None:
                client.terminate()
                out, _ = client.communicate(timeout=30)
                got = json.loads(out.strip().splitlines()[-1]) if out.strip() and not variant.endswith("stalled") else {}
    return {"rtf": stats.real_time_factor, "client": got,
            "dropped": counters.get("snapshots_dropped", 0)}


def test_what_watching_costs_the_delivery_scenario(benchmark):
    results: dict[str, list[dict]] = {v: [] for v in VARIANTS}

    def rounds():
        with tempfile.TemporaryDirectory() as scratch:
            for _ in range(ROUNDS):
                for variant in VARIANTS:
                    results[variant].append(run_variant(variant, Path(scratch)))

    benchmark.pedantic(rounds, rounds=1, iterations=1)
    base = statistics.median(r["rtf"] for r in results["plain"])
    print(f"\ndelivery scenario, {RUN_S:.0f} simulated s per run, median of {ROUNDS} interleaved rounds")
    for variant in VARIANTS:
        rtf = statistics.median(r["rtf"] for r in results[variant])
        cost = 100.0 * (1.0 - rtf / base)
        spread = ", ".join(f"{r['rtf']:.2f}" for r in results[variant])
        received = results[variant][-1]["client"]
        print(f"  {variant:17s} real-time factor {rtf:.3f} ({spread})  cost {cost:+.1f} %"
              + (f"  client got {received['messages']} messages, {received['bytes'] / 1e6:.0f} MB" if received else ""))
        benchmark.extra_info[f"{variant}_rtf"] = round(rtf, 3)
        benchmark.extra_info[f"{variant}_cost_pct"] = round(cost, 1)


if __name__ == "__main__":
    sys.exit(pytest.main([__file__, "--benchmark-only", "-s"]))
