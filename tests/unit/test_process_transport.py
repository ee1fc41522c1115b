"""A transport in a worker process: what crosses the pipe rebuilds the snapshot the transport would have seen."""

from __future__ import annotations

import io
import os

import numpy as np
import pytest

from unetyemu_ecs.transport.api import CommandResult, CommandStatus, Snapshot
from unetyemu_ecs.transport.worker import read_frame, slim, write_frame
from unetyemu_ecs.transport.worker_main import SnapshotRebuilder


def snapshot(step: int, events: list, results: list) -> Snapshot:
    arrays = {"pos_enu_m": np.full((2, 3), float(step)), "soc_frac": np.array([0.9, 0.8])}
    return Snapshot(step=step, sim_time_s=step / 240.0, dt_s=1 / 240.0, vehicles=("d1", "c1"),
                    kinds=("quadrotor", "car"), arrays=arrays, sensors=(), events=events, events_end=len(events),
                    results=results, results_end=len(results), mission_status={"d1": {"state": "cruise"}})


def test_events_and_results_cross_as_increments_and_read_with_the_same_cursors():
    # GIVEN the simulation's append-only lists, three snapshots of which the second is never sent (dropped)
    events, results = [], []
    sent, rebuild = [], SnapshotRebuilder(("d1", "c1"), ("quadrotor", "car"))
    cursor_e = cursor_r = 0
    for step in range(3):
        events.append((step / 240.0, "d1", f"event {step}"))
        results.append(CommandResult(step + 1, "d1", "arm", "api", CommandStatus.ACCEPTED))
        snap = snapshot(step, events, results)
        if step == 1:
            continue
        # WHEN each sent one carries what is new since the last sent one
        sent.append(rebuild(slim(snap, ("pos_enu_m",), cursor_e, cursor_r)))
        cursor_e, cursor_r = snap.events_end, snap.results_end
    # THEN the worker's lists hold every event and result, in order, none lost with the dropped snapshot
    last = sent[-1]
    assert [text for _, _, text in last.events[:last.events_end]] == ["event 0", "event 1", "event 2"]
    assert [r.command_id for r in last.results[:last.results_end]] == [1, 2, 3]
    # AND only the arrays asked for crossed, with the vehicles and the mission status
    assert set(last.arrays) == {"pos_enu_m"} and last.pos_enu_m[0, 0] == 2.0
    assert last.vehicles == ("d1", "c1") and last.mission_status == {"d1": {"state": "cruise"}}


def test_a_frame_is_a_length_and_a_pickle_and_a_closed_pipe_reads_as_the_end():
    r, w = os.pipe()
    try:
        n = write_frame(w, ("snap", {"x": np.arange(3)}))
    finally:
        os.close(w)
    with os.fdopen(r, "rb") as stream:
        kind, payload = read_frame(stream)
        assert kind == "snap" and payload["x"].tolist() == [0, 1, 2] and n > 4
        with pytest.raises(EOFError):
            read_frame(stream)
    with pytest.raises(EOFError, match="mid-frame"):
        read_frame(io.BytesIO(b"\x10\x00\x00\x00abc"))          # a frame cut short


class NeverDone:
    """A transport (run in the worker) that never catches up: its flush always reports False."""

    name = "never_done"

    def start(self, port, first) -> None:
        self.snapshots = 1

    def offer(self, snapshot) -> None:
        self.snapshots += 1

    def flush(self, timeout_s: float = 2.0) -> bool:
        return False

    def stop(self, timeout_s: float = 2.0) -> None:
        pass

    def counters(self) -> dict:
        return {"snapshots": self.snapshots}


def never_done(world, options) -> NeverDone:
    return NeverDone()


def test_a_flush_reports_what_the_worker_s_transport_reported(monkeypatch):
    from unetyemu_ecs.transport.api import TransportOptions
    from unetyemu_ecs.transport.worker import ProcessTransport

    from ..conftest import REPO_ROOT

    monkeypatch.chdir(REPO_ROOT)                       # the worker imports this module as tests.unit....
    transport = ProcessTransport("never_done", f"{__name__}:never_done", None, TransportOptions())
    transport.start(None, snapshot(0, [], []))
    try:
        transport.offer(snapshot(1, [], []))
        assert transport.flush(30.0) is False          # the worker's transport said it is not done
        assert transport.counters()["snapshots"] == 2
    finally:
        transport.stop()
