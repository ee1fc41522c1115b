"""The MAVLink mission protocol of one drone's endpoint: mission (type 0), fence (1) and rally (2).

Upload: MISSION_COUNT -> we send MISSION_REQUEST_INT for each seq (a MISSION_ITEM answer is taken
like a MISSION_ITEM_INT) -> MISSION_ACK after the last item, whose result is the validation of the
whole list (:mod:`.items`); nothing is replaced unless all of it is valid. A request is sent again
after ``RETRY_S`` without the item, the transfer is given up (MISSION_ACK OPERATION_CANCELLED)
after ``TIMEOUT_S`` without progress (wall clock, :meth:`MissionService.tick`; PX4's
``mavlink_mission.h`` uses about the same). COUNT 0 clears at once; more than ``MAX_ITEMS`` ->
NO_SPACE. A non-zero COUNT is never acknowledged before its items (MAVSDK calls that a protocol
error). Download: MISSION_REQUEST_LIST -> MISSION_COUNT -> the peer's MISSION_REQUEST_INT
(answered with MISSION_ITEM_INT) or MISSION_REQUEST (answered with MISSION_ITEM), items exactly
as uploaded -> the peer's MISSION_ACK. MISSION_CLEAR_ALL clears one type (or all, 255).
MISSION_SET_CURRENT makes the step holding that item current. One transfer per link at a time.

An accepted list is submitted as StoreMission / SetGeofence / SetRallyPoints (``source="mavlink"``);
if the simulation refuses it (its CommandResult, :meth:`MissionService.on_result`), the previous
list comes back so a download shows what the drone really has.

Progress (:meth:`MissionService.on_snapshot`): MISSION_CURRENT (seq, total, mission_state,
mission_mode) on change and once a second of sim time; MISSION_ITEM_REACHED for each item in
order: a waypoint of a cruise step when the drone comes within NAV_ACC_RAD horizontally and
NAV_MC_ALT_RAD vertically of it, every item of a step once the mission moves past that step (DO
items are reported with the step before them, as PX4 does when it executes them), all of them
when the mission completes.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from pymavlink.dialects.v20 import common as mav

from ...geodesy import GeodeticOrigin
from ...systems.flight_state import MissionState, NavState
from ..api import CommandResult, Snapshot
from ..bus import SetGeofence, SetMissionCurrent, SetRallyPoints, StoreMission
from .items import (MAX_ITEMS, ItemError, MissionItem, MissionPlan, build_geofence, build_mission, build_rally)

RETRY_S = 0.25          # re-request an item not received after this long [s, wall clock]
TIMEOUT_S = 5.0         # give up an upload or download without progress for this long [s, wall clock]
CURRENT_PERIOD_S = 1.0  # MISSION_CURRENT at least this often [s, sim time]

MISSION, FENCE, RALLY = mav.MAV_MISSION_TYPE_MISSION, mav.MAV_MISSION_TYPE_FENCE, mav.MAV_MISSION_TYPE_RALLY
TYPES = (MISSION, FENCE, RALLY)
_TYPE_NAMES = {MISSION: "mission", FENCE: "fence", RALLY: "rally"}

_MISSION_STATE = {   # our MissionState -> MAVLink MISSION_STATE
    MissionState.NONE: mav.MISSION_STATE_NOT_STARTED,
    MissionState.STORED: mav.MISSION_STATE_NOT_STARTED,
    MissionState.RUNNING: mav.MISSION_STATE_ACTIVE,
    MissionState.PAUSED: mav.MISSION_STATE_PAUSED,
    MissionState.COMPLETED: mav.MISSION_STATE_COMPLETE,
    MissionState.FAILED: mav.MISSION_STATE_PAUSED,       # stopped part-way: not complete
    MissionState.CANCELLED: mav.MISSION_STATE_NOT_STARTED,
}


@dataclass
class _Upload:
    mission_type: int
    count: int
    peer: tuple[int, int]
    items: list[MissionItem] = field(default_factory=list)
    last_request_s: float = 0.0
    last_progress_s: float = 0.0


@dataclass
class _Download:
    mission_type: int
    items: tuple[MissionItem, ...]
    peer: tuple[int, int]
    last_progress_s: float = 0.0


@dataclass
class _Store:
    items: tuple[MissionItem, ...] = ()
    plan: MissionPlan | None = None          # mission type only


class MissionService:
    """Mission (type 0), fence (1) and rally (2) protocols of one drone's endpoint, shared by its links."""

    HANDLES: frozenset[int] = frozenset({
        mav.MAVLINK_MSG_ID_MISSION_ITEM, mav.MAVLINK_MSG_ID_MISSION_REQUEST, mav.MAVLINK_MSG_ID_MISSION_SET_CURRENT,
        mav.MAVLINK_MSG_ID_MISSION_REQUEST_LIST, mav.MAVLINK_MSG_ID_MISSION_COUNT,
        mav.MAVLINK_MSG_ID_MISSION_CLEAR_ALL, mav.MAVLINK_MSG_ID_MISSION_ACK,
        mav.MAVLINK_MSG_ID_MISSION_REQUEST_INT, mav.MAVLINK_MSG_ID_MISSION_ITEM_INT,
    })

    def __init__(self, vehicle: str, sysid: int, compid: int, origin: GeodeticOrigin, layout: Any,
                 submit: Callable[[Any], int]) -> None:
        self.vehicle = vehicle
        self.sysid = sysid
        self.compid = compid
        self.origin = origin
        self.layout = layout
        self._submit = submit
        self._stores = {t: _Store() for t in TYPES}
        self._transfers: dict[Any, _Upload | _Download] = {}      # link -> transfer in progress
        self._links: dict[Any, None] = {}                         # links seen (for tick's retries)
        self._pending: dict[int, tuple[int, _Store]] = {}         # command id -> (type, store it replaced)
        self._home_z_m = 0.0
        self._params: dict[str, float] = {}
        # progress
        self._last_current: tuple[int, int, int, int] | None = None
        self._last_current_t = -math.inf
        self._reached = -1            # highest seq reported reached (in order)
        self._last_step = -1
        self._last_state = MissionState.NONE
        self._counters = {k: 0 for k in (
            "uploads_started", "uploads_accepted", "uploads_rejected", "uploads_timed_out", "items_received",
            "requests_sent", "requests_resent", "downloads", "items_sent", "downloads_acked", "downloads_timed_out",
            "clears", "set_current", "denied_busy", "bad_requests", "commands_submitted", "results_ok",
            "results_refused", "mission_current_sent", "item_reached_sent")}

    # ------------------------------------------------------------------ helpers
    def _ack(self, link: Any, peer: tuple[int, int], mission_type: int, result: int) -> None:
        link.send(mav.MAVLink_mission_ack_message(peer[0], peer[1], result, mission_type))

    def _text(self, link: Any, text: str) -> None:
        link.send(mav.MAVLink_statustext_message(mav.MAV_SEVERITY_WARNING, text[:50].encode(), 0, 0))

    def _request(self, link: Any, up: _Upload, now_s: float) -> None:
        seq = len(up.items)
        link.send(mav.MAVLink_mission_request_int_message(up.peer[0], up.peer[1], seq, up.mission_type))
        up.last_request_s = now_s
        self._counters["requests_sent"] += 1

    @property
    def plan(self) -> MissionPlan | None:
        """The mission list in force (None: none uploaded over MAVLink)."""
        return self._stores[MISSION].plan

    def step_of_seq(self, seq: int) -> int | None:
        """Mission step holding MAVLink item ``seq`` of the uploaded mission (for MISSION_START p1 and
        DO_SET_MISSION_CURRENT, whose numbers are item seqs, not steps); None: no such item or step."""
        plan = self.plan
        return plan.step_of_seq(seq) if plan is not None else None

    def items(self, mission_type: int) -> tuple[MissionItem, ...]:
        """The stored list of one type, as uploaded."""
        return self._stores[mission_type].items

    # ------------------------------------------------------------------ messages
    def handle(self, msg: Any, link: Any, now_s: float) -> None:
        """Consume one message addressed to us (its id in HANDLES); replies go out through ``link.send``."""
        self._links[link] = None
        peer = (msg.get_srcSystem(), msg.get_srcComponent())
        mid = msg.get_msgId()
        mtype = int(getattr(msg, "mission_type", MISSION))
        if mid == mav.MAVLINK_MSG_ID_MISSION_COUNT:
            self._on_count(msg, link, peer, mtype, now_s)
        elif mid in (mav.MAVLINK_MSG_ID_MISSION_ITEM_INT, mav.MAVLINK_MSG_ID_MISSION_ITEM):
            self._on_item(msg, link, peer, mtype, now_s)
        elif mid == mav.MAVLINK_MSG_ID_MISSION_REQUEST_LIST:
            self._on_request_list(link, peer, mtype, now_s)
        elif mid in (mav.MAVLINK_MSG_ID_MISSION_REQUEST_INT, mav.MAVLINK_MSG_ID_MISSION_REQUEST):
            self._on_request(msg, link, peer, mtype, now_s, as_int=mid == mav.MAVLINK_MSG_ID_MISSION_REQUEST_INT)
        elif mid == mav.MAVLINK_MSG_ID_MISSION_ACK:
            tr = self._transfers.get(link)
            if isinstance(tr, _Download) and tr.mission_type == mtype:
                del self._transfers[link]
                self._counters["downloads_acked"] += 1
        elif mid == mav.MAVLINK_MSG_ID_MISSION_CLEAR_ALL:
            self._on_clear(link, peer, mtype)
        elif mid == mav.MAVLINK_MSG_ID_MISSION_SET_CURRENT:
            self._on_set_current(msg, link)

    def _on_count(self, msg: Any, link: Any, peer: tuple[int, int], mtype: int, now_s: float) -> None:
        count = int(msg.count)
        tr = self._transfers.get(link)
        if isinstance(tr, _Upload):
            if tr.mission_type == mtype and tr.count == count and not tr.items:
                self._request(link, tr, now_s)          # the peer missed our first request: ask again
                self._counters["requests_resent"] += 1
                return
            if now_s - tr.last_progress_s < TIMEOUT_S:
                self._counters["denied_busy"] += 1
                self._ack(link, peer, mtype, mav.MAV_MISSION_DENIED)
                return
        if mtype not in TYPES:
            self._ack(link, peer, mtype, mav.MAV_MISSION_UNSUPPORTED)
            return
        self._transfers.pop(link, None)                 # a new upload ends a stale download on this link
        if count > MAX_ITEMS:
            self._counters["uploads_rejected"] += 1
            self._text(link, f"{_TYPE_NAMES[mtype]}: {count} items, at most {MAX_ITEMS}")
            self._ack(link, peer, mtype, mav.MAV_MISSION_NO_SPACE)
            return
        if count == 0:
            self._replace(mtype, ())
            self._counters["clears"] += 1
            self._ack(link, peer, mtype, mav.MAV_MISSION_ACCEPTED)
            return
        up = _Upload(mission_type=mtype, count=count, peer=peer, last_progress_s=now_s)
        self._transfers[link] = up
        self._counters["uploads_started"] += 1
        self._request(link, up, now_s)

    def _on_item(self, msg: Any, link: Any, peer: tuple[int, int], mtype: int, now_s: float) -> None:
        up = self._transfers.get(link)
        if not isinstance(up, _Upload) or up.mission_type != mtype:
            self._counters["bad_requests"] += 1
            return                                      # no upload of this type on this link: ignore (PX4 ≈)
        seq = int(msg.seq)
        expected = len(up.items)
        if seq < expected:
            return                                      # a duplicate (our re-request crossed its answer)
        if seq > expected:
            del self._transfers[link]
            self._counters["uploads_rejected"] += 1
            self._text(link, f"{_TYPE_NAMES[mtype]}: got item {seq}, expected {expected}")
            self._ack(link, peer, mtype, mav.MAV_MISSION_INVALID_SEQUENCE)
            return
        up.items.append(MissionItem.from_msg(msg))
        up.last_progress_s = now_s
        self._counters["items_received"] += 1
        if len(up.items) < up.count:
            self._request(link, up, now_s)
            return
        del self._transfers[link]
        items = tuple(up.items)
        try:
            payload = self._build(mtype, items)
        except ItemError as e:
            self._counters["uploads_rejected"] += 1
            self._text(link, f"{_TYPE_NAMES[mtype]} rejected: {e}")
            self._ack(link, peer, mtype, e.result)
            return
        self._replace(mtype, items, payload)
        self._counters["uploads_accepted"] += 1
        self._ack(link, peer, mtype, mav.MAV_MISSION_ACCEPTED)

    def _build(self, mtype: int, items: tuple[MissionItem, ...]) -> Any:
        if mtype == MISSION:
            return build_mission(items, self.origin, self._home_z_m, self._params)
        if mtype == FENCE:
            return build_geofence(items, self.origin, self._home_z_m)
        return build_rally(items, self.origin, self._home_z_m)

    def _replace(self, mtype: int, items: tuple[MissionItem, ...], payload: Any = None) -> None:
        """Make ``items`` the stored list of ``mtype`` and submit it to the simulation."""
        old = self._stores[mtype]
        if mtype == MISSION:
            plan = payload if items else None
            self._stores[mtype] = _Store(items=items, plan=plan)
            command = StoreMission(self.vehicle, plan.spec if plan is not None else None, source="mavlink")
            self._reached = -1
            self._last_step = -1
            self._last_state = MissionState.NONE
            self._last_current = None
        elif mtype == FENCE:
            self._stores[mtype] = _Store(items=items)
            command = SetGeofence(self.vehicle, payload if items else None, source="mavlink")
        else:
            self._stores[mtype] = _Store(items=items)
            command = SetRallyPoints(self.vehicle, tuple(payload) if items else (), source="mavlink")
        cid = self._submit(command)
        self._counters["commands_submitted"] += 1
        if cid:
            self._pending[cid] = (mtype, old)

    def _on_request_list(self, link: Any, peer: tuple[int, int], mtype: int, now_s: float) -> None:
        if mtype not in TYPES:
            self._ack(link, peer, mtype, mav.MAV_MISSION_UNSUPPORTED)
            return
        tr = self._transfers.get(link)
        if isinstance(tr, _Upload) and now_s - tr.last_progress_s < TIMEOUT_S:
            self._counters["denied_busy"] += 1
            self._ack(link, peer, mtype, mav.MAV_MISSION_DENIED)
            return
        items = self._stores[mtype].items
        link.send(mav.MAVLink_mission_count_message(peer[0], peer[1], len(items), mtype))
        self._counters["downloads"] += 1
        if items:
            self._transfers[link] = _Download(mission_type=mtype, items=items, peer=peer, last_progress_s=now_s)
        else:
            self._transfers.pop(link, None)

    def _on_request(self, msg: Any, link: Any, peer: tuple[int, int], mtype: int, now_s: float, as_int: bool) -> None:
        tr = self._transfers.get(link)
        if isinstance(tr, _Upload):
            return                                      # not during our own upload on this link
        items = tr.items if isinstance(tr, _Download) and tr.mission_type == mtype else (
            self._stores[mtype].items if mtype in TYPES else ())
        seq = int(msg.seq)
        if not 0 <= seq < len(items):
            self._counters["bad_requests"] += 1
            self._ack(link, peer, mtype, mav.MAV_MISSION_INVALID_SEQUENCE)
            return
        if isinstance(tr, _Download):
            tr.last_progress_s = now_s
        link.send(items[seq].to_msg(as_int, peer[0], peer[1]))
        self._counters["items_sent"] += 1

    def _on_clear(self, link: Any, peer: tuple[int, int], mtype: int) -> None:
        types = TYPES if mtype == mav.MAV_MISSION_TYPE_ALL else (mtype,) if mtype in TYPES else ()
        if not types:
            self._ack(link, peer, mtype, mav.MAV_MISSION_UNSUPPORTED)
            return
        for t in types:
            self._replace(t, ())
        self._counters["clears"] += 1
        self._ack(link, peer, mtype, mav.MAV_MISSION_ACCEPTED)

    def _on_set_current(self, msg: Any, link: Any) -> None:
        plan = self.plan
        seq = int(msg.seq)
        step = plan.step_of_seq(seq) if plan is not None else None
        if step is None:
            self._counters["bad_requests"] += 1
            total = plan.count if plan is not None else 0
            self._text(link, f"mission: no item {seq} (have {total})")
            return
        self._submit(SetMissionCurrent(self.vehicle, step, source="mavlink"))
        self._counters["set_current"] += 1
        self._counters["commands_submitted"] += 1
        self._reached = plan.steps[step].first - 1        # skipped items are not reported reached
        self._last_current = None                       # report the new current item at the next snapshot

    # ------------------------------------------------------------------ time
    def tick(self, now_s: float) -> None:
        """Re-request missing items and give up stalled transfers (wall clock [s])."""
        for link, tr in list(self._transfers.items()):
            if now_s - tr.last_progress_s >= TIMEOUT_S:
                del self._transfers[link]
                if isinstance(tr, _Upload):
                    self._counters["uploads_timed_out"] += 1
                    self._ack(link, tr.peer, tr.mission_type, mav.MAV_MISSION_OPERATION_CANCELLED)
                else:
                    self._counters["downloads_timed_out"] += 1
            elif isinstance(tr, _Upload) and now_s - tr.last_request_s >= RETRY_S:
                self._request(link, tr, now_s)
                self._counters["requests_resent"] += 1

    # ------------------------------------------------------------------ results and progress
    def on_result(self, result: CommandResult) -> None:
        """Result of a command this service submitted: a refused list brings the previous one back."""
        pending = self._pending.pop(result.command_id, None)
        if result.ok:
            self._counters["results_ok"] += 1
            return
        self._counters["results_refused"] += 1
        if pending is not None:
            mtype, old = pending
            self._stores[mtype] = old
            if mtype == MISSION:
                self._last_current = None

    def on_snapshot(self, snap: Snapshot, row: int, links: Sequence[Any]) -> None:
        """Remember home and parameters; send MISSION_CURRENT (on change, 1 Hz) and MISSION_ITEM_REACHED."""
        arrays = snap.arrays
        if "home_set" in arrays and bool(arrays["home_set"][row]):
            self._home_z_m = float(arrays["home_enu_m"][row][2])
        params = snap.params.get(self.vehicle) if snap.params else None
        if params is not None:
            self._params = dict(params)
        plan = self.plan
        total = plan.count if plan is not None else 0
        state = MissionState(int(arrays["mission_state"][row])) if "mission_state" in arrays else MissionState.NONE
        step = int(arrays["mission_step"][row]) if "mission_step" in arrays else -1
        in_mission = "nav_state" in arrays and int(arrays["nav_state"][row]) == NavState.MISSION
        if plan is None or not plan.steps:
            seq, mstate = 0, (mav.MISSION_STATE_NO_MISSION if total == 0 else mav.MISSION_STATE_NOT_STARTED)
        else:
            seq, mstate = self._progress(plan, state, step, arrays, row, links)
        mode = 1 if in_mission else 2
        current = (seq, total, mstate, mode)
        if current != self._last_current or snap.sim_time_s - self._last_current_t >= CURRENT_PERIOD_S - 1e-9:
            for link in links:
                link.send(mav.MAVLink_mission_current_message(seq, total, mstate, mode))
            self._counters["mission_current_sent"] += 1
            self._last_current = current
            self._last_current_t = snap.sim_time_s

    def _progress(self, plan: MissionPlan, state: MissionState, step: int, arrays: Any, row: int,
                  links: Sequence[Any]) -> tuple[int, int]:
        """(current seq, MISSION_STATE); reports reached items on the way."""
        last_seq = plan.count - 1
        if state == MissionState.RUNNING and 0 <= step < len(plan.steps):
            if step < self._last_step or (self._last_state != MissionState.RUNNING
                                          and self._last_state != MissionState.PAUSED
                                          and step == 0):
                self._reached = plan.steps[step].first - 1    # (re)started: report again from here
            self._last_step = step
            entry = plan.steps[step]
            self._reach(entry.first - 1, links)              # every step before this one is done
            # waypoints of this step reached by position
            pos = np.asarray(arrays["pos_enu_m"][row], dtype=np.float64) if "pos_enu_m" in arrays else None
            acc = float(self._params.get("NAV_ACC_RAD", 10.0))
            alt = float(self._params.get("NAV_MC_ALT_RAD", 0.8))
            seq = entry.first
            for k, (nav_seq, target) in enumerate(entry.nav):
                if nav_seq <= self._reached:
                    continue
                if (k + 1 < len(entry.nav) and target is not None and pos is not None
                        and math.hypot(pos[0] - target[0], pos[1] - target[1]) <= acc
                        and abs(pos[2] - target[2]) <= alt):
                    # a waypoint inside a cruise step, and the DO items after it (the step's last
                    # NAV item is reached when the step is done)
                    self._reach(entry.nav[k + 1][0] - 1, links)
                    continue
                seq = nav_seq
                break
            else:
                seq = entry.nav[-1][0] if entry.nav else entry.first
            seq = max(seq, min(self._reached + 1, entry.last))
            mstate = mav.MISSION_STATE_ACTIVE
        elif state == MissionState.COMPLETED:
            self._reach(last_seq, links)
            seq, mstate = last_seq, mav.MISSION_STATE_COMPLETE
        else:
            mstate = _MISSION_STATE.get(state, mav.MISSION_STATE_NOT_STARTED)
            if 0 <= self._last_step < len(plan.steps) and state in (MissionState.PAUSED, MissionState.FAILED):
                seq = max(plan.steps[self._last_step].first, min(self._reached + 1, last_seq))
            else:
                seq = 0
        self._last_state = state
        return seq, mstate

    def _reach(self, upto: int, links: Sequence[Any]) -> None:
        """Report MISSION_ITEM_REACHED for every item after the last reported, up to ``upto``."""
        while self._reached < upto:
            self._reached += 1
            for link in links:
                link.send(mav.MAVLink_mission_item_reached_message(self._reached))
            self._counters["item_reached_sent"] += 1

    def counters(self) -> dict[str, int]:
        """Figures for the run summary."""
        return dict(self._counters)


__all__ = ["CURRENT_PERIOD_S", "RETRY_S", "TIMEOUT_S", "MissionService"]
