"""OUTPUTS phase: publish this step's sensor, odometry and TF messages and ``/clock`` over ROS 2."""

from __future__ import annotations

import esper

from ..phases import Phase
from ..sensors.messages import msg_type, stamp
from ..world import StepContext


class Ros2PublisherSystem(esper.Processor):
    """Hands every message of this step to the ROS 2 backend, plus ``/clock`` each step.

    Phase: OUTPUTS (order 50, after the sensors and TF). Reads: ``services.sensors.this_step``.
    A message that cannot be published is reported once per topic in the event log; the
    simulation goes on.
    """

    phase = Phase.OUTPUTS
    order = 50

    def __init__(self, backend) -> None:
        self.backend = backend
        self._failed: set[str] = set()

    def process(self, ctx: StepContext) -> None:
        clock = msg_type("rosgraph_msgs/msg/Clock")(clock=stamp(ctx.sim_time_s + ctx.dt_s))
        self._publish(ctx, "/clock", clock)
        for sample in ctx.services.sensors.this_step:
            self._publish(ctx, sample.topic, sample.msg)

    def _publish(self, ctx: StepContext, topic: str, msg) -> None:
        try:
            self.backend.publish(topic, msg)
        except Exception as exc:  # a transport failure must not stop the simulation
            if topic not in self._failed:
                self._failed.add(topic)
                ctx.services.note(ctx.sim_time_s, "", f"ROS 2: cannot publish {topic}: {type(exc).__name__}: {exc}")


__all__ = ["Ros2PublisherSystem"]
