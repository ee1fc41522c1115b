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

from ..mission.refs import mission_reference_issues
from ..mission.spec import MissionSpec
from ..control.layers import DEFAULT_CONTROLLER, LAYERS_OF_KIND
from ..plugins import GROUP_SENSORS, Registry
from ..scene.config import SceneConfig
from ..sensors.base import SensorSpec
from ..scene.layout import build_layout
from ..scene.primitives import SceneLayout, box_overlaps_box
from ..vehicles.presets import component_tables, preset, presets_for
from .limits import (MAX_DURATION_S, MAX_OFFSET_M, MAX_PACKAGES, MAX_PHYSICS_HZ, MAX_VEHICLES, MAX_WORLD_FILE_BYTES,
                     MAX_WORLD_NESTING, MAX_WORLD_NODES, MIN_PHYSICS_HZ, XYZ, Deg, Name)
from .schema import INVALID, ConfigError, FieldError, Ge, Gt, Issue, Le, MaxLen, Path, SourceMap, convert
from .yaml_source import load_yaml_file, load_yaml_text, prescan

_NAME_RE = re.compile(r"^[A-Za-z][A-Za-z0-9_]*$")

Gravity = Annotated[float, Ge(-30.0), Le(30.0)]                # [m/s^2]
Offset = Annotated[float, Ge(-MAX_OFFSET_M), Le(MAX_OFFSET_M)]   # [m]
PackageEdge = Annotated[float, Ge(0.02), Le(10.0)]             # [m]
PACKAGE_DRAG_COEFF = 1.05   # a cube face-on (Hoerner, "Fluid-Dynamic Drag", 1965, ch. 3)
SPAWN_TOLERANCE_M = 0.01   # bodies may touch (or sink this far into) what they stand on at t = 0


@dataclass(frozen=True, kw_only=True)
class OriginSpec:
    """Geodetic origin of the ENU world frame on WGS84."""

    lat_deg: Annotated[float, Ge(-90.0), Le(90.0)]
    lon_deg: Annotated[float, Ge(-180.0), Le(180.0)]
    # WGS84 height of the ground plane: from the Dead Sea shore (-430 m) to above Everest (8849 m)
    alt_m: Annotated[float, Ge(-500.0), Le(9_000.0)] = 0.0


@dataclass(frozen=True, kw_only=True)
class AirSpec:
    """The air of the world: ISA at the origin's altitude unless overridden.

    With nothing given the density is the International Standard Atmosphere's at ``origin.alt_m``
    (1.150 kg/m^3 at Madrid's 650 m). ``temperature_c`` gives a hot or cold day at that altitude (ISA
    pressure, density from the actual temperature); ``density_kg_m3`` sets the density outright
    (1.225 for the paper's sea-level figures). Drag and rotor power use it unless a vehicle's own
    ``energy`` / ``aero_drag`` block sets ``air_density_kg_m3``.
    """

    # -60 C (polar winter) .. +60 C (desert ground); air density of 0.01 (30 km up) .. 2 kg/m^3
    temperature_c: Annotated[float, Ge(-60.0), Le(60.0)] | None = None
    density_kg_m3: Annotated[float, Ge(0.01), Le(2.0)] | None = None


@dataclass(frozen=True, kw_only=True)
class GustSpec:
    """A discrete "1 - cosine" gust (MIL-F-8785C shape): the wind rises by ``peak_m_s`` over
    ``rise_time_s`` from ``start_s`` and falls back over the same time, toward ``toward_deg``."""

    start_s: Annotated[float, Ge(0.0), Le(MAX_DURATION_S)]
    peak_m_s: Annotated[float, Ge(-50.0), Le(50.0)]            # beyond 50 m/s no drone or car flies or drives
    rise_time_s: Annotated[float, Gt(0.0), Le(600.0)] = 2.0
    toward_deg: Deg = 0.0                                     # ENU: 0 = toward east, 90 = toward north
    vertical: bool = False                                     # an updraft (peak > 0) or downdraft instead


@dataclass(frozen=True, kw_only=True)
class WindSpec:
    """World-level wind: a mean wind, Dryden turbulence and discrete gusts, seeded by the world's seed.

    Every body with drag (drones, packages, cars) feels it through its ``aero_drag``; sensors see its
    effects, never the wind itself.
    """

    speed_m_s: Annotated[float, Ge(0.0), Le(50.0)] = 0.0     # mean horizontal wind [m/s]
    toward_deg: Deg = 0.0                                     # ENU direction it blows toward (0 = east, CCW)
    vertical_m_s: Annotated[float, Ge(-20.0), Le(20.0)] = 0.0   # mean updraft (+) / downdraft (-) [m/s]
    # Dryden turbulence intensity: the wind speed at 20 ft that sets it (MIL-F-8785C: light 7.7,
    # moderate 15.4, severe 23.1 m/s); 0 = no turbulence
    turbulence_w20_m_s: Annotated[float, Ge(0.0), Le(50.0)] = 0.0
    gusts: Annotated[list[GustSpec], MaxLen(1_000)] = field(default_factory=list)


@dataclass(frozen=True, kw_only=True)
class WorldSection:
    """Global settings of a world."""

    name: Name = "world"
    # physics below 50 Hz destabilises contacts and the rate loops; above 10 kHz only costs time
    physics_hz: Annotated[float, Ge(MIN_PHYSICS_HZ), Le(MAX_PHYSICS_HZ)] = 240.0
    # ENU; each component within 30 m/s^2 covers every solar-system surface (Jupiter 24.8)
    gravity_m_s2: tuple[Gravity, Gravity, Gravity] = (0.0, 0.0, -9.81)
    seed: Annotated[int, Ge(0), Le(2**63 - 1)] = 0      # fits an int64 (CSV, summary, ROS 2 parameter)
    origin: OriginSpec = OriginSpec(lat_deg=40.4168, lon_deg=-3.7038, alt_m=650.0)  # Madrid
    # default length of `unetyemu run`: at most one week of simulated time
    duration_s: Annotated[float, Gt(0.0), Le(MAX_DURATION_S)] = 60.0
    # CSV log rate: one row per 100 s at least (fewer says nothing), 1 kHz at most (CSV growth)
    log_hz: Annotated[float, Ge(0.01), Le(1_000.0)] = 10.0
    air: AirSpec = AirSpec()
    wind: WindSpec | None = None      # none: still air (a `systems:` wind plugin may still blow)

    def air_density_kg_m3(self) -> float:
        """The world's air density [kg/m^3]: the override, else ISA at the origin (at the given temperature)."""
        from ..control.atmosphere import air_state_at_temperature, isa_density_kg_m3

        if self.air.density_kg_m3 is not None:
            return float(self.air.density_kg_m3)
        if self.air.temperature_c is not None:
            return float(air_state_at_temperature(self.origin.alt_m, self.air.temperature_c + 273.15).density_kg_m3)
        return float(isa_density_kg_m3(self.origin.alt_m))


@dataclass(frozen=True, kw_only=True)
class PoseSpec:
    """Initial pose: an explicit position, or standing on a named pad or parking spot.

    ``position_m`` is the body's centre in ENU. On a pad or parking spot the body rests on the
    surface (its bottom on the top of the pad), shifted by ``offset_m`` (ENU, metres).
    """

    position_m: XYZ | None = None   # within 20 km of the origin, z in [-100, 10 000] m (config.limits)
    pad: Name | None = None
    parking: Name | None = None
    offset_m: tuple[Offset, Offset] = (0.0, 0.0)   # within 50 m of the pad or spot: it stands there
    yaw_deg: Deg | None = None   # ENU, 0 = east, CCW; default 0, or the parking spot's heading

    def __post_init__(self) -> None:
        given = [k for k in ("position_m", "pad", "parking") if getattr(self, k) is not None]
        if len(given) != 1:
            raise ValueError("a pose needs exactly one of position_m, pad, parking"
                             + (f" (got {', '.join(given)})" if given else ""))


@dataclass(frozen=True, kw_only=True)
class PackageSpec:
    """A box that drones can pick up."""

    name: Name
    mass_kg: Annotated[float, Gt(0.0), Le(1_000.0)]   # a parcel: a tonne is a pallet already
    # edges from 2 cm (half of Bullet's 4 cm collision margin each side) to a 10 m container
    size_m: tuple[PackageEdge, PackageEdge, PackageEdge] = (0.4, 0.4, 0.3)
    pose: PoseSpec
    components: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True, kw_only=True)
class VehicleSpec:
    """A drone or a ground vehicle."""

    name: Name
    type: Literal["quadrotor", "car"]
    preset: Name = "medium"
    pose: PoseSpec
    components: dict[str, Any] = field(default_factory=dict)
    # sensors attached with their defaults: "all" (every installed sensor that fits the vehicle) or
    # a list of sensor keys; a sensor also under `components` keeps the parameters given there
    sensors: Literal["all"] | Annotated[list[Name], MaxLen(64)] = field(default_factory=list)
    # with the ROS 2 bridge on: publish this vehicle's sensors and mission status and listen to its
    # command topics (False: none of them; its frames stay in /tf, which describes the whole world)
    ros2: bool = True
    # a streamed teleop or cmd_vel (ROS 2 topics) lapses this long after the newest one arrived: the
    # drone then hovers, the car brakes to a stop (0: held until the next command) [s, sim time];
    # 0.5 s as ros2_control's diff_drive_controller (cmd_vel_timeout) and PX4's offboard loss time
    command_timeout_s: Annotated[float, Ge(0.0), Le(60.0)] = 0.5
    # the controller of each layer (position, attitude, mixer for a drone; drive for a car), by its
    # registered name, optionally with parameters: `attitude: px4_attitude` or
    # `attitude: {name: px4_attitude, params: {...}}`; layers not named keep the built-in controller
    controller: dict[Name, Any] = field(default_factory=dict)

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
    packages: Annotated[list[PackageSpec], MaxLen(MAX_PACKAGES)] = field(default_factory=list)
    vehicles: Annotated[list[VehicleSpec], MaxLen(MAX_VEHICLES)] = field(default_factory=list)
    systems: dict[Name, Any] = field(default_factory=dict)


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
    # layer -> (registered controller name, its parameters: the component that selects it)
    controllers: dict[str, tuple[str, Any]] = field(default_factory=dict)


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
    """Read and validate a world file; raise :class:`ConfigError` listing every problem.

    The file is read bounded (``config.limits``: at most 1 MiB, a regular file, 32 levels of
    nesting, 200 000 values after expanding aliases) before it is parsed.
    """
    doc, src = load_yaml_file(path, MAX_WORLD_FILE_BYTES, max_depth=MAX_WORLD_NESTING, max_nodes=MAX_WORLD_NODES,
                              what="world file")
    return resolve_world(doc, src, registry, seed)


def load_world_text(text: str, file: str = "<string>", registry: Registry | None = None,
                    seed: int | None = None) -> WorldDefinition:
    """Like :func:`load_world` for YAML given as a string."""
    if len(text) > MAX_WORLD_FILE_BYTES:
        raise ConfigError([Issue(file, None, (), f"is larger than {MAX_WORLD_FILE_BYTES} characters "
                                                 "(the limit of a world file)")])
    prescan(text, file, max_depth=MAX_WORLD_NESTING, max_nodes=MAX_WORLD_NODES, what="world file")
    doc, src = load_yaml_text(text, file)
    return resolve_world(doc, src, registry, seed)


def resolve_world(doc: Any, src: SourceMap, registry: Registry | None = None,
                  seed: int | None = None) -> WorldDefinition:
    """Validate a parsed document and resolve it into a :class:`WorldDefinition`."""
    if doc is None or doc == {}:
        raise ConfigError([src.issue((), "the world file is empty (expected the sections world, scene, "
                                         "packages, vehicles)")])
    registry = registry if registry is not None else Registry.discover()
    issues: list[Issue] = []
    try:
        spec = convert(doc, WorldFile, (), src, issues)
    except RecursionError:     # prescan bounds the nesting; this guards documents built in Python
        raise ConfigError([src.issue((), "the world is nested too deeply")]) from None
    if spec is INVALID:
        raise ConfigError(issues)
    if seed is not None:
        if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed <= 2**63 - 1:
            raise ConfigError([Issue(src.file, None, ("world", "seed"), f"the seed override must be an integer in "
                                                                       f"[0, 2**63 - 1], got {seed!r}")])
        spec = replace(spec, world=replace(spec.world, seed=seed))

    _check_names(spec, src, issues)

    layout = None
    try:
        layout = build_layout(spec.scene, spec.world.seed if spec.scene.seed is None else spec.scene.seed)
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
    where: list[Path] = []                      # (group, index) of each entity
    if layout is not None:
        counts: dict[str, int] = {}
        for group, items in (("vehicles", spec.vehicles), ("packages", spec.packages)):
            for i, item in enumerate(items):
                ent = _resolve_entity(group, i, item, layout, registry, src, issues, counts)
                if ent is not None:
                    entities.append(ent)
                    where.append((group, i))
        _check_mission_references(entities, where, layout, [p.name for p in spec.packages], src, issues)
        _check_lift(entities, where, float(np.linalg.norm(spec.world.gravity_m_s2)), src, issues)
        _check_spawn_clearance(entities, where, layout, src, issues)
    if issues:
        raise ConfigError(issues)
    assert layout is not None
    return WorldDefinition(src.file, spec, layout, tuple(entities), systems, registry)


def _check_mission_references(entities: list[EntityDefinition], where: list[Path], layout: SceneLayout,
                              package_names: list[str], src: SourceMap, issues: list[Issue]) -> None:
    """A mission naming a pad or package this world lacks fails at load, at the step that names it."""
    for ent, (group, i) in zip(entities, where):
        for key, comp in ent.components.items():
            if isinstance(comp, MissionSpec):
                for path, message in mission_reference_issues(comp, layout, package_names):
                    issues.append(src.issue((group, i, "components", key, *path), message))


def _check_lift(entities: list[EntityDefinition], where: list[Path], gravity_m_s2: float, src: SourceMap,
                issues: list[Issue]) -> None:
    """A drone whose motors cannot hover it with its own max payload fails at load (it would sit on
    the ground at full thrust with a mission that never ends)."""
    for ent, (group, i) in zip(entities, where):
        motors, bay = ent.components.get("motors"), ent.components.get("payload")
        if ent.kind != "quadrotor" or motors is None:
            continue
        max_payload_kg = getattr(bay, "max_payload_kg", 0.0)
        weight_n = (float(ent.params["mass_kg"]) + max_payload_kg) * gravity_m_s2
        thrust_n = 4.0 * motors.max_thrust_per_motor_n
        if thrust_n < weight_n:
            path: Path = (group, i, "components", "payload" if bay is not None and max_payload_kg > 0 else "motors")
            issues.append(src.issue(path, f"{ent.name} cannot hover its max payload: 4 x "
                                          f"{motors.max_thrust_per_motor_n:g} N = {thrust_n:.1f} N of thrust < "
                                          f"({ent.params['mass_kg']:g} + {max_payload_kg:g}) kg x {gravity_m_s2:.2f} "
                                          f"m/s^2 = {weight_n:.1f} N (raise motors.max_thrust_per_motor_n to at least "
                                          f"{weight_n / 4.0:.1f} N or lower payload.max_payload_kg)"))


def _body_box(ent: EntityDefinition) -> tuple[np.ndarray, np.ndarray]:
    """Centre (3,) and half extents (3,) [m] of the box an entity occupies at spawn (yaw: ``ent.yaw_rad``).

    A car's box reaches down to its wheels' contact patches (``ground_clearance_m`` below the chassis).
    """
    if ent.kind == "package":
        half = 0.5 * np.asarray(ent.params["size_m"], dtype=float)
        return np.asarray(ent.pos_enu_m, dtype=float), half
    half = np.asarray(ent.params["body_half_extents_m"], dtype=float).copy()
    clearance = float(ent.params.get("ground_clearance_m", 0.0))
    center = np.asarray(ent.pos_enu_m, dtype=float).copy()
    center[2] -= 0.5 * clearance
    half[2] += 0.5 * clearance
    return center, half


def _check_spawn_clearance(entities: list[EntityDefinition], where: list[Path], layout: SceneLayout,
                           src: SourceMap, issues: list[Issue]) -> None:
    """Refuse bodies that start inside a scene object, below the ground or inside each other.

    PyBullet resolves such overlaps by throwing the bodies out at tens of m/s at t = 0. Touching is
    fine: each box is shrunk by :data:`SPAWN_TOLERANCE_M` first (bodies on pads rest 5 mm above).
    """
    boxes = []
    for ent, (group, i) in zip(entities, where):
        center, half = _body_box(ent)
        inner = np.maximum(half - SPAWN_TOLERANCE_M, 1e-6)
        boxes.append((center, inner))
        path: Path = (group, i, "pose")
        bottom = center[2] - half[2]
        if bottom < -SPAWN_TOLERANCE_M:
            issues.append(src.issue(path, f"{ent.name} starts underground: its bottom is at z = {bottom:.2f} m, "
                                          "below the ground (z = 0)"))
            continue
        if not layout.contains_xy(center[0], center[1]):
            issues.append(src.issue(path, f"{ent.name} starts off the ground at ({center[0]:g}, {center[1]:g}) m: the "
                                          f"world spans {layout.extent_text()}"))
            continue
        hits = layout.objects_overlapping_box(center, inner, ent.yaw_rad, skip_ground=True)
        if hits:
            names = ", ".join(f"{layout.objects[k].cls.name.lower()} {layout.objects[k].name!r}" for k in hits[:3])
            more = f" and {len(hits) - 3} more" if len(hits) > 3 else ""
            issues.append(src.issue(path, f"{ent.name} starts inside {names}{more} (its box: centre "
                                          f"{np.round(center, 2).tolist()} m, half extents "
                                          f"{np.round(half, 2).tolist()} m)"))
    if not boxes:
        return
    # only pairs whose bounding spheres meet get the exact test (1 280 bodies are 800 000 pairs)
    centers = np.array([c for c, _ in boxes])
    radii = np.array([float(np.linalg.norm(h)) for _, h in boxes])
    near = np.linalg.norm(centers[:, None, :] - centers[None, :, :], axis=2) < radii[:, None] + radii[None, :]
    for a, b in zip(*np.nonzero(np.tril(near, k=-1))):
        a, b = int(a), int(b)
        ca, ha = boxes[a]
        cb, hb = boxes[b]
        if box_overlaps_box(ca, ha, entities[a].yaw_rad, cb, hb, entities[b].yaw_rad):
            first = where[b]
            issues.append(src.issue((*where[a], "pose"), f"{entities[a].name} overlaps {entities[b].name} at spawn "
                                                         f"({first[0]}[{first[1]}], line {src.line_of(first)})"))


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
    if kind == "package":                                          # a box in the wind: C_d 1.05 on each face
        sx, sy, sz = item.size_m
        blocks["aero_drag"] = {"drag_coeff": PACKAGE_DRAG_COEFF, "area_flu_m2": [sy * sz, sx * sz, sx * sy]}
    for key, block in item.components.items():                    # the world file's additions/overrides
        if block is None and key in registry.component_keys():
            issues.append(src.issue((group, i, "components", key), f"{key}: null is not a parameter block: give a "
                                    "mapping of its parameters ({} keeps the defaults)"))
            continue
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
        comp = resolve_component(key, block, kind, registry, (group, i, "components", key), src, issues)
        if comp is not INVALID:
            components[key] = comp

    controllers = (_resolve_controllers(kind, item.controller, (group, i, "controller"), registry, src, issues)
                   if isinstance(item, VehicleSpec) else {})
    if len(issues) > n_before or pos is None:
        return None
    index = counts.get(kind, 0)
    counts[kind] = index + 1
    on_ros2 = getattr(item, "ros2", True)
    if not on_ros2:                                  # a vehicle off ROS 2 takes its sensors with it
        components = {k: replace(c, ros2=False) if isinstance(c, SensorSpec) else c for k, c in components.items()}
    return EntityDefinition(item.name, kind, preset_name, index, pos, float(yaw_rad), params, components, on_ros2,
                            controllers)


def resolve_component(key: str, block: Any, kind: str, registry: Registry, path: Path, src: SourceMap,
                      issues: list[Issue]) -> Any:
    """The component or sensor ``key`` with the parameter ``block`` for a ``kind`` entity, or
    :data:`INVALID` with the reasons in ``issues`` (unknown key, a kind it does not fit, bad
    parameters). Used by the loader and by ``Simulation.attach``."""
    try:
        entry = registry.component_entry(key)
    except KeyError as exc:
        issues.append(src.issue(path, exc.args[0]))
        return INVALID
    if kind not in entry.spec.applies_to:
        issues.append(src.issue(path, f"component {key!r} cannot be attached to a {kind} "
                                      f"(applies to: {', '.join(sorted(entry.spec.applies_to))})"))
        return INVALID
    return convert(block, entry.spec.component, path, src, issues)


def _resolve_controllers(kind: str, chosen: dict[str, Any], path: Path, registry: Registry, src: SourceMap,
                         issues: list[Issue]) -> dict[str, tuple[str, Any]]:
    """Each layer of a ``kind`` vehicle -> (controller name, parameters), from its ``controller:`` block
    (``layer: name`` or ``layer: {name: ..., params: {...}}``) and the built-in defaults."""
    layers = LAYERS_OF_KIND.get(kind, ())
    out: dict[str, tuple[str, Any]] = {}
    for layer_key in chosen:
        if layer_key not in layers:
            issues.append(src.issue((*path, layer_key), f"a {kind} has no controller layer {layer_key!r} "
                                                        f"(its layers: {', '.join(layers)})"))
    for layer in layers:
        lpath: Path = (*path, layer.value)
        block = chosen.get(layer.value, DEFAULT_CONTROLLER[layer])
        params_block: Any = {}
        if isinstance(block, dict):
            unknown = sorted(set(block) - {"name", "params"})
            if unknown:
                issues.append(src.issue((*lpath, unknown[0]), f"unknown key {unknown[0]!r} (a controller is "
                                                              "{name: <controller>, params: {...}})"))
                continue
            name, params_block = block.get("name"), block.get("params", {})
            if params_block is None:
                issues.append(src.issue((*lpath, "params"), "params: null is not a parameter block: give a mapping of "
                                                            "the controller's parameters ({} keeps the defaults)"))
                continue
        else:
            name = block
        available = sorted(k for k, e in registry.entries["unetyemu_ecs.controllers"].items() if e.spec.layer == layer)
        if not isinstance(name, str) or not name:
            article = "an" if layer.value[0] in "aeiou" else "a"
            issues.append(src.issue(lpath, f"a {kind} needs {article} {layer.value} controller: name one of "
                                           f"{', '.join(available) or 'none installed'} (got {name!r})"))
            continue
        try:
            entry = registry.controller_entry(name, layer)
        except KeyError as exc:
            issues.append(src.issue(lpath, exc.args[0]))
            continue
        where = (*lpath, "params") if isinstance(block, dict) and "params" in block else lpath
        params = convert(params_block, entry.spec.params, where, src, issues)
        if params is not INVALID:
            out[layer.value] = (name, params)
    return out
