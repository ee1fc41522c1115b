"""The worker process of a :class:`~.worker.ProcessTransport`: ``python -m unetyemu_ecs.transport.worker_main``.

It reads frames from stdin (see :mod:`.worker`), builds the real transport with the factory it is
given, and feeds it the snapshots rebuilt from what crossed: the events and command results arrive
as increments and are appended to this process's own lists, so ``snapshot.events[cursor:events_end]``
reads as in the simulation's process. Replies go to stdout (nothing else may write there: print()
and warnings go to stderr), one writer at a time: a selective transport's thread writes its
``wants`` there too (:class:`WantsReporter`). It ends when stdin closes or after a ``stop``.
"""

from __future__ import annotations

import os
import signal
import sys
import threading
from importlib import import_module
from typing import Any

from .api import Snapshot, TransportError
from .worker import read_frame, write_frame


class RefusingPort:
    """The command port of a transport in a worker: it is output-only, so every submission is refused."""

    def submit(self, command: Any) -> int:
        raise TransportError("a transport run in a worker process cannot submit commands")

    def reject(self, vehicle: str, kind: str, text: str, source: str) -> int:
        raise TransportError("a transport run in a worker process cannot report rejected samples")


class SnapshotRebuilder:
    """Turns the slim tuples back into :class:`Snapshot` objects with append-only events and results."""

    def __init__(self, vehicles: tuple[str, ...], kinds: tuple[str, ...]) -> None:
        self.vehicles, self.kinds = tuple(vehicles), tuple(kinds)
        self.events: list[Any] = []
        self.results: list[Any] = []

    def __call__(self, item: tuple) -> Snapshot:
        step, sim_time_s, dt_s, arrays, sensors, events, results, mission_status = item
        self.events.extend(events)
        self.results.extend(results)
        return Snapshot(step=step, sim_time_s=sim_time_s, dt_s=dt_s, vehicles=self.vehicles, kinds=self.kinds,
                        arrays=arrays, sensors=sensors, events=self.events, events_end=len(self.events),
                        results=self.results, results_end=len(self.results), mission_status=mission_status)


class Replies:
    """The reply pipe, written by the serve loop and by a selective transport's thread (one at a time)."""

    def __init__(self, out_fd: int) -> None:
        self.out_fd = out_fd
        self._lock = threading.Lock()

    def write(self, obj: Any) -> None:
        with self._lock:
            write_frame(self.out_fd, obj)


class WantsReporter:
    """Sends a selective transport's ``wanted()`` (see :class:`~.worker.Wants`) when it differs from what
    was sent last; the transport calls it (as its ``on_wants_changed``) whenever its consumers change."""

    def __init__(self, transport: Any, replies: Replies) -> None:
        self.transport = transport
        self.replies = replies
        self._sent: tuple | None = None
        self._lock = threading.Lock()

    def __call__(self, force: bool = False) -> None:
        with self._lock:
            wants = tuple(self.transport.wanted())
            if force or wants != self._sent:
                self.replies.write(("wants", wants))
                self._sent = wants


def _build(factory: str, world: Any, options: Any) -> Any:
    module, _, attr = factory.partition(":")
    fn: Any = import_module(module)
    for part in attr.split("."):
        fn = getattr(fn, part)
    transport = fn(world, options)
    if transport is None:
        raise TransportError(f"worker: {factory} made no transport for these options")
    return transport


def serve(inp: Any, out_fd: int) -> int:
    """Run one transport from the frames on ``inp``, replying on ``out_fd``; returns the exit status."""
    replies = Replies(out_fd)
    transport = None
    report_wants: WantsReporter | None = None
    rebuild: SnapshotRebuilder | None = None
    stop_timeout_s = 2.0
    try:
        while True:
            try:
                frame = read_frame(inp)
            except EOFError:
                break
            kind = frame[0]
            if kind == "start":
                _, factory, world, options, vehicles, kinds, first = frame
                rebuild = SnapshotRebuilder(vehicles, kinds)
                try:
                    transport = _build(factory, world, options)
                    if callable(getattr(transport, "wanted", None)):      # selective: says what it wants
                        report_wants = transport.on_wants_changed = WantsReporter(transport, replies)
                    transport.start(RefusingPort(), rebuild(first))
                    if report_wants is not None:
                        report_wants(force=True)
                except Exception as exc:         # reported to the simulation, which raises it at start
                    text = str(exc) if isinstance(exc, TransportError) else f"{type(exc).__name__}: {exc}"
                    replies.write(("error", text))
                    if transport is not None:
                        transport.stop()
                    return 1
                info = {k: getattr(transport, k) for k in ("url", "port", "path") if hasattr(transport, k)}
                replies.write(("ready", {k: (str(v) if k == "path" else v) for k, v in info.items()}))
            elif kind == "snaps" and transport is not None and rebuild is not None:
                for item in frame[1]:
                    transport.offer(rebuild(item))
            elif kind == "flush" and transport is not None:
                ok = transport.flush(frame[2])
                if report_wants is not None:        # what it wants now reaches the simulation before this flush ends
                    report_wants()
                replies.write(("flushed", frame[1], ok, transport.counters()))
            elif kind == "counters" and transport is not None:
                replies.write(("counters", frame[1], transport.counters()))
            elif kind == "stop":
                stop_timeout_s = frame[1]
                break
    finally:
        if transport is not None:
            transport.stop(stop_timeout_s)
            try:
                replies.write(("stopped", transport.counters()))
            except OSError:
                pass
    return 0


def main() -> int:
    # Ctrl-C reaches the whole process group: the simulation stops cleanly and then stops this worker
    # (which closes its files); ending here first would lose the run's last snapshots
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    out_fd = os.dup(sys.stdout.fileno())        # replies only; anything printed goes to stderr
    os.dup2(sys.stderr.fileno(), sys.stdout.fileno())
    return serve(sys.stdin.buffer, out_fd)


if __name__ == "__main__":
    sys.exit(main())
