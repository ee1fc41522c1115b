"""Hand a sweep's runs to Ray: one actor per worker slot (one CPU each), one run per actor at a time.

Ray does the placement, the processes and the transport of tasks and results, on a local cluster it
starts (``ray.init(num_cpus=workers)``) or an existing one (``--address``). This module only keeps
each slot busy, notices runs that end, fail, kill their worker or overrun their time limit, and stops
everything at once when asked (Ctrl-C).
"""

from __future__ import annotations

import logging
import os
import signal
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from .plan import RunSpec
from .worker import RunOutcome, RunTask, SweepWorker

POLL_S = 0.25               # how often the driver looks at time limits and a stop request [s]
# the env of every worker process: BLAS and OpenMP pools of one thread from the start (one core per run)
WORKER_ENV = {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}


class RayUnavailable(RuntimeError):
    """Ray is not installed, or the cluster cannot be reached or started."""


@dataclass
class Cluster:
    """A Ray connection: ``workers`` slots; ``started`` when this process started a local cluster."""

    workers: int
    address: str | None
    started: bool
    description: str


def connect(workers: int | None, address: str | None) -> Cluster:
    """Start a local Ray cluster of ``workers`` CPUs (default: this machine's cores), or connect to the
    one at ``address`` (``ray://host:10001`` or ``host:6379``; ``auto``: the one ``ray start`` made here)."""
    try:
        import ray
    except ImportError as exc:
        raise RayUnavailable(f"unetyemu sweep needs Ray, a dependency of unetyemu_ecs: reinstall it ({exc})") from None
    runtime_env = {"env_vars": dict(WORKER_ENV)}
    # ray.init installs its own SIGTERM handler (exit at once); the caller's (a clean stop that keeps the
    # finished runs) comes back when it returns
    main = threading.current_thread() is threading.main_thread()
    handlers = {sig: signal.getsignal(sig) for sig in (signal.SIGINT, signal.SIGTERM)} if main else {}
    try:
        if address is None:
            cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
            asked, workers = workers, min(workers or cores, cores)       # one core each, never more than there are
            ray.init(num_cpus=workers, include_dashboard=False, log_to_driver=False, logging_level=logging.WARNING,
                     runtime_env=runtime_env, configure_logging=True)
            _restore(handlers)
            note = f" (of {asked} asked: this machine has {cores} cores)" if asked and asked > workers else ""
            return Cluster(workers, None, True, f"local Ray cluster, {workers} worker{'s' * (workers != 1)}{note}")
        ray.init(address=address, log_to_driver=False, logging_level=logging.WARNING, runtime_env=runtime_env)
        _restore(handlers)
    except Exception as exc:            # Ray raises ConnectionError, RuntimeError, ValueError... by cause
        if ray.is_initialized():
            ray.shutdown()
        hint = ""
        if address not in (None, "auto") and not os.environ.get("RAY_AUTH_MODE"):
            hint = ("; if the cluster uses token authentication (Ray's default), set RAY_AUTH_MODE=token and give "
                    "its token (the head's ~/.ray/auth_token here, or RAY_AUTH_TOKEN)")
        raise RayUnavailable(f"cannot {'start a local Ray cluster' if address is None else f'connect to Ray at {address}'}: "
                             f"{type(exc).__name__}: {exc}{hint}") from None
    cpus = int(ray.cluster_resources().get("CPU", 0))
    if cpus < 1:
        ray.shutdown()
        raise RayUnavailable(f"the Ray cluster at {address} has no CPUs to run on")
    # a worker holds one CPU for the whole sweep: more workers than CPUs would wait forever
    asked, workers = workers, min(workers or cpus, cpus)
    note = f" (of {asked} asked)" if asked and asked > workers else ""
    return Cluster(workers, address, False, f"Ray cluster at {address} ({cpus} CPUs), {workers} workers{note}")


def _restore(handlers: dict[int, Any]) -> None:
    for sig, handler in handlers.items():
        if handler is not None:
            signal.signal(sig, handler)


def disconnect(cluster: Cluster) -> None:
    """Leave the cluster (and stop it when this process started it)."""
    import ray

    if ray.is_initialized():
        ray.shutdown()


def run_all(cluster: Cluster, runs: list[RunSpec], make_task: Callable[[RunSpec, int], RunTask],
            on_outcome: Callable[[RunSpec, RunOutcome], None], should_stop: Callable[[], bool],
            tick: Callable[[int], None], hard_limit_s: float | None = None) -> list[RunSpec]:
    """Run ``runs`` on the cluster's slots; return those left unrun or unfinished when ``should_stop()``
    turned true (their workers are killed at once).

    ``make_task(run, slot)`` builds a run's task for the slot it goes to; ``on_outcome`` gets every run
    that ended (ok, failed, timed out, or its worker died); ``tick(running)`` is called at least every
    :data:`POLL_S`. A run still going ``hard_limit_s`` after it started is killed with its worker and
    reported as timed out (the run's own ``timeout_s`` normally stops it first and keeps its logs).
    """
    import ray
    from ray.exceptions import RayActorError, RayError

    actor_class = ray.remote(num_cpus=1, max_restarts=0, max_task_retries=0)(SweepWorker)
    actors: list[Any] = [None] * cluster.workers
    queue = deque(runs)
    active: dict[Any, tuple[int, RunSpec, float]] = {}      # result ref -> (slot, run, start time)
    stopped: list[RunSpec] = []

    def retire(slot: int) -> None:
        if actors[slot] is not None:
            ray.kill(actors[slot], no_restart=True)
            actors[slot] = None

    try:
        while queue or active:
            if should_stop():
                # runs that ended before the stop are results: collect them, then leave
                ready, _ = ray.wait(list(active), num_returns=len(active), timeout=0) if active else ([], [])
                for ref in ready:
                    slot, run, _t = active.pop(ref)
                    try:
                        outcome = ray.get(ref)
                    except RayError:
                        stopped.append(run)
                        continue
                    if outcome.status == "ok":
                        on_outcome(run, outcome)
                    else:
                        stopped.append(run)
                break
            busy = {slot for slot, _run, _t in active.values()}
            for slot in range(cluster.workers):
                if slot in busy or not queue:
                    continue
                run = queue.popleft()
                if actors[slot] is None:
                    actors[slot] = actor_class.remote(slot)
                active[actors[slot].run.remote(make_task(run, slot))] = (slot, run, time.monotonic())
            ready, _ = ray.wait(list(active), num_returns=1, timeout=POLL_S)
            for ref in ready:
                slot, run, _t = active.pop(ref)
                try:
                    outcome = ray.get(ref)
                except RayActorError as exc:    # the process died under the run (a crash, out of memory, killed)
                    actors[slot] = None
                    outcome = RunOutcome(run.run_id, "failed", error=f"the worker process died: {_first_line(exc)}")
                except RayError as exc:
                    outcome = RunOutcome(run.run_id, "failed", error=f"{type(exc).__name__}: {_first_line(exc)}")
                if outcome.status == "cancelled" or (should_stop() and outcome.status != "ok"):
                    stopped.append(run)         # cut short by the stop itself: not a result
                    continue
                on_outcome(run, outcome)
            if hard_limit_s is not None:
                now = time.monotonic()
                for ref, (slot, run, started) in list(active.items()):
                    if now - started > hard_limit_s:
                        active.pop(ref)
                        retire(slot)
                        on_outcome(run, RunOutcome(run.run_id, "timeout", error=f"killed with its worker after "
                                                   f"{hard_limit_s:.0f} s: it did not stop at its time limit"))
            tick(len(active))
    finally:
        unfinished = stopped + [run for _slot, run, _t in active.values()] + list(queue)
        for slot in range(cluster.workers):
            retire(slot)
    return unfinished


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip()
    return text.splitlines()[0] if text else type(exc).__name__


__all__ = ["Cluster", "RayUnavailable", "WORKER_ENV", "connect", "disconnect", "run_all"]
