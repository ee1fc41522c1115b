"""The MAVLink transport: every drone's endpoint, served by one thread.

``offer`` (simulation thread) appends the snapshot to a bounded drop-oldest queue and wakes the
thread through a socketpair. The thread waits on all link sockets and the wake-up socket
(``selectors``), parses what arrived (bounded per socket and turn), then takes the queued
snapshots: results and events of each (cursors into the append-only lists), telemetry from the
newest only.
"""

from __future__ import annotations

import collections
import dataclasses
import selectors
import socket
import threading
import time
from pathlib import Path
from typing import Any

from ..api import CommandPort, Snapshot, TransportError
from .codec import load_key
from .component import MavlinkEndpoint
from .endpoint import DroneEndpoint

QUEUE_LEN = 8
LOOP_TIMEOUT_S = 0.05           # wall clock: mission retries and peer expiry run at least this often


class MavlinkTransport:
    """MAVLink endpoints of the drones of one simulation."""

    name = "mavlink"

    def __init__(self, endpoints: list[tuple[str, MavlinkEndpoint]], origin: Any, layout: Any, physics_dt_s: float,
                 out_dir: Path | None, base_dir: Path | None = None) -> None:
        self._configs = endpoints
        self._origin = origin
        self._layout = layout
        self._dt_s = physics_dt_s
        self._out_dir = out_dir
        self._base_dir = base_dir
        self.endpoints: dict[str, DroneEndpoint] = {}
        self._queue: collections.deque[Snapshot] = collections.deque()
        self._lock = threading.Lock()
        self._cond = threading.Condition(self._lock)
        self._offered = 0
        self._handled = 0
        self._dropped = 0
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._wake_r: socket.socket | None = None
        self._wake_w: socket.socket | None = None
        self._event_cursor = 0
        self._result_cursor = 0
        self._port: CommandPort | None = None
        self._thread_error: str = ""
        self._handler_errors = 0
        self._first_handler_error = ""

    # -- Transport ---------------------------------------------------------------------------------------

    def start(self, port: CommandPort, first: Snapshot) -> None:
        if self._thread is not None:
            return
        self._port = port
        for vehicle, cfg in self._configs:
            key = None
            if cfg.signing is not None:
                try:
                    key = load_key(cfg.signing.key_file, cfg.signing.key_env, self._base_dir)
                except ValueError as exc:
                    self._close_all()
                    raise TransportError(f"mavlink endpoint of {vehicle}: {exc}") from None
            ep = DroneEndpoint(vehicle, cfg, self._origin, self._layout, port.submit, self._dt_s, self._out_dir, key)
            try:
                ep.open()
            except TransportError:
                self._close_all()
                raise
            self.endpoints[vehicle] = ep
        self._event_cursor = first.events_end
        self._result_cursor = first.results_end
        self._wake_r, self._wake_w = socket.socketpair()
        self._wake_r.setblocking(False)
        self._wake_w.setblocking(False)
        self._queue.append(first)
        self._offered += 1
        self._thread = threading.Thread(target=self._run, name="mavlink", daemon=True)
        self._thread.start()

    def offer(self, snapshot: Snapshot) -> None:
        with self._lock:
            if len(self._queue) >= QUEUE_LEN:
                self._queue.popleft()
                self._dropped += 1
                self._handled += 1
            self._queue.append(snapshot)
            self._offered += 1
        w = self._wake_w
        if w is not None:
            try:
                w.send(b"\0")
            except OSError:              # full (the thread is behind and will see the queue anyway) or closed
                pass

    def flush(self, timeout_s: float = 2.0) -> bool:
        deadline = time.monotonic() + timeout_s
        with self._cond:
            target = self._offered
            while self._handled < target and self._thread is not None and self._thread.is_alive():
                left = deadline - time.monotonic()
                if left <= 0:
                    return False
                self._cond.wait(left)
            return self._handled >= target

    def stop(self, timeout_s: float = 2.0) -> None:
        self._stop.set()
        if self._wake_w is not None:
            try:
                self._wake_w.send(b"\0")
            except OSError:
                pass
        if self._thread is not None:
            self._thread.join(timeout_s)
        self._close_all()

    def _close_all(self) -> None:
        for ep in self.endpoints.values():
            ep.close()
        for s in (self._wake_r, self._wake_w):
            if s is not None:
                s.close()
        self._wake_r = self._wake_w = None

    def counters(self) -> dict[str, Any]:
        out: dict[str, Any] = {v: ep.counters() for v, ep in self.endpoints.items()}
        out["snapshots_dropped"] = self._dropped
        if self._handler_errors:
            out["handler_errors"] = self._handler_errors
            out["first_handler_error"] = self._first_handler_error
        if self._thread_error:
            out["thread_error"] = self._thread_error
        return out

    # -- thread ------------------------------------------------------------------------------------------

    def _run(self) -> None:
        sel = selectors.DefaultSelector()
        assert self._wake_r is not None
        sel.register(self._wake_r, selectors.EVENT_READ, None)
        for ep in self.endpoints.values():
            for link in ep.links:
                sel.register(link.sock, selectors.EVENT_READ, (ep, link))
        paused: list[tuple[Any, Any]] = []          # (endpoint, link) whose receive budget is spent
        try:
            while not self._stop.is_set():
                now = time.monotonic()
                for ep, link in [p for p in paused if p[1].paused_until_s <= now]:
                    paused.remove((ep, link))
                    sel.register(link.sock, selectors.EVENT_READ, (ep, link))
                timeout = LOOP_TIMEOUT_S
                if paused:
                    timeout = max(0.0, min(timeout, min(link.paused_until_s for _, link in paused) - now))
                for key, _ in sel.select(timeout):
                    if key.data is None:
                        try:
                            while self._wake_r.recv(4096):
                                pass
                        except (BlockingIOError, InterruptedError, OSError):
                            pass
                        continue
                    ep, link = key.data
                    now = time.monotonic()
                    for data, addr in link.receive(now):
                        ep.on_datagram(link, data, addr, now)
                    if link.paused_until_s > now:          # budget spent: the kernel queues (and drops) meanwhile
                        sel.unregister(link.sock)
                        paused.append((ep, link))
                self._drain()
                now = time.monotonic()
                for ep in self.endpoints.values():
                    ep.expire(now)
                    ep.tick(now)
        except Exception as exc:          # noqa: BLE001 - reported in the counters, never silently
            self._thread_error = f"{type(exc).__name__}: {exc}"
            with self._cond:
                self._cond.notify_all()
        finally:
            sel.close()

    def _guarded(self, handler: Any, *args: Any) -> None:
        """Run one endpoint's handler; an exception is counted (and the first one kept for the summary)
        instead of ending the thread that serves every drone."""
        try:
            handler(*args)
        except Exception as exc:          # noqa: BLE001 - one drone's fault must not silence the others
            self._handler_errors += 1
            if not self._first_handler_error:
                self._first_handler_error = f"{type(exc).__name__}: {exc}"

    def _drain(self) -> None:
        with self._lock:
            snaps = list(self._queue)
            self._queue.clear()
        if not snaps:
            return
        for snap in snaps:
            for result in snap.results[self._result_cursor:snap.results_end]:
                ep = self.endpoints.get(result.vehicle)
                if ep is not None:
                    self._guarded(ep.on_result, result)
            self._result_cursor = max(self._result_cursor, snap.results_end)
            for _, vehicle, text in snap.events[self._event_cursor:snap.events_end]:
                ep = self.endpoints.get(vehicle)
                if ep is not None:
                    self._guarded(ep.on_event, text)
            self._event_cursor = max(self._event_cursor, snap.events_end)
        newest = snaps[-1]
        if len(snaps) > 1 and any(s.mission_status for s in snaps[:-1]):
            merged: dict[str, Any] = {}
            for s in snaps:                  # a mission status change of a skipped step is not lost
                merged.update(s.mission_status)
            newest = dataclasses.replace(newest, mission_status=merged)
        for vehicle, ep in self.endpoints.items():
            try:
                row = newest.row(vehicle)
            except ValueError:
                continue
            self._guarded(ep.on_snapshot, newest, row)
        with self._cond:
            self._handled += len(snaps)
            self._cond.notify_all()


__all__ = ["MavlinkTransport"]
