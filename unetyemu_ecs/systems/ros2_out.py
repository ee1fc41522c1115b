"""OUTPUTS phase: the simulation's side of ROS 2 — publish this step's messages, ``/clock``, mission
status and command rejections (``/rosout``)."""

from __future__ import annotations

import json
import queue

import esper

from ..components.body import Identity
from ..components.mission import MissionRuntime
from ..phases import Phase
from ..sensors.messages import msg_type, stamp
from ..world import StepContext

STATUS_HZ = 10.0            # how often mission status is checked (published when it changes)
IDLE_STATUS = {"mission": None, "state": "idle"}      # a drone without a mission
ROSOUT_WARN = 30            # rcl_interfaces/Log WARN
NODE_NAME = "unetyemu_sim"


class Ros2PublisherSystem(esper.Processor):
    """Hands every message of this step to the ROS 2 backend, and more.

    Phase: OUTPUTS (order 50, after the sensors and TF). Publishes: every sample of
    ``services.sensors.this_step`` on its topic, ``/clock`` each step, ``/<v>/mission/status``
    (std_msgs/String JSON, latched: TransientLocal, KeepLast(1)) for every drone at the first step
    (``{"mission": null, "state": "idle"}`` without a mission) and whenever it changes (and
    ``{"state": "rejected", "reason": ...}`` when a mission sent over ROS 2 is rejected), and
    every rejected command as a WARN on ``/rosout`` (TransientLocal, KeepLast(1000), as rcl
    writes it; also in the event log). Samples marked ``ros2=False`` (a sensor or vehicle
    switched off ROS 2 in the world file) and the mission status of ``hidden`` vehicles stay local.
    Rejections found on the transport's thread arrive through ``notices`` (a thread-safe queue of
    ``(vehicle, topic, reason)``). A message that cannot be published is reported once per topic in
    the event log; the simulation goes on.
    """

    phase = Phase.OUTPUTS
    order = 50

    def __init__(self, backend, notices: queue.SimpleQueue | None = None,
                 hidden: frozenset[str] = frozenset()) -> None:
        self.backend = backend
        self.hidden = hidden                       # vehicles off ROS 2 (world file ``ros2: false``)
        self.notices = notices if notices is not None else queue.SimpleQueue()
        self._failed: set[str] = set()
        self._events_seen = 0
        self._status: dict[str, str] = {}
        self._next_status_s = 0.0

    def process(self, ctx: StepContext) -> None:
        t = ctx.sim_time_s + ctx.dt_s
        while True:
            try:
                vehicle, topic, reason = self.notices.get_nowait()
            except queue.Empty:
                break
            ctx.services.note(ctx.sim_time_s, vehicle, f"rejected {topic}: {reason}")
            if topic.endswith("/mission"):
                # say it where mission progress is watched too; the running mission's status follows
                # again at the next status check (it is no longer "unchanged")
                text = json.dumps({"mission": None, "state": "rejected", "reason": reason}, sort_keys=True)
                self._publish(ctx, f"{topic}/status", msg_type("std_msgs/msg/String")(data=text))
                self._status.pop(vehicle, None)
        self._publish(ctx, "/clock", msg_type("rosgraph_msgs/msg/Clock")(clock=stamp(t)))
        for sample in ctx.services.sensors.this_step:
            if sample.ros2:
                self._publish(ctx, sample.topic, sample.msg)
        events = ctx.services.events
        for _, vehicle, text in events[self._events_seen:]:
            if text.startswith("rejected"):
                log = msg_type("rcl_interfaces/msg/Log")(stamp=stamp(t), level=ROSOUT_WARN, name=NODE_NAME,
                                                         msg=f"{vehicle}: {text}", file="", function="", line=0)
                self._publish(ctx, "/rosout", log)
        self._events_seen = len(events)
        if t + 1e-9 >= self._next_status_s:
            self._next_status_s = t + 1.0 / STATUS_HZ
            String = msg_type("std_msgs/msg/String")
            for ent, ident in esper.get_component(Identity):
                if ident.kind != "quadrotor" or ident.name in self.hidden:
                    continue
                rt = esper.try_component(ent, MissionRuntime)
                text = json.dumps(rt.status() if rt is not None else IDLE_STATUS, sort_keys=True)
                if self._status.get(ident.name) != text:
                    self._status[ident.name] = text
                    self._publish(ctx, f"/{ident.name}/mission/status", String(data=text))

    def _publish(self, ctx: StepContext, topic: str, msg) -> None:
        try:
            self.backend.publish(topic, msg)
        except Exception as exc:  # a transport failure must not stop the simulation
            if topic not in self._failed:
                self._failed.add(topic)
                ctx.services.note(ctx.sim_time_s, "", f"ROS 2: cannot publish {topic}: {type(exc).__name__}: {exc}")


__all__ = ["Ros2PublisherSystem"]
