"""Mission definitions: the schema of our mission JSON (docs/architecture.md §5), as frozen dataclasses.

A mission is a list of steps (``takeoff``, ``cruise``, ``land``, ``pickup``, ``deliver``,
``recharge``, ``idle``, ``return``) run in order by the MISSION-phase state machine
(:mod:`unetyemu_ecs.systems.mission`). Each step waits ``wait_before`` seconds, does its job, then
waits ``wait_after`` seconds.

Frames and units at this edge: positions in world ENU metres (z is height above the world's ground
plane z = 0), speeds in m/s, yaw in degrees ENU (0 = east, counter-clockwise positive; REP-103).
The engine converts yaw to radians when it builds a route.

The type hints are the schema: :func:`unetyemu_ecs.config.schema.convert` checks the ``Annotated``
markers (and speed caps) when a mission is parsed, and each class's ``__post_init__`` checks the
rules that span fields, raising :class:`~unetyemu_ecs.config.schema.FieldError` so the message
names the step and field. Constructing these classes directly in Python runs only the
``__post_init__`` rules; parse text with :func:`unetyemu_ecs.mission.parse_mission`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Annotated, Literal, get_args

from ..config.limits import MAX_DURATION_S, MAX_MISSION_STEPS, MAX_WAIT_S, MAX_WAYPOINTS, XM, ZM, Deg, Name, MAX_Z_M
from ..config.schema import FieldError, Ge, Gt, Le, MaxLen, NonEmpty

StepType = Literal["takeoff", "cruise", "land", "pickup", "deliver", "recharge", "idle", "return"]
STEP_TYPES: tuple[str, ...] = get_args(StepType)

# Speed caps of a mission (docs/architecture.md §5). Exceeding one is an error, never a
# silent clamp; the guidance layer may still fly slower (GuidanceLimits.lim_climb_m_s etc.).
MAX_CRUISE_SPEED_M_S = 30.0
MAX_CLIMB_SPEED_M_S = 8.0
MAX_DESCENT_SPEED_M_S = 5.0

# Waits within a step: up to a day (config.limits.MAX_WAIT_S).
Wait = Annotated[float, Ge(0), Le(MAX_WAIT_S)]   # [s]

CruiseSpeed = Annotated[float, Gt(0), Le(MAX_CRUISE_SPEED_M_S)]      # [m/s]
ClimbSpeed = Annotated[float, Gt(0), Le(MAX_CLIMB_SPEED_M_S)]        # [m/s]
DescentSpeed = Annotated[float, Gt(0), Le(MAX_DESCENT_SPEED_M_S)]    # [m/s]


@dataclass(frozen=True, kw_only=True)
class Waypoint:
    """One point of a route, ENU metres; speeds left as None fall back to the mission's defaults."""

    # within the world's extent (config.limits): |x|, |y| <= 20 km, z in [-100, 10 000] m
    x: XM                                      # east [m]
    y: XM                                      # north [m]
    z: ZM                                      # height above the world's ground plane z = 0 [m]
    yaw_deg: Deg | None = None                 # ENU yaw [deg], 0 = east, CCW; None: guidance decides
    cruise_speed: CruiseSpeed | None = None    # horizontal speed [m/s]
    climb_speed: ClimbSpeed | None = None      # [m/s]
    descent_speed: DescentSpeed | None = None  # [m/s]


# Which optional fields each step type uses; a field set to a non-default value on a step type that
# does not use it is an error (it would be silently ignored by the state machine otherwise).
_USES: dict[str, frozenset[str]] = {
    "takeoff": frozenset({"waypoints", "altitude_m"}),
    "cruise": frozenset({"waypoints", "pad"}),
    "land": frozenset({"waypoints", "pad"}),
    "pickup": frozenset({"waypoints", "package"}),
    "deliver": frozenset({"waypoints", "pad"}),
    "recharge": frozenset({"waypoints", "pad", "duration_s", "target_soc_frac", "charge_power_w"}),
    "idle": frozenset({"duration_s"}),
    "return": frozenset(),
}
# Step types that go to (at most) one place: the state machine reads a single waypoint.
_ONE_PLACE = frozenset({"takeoff", "land", "pickup", "deliver", "recharge"})


@dataclass(frozen=True, kw_only=True)
class MissionStep:
    """One step of a mission; which optional fields apply depends on ``type``.

    takeoff  : climb to ``altitude_m`` above the ground under the drone, or to the one waypoint
               given; neither: the vehicle's ``GuidanceLimits.takeoff_altitude_m`` (10 m in
               ``vehicles/params/quadrotor.toml``).
    cruise   : fly the waypoints in order (pure pursuit), then over ``pad`` if one is named.
    land     : land at the waypoint's (x, y), on ``pad``, or where the drone is.
    pickup   : fly to the waypoint (if any), grab ``package`` (None: the nearest within reach).
    deliver  : land as ``land`` does, then release the carried package.
    recharge : land as ``land`` does (if airborne), charge to ``target_soc_frac`` at
               ``charge_power_w`` (None: the vehicle's charger), for at most ``duration_s``.
    idle     : hold (hover, or stay on the ground) for ``duration_s``.
    return   : PX4's RTL: climb to RTL_RETURN_ALT above the closest of home and the rally points, fly
               there at MPC_XY_CRUISE, descend to RTL_DESCEND_ALT, land and disarm (the drone's
               flight parameters, ``navigation.params``).
    """

    type: StepType
    wait_before: Wait = 0.0                                       # [s]
    wait_after: Wait = 0.0                                        # [s]
    waypoints: Annotated[list[Waypoint], MaxLen(MAX_WAYPOINTS)] = field(default_factory=list)
    altitude_m: Annotated[float, Gt(0), Le(MAX_Z_M)] | None = None   # takeoff: height above the ground [m]
    package: Name | None = None                                   # pickup: package name; None = nearest
    pad: Name | None = None                                       # land/deliver/cruise/recharge: named pad
    # idle: how long; recharge: max time [s]; at most a week (config.limits.MAX_DURATION_S)
    duration_s: Annotated[float, Ge(0), Le(MAX_DURATION_S)] | None = None
    target_soc_frac: Annotated[float, Gt(0), Le(1)] = 1.0         # recharge: stop at this state of charge
    # recharge; None = vehicle's charger [W]; 1 MW is a megawatt truck charger, far above any drone's
    charge_power_w: Annotated[float, Gt(0), Le(1e6)] | None = None

    def __post_init__(self) -> None:
        if self.type not in _USES:
            # convert() rejects this before construction; this guards Python callers
            raise FieldError("type", f"unknown step type {self.type!r} (expected one of: {', '.join(STEP_TYPES)})")
        uses = _USES[self.type]
        given = {
            "waypoints": bool(self.waypoints),
            "altitude_m": self.altitude_m is not None,
            "package": self.package is not None,
            "pad": self.pad is not None,
            "duration_s": self.duration_s is not None,
            "target_soc_frac": self.target_soc_frac != 1.0,
            "charge_power_w": self.charge_power_w is not None,
        }
        for name, is_set in given.items():
            if is_set and name not in uses:
                users = sorted(t for t, u in _USES.items() if name in u)
                raise FieldError(name, f"not used by a {self.type} step (used by: {', '.join(users)})")
        if self.type in _ONE_PLACE and len(self.waypoints) > 1:
            raise FieldError("waypoints", f"a {self.type} step takes at most 1 waypoint, got {len(self.waypoints)}"
                             + (" (use a cruise step for a route)" if self.type != "cruise" else ""))
        if self.type == "cruise" and not self.waypoints and self.pad is None:
            raise FieldError("waypoints", "a cruise step needs at least 1 waypoint or a pad")
        if self.type == "takeoff" and self.waypoints and self.altitude_m is not None:
            raise FieldError("altitude_m", "give either altitude_m or a waypoint for a takeoff step, not both")
        if self.type in ("land", "deliver", "recharge") and self.waypoints and self.pad is not None:
            raise FieldError("pad", f"give either a waypoint or a pad for a {self.type} step, not both")
        if self.type == "idle" and self.duration_s is None:
            raise FieldError("duration_s", "an idle step needs duration_s")


@dataclass(frozen=True, kw_only=True)
class MissionSpec:
    """A whole mission: default speeds for waypoints that give none, and the steps in order."""

    name: Name = "mission"
    cruise_speed: CruiseSpeed = 5.0       # [m/s]
    climb_speed: ClimbSpeed = 3.0         # [m/s]
    descent_speed: DescentSpeed = 1.5     # [m/s]
    steps: Annotated[list[MissionStep], NonEmpty(), MaxLen(MAX_MISSION_STEPS)]   # refused before parsing the steps


__all__ = [
    "MAX_CLIMB_SPEED_M_S",
    "MAX_CRUISE_SPEED_M_S",
    "MAX_DESCENT_SPEED_M_S",
    "STEP_TYPES",
    "MissionSpec",
    "MissionStep",
    "StepType",
    "Waypoint",
]
