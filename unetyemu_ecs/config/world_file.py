"""World-file schema (docs/architecture.md §8) and loading: YAML -> validated, resolved world definition.

Loading happens in three passes, each collecting *every* problem before anything starts:

1. YAML syntax and duplicate keys (``yaml_source``);
2. types, ranges and unknown keys against the dataclasses below (``schema.convert``), including the
   parameter block of each plugin component and world system against its registered dataclass;
3. cross references: unique entity names, presets, poses on pads or parking spots that exist in the
   generated scene.

Every issue is reported as ``file:line: key.path: message``.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field, replace
from pathlib import Path as FsPath
from typing import Annotated, Any, Literal

import numpy as np

from ..plugins import GROUP_SENSORS, Registry
from ..scene.config import SceneConfig
from ..sensors.base import SensorSpec
from ..scene.layout import build_layout
from ..scene.primitives import SceneLayout
from ..vehicles.presets import component_tables, preset, presets_for
from .schema import INVALID, ConfigError, Each, FieldError, Ge, Gt, Issue, Le, NonEmpty, Path, SourceMap, convert
from .yaml_source import load_yaml_file, load_yaml_text

_NAME_RE = re.compile(r"^[A-Za-z][A-Za-z0-9_]*$")


@dataclass(frozen=True, kw_only=True)
class OriginSpec:
    """Geodetic origin of the ENU world frame on WGS84."""

    lat_deg: Annotated[float, Ge(-90.0), Le(90.0)]
    lon_deg: Annotated[float, Ge(-180.0), Le(180.0)]
    alt_m: float = 0.0


@dataclass(frozen=True, kw_only=True)
class WorldSection:
    """Global settings of a world."""

    name: Annotated[str, NonEmpty()] = "world"
    physics_hz: Annotated[float, Gt(0.0), Le(10_000.0)] = 240.0
    gravity_m_s2: tuple[float, float, float] = (0.0, 0.0, -9.81)   # ENU
    seed: Annotated[int, Ge(0)] = 0
    origin: OriginSpec = OriginSpec(lat_deg=40.4168, lon_deg=-3.7038, alt_m=650.0)  # Madrid
    duration_s: Annotated[float, Gt(0.0)] = 60.0    # default length of `unetyemu run`
    log_hz: Annotated[float, Gt(0.0)] = 10.0        # CSV log rate


@dataclass(frozen=True, kw_only=True)
class PoseSpec:
    """Initial pose: an explicit position, or standing on a named pad or parking spot.

    ``position_m`` is the body's centre in ENU. On a pad or parking spot the body rests on the
    surface (its bottom on the top of the pad), shifted by ``offset_m`` (ENU, metres).
    """

    position_m: tuple[float, float, float] | None = None
    pad: str | None = None
    parking: str | None = None
    offset_m: tuple[float, float] = (0.0, 0.0)
    yaw_deg: float | None = None   # ENU, 0 = east, CCW; default 0, or the parking spot's heading

    def __post_init__(self) -> None:
        given = [k for k in ("position_m", "pad", "parking") if getattr(self, k) is not None]
        if len(given) != 1:
            raise ValueError("a pose needs exactly one of position_m, pad, parking"
                             + (f" (got {', '.join(given)})" if given else ""))


@dataclass(frozen=True, kw_only=True)
class PackageSpec:
    """A box that drones can pick up."""

    name: Annotated[str, NonEmpty()]
    mass_kg: Annotated[float, Gt(0.0)]
    size_m: Annotated[tuple[float, float, float], Each(Gt(0.0))] = (0.4, 0.4, 0.3)
    pose: PoseSpec
    components: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True, kw_only=True)
class VehicleSpec:
    """A drone or a ground vehicle."""

    name: Annotated[str, NonEmpty()]
    type: Literal["quadrotor", "car"]
    preset: str = "medium"
    pose: PoseSpec
    components: dict[str, Any] = field(default_factory=dict)
    # sensors attached with their defaults: "all" (every installed sensor that fits the vehicle) or
    # a list of sensor keys; a sensor also under `components` keeps the parameters given there
    sensors: Literal["all"] | list[Annotated[str, NonEmpty()]] = field(default_factory=list)
    # with the ROS 2 bridge on: publish this vehicle's sensors and mission status and listen to its
    # command topics (False: none of them; its frames stay in /tf, which describes the whole world)
    ros2: bool = True
    # a streamed teleop or cmd_vel (ROS 2 topics) lapses this long after the newest one arrived: the
    # drone then hovers, the car brakes to a stop (0: held until the next command) [s, sim time];
    # 0.5 s as ros2_control diff_drive_controller (cmd_vel_timeout) and PX4 offboard loss time
    command_timeout_s: Annotated[float, Ge(0.0), Le(60.0)] = 0.5

    def __post_init__(self) -> None:
        known = presets_for(self.type)
        if self.preset not in known:
            raise FieldError("preset", f"unknown {self.type} preset {self.preset!r} "
                                       f"(expected one of: {', '.join(sorted(known))})")


@dataclass(frozen=True, kw_only=True)
class WorldFile:
    """The whole world file."""

    world: WorldSection = field(default_factory=WorldSection)
    scene: SceneConfig = field(default_factory=SceneConfig)
    packages: list[PackageSpec] = field(default_factory=list)
    vehicles: list[VehicleSpec] = field(default_factory=list)
    systems: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class EntityDefinition:
    """A vehicle or package, resolved: where it starts and which plugin components it carries."""

    name: str
    kind: str                          # "quadrotor" | "car" | "package"
    preset: str | None
    index: int                         # among entities of the same kind, from 0
    pos_enu_m: np.ndarray              # (3,) [m] centre of the body
    yaw_rad: float                     # ENU
    params: dict[str, Any]             # preset parameters (vehicles) or mass/size (packages)
    components: dict[str, Any]         # world-file key -> component instance
    ros2: bool = True                  # on the ROS 2 bridge (VehicleSpec.ros2); packages: unused


@dataclass(frozen=True)
class WorldDefinition:
    """A validated world, ready to be built into a :class:`~unetyemu_ecs.app.Simulation`."""

    file: str
    spec: WorldFile
    layout: SceneLayout
    entities: tuple[EntityDefinition, ...]
    systems: dict[str, Any]            # world system key -> config instance
    registry: Registry

    @property
    def name(self) -> str:
        return self.spec.world.name

    @property
    def vehicles(self) -> tuple[EntityDefinition, ...]:
        return tuple(e for e in self.entities if e.kind != "package")

    @property
    def packages(self) -> tuple[EntityDefinition, ...]:
        return tuple(e for e in self.entities if e.kind == "package")


def load_world(path: str | FsPath, registry: Registry | None = None, seed: int | None = None) -> WorldDefinition:
    """Read and validate a world file; raise :class:`ConfigError` listing every problem."""
    doc, src = load_yaml_file(path)
    return resolve_world(doc, src, registry, seed)


def load_world_text(text: str, file: str = "<string>", registry: Registry | None = None,
                    seed: int | None = None) -> WorldDefinition:
    """Like :func:`load_world` for YAML given as a string."""
    doc, src = load_yaml_text(text, file)
    return resolve_world(doc, src, registry, seed)


def resolve_world(doc: Any, src: SourceMap, registry: Registry | None = None,
                  seed: int | None = None) -> WorldDefinition:
    """Validate a parsed document and resolve it into a :class:`WorldDefinition`."""
    registry = registry if registry is not None else Registry.discover()
    issues: list[Issue] = []
    spec = convert(doc, WorldFile, (), src, issues)
    if spec is INVALID:
        raise ConfigError(issues)
    if seed is not None:
        spec = replace(spec, world=replace(spec.world, seed=seed))

    _check_names(spec, src, issues)

    layout = None
    try:
        layout = build_layout(spec.scene, spec.world.seed)
    except ValueError as exc:
        issues.append(src.issue(_path_in_message(str(exc), ("scene",)), str(exc)))

    systems: dict[str, Any] = {}
    for key, params in spec.systems.items():
        path: Path = ("systems", key)
        try:
            entry = registry.system_entry(key)
        except KeyError as exc:
            issues.append(src.issue(path, exc.args[0]))
            continue
        cfg = convert(params, entry.spec.config, path, src, issues)
        if cfg is not INVALID:
            systems[key] = cfg

    entities: list[EntityDefinition] = []
    if layout is not None:
        counts: dict[str, int] = {}
        for group, items in (("vehicles", spec.vehicles), ("packages", spec.packages)):
            for i, item in enumerate(items):
                ent = _resolve_entity(group, i, item, layout, registry, src, issues, counts)
                if ent is not None:
                    entities.append(ent)
    if issues:
        raise ConfigError(issues)
    assert layout is not None
    return WorldDefinition(src.file, spec, layout, tuple(entities), systems, registry)


def _path_in_message(message: str, default: Path) -> Path:
    """Recover a key path like ``scene.pads[1]`` from the start of a scene error message."""
    m = re.match(r"^([A-Za-z_][\w.\[\]]*):", message)
    if not m:
        return default
    parts: list[str | int] = []
    for token in re.findall(r"[A-Za-z_]\w*|\[\d+\]", m.group(1)):
        parts.append(int(token[1:-1]) if token.startswith("[") else token)
    return tuple(parts)


def _check_names(spec: WorldFile, src: SourceMap, issues: list[Issue]) -> None:
    seen: dict[str, Path] = {}
    for group, items in (("vehicles", spec.vehicles), ("packages", spec.packages)):
        for i, item in enumerate(items):
            path: Path = (group, i, "name")
            if not _NAME_RE.match(item.name):
                issues.append(src.issue(path, f"name {item.name!r} must start with a letter and contain only "
                                              "letters, digits and underscores (it becomes a ROS 2 topic prefix)"))
            if item.name in seen:
                first = seen[item.name]
                issues.append(src.issue(path, f"duplicate name {item.name!r} (already used by "
                                              f"{first[0]}[{first[1]}] on line {src.line_of(first)})"))
            else:
                seen[item.name] = path


def _resolve_entity(group: str, i: int, item: VehicleSpec | PackageSpec, layout: SceneLayout, registry: Registry,
                    src: SourceMap, issues: list[Issue], counts: dict[str, int]) -> EntityDefinition | None:
    n_before = len(issues)
    if isinstance(item, VehicleSpec):
        kind = item.type
        params = preset(kind, item.preset)
        # height of the body centre above the surface it stands on (cars ride on their wheels)
        half_z = float(params["body_half_extents_m"][2]) + float(params.get("ground_clearance_m", 0.0))
        preset_name: str | None = item.preset
    else:
        kind = "package"
        params = {"mass_kg": item.mass_kg, "size_m": item.size_m}
        half_z = item.size_m[2] / 2.0
        preset_name = None

    pose = item.pose
    pose_path: Path = (group, i, "pose")
    yaw_rad = np.deg2rad(pose.yaw_deg) if pose.yaw_deg is not None else 0.0
    pos = None
    if pose.position_m is not None:
        pos = np.array(pose.position_m, dtype=float)
    elif pose.pad is not None:
        pad = layout.pads.get(pose.pad)
        if pad is None:
            issues.append(src.issue((*pose_path, "pad"), f"unknown pad {pose.pad!r} (pads in this scene: "
                                                          f"{', '.join(sorted(layout.pads)) or 'none'})"))
        else:
            pos = np.array(pad.center_enu_m, dtype=float) + np.array([*pose.offset_m, half_z + 0.005])
    else:
        spot = layout.parking.get(pose.parking)
        if spot is None:
            issues.append(src.issue((*pose_path, "parking"),
                                    f"unknown parking spot {pose.parking!r} (spots in this scene: "
                                    f"{', '.join(sorted(layout.parking)) or 'none'})"))
        else:
            pos = np.array(spot.center_enu_m, dtype=float) + np.array([*pose.offset_m, half_z + 0.005])
            if pose.yaw_deg is None:
                yaw_rad = float(spot.yaw_rad)

    components: dict[str, Any] = {}
    blocks: dict[str, Any] = dict(component_tables(params))       # the preset's built-in components
    for key, block in item.components.items():                    # the world file's additions/overrides
        if key in blocks and isinstance(block, dict):
            blocks[key] = {**blocks[key], **block}
        else:
            blocks[key] = block
    if isinstance(item, VehicleSpec) and item.sensors:             # sensors with their defaults
        if item.sensors == "all":
            wanted = [k for k, e in registry.entries[GROUP_SENSORS].items() if kind in e.spec.applies_to]
        else:
            wanted = list(item.sensors)
            for j, key in enumerate(wanted):
                if key not in registry.entries[GROUP_SENSORS]:
                    issues.append(src.issue((group, i, "sensors", j), f"unknown sensor {key!r} (installed: "
                                            f"{', '.join(sorted(registry.entries[GROUP_SENSORS])) or 'none'})"))
            wanted = [k for k in wanted if k in registry.entries[GROUP_SENSORS]]
        for key in wanted:
            blocks.setdefault(key, {})
    for key, block in blocks.items():
        cpath: Path = (group, i, "components", key)
        try:
            entry = registry.component_entry(key)
        except KeyError as exc:
            issues.append(src.issue(cpath, exc.args[0]))
            continue
        if kind not in entry.spec.applies_to:
            issues.append(src.issue(cpath, f"component {key!r} cannot be attached to a {kind} "
                                           f"(applies to: {', '.join(sorted(entry.spec.applies_to))})"))
            continue
        comp = convert(block, entry.spec.component, cpath, src, issues)
        if comp is not INVALID:
            components[key] = comp

    if len(issues) > n_before or pos is None:
        return None
    index = counts.get(kind, 0)
    counts[kind] = index + 1
    on_ros2 = getattr(item, "ros2", True)
    if not on_ros2:                                  # a vehicle off ROS 2 takes its sensors with it
        components = {k: replace(c, ros2=False) if isinstance(c, SensorSpec) else c for k, c in components.items()}
    return EntityDefinition(item.name, kind, preset_name, index, pos, float(yaw_rad), params, components, on_ros2)
