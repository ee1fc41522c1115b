"""Mission runtime state of one drone (event state: changes a few times per mission, never per step maths)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any


@dataclass(slots=True)
class MissionRuntime:
    """Where a drone is in its mission.

    state : "stored" (uploaded, not started) | "running" | "paused" (a mode switch or PauseMission; MISSION
        mode or PauseMission(resume) continues it) | "completed" | "failed" | "cancelled"; the fleet array
        ``mission_state`` mirrors it (MissionState)
    stage : "wait_before" | "active" | "wait_after" within the current step
    reason : why the mission failed or was cancelled ("" otherwise), e.g. "overweight", "low_battery"
    scratch : per-step working values of the state machine (sub-stage, timers, targets; ``takeoff_first``
        when a mission started on the ground climbs before its first step, as PX4 does)
    """

    spec: Any                       # unetyemu_ecs.mission.MissionSpec
    step_index: int = 0
    stage: str = "wait_before"
    stage_started_s: float = 0.0
    state: str = "running"
    reason: str = ""
    scratch: dict[str, Any] = field(default_factory=dict)

    def status(self) -> dict[str, Any]:
        """JSON-ready status: mission name, step index and type, state, stage, reason."""
        steps = self.spec.steps
        idx = min(self.step_index, len(steps) - 1)
        return {
            "mission": self.spec.name,
            "step": self.step_index if self.state == "running" else idx,
            "step_type": steps[idx].type,
            "steps": len(steps),
            "state": self.state,
            "stage": self.stage,
            "reason": self.reason,
        }
