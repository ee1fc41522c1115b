"""Per-drone navigator state: what the PX4-style mode in charge is doing (event state, a few changes per flight).

The fleet arrays (``nav_state``, ``landed_state``, ``home_enu_m`` ...) are what transports read; this
component holds the navigator's working values behind them: the phase of a TAKEOFF, LAND or RTL, the
timers of the land detector and of auto-disarm, rally points, the OFFBOARD stream.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np


@dataclass(slots=True)
class NavRuntime:
    """Working state of one drone's navigator.

    mode : the navigator-flown mode in progress: "" (none: HOLD, GOTO, a mission, a stream), "takeoff",
        "land" or "rtl"
    phase : within ``mode``: takeoff "climb"; land "descend" / "landed"; rtl "return" / "delay" / "land" /
        "landed"
    goal_enu_m : where ``mode`` ends (takeoff: the altitude point; land / rtl: the touchdown point)
    phase_started_s : sim time the phase began [s]
    took_off : left the ground since it was armed (COM_DISARM_LAND applies, not COM_DISARM_PRFLT)
    armed_s : sim time of arming [s] (NaN: disarmed)
    contact_since_s : since when the land-detector conditions hold [s] (NaN: they do not)
    ground_since_s : since when the drone is ON_GROUND [s] (NaN: it is not)
    rally_enu_m : rally points, ENU [m]; RTL goes to the closest of these and home
    speeds : ChangeSpeed overrides of the automatic modes, "ground" / "climb" / "descent" -> m/s
    offboard : the newest OFFBOARD setpoint (an OffboardSetpoint) and the sim time it arrived
    manual : the newest ManualControl sticks and the sim time they arrived (POSCTL / MANUAL)
    orbit : the Orbit command being flown (mode "orbit")
    follow : the newest FollowTargetFix and its sim time; follow_sp_enu_m the filtered follow setpoint
    fence : the geofence (navigation.geofence.Geofence, None: none); fence_ok whether the last check passed;
        fence_enabled False: neither enforced nor checked at arming (MAV_CMD_DO_FENCE_ENABLE 0)
    """

    mode: str = ""
    phase: str = ""
    goal_enu_m: np.ndarray | None = None
    phase_started_s: float = 0.0
    took_off: bool = False
    armed_s: float = math.nan
    contact_since_s: float = math.nan
    ground_since_s: float = math.nan
    rally_enu_m: tuple[tuple[float, float, float], ...] = ()
    speeds: dict[str, float] = field(default_factory=dict)
    offboard: Any = None
    offboard_s: float = -math.inf
    manual: Any = None
    manual_s: float = -math.inf
    orbit: Any = None
    follow: Any = None
    follow_s: float = -math.inf
    follow_sp_enu_m: np.ndarray | None = None
    follow_course_rad: float = 0.0
    fence: Any = None
    fence_ok: bool = True
    fence_enabled: bool = True


__all__ = ["NavRuntime"]
