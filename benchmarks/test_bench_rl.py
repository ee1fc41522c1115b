"""RL environment throughput: env steps per second of the hover task with random actions, resets included,
ours (one env; 16 as one batch; 16 through Gymnasium's SyncVectorEnv) next to gym-pybullet-drones'
HoverAviary (one env; 16 through SyncVectorEnv), skipped when the peer is not installed.

Run: python3 -m pytest benchmarks/test_bench_rl.py --benchmark-only --benchmark-columns=median,min,max,rounds
Each round is a fixed number of env steps (600 for one env, 100 vector steps = 1600 env steps for 16) of
actions sampled up front (seed 0); the cases are those of ``benchmarks/rl_steps.py`` (the plain script
with interleaved rounds and CPU figures). Env steps/s are in each result's extra_info and printed, with
the ours / peer ratios (wall, from each case's median round), at the end of the run.
"""

from __future__ import annotations

import contextlib
import time

import pytest

from rl_steps import (CASES, PEER_OF, REFERENCE_PEER_STEPS_S, Bench,  # noqa: E402  (benchmarks/ is on sys.path)
                      peer_available)

ROUNDS = 3
RESULTS: dict[str, float] = {}


@pytest.fixture(scope="module", autouse=True)
def _report(request):
    yield
    if not RESULTS:
        return
    measured = {n: v for n, v in RESULTS.items() if CASES[n].peer}
    peer = {**{n: v["wall"] for n, v in REFERENCE_PEER_STEPS_S.items()}, **measured}
    lines = [f"{'case':<23} {'envs':>4} {'env steps/s':>11} {'ours / peer':>11}"]
    for name, rate in RESULTS.items():
        ref = PEER_OF.get(name)
        ratio = f"{rate / peer[ref]:11.2f}{'' if ref in measured else '*'}" if ref else ""
        lines.append(f"{name:<23} {CASES[name].n_envs:>4} {rate:>11.0f} {ratio}")
    reference = [n for n in REFERENCE_PEER_STEPS_S if n not in measured]
    if reference:
        lines += [f"{n:<23} {CASES[n].n_envs:>4} {peer[n]:>10.0f}*" for n in reference]
        lines.append("* gym-pybullet-drones v2.1.0 measured on the project's 2-core machine on 2026-11-24 (not in this run)")
    capture = request.config.pluginmanager.get_plugin("capturemanager")
    with capture.global_and_fixture_disabled() if capture is not None else contextlib.nullcontext():
        print("\n\nRL env steps/s (median round, wall)\n" + "\n".join(lines), flush=True)


@pytest.mark.parametrize("case", list(CASES))
def test_env_steps_per_second(benchmark, case):
    spec = CASES[case]
    if spec.peer and not peer_available():
        pytest.skip("gym-pybullet-drones is not installed (or setuptools' pkg_resources is missing)")
    bench = Bench(spec)
    try:
        cpu_s: list[float] = []
        ended: list[int] = []

        def one_round():
            c0 = time.process_time()
            ended.append(bench.run())
            cpu_s.append(time.process_time() - c0)

        benchmark.pedantic(one_round, rounds=ROUNDS, iterations=1)
        rate = bench.env_steps / benchmark.stats.stats.median
        benchmark.extra_info.update({
            "env_steps_per_round": bench.env_steps,
            "env_steps_per_s": rate,
            "env_steps_per_cpu_s": bench.env_steps / sorted(cpu_s)[len(cpu_s) // 2],
            "episodes_ended_per_1k_steps": 1000.0 * sum(ended) / (len(ended) * bench.env_steps),
        })
        RESULTS[case] = rate
        assert rate > 0.0
    finally:
        bench.close()
