"""A transport run in a process of its own, so that its Python work never competes with the loop for the GIL.

A transport thread in the simulation's process still holds the interpreter lock while it builds,
serialises and writes messages; on a 2-core machine the loop then waits for it, and the recording of
the delivery scenario cost a sixth of its real-time factor that way although the writer had a core
to itself. :class:`ProcessTransport` keeps in this process only what is cheap: its ``offer`` appends
the snapshot to a drop-oldest queue (as every transport's does), and its thread sends what gathered
every 20 ms to a worker process as one pickle over a pipe (about 40 us per step for the delivery
scenario: the sensor samples travel unbuilt, as the functions and copied arrays that build their
messages). The worker
(:mod:`.worker_main`, started as ``python -m unetyemu_ecs.transport.worker_main``) rebuilds the
snapshot and hands it to the real transport, which runs there exactly as it would here: its own
queue, thread and counters.

Only what the inner transport needs crosses: the sensor samples, mission status, new events and
command results (the worker appends them to lists of its own, so the cursors work as in
:class:`~.api.Snapshot`), and the arrays named by ``arrays``. Inner transports are output-only: the
worker refuses command submissions (a transport that takes commands runs in the simulation's process).

A *selective* inner transport (one whose consumers choose what they get: Foxglove's subscribe per
topic, the web view's pages pick a vehicle and its LiDAR) says what it wants with a :class:`Wants`
(its ``wanted()``; the worker sends it before ``ready``, before every ``flushed`` and whenever the
transport calls ``on_wants_changed``). Then ``offer`` queues only these, deciding on the simulation
thread in a few microseconds: the samples of the topics (or vehicles' sensors) it wants, the first
sample of every topic (so that it can advertise the topic), every sample of the topics ``keep``
names (latched ones), the arrays only while it wants them (at ``arrays_hz``, and with every sample if
``arrays_with_samples``), and a snapshot only when it carries one of those, new events or results, a
mission status, or when the transport wants every snapshot (``/clock``). What stays behind is
counted (``samples_held_back``, ``snapshots_held_back``): a server nobody watches costs the loop the
snapshot, and its send thread sleeps.

Frames on both pipes: 4-byte little-endian length, then a pickle. To the worker: ``("start",
factory, world, options, vehicles, kinds, first)``, ``("flush", n, timeout_s)``,
``("counters", n)``, ``("stop", timeout_s)``, and the snapshots in batches, ``("snaps", [slim, ...])``:
one frame for all that gathered while the send thread napped (fewer wake-ups and writes, so fewer
times the loop waits for the interpreter lock). Back: ``("ready", info)`` or ``("error", text)``
after start, ``("flushed", n, ok, counters)``, ``("counters", n, counters)``, ``("stopped",
counters)``, and from a selective transport ``("wants", Wants)`` at any time. The worker's stderr is
this process's, so its warnings and tracebacks land in the same log.
"""

from __future__ import annotations

import os
import pickle
import struct
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Sequence
from typing import Any, NamedTuple

from .api import CommandPort, Snapshot, TransportError, TransportOptions
from .snapshot import SnapshotQueue, start_consumer, stop_consumer, ticks_in_step

SEND_QUEUE_DEPTH = 64          # snapshots waiting to be sent (default; a recorder asks for as many as it keeps)
# when the queue is empty, the send thread waits this long [s, wall] before taking the next snapshots, so that
# it wakes (and takes the interpreter lock from the loop) once for several steps instead of once for each
BATCH_WAIT_S = 0.02
START_TIMEOUT_S = 60.0         # importing the worker's modules (numpy, rosbags ...) on a busy machine
COUNTERS_WAIT_S = 2.0          # how long counters() waits for the worker's figures
_LEN = struct.Struct("<I")


def write_frame(fd: int, obj: Any) -> int:
    """Pickle ``obj`` and write it as one frame to the file descriptor ``fd``; returns the bytes written."""
    data = pickle.dumps(obj, protocol=pickle.HIGHEST_PROTOCOL)
    parts = [_LEN.pack(len(data)), memoryview(data)]      # no copy of the frame to put its length first
    total = len(data) + _LEN.size
    written = 0
    while written < total:
        n = os.writev(fd, parts)
        written += n
        while parts and n >= len(parts[0]):
            n -= len(parts[0])
            parts.pop(0)
        if n:
            parts[0] = memoryview(parts[0])[n:]
    return total


def read_frame(stream: Any) -> Any:
    """The next frame's object from the binary ``stream``; EOFError when the other side closed it."""
    head = stream.read(_LEN.size)
    if len(head) < _LEN.size:
        raise EOFError("pipe closed")
    (size,) = _LEN.unpack(head)
    data = stream.read(size)
    if len(data) < size:
        raise EOFError("pipe closed mid-frame")
    return pickle.loads(data)


class Wants(NamedTuple):
    """What a selective transport in a worker wants of each snapshot (see the module docstring).

    topics : the sample topics to send (besides each topic's first sample and the ``keep`` topics)
    every_snapshot : send every snapshot, even one that carries nothing else (it publishes from each)
    arrays : send the named arrays (at ``arrays_hz``, and with every sample sent if ``arrays_with_samples``)
    samples : (vehicle, sensor key) of more samples to send, whatever their topic
    """

    topics: frozenset[str] = frozenset()
    every_snapshot: bool = False
    arrays: bool = False
    samples: frozenset[tuple[str, str]] = frozenset()


def slim(snap: Snapshot, arrays: Sequence[str], events_from: int, results_from: int) -> tuple:
    """What crosses to the worker of one snapshot: only the arrays named, only new events and results."""
    return (snap.step, snap.sim_time_s, snap.dt_s, {k: snap.arrays[k] for k in arrays}, tuple(snap.sensors),
            list(snap.events[events_from:snap.events_end]), list(snap.results[results_from:snap.results_end]),
            {k: dict(v) for k, v in snap.mission_status.items()})


class ProcessTransport:
    """A transport whose work runs in a worker process (see the module docstring).

    name : the transport's name (summary.json ``transports.<name>``)
    factory : ``"module:function"``; the worker calls ``function(world, options)`` for the real transport
    world, options : what the factory gets (pickled once, at start)
    arrays : the snapshot arrays the real transport reads (none for a recorder of sensor messages)
    queue_depth : snapshots waiting to be sent before the oldest are dropped (a run faster than the
        worker, or the send thread's 20 ms naps, must not lose what a recorder is meant to keep)
    keep : for a selective transport, the topics whose every sample crosses whatever it wants (latched
        topics: a late subscriber gets them from the worker); None: none
    arrays_hz : for a selective transport, the rate [Hz, sim time] at which the arrays cross while it wants
        them: in the steps where a clock of that rate ticks (:func:`~.snapshot.ticks_in_step`)
    arrays_with_samples : for a selective transport, the arrays also cross (while wanted) with every step
        that carries a sample (a LiDAR cloud drawn in the world frame needs the pose of its own step)
    """

    def __init__(self, name: str, factory: str, world: Any, options: TransportOptions,
                 arrays: Sequence[str] = (), queue_depth: int = SEND_QUEUE_DEPTH,
                 keep: Callable[[str], Any] | None = None, arrays_hz: float = 240.0,
                 arrays_with_samples: bool = False) -> None:
        self.name = name
        self.factory = factory
        self._world = world
        self._options = options
        self._arrays = tuple(arrays)
        self._keep = keep
        self._arrays_hz = float(arrays_hz)
        self._arrays_with_samples = arrays_with_samples
        self._wants: Wants | None = None              # None: everything (not a selective transport)
        # selection (simulation thread): topics of which a sample was queued, keep(topic) per topic, the
        # event and result cursors of the last snapshot queued
        self._topics_offered: set[str] = set()
        self._kept: dict[str, bool] = {}
        self._events_offered = 0
        self._results_offered = 0
        self._queue = SnapshotQueue(queue_depth)
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._proc: subprocess.Popen | None = None
        self._write_lock = threading.Lock()
        self._batch: list[tuple] = []                 # slim snapshots gathered, not yet sent (under the lock)
        self._replies: dict[Any, Any] = {}
        self._replied = threading.Condition()
        self._reader: threading.Thread | None = None
        self._events_sent = 0
        self._results_sent = 0
        self._flushes = 0
        self._asked = 0                              # counters requests sent
        self._counters: dict[str, Any] = {}          # the worker's transport's, newest
        self.info: dict[str, Any] = {}               # what the worker's transport said at start (url ...)
        self.bytes_sent = 0
        self.send_errors = 0
        self.samples_held_back = 0                   # samples a selective transport did not want
        self.snapshots_held_back = 0                 # snapshots that carried nothing it wanted
        self.error = ""

    # -- life cycle (simulation thread) --------------------------------------------------------
    def start(self, port: CommandPort, first: Snapshot) -> None:
        env = dict(os.environ, OPENBLAS_NUM_THREADS=os.environ.get("OPENBLAS_NUM_THREADS", "1"),
                   # what this process can import the worker can too (plugins on a path a script added: the
                   # world it is sent names their classes)
                   PYTHONPATH=os.pathsep.join(p for p in [*sys.path, os.environ.get("PYTHONPATH", "")] if p))
        try:
            self._proc = subprocess.Popen([sys.executable, "-m", "unetyemu_ecs.transport.worker_main"],
                                          stdin=subprocess.PIPE, stdout=subprocess.PIPE, env=env)
        except OSError as exc:
            raise TransportError(f"{self.name}: cannot start its worker process: {exc}") from exc
        self._reader = threading.Thread(target=self._read_replies, name=f"unetyemu-{self.name}-replies", daemon=True)
        self._reader.start()
        first_slim = slim(first, self._arrays, 0, 0)
        self._events_sent, self._results_sent = first.events_end, first.results_end
        self._events_offered, self._results_offered = first.events_end, first.results_end
        try:
            self._send(("start", self.factory, self._world, self._options, first.vehicles, first.kinds, first_slim))
        except OSError as exc:
            raise TransportError(f"{self.name}: its worker process did not take the world: {exc}") from exc
        reply = self._wait_reply("start", START_TIMEOUT_S)
        if reply is None:
            why = self.error or f"no answer within {START_TIMEOUT_S:.0f} s"
            raise TransportError(f"{self.name}: its worker process did not start ({why}; its stderr above says more)")
        if reply[0] == "error":
            raise TransportError(reply[1])
        self.info = dict(reply[1])
        self._thread = start_consumer(self._queue, self._send_snapshot, self._stop, self._gather,
                                      f"unetyemu-{self.name}-send")

    def offer(self, snapshot: Snapshot) -> None:
        """Queue ``snapshot``; for a selective transport only what it wants of it, and nothing when that is
        nothing (decided here, on the simulation thread, in a few microseconds: a send thread woken for
        every step to find nothing to send would take the interpreter lock from the loop each time)."""
        wants = self._wants
        if wants is not None:
            selected = self._selected(snapshot, wants)
            if selected is None:
                self.snapshots_held_back += 1
                return
            snapshot = selected
        self._queue.put(snapshot)

    def flush(self, timeout_s: float = 2.0) -> bool:
        """Wait until the worker's transport has handled everything offered so far."""
        deadline = time.monotonic() + timeout_s
        if self._thread is None or not self._thread.is_alive() or not self._alive():
            return True
        if not self._queue.wait_done(timeout_s):
            return False
        self._flushes += 1
        key = ("flushed", self._flushes)
        try:
            self._send(("flush", self._flushes, max(0.0, deadline - time.monotonic())))
        except OSError:
            return True                             # the worker is gone: nothing more will be handled
        reply = self._wait_reply(key, max(0.0, deadline - time.monotonic()) + 1.0)
        return bool(reply is not None and reply[2])        # ("flushed", n, ok, counters)

    def stop(self, timeout_s: float = 2.0) -> None:
        stop_consumer(self._queue, self._stop, self._thread, timeout_s)
        self._thread = None
        proc, self._proc = self._proc, None
        if proc is None:
            return
        try:
            self._send_to(proc, ("stop", timeout_s))
            self._wait_reply("stopped", timeout_s + 5.0)
        except OSError:
            pass
        try:
            proc.stdin.close()
        except OSError:
            pass
        try:
            proc.wait(timeout_s + 5.0)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(5.0)
        if self._reader is not None:
            self._reader.join(2.0)

    def __getattr__(self, name: str) -> Any:
        """What the worker's transport said at start (``url``, ``port``, ``path``) reads as attributes."""
        info = self.__dict__.get("info") or {}
        if name in info:
            return info[name]
        raise AttributeError(f"{type(self).__name__} {self.__dict__.get('name')!r} has no attribute {name!r}")

    def counters(self) -> dict[str, Any]:
        """The worker's transport's counters, asked for now (at most COUNTERS_WAIT_S; else the newest it sent
        with a flush or at its stop), with this side's: snapshots offered and dropped, the pipe's figures."""
        proc = self._proc
        if proc is not None and proc.poll() not in (None, 0) and not self.error:
            self.error = f"the worker process ended with exit status {proc.returncode}"
        if proc is not None and self._alive():
            self._asked += 1
            try:
                self._send(("counters", self._asked))
                self._wait_reply(("counters", self._asked), COUNTERS_WAIT_S)    # its reader keeps what came
            except OSError:
                pass
        counters = dict(self._counters)
        # the first went with "start"; a selective transport's held-back snapshots were offered too
        counters["snapshots_offered"] = self._queue.offered + self.snapshots_held_back + (self.info != {})
        counters["snapshots_dropped"] = self._queue.dropped + int(counters.get("snapshots_dropped", 0))
        counters["worker"] = {"pid": self._proc.pid if self._proc is not None else None,
                              "bytes_sent": self.bytes_sent, "send_errors": self.send_errors,
                              **({"error": self.error} if self.error else {})}
        if self._wants is not None:
            counters["worker"].update(samples_held_back=self.samples_held_back,
                                      snapshots_held_back=self.snapshots_held_back)
        return counters

    # -- selection (simulation thread) ---------------------------------------------------------
    def _selected(self, snap: Snapshot, wants: Wants) -> Snapshot | None:
        """What a selective transport gets of ``snap`` (see the module docstring): a snapshot with only those
        samples, and without arrays where it gets none; None: nothing (simulation thread)."""
        sensors = []
        for sample in snap.sensors:
            topic = sample.topic
            if (topic in wants.topics or topic not in self._topics_offered or self._kept_topic(topic)
                    or (sample.vehicle, sample.sensor) in wants.samples):
                self._topics_offered.add(topic)
                sensors.append(sample)
            else:
                self.samples_held_back += 1
        arrays = wants.arrays and ((self._arrays_with_samples and bool(sensors))
                                   or ticks_in_step(snap.sim_time_s, snap.dt_s, self._arrays_hz))
        news = snap.events_end > self._events_offered or snap.results_end > self._results_offered
        if not (sensors or arrays or wants.every_snapshot or news or snap.mission_status):
            return None
        self._events_offered, self._results_offered = snap.events_end, snap.results_end
        return Snapshot(step=snap.step, sim_time_s=snap.sim_time_s, dt_s=snap.dt_s, vehicles=snap.vehicles,
                        kinds=snap.kinds, arrays=snap.arrays if arrays else {}, sensors=tuple(sensors),
                        events=snap.events, events_end=snap.events_end, results=snap.results,
                        results_end=snap.results_end, mission_status=snap.mission_status, params=snap.params,
                        params_version=snap.params_version)

    def _kept_topic(self, topic: str) -> bool:
        kept = self._kept.get(topic)
        if kept is None:
            kept = self._kept[topic] = self._keep is not None and bool(self._keep(topic))
        return kept

    # -- the send thread -------------------------------------------------------------------------
    def _send_snapshot(self, snap: Snapshot) -> None:
        if self.send_errors:                        # the worker is gone: drop (counted once)
            return
        item = slim(snap, self._arrays if snap.arrays else (), self._events_sent, self._results_sent)
        self._events_sent, self._results_sent = snap.events_end, snap.results_end
        with self._write_lock:
            self._batch.append(item)

    def _gather(self) -> None:
        """Between snapshots: once the queue is empty, send what was gathered as one frame, then nap."""
        if len(self._queue):
            return
        try:
            self._send(None)
        except (OSError, pickle.PicklingError, TypeError, AttributeError) as exc:
            self.send_errors += 1
            self.error = self.error or f"cannot send to the worker: {type(exc).__name__}: {exc}"
            with self._write_lock:
                self._batch.clear()
        self._stop.wait(BATCH_WAIT_S)

    def _send(self, obj: Any) -> None:
        proc = self._proc
        if proc is None:
            raise OSError("the worker process is not running")
        self._send_to(proc, obj)

    def _send_to(self, proc: subprocess.Popen, obj: Any) -> None:
        """Write the gathered snapshots (one ``snaps`` frame), then ``obj`` (None: nothing more)."""
        with self._write_lock:
            if self._batch:
                batch, self._batch = self._batch, []
                self.bytes_sent += write_frame(proc.stdin.fileno(), ("snaps", batch))
            if obj is not None:
                self.bytes_sent += write_frame(proc.stdin.fileno(), obj)

    def _alive(self) -> bool:
        return self._proc is not None and self._proc.poll() is None

    # -- replies (the reader thread) -------------------------------------------------------------
    def _read_replies(self) -> None:
        proc = self._proc
        stream = proc.stdout if proc is not None else None
        while stream is not None:
            try:
                reply = read_frame(stream)
            except (EOFError, OSError, pickle.UnpicklingError) as exc:
                if not self.error and proc.poll() not in (0, None):
                    self.error = f"the worker process ended with exit status {proc.returncode}"
                elif not self.error and not isinstance(exc, EOFError):
                    self.error = f"unreadable reply from the worker: {exc}"
                break
            kind = reply[0]
            if kind == "wants":
                self._wants = Wants(*reply[1])
                continue
            if kind in ("flushed", "stopped", "counters"):
                self._counters = dict(reply[-1])
            key = ((kind, reply[1]) if kind in ("flushed", "counters")
                   else ("start" if kind in ("ready", "error") else kind))
            with self._replied:
                self._replies[key] = reply
                self._replied.notify_all()
        with self._replied:
            self._replies["eof"] = True
            self._replied.notify_all()

    def _wait_reply(self, key: Any, timeout_s: float) -> Any:
        with self._replied:
            self._replied.wait_for(lambda: key in self._replies or "eof" in self._replies, timeout_s)
            return self._replies.pop(key, None)


__all__ = ["ProcessTransport", "Wants", "read_frame", "slim", "write_frame"]
