"""The transport seam (docs/architecture.md §2): command ids and results, the inbox's coalescing,
transport plugins' life cycle, and the per-step snapshot they are offered."""

from __future__ import annotations

import json
import threading
from typing import Any

import esper
import numpy as np
import pytest

from unetyemu_ecs import Simulation, load_world_text
from unetyemu_ecs.plugins import GROUP_TRANSPORTS, Registry
from unetyemu_ecs.transport.api import CommandStatus, Snapshot, TransportError, TransportPlugin
from unetyemu_ecs.systems.flight_state import NavState
from unetyemu_ecs.transport.bus import Inbox, OffboardSetpoint, SetNavMode, SetTarget, Teleop
from unetyemu_ecs.transport.snapshot import SnapshotQueue

WORLD = """
world: {name: seam, physics_hz: 240, seed: 3}
scene: {generator: none, ground_size_m: 200}
vehicles:
  - {name: d1, type: quadrotor, preset: small, pose: {position_m: [0, 0, 0.2]}, components: {imu: {}}}
  - {name: c1, type: car, preset: medium, pose: {position_m: [0, 30, 0.9]}}
  - {name: d2, type: quadrotor, preset: small, pose: {position_m: [5, 0, 0.2]}}
"""


class Recorder:
    """A transport that keeps what it is given (on the simulation thread: offer is O(1) anyway)."""

    name = "recorder"

    def __init__(self, calls: list[str], fail: str = "") -> None:
        self.calls = calls
        self.fail = fail
        self.snapshots: list[Snapshot] = []
        self.port: Any = None

    def start(self, port: Any, first: Snapshot) -> None:
        self.calls.append(f"start {self.name}")
        if self.fail:
            raise TransportError(self.fail)
        self.port = port
        self.snapshots.append(first)

    def offer(self, snapshot: Snapshot) -> None:
        self.snapshots.append(snapshot)

    def flush(self, timeout_s: float = 2.0) -> bool:
        self.calls.append(f"flush {self.name}")
        return True

    def stop(self, timeout_s: float = 2.0) -> None:
        self.calls.append(f"stop {self.name}")

    def counters(self) -> dict[str, Any]:
        return {"snapshots": len(self.snapshots)}


def registry_with(*transports: Recorder) -> Registry:
    reg = Registry.discover()
    for t in transports:
        reg.add(GROUP_TRANSPORTS, t.name, TransportPlugin(create=lambda world, options, t=t: t))
    return reg


def make(*transports: Recorder, **kwargs: Any) -> Simulation:
    return Simulation(load_world_text(WORLD, registry=registry_with(*transports)), **kwargs)


# -- command ids and results ------------------------------------------------------------------


def test_api_commands_get_an_id_and_a_result_accepted_refused_or_unknown_vehicle():
    with make() as sim:
        # GIVEN commands sent through the Python API and one for a vehicle that does not exist
        ok = sim.set_target("d1", 1.0, 2.0, 3.0)
        too_fast = sim.cmd_vel("c1", 28.0, 0.0)              # in the API's range, beyond this car's 25 m/s
        ghost = sim.inbox.submit(SetTarget("ghost", (0.0, 0.0, 1.0), None, None))
        wrong_kind = sim.inbox.submit(Teleop("c1", (0.0, 0.0, 0.0, 0.0)))
        # THEN each has its own id, and no result before the step that applies it
        assert len({ok, too_fast, ghost, wrong_kind}) == 4
        assert sim.command_result(ok) is None
        # WHEN the next step runs
        sim.step()
        # THEN each result says what became of it, with a machine reason for the refusals
        r = sim.command_result(ok)
        assert r.status == CommandStatus.ACCEPTED and r.ok and r.vehicle == "d1" and r.kind == "target"
        assert r.source == "api" and r.command_id == ok
        r = sim.command_result(too_fast)
        assert r.status == CommandStatus.REJECTED_INVALID and not r.ok and "top speed" in r.text
        r = sim.command_result(ghost)
        assert r.status == CommandStatus.REJECTED_INVALID and r.reason == "unknown_vehicle"
        r = sim.command_result(wrong_kind)
        assert r.status == CommandStatus.REJECTED_INVALID and r.reason == "unsupported"
        # AND the refusals are in the event log as before
        assert any("rejected cmd_vel command" in text for _, who, text in sim.events if who == "c1")
        assert sim.command_result(10**9) is None


def test_command_ids_are_unique_across_threads():
    inbox = Inbox()
    ids: list[int] = []
    lock = threading.Lock()

    def submit_many() -> None:
        mine = [inbox.submit(Teleop("d1", (0.0, 0.0, 0.0, 0.0))) for _ in range(2000)]
        with lock:
            ids.extend(mine)

    # GIVEN eight threads submitting at once
    threads = [threading.Thread(target=submit_many) for _ in range(8)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    # THEN every id is different and positive
    assert len(ids) == 16000 and len(set(ids)) == 16000 and min(ids) > 0


def test_discrete_commands_are_all_applied_in_order_and_only_streams_are_coalesced():
    with make() as sim:
        # GIVEN two targets and three stick commands for one drone within one step
        first = sim.set_target("d1", 1.0, 0.0, 3.0)
        second = sim.set_target("d1", 2.0, 0.0, 3.0)
        arm = sim.arm("d2")
        sticks = [sim.teleop("d2", 0.1 * k, 0.0, 0.0, 0.0) for k in range(3)]
        sim.step()
        # THEN both targets were applied (each has a result), the second last: it is the one flown
        assert sim.command_result(first).ok and sim.command_result(second).ok and sim.command_result(arm).ok
        order = [r.command_id for r in sim.services.results]
        assert order.index(first) < order.index(second) < order.index(arm)
        # AND of the stick stream only the newest was applied
        assert [sim.command_result(i) is None for i in sticks] == [True, True, False]
        assert sim.fleet.stick[sim.row("d2")][0] == pytest.approx(0.2)


def test_inbox_keeps_the_newest_of_each_stream_where_the_stream_began():
    # GIVEN two stick streams, targets and a rejection queued in one step
    inbox = Inbox()
    inbox.submit(Teleop("d1", (0.1, 0.0, 0.0, 0.0)))
    t1 = inbox.submit(SetTarget("d1", (1.0, 0.0, 1.0), None, None))
    b = inbox.submit(Teleop("d1", (0.2, 0.0, 0.0, 0.0)))
    other = inbox.submit(Teleop("d2", (0.3, 0.0, 0.0, 0.0)))
    t2 = inbox.submit(SetTarget("d1", (2.0, 0.0, 1.0), None, None))
    rejected = inbox.reject("d1", "/d1/teleop", "bad", "ros2")
    # WHEN drained: the newest of d1's sticks takes the place of its first, everything else in order
    assert [m.command_id for m in inbox.drain()] == [b, t1, other, t2, rejected]
    assert inbox.drain() == []


def test_a_mode_switch_after_the_first_setpoint_of_a_stream_finds_the_stream():
    # GIVEN (MAVSDK's offboard start) a setpoint, then the switch to OFFBOARD, then the next setpoint, in one step
    inbox = Inbox()
    sp1 = inbox.submit(OffboardSetpoint("d1", pos_enu_m=(0.0, 0.0, 5.0)))
    mode = inbox.submit(SetNavMode("d1", NavState.OFFBOARD))
    sp2 = inbox.submit(OffboardSetpoint("d1", pos_enu_m=(1.0, 0.0, 5.0)))
    # WHEN drained: the newest setpoint is applied before the mode switch
    drained = inbox.drain()
    assert [m.command_id for m in drained] == [sp2, mode] and drained[0].pos_enu_m == (1.0, 0.0, 5.0)
    assert sp1 not in (sp2, mode)


# -- transport plugins -------------------------------------------------------------------------


def test_a_registered_transport_is_started_offered_every_step_stopped_and_counted_in_the_summary(tmp_path):
    calls: list[str] = []
    rec = Recorder(calls)
    # GIVEN a transport plugin registered in the world's registry
    sim = make(rec, out_dir=tmp_path)
    try:
        # THEN it was started with the port and the snapshot of the built world
        assert calls == ["start recorder"] and rec.port is sim.inbox and rec.snapshots[0].step == 0
        # WHEN the simulation steps
        sim.step(10)
        # THEN it was offered one snapshot per step
        assert [s.step for s in rec.snapshots] == list(range(11))
        assert sim.transports == {"recorder": rec}
    finally:
        sim.close()
    # AND close() flushed and stopped it before anything else, and its counters are in the summary
    assert calls == ["start recorder", "flush recorder", "stop recorder"]
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["transports"] == {"recorder": {"snapshots": 11}}


def test_a_transport_that_cannot_start_leaves_no_open_simulation():
    calls: list[str] = []
    good, bad = Recorder(calls), Recorder(calls, fail="port 14540 of d1 is in use")
    good.name, bad.name = "a_good", "b_bad"
    worlds_before = set(esper.list_worlds())
    # WHEN the second of two transports fails to start
    with pytest.raises(TransportError, match="port 14540 of d1 is in use"):
        make(good, bad)
    # THEN both were stopped (the started one too) and the simulation's world is gone
    assert calls == ["start a_good", "start b_bad", "flush a_good", "stop a_good", "flush b_bad", "stop b_bad"]
    assert set(esper.list_worlds()) == worlds_before


def test_transport_options_are_checked_before_anything_is_built():
    world = load_world_text(WORLD)
    with pytest.raises(ValueError, match="mavlink must be True or False, got 'yes'"):
        Simulation(world, mavlink="yes")
    with pytest.raises(ValueError, match="mavlink_bind must be an IPv4 or IPv6 address .* got '999.1.1.1'"):
        Simulation(world, mavlink_bind="999.1.1.1")
    with pytest.raises(ValueError, match=r"ros2 must be one of off, auto, rclpy, dds, got 'zenoh'"):
        Simulation(world, ros2="zenoh")


def test_a_transport_returning_none_is_not_enabled_and_no_snapshot_is_built():
    reg = Registry.discover()
    reg.add(GROUP_TRANSPORTS, "off", TransportPlugin(create=lambda world, options: None))
    with Simulation(load_world_text(WORLD, registry=reg)) as sim:
        sim.step()
        assert sim.transports == {} and sim.transport_counters() == {}
        assert not [s for s in sim.ecs.systems if type(s).__name__ == "TransportSnapshotSystem"]


# -- the snapshot ------------------------------------------------------------------------------


def test_snapshot_arrays_are_read_only_copies_consistent_with_the_simulation():
    rec = Recorder([])
    with make(rec) as sim:
        first = rec.snapshots[0]
        # THEN the first snapshot reports every drone's mission status (idle: none loaded)
        assert first.vehicles == ("d1", "c1", "d2") and first.kinds == ("quadrotor", "car", "quadrotor")
        assert dict(first.mission_status) == {"d1": {"mission": None, "state": "idle"},
                                              "d2": {"mission": None, "state": "idle"}}
        # WHEN a drone is armed and sent up, and the world runs
        sim.arm("d1")
        sim.set_target("d1", 0.0, 0.0, 4.0)
        sim.step(240)
        snap = rec.snapshots[-1]
        # THEN the newest snapshot is the state at the end of the last step
        assert snap.step == sim.step_count and snap.sim_time_s == pytest.approx(sim.sim_time_s)
        for name in ("d1", "c1", "d2"):
            row = snap.row(name)
            np.testing.assert_array_equal(snap.pos_enu_m[row], sim.position_enu_m(name))
            np.testing.assert_array_equal(snap.vel_enu_m_s[row], sim.velocity_enu_m_s(name))
            np.testing.assert_array_equal(snap.quat_enu_flu_xyzw[row], sim.attitude_enu_flu_xyzw(name))
        assert snap.armed.tolist() == [True, False, False]
        assert snap.soc_frac[snap.row("d1")] == sim.fleet.soc_frac[sim.row("d1")]
        # AND its arrays are read-only copies: the simulation moving on does not change them
        with pytest.raises(ValueError):
            snap.pos_enu_m[0, 0] = 1.0
        kept = snap.pos_enu_m.copy()
        sim.step(24)
        np.testing.assert_array_equal(snap.pos_enu_m, kept)
        # AND the step's sensor samples, events and results are there
        last = rec.snapshots[-1]
        assert last.sensors == tuple(sim.services.sensors.this_step)
        assert any(s.vehicle == "d1" and s.sensor == "imu" for s in rec.snapshots[1].sensors)
        after_first = rec.snapshots[1]
        assert [(r.kind, r.vehicle) for r in after_first.results[:after_first.results_end]] == [("arm", "d1"),
                                                                                                ("target", "d1")]
        # AND no mission status is repeated while nothing changed
        assert all(not s.mission_status for s in rec.snapshots[1:])


def test_flight_parameters_are_the_same_object_until_one_changes():
    from unetyemu_ecs.navigation.params import FlightParams

    rec = Recorder([])
    with make(rec) as sim:
        sim.step(3)
        if not rec.snapshots[-1].params:
            pytest.skip("no drone carries FlightParams in this build")
        # GIVEN the drones' parameters (attached by the navigation systems by the first step)
        steady = rec.snapshots[-1]
        assert set(steady.params) == {"d1", "d2"}
        # THEN while none changes, every snapshot carries the very same object and version
        sim.step(3)
        assert all(s.params is steady.params and s.params_version == steady.params_version for s in rec.snapshots[-4:])
        # WHEN one parameter changes
        assert sim.component("d1", FlightParams).set("MIS_TAKEOFF_ALT", 7.5) == ""
        sim.step()
        # THEN the next snapshot has a new object with the new value and a higher version
        snap = rec.snapshots[-1]
        assert snap.params is not steady.params and snap.params_version > steady.params_version
        assert snap.params["d1"]["MIS_TAKEOFF_ALT"] == 7.5 and steady.params["d1"]["MIS_TAKEOFF_ALT"] != 7.5
        with pytest.raises(TypeError):
            snap.params["d1"]["MIS_TAKEOFF_ALT"] = 1.0                  # read-only


# -- the queue a transport keeps ----------------------------------------------------------------


def _snap(step: int, status: dict[str, Any] | None = None) -> Snapshot:
    return Snapshot(step, step * 0.01, 0.01, ("d1",), ("quadrotor",), {}, (), [], 0, [], 0, status or {})


def test_a_full_queue_drops_the_oldest_but_keeps_its_mission_status_changes():
    q = SnapshotQueue(2)
    # GIVEN a consumer that fell behind by two snapshots, one of which changed the mission status
    q.put(_snap(1, {"d1": {"state": "running", "step": 0}}))
    q.put(_snap(2, {"d2": {"state": "idle"}}))
    q.put(_snap(3))
    q.put(_snap(4, {"d1": {"state": "running", "step": 1}}))
    # THEN the two oldest were dropped and counted
    assert q.dropped == 2 and q.offered == 4
    # AND the first snapshot taken carries the dropped ones' status changes (newer ones win)
    (seq3, snap3), (seq4, snap4) = q.get_all(0.0)
    assert snap3.step == 3 and dict(snap3.mission_status) == {"d1": {"state": "running", "step": 0},
                                                               "d2": {"state": "idle"}}
    assert snap4.step == 4 and dict(snap4.mission_status) == {"d1": {"state": "running", "step": 1}}
    q.task_done(seq3)
    assert not q.wait_done(0.0)
    q.task_done(seq4)
    assert q.wait_done(0.0) and q.get_all(0.0) == []
