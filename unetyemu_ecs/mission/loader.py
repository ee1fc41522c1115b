"""Parse mission text (ours, or the paper's Unity format) into a :class:`MissionSpec`, and back.

Our format (docs/architecture.md §5; the schema is :mod:`unetyemu_ecs.mission.spec`)
-------------------------------------------------------------------------
A JSON object ``{"name": ..., "cruise_speed": ..., "climb_speed": ..., "descent_speed": ...,
"steps": [...]}``, or a bare JSON list of steps. Each step is
``{"type": "takeoff"|"cruise"|"land"|"pickup"|"deliver"|"recharge"|"idle"|"return", "wait_before": s,
"wait_after": s, "waypoints": [{"x", "y", "z", "yaw_deg", "cruise_speed", "climb_speed",
"descent_speed"}], "altitude_m", "package", "pad", "duration_s", "target_soc_frac",
"charge_power_w"}`` in ENU metres, m/s and degrees (0 = east, counter-clockwise). YAML is accepted
too (JSON is YAML), except anchors and aliases.

The paper's format (UNetyEmuROS, Unity), as we define it
--------------------------------------------------------
A JSON list of items, or ``{"missions": [...]}``, or ``{"steps": [...]}`` (optionally with a
``"name"``); it is recognised by ``"missions"`` or by ``movementId`` in the steps. Each item::

    {"movementId": int, "x": float, "y": float, "z": float,
     "yaw": float (optional, degrees), "speed": float (optional, m/s),
     "waitBefore": float (optional, s), "waitAfter": float (optional, s)}

``movementId``: 1 cruise, 2 takeoff, 3 land, 4 pickup, 5 deliver; any other id is an error naming
the item. Unknown keys are errors, as in our format.

Axes: Unity is left-handed with x right, y up, z forward; the scene's forward is north, so Unity
(x, y, z) is ENU (x, z, y). Yaw is clockwise from forward (a compass heading), so
``yaw_deg = 90 - yaw`` wrapped to (-180, 180]: Unity 0 -> 90, 90 -> 0, 180 -> -90.

Conversion:

- every item becomes one waypoint at its converted position;
- a takeoff item's y (height) is the target altitude: the takeoff step's waypoint is (x, z, y);
- a land item is the landing point; pickup and deliver items carry their location, which the
  drone flies to first (pickup takes the nearest package there);
- ``speed`` becomes the waypoint's climb_speed on takeoff, descent_speed on land, cruise_speed
  otherwise; each is capped as in our format (an excess is an error, not a clamp);
- consecutive cruise items merge into ONE cruise step (the Unity planner flies a run of cruise
  points as one route). A wait splits the run, because the drone has to stop there: an item with
  ``waitAfter`` > 0 ends its cruise step, an item with ``waitBefore`` > 0 starts a new one. The
  merged step waits the first item's ``waitBefore`` and the last item's ``waitAfter``.

Errors
------
Every problem is a :class:`~unetyemu_ecs.config.schema.ConfigError` listing all issues with the
source name, the line and the key path (``mission:5: steps[2].waypoints[0].z: expected a number,
got string 'high'``). A bare list is reported as ``steps[i]``. Syntax errors, duplicate keys and
non-finite numbers (JSON ``NaN``/``Infinity``, YAML ``.nan``/``.inf``) are ConfigErrors too; a bad
mission is rejected whole.
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass
from typing import Annotated, Any

from ..config.limits import (MAX_MISSION_NESTING, MAX_MISSION_NODES, MAX_MISSION_STEPS, MAX_MISSION_TEXT_BYTES, XM,
                             ZM, Deg, Name)
from ..config.schema import ConfigError, FieldError, Gt, Issue, MaxLen, NonEmpty, SourceMap, convert, parse
from ..config.yaml_source import load_yaml_text, prescan
from .spec import (MAX_CLIMB_SPEED_M_S, MAX_CRUISE_SPEED_M_S, MAX_DESCENT_SPEED_M_S, MissionSpec,
                   MissionStep, Wait, Waypoint)

MOVEMENT_STEP_TYPES: dict[int, str] = {1: "cruise", 2: "takeoff", 3: "land", 4: "pickup", 5: "deliver"}
_MOVEMENTS_LISTED = ", ".join(f"{k} {v}" for k, v in MOVEMENT_STEP_TYPES.items())

# The item's single ``speed`` lands in this waypoint field, with this cap.
_SPEED_FIELD = {"takeoff": ("climb_speed", MAX_CLIMB_SPEED_M_S),
                "land": ("descent_speed", MAX_DESCENT_SPEED_M_S)}
_DEFAULT_SPEED_FIELD = ("cruise_speed", MAX_CRUISE_SPEED_M_S)


# ---------------------------------------------------------------------------------------------
# The paper's (Unity) format
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True, kw_only=True)
class _UnityItem:
    """One item of a paper-format mission, in Unity axes (x right, y up, z forward = north)."""

    movementId: int                                  # noqa: N815 (the paper's key; one of MOVEMENT_STEP_TYPES)
    x: XM                                            # right = east [m], within 20 km (config.limits)
    y: ZM                                            # up [m], in [-100, 10 000]
    z: XM                                            # forward = north [m]
    yaw: Deg | None = None                           # clockwise from forward [deg]
    speed: Annotated[float, Gt(0)] | None = None     # [m/s]; capped per item kind in __post_init__
    waitBefore: Wait = 0.0                           # noqa: N815 [s]
    waitAfter: Wait = 0.0                            # noqa: N815 [s]

    def __post_init__(self) -> None:
        kind = MOVEMENT_STEP_TYPES.get(self.movementId)
        if kind is None:
            raise FieldError("movementId", f"unknown movementId {self.movementId!r} "
                                           f"(expected one of: {_MOVEMENTS_LISTED})")
        name, cap = _SPEED_FIELD.get(kind, _DEFAULT_SPEED_FIELD)
        if self.speed is not None and self.speed > cap:
            raise FieldError("speed", f"must be <= {cap:g} (the {name.replace('_', ' ')} limit of a "
                                      f"{kind} item), got {self.speed!r}")


def unity_to_enu_m(x: float, y: float, z: float) -> tuple[float, float, float]:
    """Map a Unity position (x right, y up, z forward = north) to ENU (east, north, up) [m]."""
    return (x, z, y)


def unity_yaw_to_enu_deg(yaw_deg: float) -> float:
    """Map a Unity yaw (clockwise from forward = north) [deg] to ENU yaw (CCW from east) in (-180, 180]."""
    wrapped = -((yaw_deg - 90.0 + 180.0) % 360.0 - 180.0)   # 90 - yaw, wrapped so that +180 stays
    return wrapped + 0.0                                    # no -0.0


def _waypoint_from_unity(item: _UnityItem, kind: str) -> Waypoint:
    east, north, up = unity_to_enu_m(item.x, item.y, item.z)
    speed: dict[str, float] = {}
    if item.speed is not None:
        speed[_SPEED_FIELD.get(kind, _DEFAULT_SPEED_FIELD)[0]] = item.speed
    yaw = None if item.yaw is None else unity_yaw_to_enu_deg(item.yaw)
    return Waypoint(x=east, y=north, z=up, yaw_deg=yaw, **speed)


def _steps_from_unity(items: list[_UnityItem]) -> list[MissionStep]:
    steps: list[MissionStep] = []
    run: list[_UnityItem] = []     # the cruise items of the current route

    def flush() -> None:
        if run:
            steps.append(MissionStep(type="cruise", wait_before=run[0].waitBefore, wait_after=run[-1].waitAfter,
                                     waypoints=[_waypoint_from_unity(it, "cruise") for it in run]))
            run.clear()

    for item in items:
        kind = MOVEMENT_STEP_TYPES[item.movementId]
        if kind == "cruise":
            if run and (run[-1].waitAfter > 0.0 or item.waitBefore > 0.0):
                flush()
            run.append(item)
            continue
        flush()
        steps.append(MissionStep(type=kind, wait_before=item.waitBefore, wait_after=item.waitAfter,
                                 waypoints=[_waypoint_from_unity(item, kind)]))
    flush()
    return steps


def _paper_key(doc: dict[Any, Any]) -> str | None:
    """Which key of ``doc`` holds paper-format items, or None if ``doc`` is in our format."""
    if "missions" in doc:
        return "missions"
    steps = doc.get("steps")
    if isinstance(steps, list) and any(isinstance(s, dict) and "movementId" in s for s in steps):
        return "steps"
    return None


def _parse_paper(doc: dict[Any, Any], key: str, src: SourceMap) -> MissionSpec:
    issues: list[Issue] = []
    for k in doc:
        if k not in (key, "name"):
            issues.append(src.issue((k,), f"unknown key {k!r} (allowed: name, {key})"))
    name = convert(doc.get("name", "mission"), Name, ("name",), src, issues)
    # each item is at most one step: the same cap as our format's steps
    items = convert(doc[key], Annotated[list[_UnityItem], NonEmpty(), MaxLen(MAX_MISSION_STEPS)], (key,), src, issues)
    if issues:
        raise ConfigError(issues)
    spec = MissionSpec(name=name, steps=_steps_from_unity(items))
    # The result must pass our own schema too: it is what mission_to_json writes and re-reads.
    return parse(_to_document(spec), MissionSpec, SourceMap(src.file))


# ---------------------------------------------------------------------------------------------
# Text -> document
# ---------------------------------------------------------------------------------------------
class _DuplicateKey(ValueError):
    pass


def _no_duplicates(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for k, v in pairs:
        if k in out:
            raise _DuplicateKey(k)
        out[k] = v
    return out


def _prescan(text: str, source: str) -> None:
    """Refuse YAML aliases, deep nesting and too many values before the document is built.

    Missions arrive over the network: the same guard as world files (:func:`prescan`), with aliases
    refused outright and tighter bounds.
    """
    if len(text) > MAX_MISSION_TEXT_BYTES:
        raise ConfigError([Issue(source, None, (), f"mission text is longer than {MAX_MISSION_TEXT_BYTES} "
                                                   "characters")])
    prescan(text, source, max_depth=MAX_MISSION_NESTING, max_nodes=MAX_MISSION_NODES, aliases=False,
            what="mission")


def _load_document(text: Any, source: str) -> tuple[Any, SourceMap]:
    """Parse JSON (or YAML) text; return the document and the line of each key path."""
    if isinstance(text, (bytes, bytearray)):
        try:
            text = bytes(text).decode("utf-8")
        except UnicodeDecodeError as exc:
            raise ConfigError([Issue(source, None, (), f"mission text is not UTF-8: {exc}")]) from None
    if not isinstance(text, str):
        raise ConfigError([Issue(source, None, (), f"expected mission text (JSON), got {type(text).__name__}")])
    _prescan(text, source)
    yaml_error: ConfigError | None = None
    try:
        doc, src = load_yaml_text(text, source)
    except ConfigError as exc:
        yaml_error, doc, src = exc, None, SourceMap(source)
    # JSON text is read by the JSON parser: YAML 1.1 would read `1e5` as a string and has no NaN.
    # Non-finite constants parse to floats here and are rejected, at their key, by the schema.
    try:
        return json.loads(text, object_pairs_hook=_no_duplicates), src
    except json.JSONDecodeError as exc:
        json_error: json.JSONDecodeError | None = exc
    except _DuplicateKey:
        json_error = None   # the YAML loader has reported it, with both lines
    except (ValueError, RecursionError) as exc:   # e.g. an integer of more than 4300 digits
        raise ConfigError([Issue(source, None, (), f"invalid JSON: {exc}")]) from None
    if yaml_error is None:
        return doc, src
    if json_error is not None and text.lstrip()[:1] in ("{", "["):
        raise ConfigError([Issue(source, json_error.lineno, (),
                                 f"invalid JSON: {json_error.msg} (line {json_error.lineno}, "
                                 f"column {json_error.colno})")]) from None
    raise yaml_error


def _describe(value: Any) -> str:
    if value is None:
        return "nothing"
    if isinstance(value, str):
        return f"string {value!r}"
    if isinstance(value, bool):
        return f"boolean {value!r}"
    if isinstance(value, (int, float)):
        return f"number {value!r}"
    return type(value).__name__


# ---------------------------------------------------------------------------------------------
# Public API
# ---------------------------------------------------------------------------------------------
def parse_mission(text: str, source: str = "mission") -> MissionSpec:
    """Parse a mission in our JSON format, as a bare list of steps, or in the paper's format.

    Parameters
    ----------
    text : the mission as JSON (or YAML) text; UTF-8 bytes are accepted too
    source : how issues name the mission (a file name, ``"mission for drone1"``)

    Raises
    ------
    ConfigError
        Listing every problem with source, line and key path; nothing else is raised for bad input.
    """
    try:
        doc, src = _load_document(text, source)
        if isinstance(doc, list):
            # a bare list is read as {"steps": [...]}: issues say steps[i], like our format does
            src = SourceMap(src.file, {**{("steps", *p): n for p, n in src.lines.items()},
                                       **({(): src.lines[()]} if () in src.lines else {})})
            doc = {"steps": doc}
        if not isinstance(doc, dict):
            raise ConfigError([src.issue((), "expected a mission: a mapping with 'steps' or a list of steps, "
                                             f"got {_describe(doc)}")])
        key = _paper_key(doc)
        if key is not None:
            return _parse_paper(doc, key, src)
        return parse(doc, MissionSpec, src)
    except RecursionError:
        raise ConfigError([Issue(source, None, (), "mission is nested too deeply")]) from None


def _to_document(obj: Any) -> Any:
    """Plain JSON-ready data for a spec dataclass; fields equal to their defaults are left out."""
    if dataclasses.is_dataclass(obj):
        out: dict[str, Any] = {}
        for f in dataclasses.fields(obj):
            value = getattr(obj, f.name)
            if f.default is not dataclasses.MISSING:
                default = f.default
            elif f.default_factory is not dataclasses.MISSING:
                default = f.default_factory()
            else:
                default = dataclasses.MISSING
            if f.name == "name" or default is dataclasses.MISSING or value != default:
                out[f.name] = _to_document(value)
        return out
    if isinstance(obj, (list, tuple)):
        return [_to_document(v) for v in obj]
    return obj


def mission_to_json(spec: MissionSpec, indent: int | None = 2) -> str:
    """Write ``spec`` in our JSON format; ``parse_mission(mission_to_json(spec)) == spec``.

    Fields at their defaults are omitted. Raises ``ValueError`` for a non-finite number (possible
    only in a spec built in Python without :func:`parse_mission`).
    """
    return json.dumps(_to_document(spec), indent=indent, allow_nan=False)


__all__ = ["MOVEMENT_STEP_TYPES", "mission_to_json", "parse_mission", "unity_to_enu_m", "unity_yaw_to_enu_deg"]
