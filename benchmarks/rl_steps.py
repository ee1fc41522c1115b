"""Environment steps per second of the RL environments, next to gym-pybullet-drones' HoverAviary: random
actions, episodes reset when they end (resets in the time, as in training), median of interleaved rounds.

Usage:
    python3 benchmarks/rl_steps.py --rounds 3                     # every case, 3 interleaved rounds
    python3 benchmarks/rl_steps.py --rounds 1 --cases ours-1-motors peer-1

Cases (the hover task, 240 Hz physics, 30 Hz control, 8 s episodes on both sides):
    ours-1-motors, ours-1-velocity       ``DroneEnv("hover")`` at the motors and velocity action levels
    ours-16-batch-motors, -velocity      ``DroneVectorEnv("hover", 16)``: 16 copies as one batch in one world
    ours-16-sync                         Gymnasium's ``SyncVectorEnv`` of 16 ``DroneEnv`` (motors)
    peer-1                               gym-pybullet-drones' ``HoverAviary`` (ActionType.RPM, obs KIN)
    peer-16-sync                         ``SyncVectorEnv`` of 16 ``HoverAviary``

Each round is a fixed number of env steps (``--steps`` for one env, ``--batch-steps`` vector steps of 16
env steps each) of actions sampled up front from the action space (seed 0, so sampling is not timed);
a single env is reset when its episode ends, the vector envs reset their ended copies in the same step
(``AutoresetMode.SAME_STEP``, ours by design, ``SyncVectorEnv`` told so). Wall and CPU steps/s are
shown as median (min-max over the rounds); "ours / peer" divides the CPU figures (what a shared
machine disturbs least): each single env by ``peer-1``, each 16-env case by ``peer-16-sync``; "ends/1k"
is episodes ended per 1000 env steps. Random actions end episodes early on both sides (ours: a crash
after ~30 steps; the peer: its tilt > 0.4 rad truncation after ~15), and the peer's reset rebuilds its
world (``p.resetSimulation`` and the URDFs loaded again, ~30 ms against ~0.4 ms for a step), so most of
its time here is resets: a policy that flies full episodes sees the peer several times faster.

The peer (gym-pybullet-drones v2.1.0, not on PyPI; importing it needs setuptools' ``pkg_resources``)
is measured in the same run when installed; otherwise its figures measured on the project's 2-core
machine are shown as the reference (then compare the ratios only roughly: the machines may differ).
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import io
import statistics
import sys
import time
import warnings
from dataclasses import dataclass
from functools import partial
from typing import Any, Callable

import numpy as np

N_ENVS = 16
STEPS = 600                  # env steps per round, one env
BATCH_STEPS = 100            # vector steps per round, 16 envs (1600 env steps)
SEED = 0
LEVELS = ("motors", "velocity")
# gym-pybullet-drones v2.1.0 HoverAviary (RPM, KIN), env steps/s {"wall", "cpu"}, median of 3 interleaved
# rounds of this script: measured on the project's 2-core machine on 2026-11-24
REFERENCE_PEER_STEPS_S = {"peer-1": {"wall": 531.0, "cpu": 531.0},
                          "peer-16-sync": {"wall": 425.0, "cpu": 426.0}}
# the peer each case is compared with
PEER_OF = {"ours-1-motors": "peer-1", "ours-1-velocity": "peer-1", "ours-16-batch-motors": "peer-16-sync",
           "ours-16-batch-velocity": "peer-16-sync", "ours-16-sync": "peer-16-sync"}


def peer_available() -> bool:
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")          # pkg_resources' deprecation warning
            importlib.import_module("gym_pybullet_drones.envs")   # needs setuptools' pkg_resources
    except ImportError:
        return False
    return True


# -- the environments ------------------------------------------------------------------------------
def ours_batch(level: str) -> Any:
    """``DroneVectorEnv("hover", 16)`` at ``level``: 16 copies stepped as one batch."""
    from unetyemu_ecs.rl.envs import DroneVectorEnv

    return DroneVectorEnv("hover", N_ENVS, action_level=level)


def ours_single(level: str) -> Any:
    from unetyemu_ecs.rl.envs import DroneEnv

    return DroneEnv("hover", action_level=level)


def ours_sync() -> Any:
    from gymnasium.vector import AutoresetMode, SyncVectorEnv
    from unetyemu_ecs.rl.envs import DroneEnv

    return SyncVectorEnv([partial(DroneEnv, "hover") for _ in range(N_ENVS)], autoreset_mode=AutoresetMode.SAME_STEP)


def _quiet(make: Callable[[], Any]) -> Any:
    """The peer prints its URDF's parameters when built."""
    with warnings.catch_warnings(), contextlib.redirect_stdout(io.StringIO()):
        warnings.simplefilter("ignore")
        return make()


def peer_single() -> Any:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        from gym_pybullet_drones.envs import HoverAviary
    return _quiet(HoverAviary)


def peer_sync() -> Any:
    from gymnasium.vector import AutoresetMode, SyncVectorEnv

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        from gym_pybullet_drones.envs import HoverAviary
    return _quiet(lambda: SyncVectorEnv([HoverAviary] * N_ENVS, autoreset_mode=AutoresetMode.SAME_STEP))


@dataclass(frozen=True)
class CaseSpec:
    name: str
    label: str
    n_envs: int
    peer: bool
    make: Callable[[], Any]                   # -> the environment


CASES = {c.name: c for c in (
    CaseSpec("ours-1-motors", "DroneEnv, motors", 1, False, partial(ours_single, "motors")),
    CaseSpec("ours-1-velocity", "DroneEnv, velocity", 1, False, partial(ours_single, "velocity")),
    CaseSpec("ours-16-batch-motors", "DroneVectorEnv(16), motors", N_ENVS, False, partial(ours_batch, "motors")),
    CaseSpec("ours-16-batch-velocity", "DroneVectorEnv(16), velocity", N_ENVS, False, partial(ours_batch, "velocity")),
    CaseSpec("ours-16-sync", "SyncVectorEnv(16 DroneEnv), motors", N_ENVS, False, ours_sync),
    CaseSpec("peer-1", "HoverAviary, RPM", 1, True, peer_single),
    CaseSpec("peer-16-sync", "SyncVectorEnv(16 HoverAviary), RPM", N_ENVS, True, peer_sync),
)}


class Bench:
    """One case built and reset, its actions sampled; :meth:`run` steps through them once."""

    def __init__(self, spec: CaseSpec, steps: int = STEPS, batch_steps: int = BATCH_STEPS) -> None:
        self.spec = spec
        self.env = spec.make()
        self.vector = spec.n_envs > 1
        calls = batch_steps if self.vector else steps
        self.env_steps = calls * spec.n_envs
        self.env.action_space.seed(SEED)
        self.actions = [self.env.action_space.sample() for _ in range(calls)]
        self.env.reset(seed=SEED)
        self.run(self.actions[: max(1, calls // 10)])          # warm up, untimed

    def run(self, actions: list[np.ndarray] | None = None) -> int:
        """Step through ``actions`` (default: the round's); returns the number of episodes that ended."""
        env, ended = self.env, 0
        for a in self.actions if actions is None else actions:
            _obs, _reward, terminated, truncated, _info = env.step(a)
            if self.vector:
                ended += int(np.count_nonzero(np.logical_or(terminated, truncated)))
            elif terminated or truncated:
                env.reset()
                ended += 1
        return ended

    def timed(self) -> tuple[float, float, int]:
        """One round: (wall s, CPU s, episodes ended)."""
        w0, c0 = time.perf_counter(), time.process_time()
        ended = self.run()
        return time.perf_counter() - w0, time.process_time() - c0, ended

    def close(self) -> None:
        self.env.close()


def spread(values: list[float]) -> str:
    return f"{statistics.median(values):8.0f} ({min(values):.0f}-{max(values):.0f})"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=3, help="interleaved rounds per case, the median is shown (1-9)")
    parser.add_argument("--steps", type=int, default=STEPS, help="env steps per round of one env (10-100000)")
    parser.add_argument("--batch-steps", type=int, default=BATCH_STEPS,
                        help=f"vector steps per round of {N_ENVS} envs (10-10000)")
    parser.add_argument("--cases", nargs="+", default=list(CASES), choices=list(CASES))
    args = parser.parse_args(argv)
    if not 1 <= args.rounds <= 9:
        parser.error(f"--rounds must be in [1, 9], got {args.rounds}")
    if not 10 <= args.steps <= 100_000:
        parser.error(f"--steps must be in [10, 100000], got {args.steps}")
    if not 10 <= args.batch_steps <= 10_000:
        parser.error(f"--batch-steps must be in [10, 10000], got {args.batch_steps}")
    measure_peer = peer_available()
    cases = [CASES[n] for n in args.cases if measure_peer or not CASES[n].peer]
    print(f"peer: {'gym-pybullet-drones, measured in this run' if measure_peer else 'not installed: reference figures'}")
    benches = {c.name: Bench(c, args.steps, args.batch_steps) for c in cases}
    wall: dict[str, list[float]] = {n: [] for n in benches}
    cpu: dict[str, list[float]] = {n: [] for n in benches}
    ended: dict[str, int] = dict.fromkeys(benches, 0)
    try:
        for _ in range(args.rounds):                   # interleaved: every case sees the same machine state
            for name, bench in benches.items():
                w, c, e = bench.timed()
                wall[name].append(bench.env_steps / w)
                cpu[name].append(bench.env_steps / c)
                ended[name] += e
    finally:
        for bench in benches.values():
            bench.close()
    peer_cpu = {n: statistics.median(cpu[n]) for n in benches if CASES[n].peer}
    if not measure_peer:
        peer_cpu = {n: v["cpu"] for n, v in REFERENCE_PEER_STEPS_S.items()}
    print(f"{'case':<23} {'envs':>4} {'wall steps/s (min-max)':>24} {'CPU steps/s (min-max)':>24} "
          f"{'ends/1k':>7} {'ours / peer':>11}")
    for name, bench in benches.items():
        peer = peer_cpu.get(PEER_OF.get(name, ""))         # None: no peer case to divide by in this run
        ratio = f"{statistics.median(cpu[name]) / peer:11.2f}" if peer else f"{'':>11}"
        if name in PEER_OF and not measure_peer:
            ratio += "*"
        print(f"{name:<23} {bench.spec.n_envs:>4} {spread(wall[name]):>24} {spread(cpu[name]):>24} "
              f"{1000.0 * ended[name] / (args.rounds * bench.env_steps):7.1f} {ratio}", flush=True)
    if not measure_peer:
        for name, fig in REFERENCE_PEER_STEPS_S.items():
            print(f"{name:<23} {CASES[name].n_envs:>4} {fig['wall']:>8.0f}*{'':>15} {fig['cpu']:>8.0f}*")
        print("* gym-pybullet-drones v2.1.0 measured on the project's 2-core machine on 2026-11-24 (not in this run)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
