"""Flight parameters of a drone, with PX4's names, units, defaults and ranges (docs/architecture.md §7).

These are the parameters the navigator honours (takeoff altitude, cruise speed, RTL altitudes, land
detector thresholds, failsafe timeouts, follow-target geometry...). Each drone carries a
:class:`FlightParams` component holding its values: the defaults below, overridden per drone in the
world file (``flight_params: {MIS_TAKEOFF_ALT: 5}``), changed at run time by :class:`SetParam`
commands (``Simulation.set_param``, MAVLink PARAM_SET). MAVLink's PARAM protocol lists them in the
order of :data:`PX4_PARAMS` (that order is the parameter index). Values are floats; ``is_int``
parameters hold whole numbers (MAVLink type INT32).

Defaults and ranges are PX4 v1.15's (``*_params.yaml`` / ``*_params.c`` of the modules named in each
entry), except where an entry says otherwise.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Mapping


@dataclass(frozen=True, slots=True)
class ParamDef:
    """One parameter: name (≤ 16 characters, MAVLink's limit), default, closed range, unit, meaning."""

    name: str
    default: float
    lo: float
    hi: float
    unit: str = ""
    description: str = ""
    is_int: bool = False

    def check(self, value: float) -> str:
        """"" when ``value`` is acceptable, else why not (NaN, out of range, not a whole number)."""
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            return f"{self.name} must be a finite number, got {value!r}"
        if not self.lo <= value <= self.hi:
            return f"{self.name} must be in [{self.lo:g}, {self.hi:g}] {self.unit}".rstrip() + f", got {value:g}"
        if self.is_int and value != int(value):
            return f"{self.name} must be a whole number, got {value:g}"
        return ""


def _p(name: str, default: float, lo: float, hi: float, unit: str, description: str, is_int: bool = False) -> ParamDef:
    return ParamDef(name, float(default), float(lo), float(hi), unit, description, is_int)


# The order is the MAVLink parameter index: append, never reorder.
PX4_PARAMS: tuple[ParamDef, ...] = (
    # navigator / position control (mc_pos_control, navigator)
    _p("MIS_TAKEOFF_ALT", 2.5, 0.0, 10000.0, "m", "takeoff altitude above home (TAKEOFF mode, MAVLink takeoff without an altitude)"),
    _p("MPC_XY_CRUISE", 5.0, 3.0, 20.0, "m/s", "horizontal cruise speed of automatic modes (missions, RTL, goto)"),
    _p("MPC_XY_VEL_MAX", 12.0, 0.0, 20.0, "m/s", "horizontal speed limit (offboard position, POSCTL full stick)"),
    _p("MPC_TKO_SPEED", 1.5, 1.0, 5.0, "m/s", "climb speed of a takeoff"),
    _p("MPC_Z_V_AUTO_UP", 3.0, 0.5, 8.0, "m/s", "climb speed of automatic modes"),
    _p("MPC_Z_V_AUTO_DN", 1.5, 0.5, 4.0, "m/s", "descent speed of automatic modes"),
    _p("MPC_LAND_SPEED", 0.7, 0.6, 4.0, "m/s", "descent speed of the last MPC_LAND_ALT2 metres of a landing"),
    _p("MPC_LAND_ALT2", 5.0, 0.0, 122.0, "m", "height above ground below which a landing slows to MPC_LAND_SPEED"),
    _p("MPC_YAWRAUTO_MAX", 60.0, 5.0, 360.0, "deg/s", "yaw rate limit of automatic modes"),
    _p("NAV_ACC_RAD", 10.0, 0.05, 200.0, "m", "horizontal acceptance radius of a mission waypoint"),
    _p("NAV_MC_ALT_RAD", 0.8, 0.05, 200.0, "m", "vertical acceptance radius of a mission waypoint"),
    _p("RTL_RETURN_ALT", 60.0, 0.0, 150.0, "m", "RTL climbs to this height above the destination before flying back"),
    _p("RTL_DESCEND_ALT", 30.0, 0.0, 100.0, "m", "RTL descends to this height above the destination before landing"),
    _p("RTL_LAND_DELAY", 0.0, -1.0, 300.0, "s", "RTL waits this long at RTL_DESCEND_ALT before landing (-1: hover, never land)"),
    _p("RTL_TYPE", 0, 0, 0, "", "RTL destination: 0 = the closest of home and the rally points (the only type we fly)", True),
    # commander: arming, disarming, failsafes
    _p("COM_DISARM_LAND", 2.0, -1.0, 20.0, "s", "disarm this long after touchdown (-1: never)"),
    _p("COM_DISARM_PRFLT", 10.0, -1.0, 20.0, "s", "disarm this long after arming when it never took off (-1: never)"),
    _p("COM_OF_LOSS_T", 1.0, 0.0, 60.0, "s", "OFFBOARD lapses when no setpoint arrives for this long"),
    _p("COM_OBL_RC_ACT", 0, 0, 7, "", "action when OFFBOARD lapses: 0 position (HOLD), 3 return, 4 land, 5 hold, 7 disarm when landed", True),
    _p("COM_RC_LOSS_T", 0.5, 0.0, 35.0, "s", "manual control (sticks) is lost after this long without MANUAL_CONTROL"),
    _p("COM_FAIL_ACT_T", 5.0, 0.0, 25.0, "s", "hold this long after the sticks are lost before NAV_RCL_ACT"),
    _p("NAV_RCL_ACT", 2, 1, 6, "", "action when the sticks stay lost: 1 hold, 2 return, 3 land, 5 terminate, 6 disarm", True),
    _p("COM_LOW_BAT_ACT", 0, 0, 3, "", "arming refused below the low-battery threshold; 0 warn only in flight", True),
    # land detector (land_detector_params_mc.yaml)
    _p("LNDMC_Z_VEL_MAX", 0.25, 0.0, 5.0, "m/s", "landed only below this vertical speed"),
    _p("LNDMC_XY_VEL_MAX", 1.5, 0.0, 10.0, "m/s", "landed only below this horizontal speed"),
    _p("LNDMC_ROT_MAX", 20.0, 0.0, 180.0, "deg/s", "landed only below this body rotation rate"),
    # geofence (navigator/geofence_params.yaml)
    _p("GF_ACTION", 2, 0, 5, "", "geofence breach: 0 none, 1 warning, 2 hold, 3 return, 4 terminate, 5 land", True),
    _p("GF_MAX_HOR_DIST", 0.0, 0.0, 10000.0, "m", "maximum horizontal distance from home (0: no limit)"),
    _p("GF_MAX_VER_DIST", 0.0, 0.0, 10000.0, "m", "maximum height above home (0: no limit)"),
    # follow target (flight_mode_manager follow_target_params.c)
    _p("FLW_TGT_HT", 8.0, 8.0, 1000.0, "m", "follow height above home"),
    _p("FLW_TGT_DST", 8.0, 1.0, 100.0, "m", "horizontal distance kept to the target"),
    _p("FLW_TGT_FA", 180.0, -180.0, 180.0, "deg", "angle around the target, clockwise from its course (180: behind)"),
    _p("FLW_TGT_RS", 0.1, 0.0, 1.0, "", "responsiveness to target motion (0 smooth .. 1 immediate)"),
    _p("FLW_TGT_MAX_VEL", 5.0, 0.0, 20.0, "m/s", "speed limit of the follower relative to the target"),
    _p("FLW_TGT_ALT_M", 0, 0, 2, "", "altitude mode: 0 constant height above home, 1 track terrain, 2 track target", True),
)

PARAM_BY_NAME: Mapping[str, ParamDef] = MappingProxyType({p.name: p for p in PX4_PARAMS})


def default_values() -> dict[str, float]:
    """Every parameter at its default, in index order."""
    return {p.name: p.default for p in PX4_PARAMS}


def check_param(name: str, value: float) -> str:
    """"" when ``name`` is a parameter and ``value`` fits it, else why not."""
    spec = PARAM_BY_NAME.get(name)
    if spec is None:
        return f"unknown flight parameter {name!r}"
    return spec.check(value)


@dataclass(slots=True)
class FlightParams:
    """A drone's flight parameter values (name -> value, every name of :data:`PX4_PARAMS`).

    Written only on the simulation thread (by the command that sets one); ``version`` counts the
    changes so transports can tell when to re-read.
    """

    values: dict[str, float] = field(default_factory=default_values)
    version: int = 0

    def __getitem__(self, name: str) -> float:
        return self.values[name]

    def set(self, name: str, value: float) -> str:
        """Set one parameter; returns "" or why it was refused (nothing changed then)."""
        error = check_param(name, value)
        if not error:
            self.values[name] = float(value)
            self.version += 1
        return error


def _spec_post_init(self: object) -> None:
    from ..config.schema import FieldError

    for p in PX4_PARAMS:
        value = getattr(self, p.name)
        if value is not None and p.is_int and value != int(value):
            raise FieldError(p.name, f"must be a whole number, got {value:g}")


def _make_spec() -> type:
    from typing import Annotated

    from ..config.schema import Ge, Le

    fields = [(p.name, Annotated[float, Ge(p.lo), Le(p.hi)] | None, field(default=None)) for p in PX4_PARAMS]
    return dataclasses.make_dataclass("FlightParamsSpec", fields, frozen=True, kw_only=True,
                                      namespace={"__post_init__": _spec_post_init, "__module__": __name__,
                                                 "__doc__": _SPEC_DOC})


_SPEC_DOC = """World-file overrides of a drone's flight parameters (world-file key ``flight_params``):
``flight_params: {MIS_TAKEOFF_ALT: 5, RTL_RETURN_ALT: 30}``. One optional field per parameter of
:data:`PX4_PARAMS`, each within its PX4 range; a name that is not a parameter, or a value out of range,
is an error naming the file, line and key. Parameters not given keep their defaults."""

FlightParamsSpec = _make_spec()


def params_from_spec(spec: object | None) -> FlightParams:
    """A drone's FlightParams: the defaults, overridden by the world file's ``flight_params`` (may be None)."""
    params = FlightParams()
    if spec is not None:
        for p in PX4_PARAMS:
            value = getattr(spec, p.name)
            if value is not None:
                params.values[p.name] = float(value)
    return params


__all__ = ["FlightParams", "FlightParamsSpec", "PARAM_BY_NAME", "PX4_PARAMS", "ParamDef", "check_param",
           "default_values", "params_from_spec"]
