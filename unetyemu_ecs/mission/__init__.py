"""Missions: definitions, loading (ours and the paper's format) and world references (pure: no esper, no PyBullet)."""

from __future__ import annotations

from .loader import MOVEMENT_STEP_TYPES, mission_to_json, parse_mission, unity_to_enu_m, unity_yaw_to_enu_deg
from .refs import mission_reference_issues
from .spec import (MAX_CLIMB_SPEED_M_S, MAX_CRUISE_SPEED_M_S, MAX_DESCENT_SPEED_M_S, STEP_TYPES, MissionSpec,
                   MissionStep, StepType, Waypoint)

__all__ = [
    "MAX_CLIMB_SPEED_M_S",
    "MAX_CRUISE_SPEED_M_S",
    "MAX_DESCENT_SPEED_M_S",
    "MOVEMENT_STEP_TYPES",
    "STEP_TYPES",
    "MissionSpec",
    "MissionStep",
    "StepType",
    "Waypoint",
    "mission_reference_issues",
    "mission_to_json",
    "parse_mission",
    "unity_to_enu_m",
    "unity_yaw_to_enu_deg",
]
