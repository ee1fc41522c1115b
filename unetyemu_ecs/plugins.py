"""Plugin discovery through Python entry points, and the registry the world loader resolves against.

Five entry-point groups (docs/architecture.md §2):

``unetyemu_ecs.components``
    name = the world-file key under ``vehicles[i].components`` / ``packages[i].components``;
    object = a :class:`ComponentPlugin` (the component dataclass, which is also its world-file schema,
    and the systems that act on it).
``unetyemu_ecs.systems``
    name = the world-file key under the top-level ``systems:`` mapping; object = a
    :class:`SystemPlugin` (a world-wide system and its configuration dataclass).
``unetyemu_ecs.sensors``
    name = the world-file key under ``components``; object = a :class:`SensorPlugin`.
``unetyemu_ecs.controllers``
    name = the controller's name, chosen per vehicle and layer under ``controller:``
    (``controller: {attitude: px4_attitude}``); object = a :class:`ControllerPlugin`.
``unetyemu_ecs.transports``
    name = the transport's name (``ros2``, ``mavlink``; its counters' key in ``summary.json``);
    object = a :class:`~unetyemu_ecs.transport.api.TransportPlugin` whose ``create(world, options)``
    returns a transport for this simulation, or None when it is not enabled.

Built-in parts are declared in this project's own ``pyproject.toml`` and found the same way as
third-party ones. A plugin that fails to import is not fatal: the registry records why, ``unetyemu
plugins`` shows it, and a world file that uses it gets that reason as its error.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from importlib.metadata import EntryPoint, entry_points
from typing import Annotated, Any

from .control.layers import LAYERS_OF_KIND, Layer
from .phases import Phase
from .transport.api import TransportPlugin

GROUP_COMPONENTS = "unetyemu_ecs.components"
GROUP_SYSTEMS = "unetyemu_ecs.systems"
GROUP_SENSORS = "unetyemu_ecs.sensors"
GROUP_CONTROLLERS = "unetyemu_ecs.controllers"
GROUP_TRANSPORTS = "unetyemu_ecs.transports"
GROUPS = (GROUP_COMPONENTS, GROUP_SYSTEMS, GROUP_SENSORS, GROUP_CONTROLLERS, GROUP_TRANSPORTS)

ALL_KINDS = frozenset({"quadrotor", "car", "package"})


def _check_schema(cls: type, what: str) -> None:
    """Every ``Annotated`` constraint on a schema dataclass's fields must be one the loader checks
    (``unetyemu_ecs.plugin_api.Ge`` etc.): a constraint from another library would be skipped silently."""
    from typing import get_args, get_origin, get_type_hints

    def markers(tp: Any) -> Iterable[Any]:
        if get_origin(tp) is Annotated:
            base, *extra = get_args(tp)
            yield from extra
            yield from markers(base)
        else:
            for arg in get_args(tp):
                yield from markers(arg)

    for name, tp in get_type_hints(cls, include_extras=True).items():
        for marker in markers(tp):
            if not callable(getattr(marker, "check", None)):
                raise TypeError(f"{what}: field {name!r} has the constraint {marker!r}, which the world-file loader "
                                "cannot check: use the ones of unetyemu_ecs.plugin_api (Ge, Gt, Le, Lt, Each, MaxLen)")


def _check_numeric_params(cls: type, what: str) -> None:
    """A controller's parameters are stacked into float arrays: every field must be a number (or a tuple of them)."""
    from typing import get_args, get_origin, get_type_hints

    def numeric(tp: Any) -> bool:
        if get_origin(tp) is Annotated:
            return numeric(get_args(tp)[0])
        if get_origin(tp) is tuple:
            return all(numeric(a) for a in get_args(tp) if a is not Ellipsis)
        return tp in (float, int, bool)

    for name, tp in get_type_hints(cls, include_extras=True).items():
        if not numeric(tp):
            raise TypeError(f"{what}: parameter {name!r} must be a number or a tuple of numbers (the law gets every "
                            f"parameter stacked into an array), got {tp!r}")


def _check_system_class(cls: Any, what: str) -> None:
    if not isinstance(cls, type) or not callable(getattr(cls, "process", None)):
        raise TypeError(f"{what}: {cls!r} is not a system class with a process(ctx) method")
    if not isinstance(getattr(cls, "phase", None), Phase):
        raise TypeError(f"{what}: system {cls.__name__} must declare `phase` as a unetyemu_ecs.phases.Phase")


@dataclass(frozen=True)
class ComponentPlugin:
    """A component that entities can carry, plus the systems that act on it.

    ``component`` is a dataclass; its fields (with ``Annotated`` constraints) are the world-file
    schema of the component's parameter block. Each class in ``systems`` is instantiated once per
    simulation, with no arguments, when at least one entity carries the component.
    """

    component: type
    systems: tuple[type, ...] = ()
    applies_to: frozenset[str] = ALL_KINDS
    summary: str = ""

    def __post_init__(self) -> None:
        if not dataclasses.is_dataclass(self.component):
            raise TypeError(f"component {self.component!r} must be a dataclass")
        _check_schema(self.component, f"component {self.component.__name__}")
        for s in self.systems:
            _check_system_class(s, f"component {self.component.__name__}")
        unknown = set(self.applies_to) - ALL_KINDS
        if unknown:
            raise TypeError(f"applies_to has unknown kinds {sorted(unknown)}; known: {sorted(ALL_KINDS)}")


@dataclass(frozen=True)
class SystemPlugin:
    """A world-wide system, enabled by its key in the world file's top-level ``systems:`` mapping.

    ``system`` is instantiated once as ``system(config)`` where ``config`` is the ``config``
    dataclass parsed from the world file.
    """

    system: type
    config: type
    summary: str = ""

    def __post_init__(self) -> None:
        _check_system_class(self.system, "system plugin")
        if not dataclasses.is_dataclass(self.config):
            raise TypeError(f"system {self.system.__name__}: config {self.config!r} must be a dataclass")
        _check_schema(self.config, f"system {self.system.__name__} config")


@dataclass(frozen=True)
class SensorPlugin:
    """A sensor: its component (world-file schema) and the system that produces its measurements."""

    component: type
    system: type
    applies_to: frozenset[str] = ALL_KINDS
    summary: str = ""

    def __post_init__(self) -> None:
        if not dataclasses.is_dataclass(self.component):
            raise TypeError(f"sensor component {self.component!r} must be a dataclass")
        _check_schema(self.component, f"sensor {self.component.__name__}")
        _check_system_class(self.system, f"sensor {self.component.__name__}")

    @property
    def systems(self) -> tuple[type, ...]:
        return (self.system,)


@dataclass(frozen=True)
class ControllerPlugin:
    """A controller for one layer of a vehicle (see :mod:`unetyemu_ecs.control.layers`).

    ``law(setpoint, state, airframe, params, memory, dt_s) -> (command, new_memory)`` is a pure,
    vectorised function over the N vehicles that use this controller; the types of its arguments
    and command are the layer's (``INPUT_OF_LAYER`` / ``OUTPUT_OF_LAYER``). ``params`` is a frozen
    dataclass: the world-file schema of ``controller.<layer>.params`` (with ``Annotated`` ranges)
    and, one instance per vehicle, the ECS component that puts the vehicle in this controller's
    rows; the law receives it with every field stacked into an (N,) array, so fields must be
    numbers. ``memory`` declares the law's per-vehicle state: name -> (tail shape, initial value);
    it lives in the fleet arrays as ``ctl_<params class name>_<name>`` and is reset to the initial
    value while a drone is disarmed (attitude and mixer layers) and whenever a vehicle enters a
    position- or speed-controlled mode (position layer: AUTO, VELOCITY; drive layer: ROUTE, VELOCITY).
    """

    layer: Layer
    params: type
    law: Callable[..., tuple[Any, dict[str, Any]]]
    memory: Mapping[str, tuple[tuple[int, ...], float]] = field(default_factory=dict)
    summary: str = ""

    def __post_init__(self) -> None:
        object.__setattr__(self, "layer", Layer(self.layer))
        if not dataclasses.is_dataclass(self.params):
            raise TypeError(f"controller params {self.params!r} must be a dataclass")
        _check_schema(self.params, f"controller params {self.params.__name__}")
        _check_numeric_params(self.params, f"controller params {self.params.__name__}")
        if not callable(self.law):
            raise TypeError(f"controller law {self.law!r} must be callable")
        for name, spec in self.memory.items():
            if not (isinstance(name, str) and name.isidentifier() and isinstance(spec, tuple) and len(spec) == 2):
                raise TypeError(f"controller memory {name!r}: expected name -> (tail shape, initial value)")

    @property
    def applies_to(self) -> frozenset[str]:
        """The vehicle kinds that have this controller's layer."""
        return frozenset(k for k, layers in LAYERS_OF_KIND.items() if self.layer in layers)


_EXPECTED = {GROUP_COMPONENTS: ComponentPlugin, GROUP_SYSTEMS: SystemPlugin, GROUP_SENSORS: SensorPlugin,
             GROUP_CONTROLLERS: ControllerPlugin, GROUP_TRANSPORTS: TransportPlugin}


@dataclass(frozen=True)
class PluginEntry:
    """One registered part: its key, group, spec and the distribution that provides it."""

    key: str
    group: str
    spec: ComponentPlugin | SystemPlugin | SensorPlugin | ControllerPlugin | TransportPlugin
    provider: str


@dataclass
class Registry:
    """Everything installed, by group and key; ``failures`` holds plugins that could not load."""

    entries: dict[str, dict[str, PluginEntry]] = field(default_factory=lambda: {g: {} for g in GROUPS})
    failures: dict[tuple[str, str], str] = field(default_factory=dict)

    @classmethod
    def discover(cls) -> Registry:
        """Load every entry point of every group from the installed distributions."""
        reg = cls()
        for group in GROUPS:
            for ep in sorted(entry_points(group=group), key=lambda e: e.name):
                reg._load(ep, group)
        return reg

    def _load(self, ep: EntryPoint, group: str) -> None:
        provider = ep.dist.name if ep.dist is not None else "?"
        try:
            spec = ep.load()
            if callable(spec) and not isinstance(spec, _EXPECTED[group]):
                spec = spec()  # a factory returning the spec
            self.add(group, ep.name, spec, provider)
        except Exception as exc:  # a broken plugin must not take the simulator down
            self.failures[(group, ep.name)] = f"{provider}: {type(exc).__name__}: {exc}"

    def add(self, group: str, key: str, spec: Any, provider: str = "<api>") -> None:
        """Register ``spec`` under ``key`` in ``group`` (also used by tests and embedding code)."""
        if group not in GROUPS:
            raise ValueError(f"unknown plugin group {group!r}; expected one of {GROUPS}")
        if not isinstance(spec, _EXPECTED[group]):
            raise TypeError(f"entry point {key!r} in {group} must provide a {_EXPECTED[group].__name__}, "
                            f"got {type(spec).__name__}")
        if group == GROUP_CONTROLLERS:
            for other in self.entries[group].values():
                if other.spec.params is spec.params and other.key != key:
                    raise ValueError(f"controllers {other.key!r} and {key!r} share the params class "
                                     f"{spec.params.__name__}: each controller needs its own")
        if group in (GROUP_COMPONENTS, GROUP_SENSORS) and key in self.component_keys() and key not in self.entries[group]:
            other = self.component_entry(key)
            raise ValueError(f"component key {key!r} is provided twice ({other.provider} and {provider})")
        if key in self.entries[group]:
            raise ValueError(f"{group} key {key!r} is provided twice "
                             f"({self.entries[group][key].provider} and {provider})")
        self.entries[group][key] = PluginEntry(key, group, spec, provider)

    # -- lookup ----------------------------------------------------------------------------
    def component_keys(self) -> list[str]:
        """Keys usable under an entity's ``components`` (components and sensors), sorted."""
        return sorted([*self.entries[GROUP_COMPONENTS], *self.entries[GROUP_SENSORS]])

    def component_entry(self, key: str) -> PluginEntry:
        """The component or sensor registered as ``key``; ``KeyError`` with a helpful message otherwise."""
        for group in (GROUP_COMPONENTS, GROUP_SENSORS):
            if key in self.entries[group]:
                return self.entries[group][key]
        raise KeyError(self._unknown(key, [GROUP_COMPONENTS, GROUP_SENSORS], self.component_keys()))

    def system_entry(self, key: str) -> PluginEntry:
        """The world system registered as ``key``; ``KeyError`` with a helpful message otherwise."""
        if key in self.entries[GROUP_SYSTEMS]:
            return self.entries[GROUP_SYSTEMS][key]
        raise KeyError(self._unknown(key, [GROUP_SYSTEMS], sorted(self.entries[GROUP_SYSTEMS])))

    def controller_entry(self, key: str, layer: Layer | str | None = None) -> PluginEntry:
        """The controller registered as ``key`` (for ``layer``, if given); ``KeyError`` with the choices otherwise."""
        entries = self.entries[GROUP_CONTROLLERS]
        fits = sorted(k for k, e in entries.items() if layer is None or e.spec.layer == layer)
        if key in entries and (layer is None or entries[key].spec.layer == layer):
            return entries[key]
        if key in entries:
            article = "an" if str(layer)[:1] in "aeiou" else "a"
            raise KeyError(f"controller {key!r} is a {entries[key].spec.layer} controller, not {article} {layer} one "
                           f"({layer} controllers: {', '.join(fits) or 'none installed'})")
        message = self._unknown(key, [GROUP_CONTROLLERS], fits)
        raise KeyError(message.replace("unknown key", f"unknown {layer or ''} controller".replace("  ", " ")))

    def transports(self) -> list[PluginEntry]:
        """The registered transports, by name (each is asked to ``create`` one per simulation)."""
        return [e for _, e in sorted(self.entries[GROUP_TRANSPORTS].items())]

    def _unknown(self, key: str, groups: Iterable[str], available: list[str]) -> str:
        for group in groups:
            if (group, key) in self.failures:
                return f"plugin {key!r} is installed but failed to load: {self.failures[(group, key)]}"
        listed = ", ".join(available) if available else "none installed"
        return f"unknown key {key!r} (available: {listed})"

    def all_entries(self) -> list[PluginEntry]:
        return [e for g in GROUPS for _, e in sorted(self.entries[g].items())]
