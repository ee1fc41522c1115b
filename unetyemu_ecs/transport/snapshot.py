"""Building the per-step :class:`~.api.Snapshot`, and the bounded queue a transport keeps them in.

:class:`SnapshotBuilder` turns the fleet arrays, the step's sensor samples and the mission and
parameter components into one immutable snapshot (read-only array copies, one row per vehicle in
world-file order). :class:`TransportSnapshotSystem` runs it once per step in the OUTPUTS phase, after
the sensors and TF, and offers the snapshot to every started transport; it is only in the world
while at least one transport runs, so a simulation without transports pays nothing.

:class:`SnapshotQueue` is the drop-oldest queue a transport's ``offer`` appends to (O(1), never
blocks) and its thread takes from; :meth:`SnapshotQueue.wait_done` is what ``flush`` waits on.
"""

from __future__ import annotations

import math
import threading
from collections import deque
from collections.abc import Callable, Sequence
from types import MappingProxyType
from typing import Any

import esper
import numpy as np

from ..components.body import Identity
from ..components.mission import MissionRuntime
from ..fleet import row_selector
from ..navigation.params import FlightParams
from ..phases import Phase
from ..systems.car_state import DriveMode
from ..systems.flight_state import MODE_DISARMED
from .api import Snapshot

# fleet array -> snapshot array (same name); "armed" is derived (a drone not DISARMED, a car not PARKED)
SNAPSHOT_ARRAYS = ("pos_enu_m", "vel_enu_m_s", "acc_enu_m_s2", "quat_enu_flu_xyzw", "rate_flu_rad_s",
                   "flight_mode", "nav_state", "landed_state", "home_enu_m", "home_set", "soc_frac",
                   "energy_j", "energy_used_j", "power_w", "remaining_time_s", "low_battery", "pack_voltage_v",
                   "pack_current_a", "payload_kg", "mission_step", "mission_state", "speed_limit_m_s", "arm_block")
IDLE_STATUS = MappingProxyType({"mission": None, "state": "idle"})     # a drone without a mission
_NO_PARAMS: Any = MappingProxyType({})
_PARKED = int(DriveMode.PARKED)    # a plain int, like flight_state.MODE_DISARMED: enum lookups cost


class SnapshotBuilder:
    """Builds the :class:`Snapshot` of a step from a simulation's fleet and services (sim thread).

    vehicles : (name, kind) of every vehicle, in world-file order (packages are not rows)
    """

    def __init__(self, vehicles: Sequence[tuple[str, str]]) -> None:
        self.vehicles = tuple(name for name, _ in vehicles)
        self.kinds = tuple(kind for _, kind in vehicles)
        self._drone = np.array([k == "quadrotor" for k in self.kinds], dtype=bool)
        self._car = np.array([k == "car" for k in self.kinds], dtype=bool)
        self._fleet_version = -1
        self._rows = np.zeros(0, dtype=np.intp)
        self._sel: slice | np.ndarray = self._rows
        self._status_key: dict[str, tuple] = {}     # vehicle -> what its last reported status depended on
        self._params_key: tuple = ()
        self._params: Any = _NO_PARAMS
        self._params_version = 0

    def _gather_rows(self, ctx: Any) -> None:
        f, ents = ctx.fleet, ctx.services.entities
        self._rows = np.array([f.row_of(ents[name]) for name in self.vehicles], dtype=np.intp)
        self._sel = row_selector(self._rows) if np.all(np.diff(self._rows) > 0) else self._rows   # kept in order
        self._fleet_version = f.version

    def build(self, ctx: Any, step: int, sim_time_s: float, first: bool = False) -> Snapshot:
        """The snapshot after step ``step`` (the number of steps done), stamped ``sim_time_s``;
        ``first`` reports every drone's mission status (the snapshot a transport starts with)."""
        f, services = ctx.fleet, ctx.services
        if f.version != self._fleet_version:
            self._gather_rows(ctx)
        rows, sel = self._rows, self._sel
        arrays: dict[str, np.ndarray] = {}
        for name in SNAPSHOT_ARRAYS:
            # a copy: of a slice when the vehicles' rows are contiguous (a memcpy), else by take
            a = getattr(f, name)[sel].copy() if isinstance(sel, slice) else getattr(f, name).take(rows, axis=0)
            a.setflags(write=False)
            arrays[name] = a
        armed = (arrays["flight_mode"] != MODE_DISARMED) & self._drone
        armed |= (f.drive_mode.take(rows) != _PARKED) & self._car
        armed.setflags(write=False)
        arrays["armed"] = armed
        events, results = services.events, services.results
        return Snapshot(step, sim_time_s, ctx.dt_s, self.vehicles, self.kinds, MappingProxyType(arrays),
                        tuple(services.sensors.this_step), events, len(events), results, len(results),
                        self._mission_changes(first), *self._flight_parameters())

    def _mission_changes(self, first: bool) -> Any:
        """Vehicle -> mission status of the drones whose status changed (every drone when ``first``)."""
        changed: dict[str, Any] = {}
        seen = set()
        for _ent, (ident, rt) in esper.get_components(Identity, MissionRuntime):
            seen.add(ident.name)
            key = (id(rt), rt.step_index, rt.state, rt.stage, rt.reason)
            if first or self._status_key.get(ident.name) != key:
                self._status_key[ident.name] = key
                changed[ident.name] = MappingProxyType(rt.status())
        if first or len(seen) != len(self._status_key):
            for name, kind in zip(self.vehicles, self.kinds):
                if kind == "quadrotor" and name not in seen and (first or name in self._status_key):
                    self._status_key.pop(name, None)
                    changed[name] = IDLE_STATUS
        return MappingProxyType(changed) if changed else _NO_PARAMS

    def _flight_parameters(self) -> tuple[Any, int]:
        """(vehicle -> read-only parameters, number of changes); the same objects until one changes."""
        found = esper.get_components(Identity, FlightParams)
        key = tuple((ident.name, id(fp), fp.version) for _ent, (ident, fp) in found)
        if key != self._params_key:
            self._params_key = key
            self._params = MappingProxyType({ident.name: MappingProxyType(dict(fp.values))
                                             for _ent, (ident, fp) in found})
            self._params_version += 1
        return self._params, self._params_version


class TransportSnapshotSystem(esper.Processor):
    """Build this step's snapshot and offer it to every started transport.

    Phase: OUTPUTS (order 40: after TF, order 10, and every sensor; before the CSV logs). Reads the
    fleet arrays, ``services.sensors.this_step``, events, results, MissionRuntime and FlightParams;
    writes nothing. ``offer`` only appends to a transport's own queue.
    """

    phase = Phase.OUTPUTS
    order = 40

    def __init__(self, builder: SnapshotBuilder, transports: list[Any]) -> None:
        self.builder = builder
        self.transports = transports          # the simulation's own list: transports started later join

    def process(self, ctx: Any) -> None:
        snap = self.builder.build(ctx, ctx.step + 1, ctx.sim_time_s + ctx.dt_s)
        for t in self.transports:
            t.offer(snap)


class SnapshotQueue:
    """A transport's bounded drop-oldest queue of snapshots (``put`` on the sim thread, ``get_all`` on
    the transport's).

    When full, ``put`` drops the oldest snapshot (counted in ``dropped``) but keeps its mission
    status changes: the first snapshot ``get_all`` returns next carries them (newer ones win), so a
    change is never lost with its snapshot. Events and results need no such care (cursor into shared lists).
    """

    def __init__(self, maxlen: int) -> None:
        if maxlen < 1:
            raise ValueError(f"SnapshotQueue: maxlen must be >= 1, got {maxlen}")
        self.maxlen = maxlen
        self._q: deque[tuple[int, Snapshot]] = deque()
        self._lock = threading.Lock()
        self._ready = threading.Event()
        self._done = threading.Condition(self._lock)
        self._carry: dict[str, Any] = {}
        self._offered = 0          # sequence number of the last snapshot put
        self._handled = 0          # sequence number of the last snapshot the consumer finished
        self.dropped = 0

    @property
    def offered(self) -> int:
        return self._offered

    def __len__(self) -> int:
        """Snapshots waiting for the consumer."""
        return len(self._q)

    def put(self, snap: Snapshot) -> None:
        """Append (O(1), never blocks for longer than the consumer's own O(1) critical section)."""
        with self._lock:
            if len(self._q) >= self.maxlen:
                _, old = self._q.popleft()
                self.dropped += 1
                if old.mission_status:
                    self._carry.update(old.mission_status)
            self._offered += 1
            self._q.append((self._offered, snap))
        self._ready.set()

    def get_all(self, timeout_s: float | None = None) -> list[tuple[int, Snapshot]]:
        """Every queued snapshot with its sequence number, oldest first, waiting up to ``timeout_s`` for
        one; [] if none came. Taking them together costs the consumer one lock and one wake-up for all."""
        if not self._ready.wait(timeout_s):
            return []
        with self._lock:
            items = list(self._q)
            self._q.clear()
            self._ready.clear()
            if items and self._carry:
                carried, self._carry = self._carry, {}
                seq, snap = items[0]
                carried.update(snap.mission_status)
                items[0] = (seq, _with_status(snap, carried))
        return items

    def task_done(self, seq: int) -> None:
        """The consumer finished snapshot ``seq`` (and so everything before it)."""
        with self._done:
            self._handled = max(self._handled, seq)
            self._done.notify_all()

    def wait_done(self, timeout_s: float) -> bool:
        """Wait until every snapshot put so far is handled or dropped; True when it was."""
        with self._done:
            target = self._offered
            return self._done.wait_for(lambda: self._handled >= target, timeout_s)

    def wake(self) -> None:
        """Wake a consumer waiting in :meth:`get_all` (to stop it)."""
        self._ready.set()


def ticks_in_step(time_s: float, dt_s: float, hz: float) -> bool:
    """Whether a clock ticking at ``hz`` (at 0, 1/hz, 2/hz ... s of sim time) ticks in the step that ended
    at ``time_s`` and lasted ``dt_s`` (in (time_s - dt_s, time_s]): the step a sensor of that rate would
    measure in. Stateless, so two threads or processes that see different subsets of the snapshots agree
    on every one they both see."""
    period_s = 1.0 / hz
    return math.floor((time_s + 1e-9) / period_s) > math.floor((time_s - dt_s + 1e-9) / period_s)


def _with_status(snap: Snapshot, status: dict[str, Any]) -> Snapshot:
    from dataclasses import replace

    return replace(snap, mission_status=MappingProxyType(status))


def run_consumer(queue: SnapshotQueue, handle: Callable[[Snapshot], None], stop: threading.Event,
                 idle: Callable[[], None] | None = None, poll_s: float = 0.05) -> None:
    """A transport thread's loop: hand each snapshot to ``handle`` until ``stop`` is set, calling
    ``idle`` (timers, retries, batching naps) after each batch of snapshots taken together and at least
    every ``poll_s`` seconds."""
    while not stop.is_set():
        items = queue.get_all(poll_s)
        last = 0
        try:
            for seq, snap in items:
                if stop.is_set():
                    break
                last = seq                  # done once handled, or once its handling failed
                handle(snap)
        finally:
            if last:
                queue.task_done(last)
        if idle is not None:
            idle()


def start_consumer(queue: SnapshotQueue, handle: Callable[[Snapshot], None], stop: threading.Event,
                   idle: Callable[[], None] | None, name: str) -> threading.Thread:
    """Start a transport's own daemon thread running :func:`run_consumer`; the thread."""
    thread = threading.Thread(target=run_consumer, args=(queue, handle, stop, idle), name=name, daemon=True)
    thread.start()
    return thread


def stop_consumer(queue: SnapshotQueue, stop: threading.Event, thread: threading.Thread | None,
                  timeout_s: float) -> None:
    """Ask a :func:`start_consumer` thread to end (it may be waiting on ``queue``) and wait at most
    ``timeout_s`` seconds of wall time for it."""
    stop.set()
    queue.wake()
    if thread is not None:
        thread.join(timeout_s)


__all__ = ["IDLE_STATUS", "SNAPSHOT_ARRAYS", "SnapshotBuilder", "SnapshotQueue", "TransportSnapshotSystem",
           "run_consumer", "start_consumer", "stop_consumer", "ticks_in_step"]
