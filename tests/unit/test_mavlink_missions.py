"""The MAVLink mission protocol of one drone (transport/mavlink/missions.py): upload, download, clear,
set current, retries and time-outs, and progress (MISSION_CURRENT, MISSION_ITEM_REACHED), for the
mission, fence and rally types.

Every message crosses real pymavlink encoders both ways (packed to bytes, parsed back). The link is a
small recorder of what the service sends (the UDP link is the endpoint's, tested with it); commands
go to a list standing in for the simulation's inbox.
"""

from __future__ import annotations

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mav

from unetyemu_ecs.geodesy import GeodeticOrigin, enu_to_geodetic
from unetyemu_ecs.mission import spec as mission_spec
from unetyemu_ecs.systems.flight_state import MissionState, NavState
from unetyemu_ecs.transport.api import CommandResult, CommandStatus, Snapshot
from unetyemu_ecs.transport.bus import SetGeofence, SetMissionCurrent, SetRallyPoints, StoreMission
from unetyemu_ecs.transport.mavlink.missions import RETRY_S, TIMEOUT_S, MissionService

ORIGIN = GeodeticOrigin(47.397742, 8.545594, 488.0)
NAN = float("nan")
GCS = (255, 190)
_GCS_TX = mav.MAVLink(None, srcSystem=GCS[0], srcComponent=GCS[1])
_VEH_TX = mav.MAVLink(None, srcSystem=1, srcComponent=1)
_RX = mav.MAVLink(None)
HAS_RETURN = "return" in mission_spec.STEP_TYPES


def _wire(msg, tx):
    out = _RX.parse_buffer(msg.pack(tx))
    assert out and len(out) == 1, out
    return out[0]


class RecordingLink:
    """Stands in for the endpoint's link: keeps what the service sends, as the peer would decode it."""

    def __init__(self, name: str = "gcs") -> None:
        self.name = name
        self.sent: list = []

    def send(self, msg) -> None:
        self.sent.append(_wire(msg, _VEH_TX))

    def take(self) -> list:
        out, self.sent = self.sent, []
        return out


class Rig:
    def __init__(self) -> None:
        self.commands: list = []
        self.svc = MissionService("d1", 1, 1, ORIGIN, None, self._submit)
        self.link = RecordingLink()
        self.now = 100.0
        self.texts: list[str] = []

    def _submit(self, command) -> int:
        self.commands.append(command)
        return len(self.commands)

    def send(self, msg, link=None) -> list:
        """The GCS sends ``msg``; returns what the service answered on that link."""
        link = link or self.link
        self.svc.handle(_wire(msg, _GCS_TX), link, self.now)
        return link.take()

    def upload(self, items, mission_type=0, lose=()):
        """Run a whole upload like a GCS; ``lose``: seqs whose first request the GCS misses. Returns the ACK."""
        out = self.send(mav.MAVLink_mission_count_message(1, 1, len(items), mission_type))
        lost = set(lose)
        while True:
            self.texts += [m.text for m in out if m.get_type() == "STATUSTEXT"]
            out = [m for m in out if m.get_type() != "STATUSTEXT"]
            assert len(out) == 1, out
            m = out[0]
            if m.get_type() == "MISSION_ACK":
                assert (m.target_system, m.target_component, m.mission_type) == (*GCS, mission_type)
                return m
            assert m.get_type() == "MISSION_REQUEST_INT" and m.mission_type == mission_type
            if m.seq in lost:
                lost.discard(m.seq)
                self.now += RETRY_S + 0.01
                self.svc.tick(self.now)
                out = self.link.take()
                continue
            out = self.send(items[m.seq])

    def download(self, mission_type=0, as_int=True):
        out = self.send(mav.MAVLink_mission_request_list_message(1, 1, mission_type))
        assert [m.get_type() for m in out] == ["MISSION_COUNT"]
        got = []
        for seq in range(out[0].count):
            req = (mav.MAVLink_mission_request_int_message if as_int else mav.MAVLink_mission_request_message)
            reply = self.send(req(1, 1, seq, mission_type))
            assert len(reply) == 1 and reply[0].get_type() == ("MISSION_ITEM_INT" if as_int else "MISSION_ITEM")
            got.append(reply[0])
        assert self.send(mav.MAVLink_mission_ack_message(1, 1, 0, mission_type)) == []
        return got


def latlon(e, n):
    lat, lon, _ = enu_to_geodetic(np.array([e, n, 0.0]), ORIGIN)
    return int(round(float(lat) * 1e7)), int(round(float(lon) * 1e7))


def item(seq, command, e=0.0, n=0.0, z=0.0, frame=6, p1=0.0, p2=0.0, p3=0.0, p4=NAN, mission_type=0, pos=True):
    x, y = latlon(e, n) if pos else (0, 0)
    return mav.MAVLink_mission_item_int_message(1, 1, seq, frame, command, 0, 1, p1, p2, p3, p4, x, y, z, mission_type)


def mavsdk_mission():
    """What MAVSDK's mission plugin uploads: 4 waypoints, DO_CHANGE_SPEED after each, RTL at the end."""
    out = []
    for e, n, z, v in [(0.0, 30.0, 10.0, 5.0), (30.0, 30.0, 10.0, 8.0), (30.0, 0.0, 10.0, 3.0), (0.0, 0.0, 10.0, 6.0)]:
        out.append(item(len(out), mav.MAV_CMD_NAV_WAYPOINT, e, n, z, p2=1.0))
        out.append(item(len(out), mav.MAV_CMD_DO_CHANGE_SPEED, frame=2, p1=1.0, p2=v, p3=-1.0, pos=False))
    out.append(item(len(out), mav.MAV_CMD_NAV_RETURN_TO_LAUNCH, frame=2, pos=False))
    return out


FIELDS = ("seq", "frame", "command", "current", "autocontinue", "param1", "param2", "param3", "param4", "x", "y", "z",
          "mission_type")


def same(a, b) -> bool:
    return all((getattr(a, f) == getattr(b, f)) or (getattr(a, f) != getattr(a, f) and getattr(b, f) != getattr(b, f))
               for f in FIELDS)


pytestmark = pytest.mark.skipif(not HAS_RETURN, reason="needs the mission 'return' step for RTL items")


def test_mission_upload_download_round_trip_submits_the_spec():
    rig = Rig()
    items = mavsdk_mission()
    # WHEN the GCS uploads the mission
    ack = rig.upload(items)
    # THEN it is accepted, submitted once as StoreMission from mavlink with the mapped MissionSpec
    assert ack.type == mav.MAV_MISSION_ACCEPTED
    assert len(rig.commands) == 1
    cmd = rig.commands[0]
    assert isinstance(cmd, StoreMission) and cmd.source == "mavlink" and cmd.vehicle == "d1"
    assert [s.type for s in cmd.mission.steps] == ["cruise", "return"]
    assert [w.cruise_speed for w in cmd.mission.steps[0].waypoints] == [None, 5.0, 8.0, 3.0]
    # AND a download returns exactly the uploaded items, with MISSION_REQUEST_INT ...
    got = rig.download()
    assert len(got) == len(items) and all(same(a, _wire(b, _GCS_TX)) for a, b in zip(got, items))
    assert all((m.target_system, m.target_component) == GCS for m in got)
    # ... and with the old MISSION_REQUEST (lat/lon as float degrees)
    got_f = rig.download(as_int=False)
    assert got_f[0].x == pytest.approx(items[0].x / 1e7) and got_f[1].param2 == 5.0
    assert rig.svc.counters()["uploads_accepted"] == 1


def test_upload_with_mission_item_float_round_trips_as_float():
    rig = Rig()
    lat, lon = (v / 1e7 for v in latlon(10.0, 10.0))
    items = [mav.MAVLink_mission_item_message(1, 1, 0, 3, 16, 0, 1, 0, 0, 0, NAN, lat, lon, 12.0, 0)]
    assert rig.upload(items).type == mav.MAV_MISSION_ACCEPTED
    assert same(rig.download(as_int=False)[0], _wire(items[0], _GCS_TX))


def test_fence_and_rally_round_trips():
    rig = Rig()
    square = [(-50.0, -50.0), (50.0, -50.0), (50.0, 50.0), (-50.0, 50.0)]
    fence = [item(i, 5001, e, n, frame=5, p1=4, mission_type=1) for i, (e, n) in enumerate(square)]
    fence.append(item(4, 5004, 0.0, 0.0, frame=5, p1=10.0, mission_type=1))
    rally = [item(0, 5100, 40.0, 0.0, 20.0, mission_type=2), item(1, 5100, -40.0, 0.0, 20.0, mission_type=2)]
    assert rig.upload(fence, mission_type=1).type == mav.MAV_MISSION_ACCEPTED
    assert rig.upload(rally, mission_type=2).type == mav.MAV_MISSION_ACCEPTED
    f_cmd, r_cmd = rig.commands
    assert isinstance(f_cmd, SetGeofence) and f_cmd.source == "mavlink"
    assert f_cmd.fence.contains(np.array([[30.0, 30.0], [0.0, 5.0], [60.0, 0.0]])).tolist() == [True, False, False]
    assert isinstance(r_cmd, SetRallyPoints)
    assert np.allclose(r_cmd.points_enu_m, [(40.0, 0.0, 20.0), (-40.0, 0.0, 20.0)], atol=0.02)
    assert all(same(a, _wire(b, _GCS_TX)) for a, b in zip(rig.download(1), fence))
    assert all(same(a, _wire(b, _GCS_TX)) for a, b in zip(rig.download(2), rally))
    # the mission store is separate: still empty
    assert rig.download(0) == []


def test_a_lost_request_is_sent_again_and_the_count_is_never_acked_early():
    rig = Rig()
    items = mavsdk_mission()
    # GIVEN the count: the only answer is the request for item 0 (no ACK before the items)
    out = rig.send(mav.MAVLink_mission_count_message(1, 1, len(items), 0))
    assert [(m.get_type(), m.seq) for m in out] == [("MISSION_REQUEST_INT", 0)]
    # WHEN nothing comes back within the retry time THEN the same request goes out again
    rig.svc.tick(rig.now + RETRY_S / 2)
    assert rig.link.take() == []
    rig.svc.tick(rig.now + RETRY_S + 0.01)
    assert [(m.get_type(), m.seq) for m in rig.link.take()] == [("MISSION_REQUEST_INT", 0)]
    rig.svc.handle(_wire(items[0], _GCS_TX), rig.link, rig.now)     # answer it now
    rig.link.take()
    # AND a whole upload where items 3 and 6 are each missed once still completes
    rig2 = Rig()
    assert rig2.upload(items, lose=(3, 6)).type == mav.MAV_MISSION_ACCEPTED
    assert rig2.svc.counters()["requests_resent"] == 2
    assert len(rig2.commands) == 1


def test_a_stalled_upload_is_given_up_and_replaces_nothing():
    rig = Rig()
    assert rig.upload(mavsdk_mission()).type == 0
    rig.send(mav.MAVLink_mission_count_message(1, 1, 3, 0))
    rig.send(item(0, 16, 1.0, 1.0, 5.0))
    rig.svc.tick(rig.now + TIMEOUT_S + 0.1)
    acks = [m for m in rig.link.take() if m.get_type() == "MISSION_ACK"]
    assert [a.type for a in acks] == [mav.MAV_MISSION_OPERATION_CANCELLED]
    assert len(rig.commands) == 1                            # only the first upload was submitted
    rig.now += TIMEOUT_S + 1.0
    assert len(rig.download()) == 9                          # the first mission is still there


@pytest.mark.parametrize("bad_item, result", [
    (item(2, 16, 0.0, 30_000.0, 10.0), mav.MAV_MISSION_INVALID_PARAM5_X),
    (item(2, 16, 0.0, 10.0, 10.0, frame=1), mav.MAV_MISSION_UNSUPPORTED_FRAME),
    (item(2, mav.MAV_CMD_DO_JUMP, frame=2, p1=0, p2=2, pos=False), mav.MAV_MISSION_UNSUPPORTED),
    (item(2, mav.MAV_CMD_DO_CHANGE_SPEED, frame=2, p1=1, p2=99.0, pos=False), mav.MAV_MISSION_INVALID_PARAM2),
])
def test_a_bad_item_rejects_the_whole_list_and_keeps_the_old_one(bad_item, result):
    rig = Rig()
    old = mavsdk_mission()
    assert rig.upload(old).type == 0
    new = [item(0, 16, 5.0, 5.0, 5.0), item(1, 16, 6.0, 5.0, 5.0), bad_item, item(3, 16, 7.0, 5.0, 5.0)]
    ack = rig.upload(new)
    assert ack.type == result
    assert rig.texts and "item 2" in rig.texts[-1]          # a STATUSTEXT names the item
    assert len(rig.commands) == 1                            # nothing submitted for the bad list
    assert all(same(a, _wire(b, _GCS_TX)) for a, b in zip(rig.download(), old))


def test_an_item_out_of_sequence_is_invalid_sequence():
    rig = Rig()
    rig.send(mav.MAVLink_mission_count_message(1, 1, 3, 0))
    out = rig.send(item(2, 16, 1.0, 1.0, 5.0))
    acks = [m for m in out if m.get_type() == "MISSION_ACK"]
    assert [a.type for a in acks] == [mav.MAV_MISSION_INVALID_SEQUENCE]
    assert rig.commands == []


def test_count_zero_clears_too_many_is_no_space_and_clear_all():
    rig = Rig()
    assert rig.upload(mavsdk_mission()).type == 0
    out = rig.send(mav.MAVLink_mission_count_message(1, 1, 0, 0))
    assert [(m.get_type(), m.type) for m in out] == [("MISSION_ACK", mav.MAV_MISSION_ACCEPTED)]
    assert isinstance(rig.commands[-1], StoreMission) and rig.commands[-1].mission is None
    assert rig.download() == []
    out = rig.send(mav.MAVLink_mission_count_message(1, 1, 60_000, 0))
    assert [m.type for m in out if m.get_type() == "MISSION_ACK"] == [mav.MAV_MISSION_NO_SPACE]
    # CLEAR_ALL of the rally type only
    rally = [item(0, 5100, 40.0, 0.0, 20.0, mission_type=2)]
    assert rig.upload(rally, mission_type=2).type == 0
    assert rig.upload(mavsdk_mission()).type == 0
    out = rig.send(mav.MAVLink_mission_clear_all_message(1, 1, 2))
    assert [(m.get_type(), m.type, m.mission_type) for m in out] == [("MISSION_ACK", 0, 2)]
    assert isinstance(rig.commands[-1], SetRallyPoints) and rig.commands[-1].points_enu_m == ()
    assert rig.download(2) == [] and len(rig.download(0)) == 9


def test_one_transfer_per_link_a_repeated_count_is_asked_again_another_is_denied():
    rig = Rig()
    rig.send(mav.MAVLink_mission_count_message(1, 1, 9, 0))
    out = rig.send(mav.MAVLink_mission_count_message(1, 1, 9, 0))          # the GCS missed our request
    assert [(m.get_type(), m.seq) for m in out] == [("MISSION_REQUEST_INT", 0)]
    out = rig.send(mav.MAVLink_mission_request_list_message(1, 1, 1))      # a download meanwhile
    assert [(m.get_type(), m.type) for m in out] == [("MISSION_ACK", mav.MAV_MISSION_DENIED)]
    # the other link is free
    other = RecordingLink("api")
    out = rig.send(mav.MAVLink_mission_request_list_message(1, 1, 0), link=other)
    assert [(m.get_type(), m.count) for m in out] == [("MISSION_COUNT", 0)]


def test_a_refused_store_brings_the_previous_list_back():
    rig = Rig()
    first = mavsdk_mission()
    assert rig.upload(first).type == 0
    assert rig.upload([item(0, 16, 1.0, 1.0, 5.0)]).type == 0
    # WHEN the simulation refuses the second StoreMission (its CommandResult, id 2)
    rig.svc.on_result(CommandResult(2, "d1", "mission_store", "mavlink", CommandStatus.REJECTED_STATE, "busy"))
    # THEN a download shows the first mission again
    assert len(rig.download()) == len(first)
    assert rig.svc.counters()["results_refused"] == 1


def snapshot(t, *, state, step=-1, pos=(0.0, 0.0, 0.0), nav=NavState.MISSION):
    arrays = {
        "pos_enu_m": np.array([pos], dtype=float), "home_enu_m": np.zeros((1, 3)), "home_set": np.array([True]),
        "mission_state": np.array([int(state)]), "mission_step": np.array([step]), "nav_state": np.array([int(nav)]),
    }
    return Snapshot(step=int(t * 100), sim_time_s=t, dt_s=0.01, vehicles=("d1",), kinds=("quadrotor",), arrays=arrays,
                    sensors=(), events=[], events_end=0, results=[], results_end=0,
                    params={"d1": {"NAV_ACC_RAD": 2.0, "NAV_MC_ALT_RAD": 0.8}})


def test_mission_current_and_item_reached_follow_the_snapshots():
    rig = Rig()
    assert rig.upload(mavsdk_mission()).type == 0
    links = [rig.link, RecordingLink("api")]

    def progress(snap):
        rig.svc.on_snapshot(snap, 0, links)
        api = links[1].take()
        gcs = rig.link.take()
        assert [(m.get_type(), m.to_dict()) for m in gcs] == [(m.get_type(), m.to_dict()) for m in api]
        cur = [(m.seq, m.total, m.mission_state, m.mission_mode) for m in gcs if m.get_type() == "MISSION_CURRENT"]
        reached = [m.seq for m in gcs if m.get_type() == "MISSION_ITEM_REACHED"]
        return cur, reached

    # stored, not flying it: NOT_STARTED, not in mission mode
    assert progress(snapshot(0.0, state=MissionState.STORED, nav=NavState.HOLD)) == ([(0, 9, 2, 2)], [])
    # nothing changes: no MISSION_CURRENT until a second of sim time has passed, then again
    assert progress(snapshot(0.5, state=MissionState.STORED, nav=NavState.HOLD)) == ([], [])
    assert progress(snapshot(1.0, state=MissionState.STORED, nav=NavState.HOLD)) == ([(0, 9, 2, 2)], [])
    # running the cruise step, far from the first waypoint: current item 0, ACTIVE, in mission mode
    assert progress(snapshot(1.1, state=MissionState.RUNNING, step=0, pos=(0.0, 10.0, 10.0))) == ([(0, 9, 3, 1)], [])
    # at waypoint 0 (item 0): reached, with the DO_CHANGE_SPEED after it; current becomes item 2
    assert progress(snapshot(2.0, state=MissionState.RUNNING, step=0, pos=(0.5, 29.0, 10.3))) == ([(2, 9, 3, 1)],
                                                                                                  [0, 1])
    # within the horizontal radius but 3 m too low: not reached
    assert progress(snapshot(3.0, state=MissionState.RUNNING, step=0, pos=(30.0, 30.0, 7.0))) == ([(2, 9, 3, 1)], [])
    assert progress(snapshot(3.5, state=MissionState.RUNNING, step=0, pos=(30.0, 30.0, 10.0))) == ([(4, 9, 3, 1)],
                                                                                                   [2, 3])
    # the return step starts: everything of the cruise step is reached, the RTL item is current
    assert progress(snapshot(5.0, state=MissionState.RUNNING, step=1, pos=(0.0, 0.0, 10.0))) == ([(8, 9, 3, 1)],
                                                                                                 [4, 5, 6, 7])
    # completed: the RTL item is reached, state COMPLETE
    assert progress(snapshot(9.0, state=MissionState.COMPLETED, nav=NavState.HOLD)) == ([(8, 9, 5, 2)], [8])
    assert rig.svc.counters()["item_reached_sent"] == 9


def test_set_current_submits_the_step_holding_the_item():
    rig = Rig()
    items = [item(0, mav.MAV_CMD_NAV_TAKEOFF, z=10.0, pos=False)] + [
        item(i, 16, 10.0 * i, 0.0, 10.0, p1=1.0) for i in range(1, 4)]
    assert rig.upload(items).type == 0
    assert rig.send(mav.MAVLink_mission_set_current_message(1, 1, 2)) == []
    assert rig.commands[-1] == SetMissionCurrent("d1", 2, source="mavlink")
    # an item that does not exist: nothing submitted, a STATUSTEXT says why
    out = rig.send(mav.MAVLink_mission_set_current_message(1, 1, 7))
    assert [m.get_type() for m in out] == ["STATUSTEXT"]
    assert len(rig.commands) == 2


def test_step_of_seq_maps_item_numbers_to_steps_for_mission_start():
    rig = Rig()
    assert rig.svc.step_of_seq(0) is None                    # no mission uploaded
    assert rig.upload(mavsdk_mission()).type == 0
    assert [rig.svc.step_of_seq(s) for s in (0, 3, 7, 8, 9)] == [0, 0, 0, 1, None]
