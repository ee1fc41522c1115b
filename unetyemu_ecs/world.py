"""The esper world of one simulation, and the context every system receives each step.

esper keeps its worlds in module-level state and switches between them by name. This module is the
only caller of ``esper.switch_world`` and ``esper.delete_world``: every simulation owns one uniquely
named world and activates it for exactly as long as its systems or API calls touch entities, so two
simulations in one process never see each other's entities or processors.
"""

from __future__ import annotations

import time
import uuid
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import esper
import numpy as np

from .phases import Phase, priority
from .transport.api import CommandResult, CommandStatus

if TYPE_CHECKING:
    from .fleet import FleetState
    from .geodesy import GeodeticOrigin
    from .sensors.base import SensorOutputs
    from .physics.client import PhysicsClient
    from .scene.primitives import SceneLayout
    from .transport.bus import Inbox


def _sensor_outputs() -> SensorOutputs:
    from .sensors.base import SensorOutputs

    return SensorOutputs()


@dataclass
class SimServices:
    """World-level things systems may need besides the fleet arrays.

    Attributes
    ----------
    layout : the static scene (pads, parking spots, surface heights)
    inbox : commands from the API and transports, drained in COMMANDS
    entities : world-file name -> esper entity id
    events : (sim_time_s, vehicle, message) notices of rare events (mission steps, payload), in order
    pending : commands drained from the inbox this step, not yet taken by a command system
    results : CommandResult of every command applied or refused, in order (append-only, like events)
    sensors : sensor messages (newest per vehicle and sensor; this step's for publishers)
    gravity_enu_m_s2 : the world's gravity vector
    origin : the world's geodetic origin (WGS84) of the ENU frame
    air_density_kg_m3 : the world's air density (ISA at the origin unless the world file overrides it)
    raycast_threads : threads each LiDAR and camera ray cast may use (0: every core)
    """

    layout: SceneLayout
    inbox: Inbox
    entities: dict[str, int]
    events: list[tuple[float, str, str]]
    pending: list[Any] = field(default_factory=list)
    results: list[Any] = field(default_factory=list)
    sensors: SensorOutputs = field(default_factory=_sensor_outputs)
    gravity_enu_m_s2: tuple[float, float, float] = (0.0, 0.0, -9.81)
    origin: GeodeticOrigin | None = None
    air_density_kg_m3: float = 1.225
    raycast: Any = None          # the RaycastWorld of LiDARs and cameras, built by the first that needs it
    raycast_threads: int = 0     # threads of each ray cast (0: every core)
    camera_casts: dict[Any, Any] = field(default_factory=dict)   # this step's camera frames, shared (sensors.camera)
    _mesh: Any = None

    def scene_mesh(self) -> Any:
        """The static scene as one triangle mesh (built on first use, then shared: API, LiDAR, cameras)."""
        if self._mesh is None:
            from .scene.mesh import triangulate

            self._mesh = triangulate(self.layout)
        return self._mesh

    def report(self, sim_time_s: float, msg: Any, status: Any, reason: str = "", text: str = "") -> None:
        """Record the result of command ``msg`` (:class:`~unetyemu_ecs.transport.api.CommandResult`); a
        refusal or failure also goes to the event log as ``rejected <kind> command: <text>``."""
        self.results.append(CommandResult(msg.command_id, msg.vehicle, msg.kind, msg.source, CommandStatus(status),
                                          reason, text, round(sim_time_s, 6)))
        if status in (CommandStatus.REJECTED_INVALID, CommandStatus.REJECTED_STATE):
            self.note(sim_time_s, msg.vehicle, f"rejected {msg.kind} command: {text or reason}")
        elif status == CommandStatus.FAILED:
            self.note(sim_time_s, msg.vehicle, f"{msg.kind} command failed: {text or reason}")

    def note(self, sim_time_s: float, vehicle: str, message: str) -> None:
        """Record a rare event (never called per step in steady state)."""
        self.events.append((round(sim_time_s, 6), vehicle, message))


@dataclass(frozen=True, slots=True)
class StepContext:
    """Everything a system may use during one physics step; the only argument of ``process``.

    Attributes
    ----------
    step : index of the step being computed (0 for the first)
    sim_time_s : simulated time at the start of this step [s]
    dt_s : physics step [s]
    rng : the simulation's seeded random generator (never the global ``np.random``)
    fleet : hot per-body arrays
    physics : the PyBullet client wrapper (ACTUATE applies forces, PHYSICS steps, PAYLOAD joins bodies)
    services : layout, inbox, names, event notes
    """

    step: int
    sim_time_s: float
    dt_s: float
    rng: np.random.Generator
    fleet: FleetState
    physics: PhysicsClient
    services: SimServices


class StepProfile:
    """Wall time spent in each system (by class) over the profiled steps.

    The world charges each step's times to slots, one per system class, in running order (one clock reading
    per system: a system's slot also holds the loop's own cost of calling it)."""

    def __init__(self) -> None:
        self.steps = 0
        self._kinds: list[type] = []            # slot -> system class
        self._spent_s: list[float] = []         # slot -> seconds
        self._slot_of: dict[type, int] = {}

    def slots(self, kinds: list[type]) -> list[int]:
        """The slot of each system class in ``kinds`` (new ones get a slot at zero)."""
        for kind in kinds:
            if kind not in self._slot_of:
                self._slot_of[kind] = len(self._kinds)
                self._kinds.append(kind)
                self._spent_s.append(0.0)
        return [self._slot_of[kind] for kind in kinds]

    @property
    def spent_s(self) -> list[float]:
        """Seconds by slot (what the world adds to)."""
        return self._spent_s

    @property
    def seconds(self) -> dict[type, float]:
        """Seconds spent in each system class."""
        return dict(zip(self._kinds, self._spent_s))

    def rows(self) -> list[tuple[str, str, float, float]]:
        """``(phase, system, microseconds per step, share of the profiled time)`` for every system that ran,
        in running order of phases, the costliest first within a phase."""
        total = sum(self.seconds.values()) or 1.0
        steps = max(self.steps, 1)
        out = [(getattr(cls, "phase", Phase.OUTPUTS), cls.__name__, 1e6 * sec / steps, sec / total)
               for cls, sec in self.seconds.items()]
        out.sort(key=lambda r: (int(r[0]), -r[2]))
        return [(phase.name, name, us, share) for phase, name, us, share in out]

    def table(self) -> str:
        """The profile as a text table: per system, and a subtotal per phase."""
        rows = self.rows()
        total_us = sum(r[2] for r in rows)
        lines = [f"step profile over {self.steps} steps: {total_us:.0f} us per step in the systems",
                 f"{'phase':<15} {'system':<44} {'us/step':>9} {'share':>7}"]
        phase = None
        for name, system, us, share in rows:
            if name != phase:
                phase = name
                sub = sum(r[2] for r in rows if r[0] == name)
                lines.append(f"{name:<15} {'(phase total)':<44} {sub:9.1f} {sub / max(total_us, 1e-12):7.1%}")
            lines.append(f"{'':<15} {system[:44]:<44} {us:9.1f} {share:7.1%}")
        return "\n".join(lines)


class EcsWorld:
    """One named esper world plus its ordered systems."""

    def __init__(self, label: str = "sim") -> None:
        self.name = f"unetyemu-{label}-{uuid.uuid4().hex[:12]}"
        self._closed = False
        self._systems: list[tuple[int, Any]] = []
        self.profile: StepProfile | None = None     # per-system timing (``unetyemu run --profile``)
        self._profile_plan: tuple[StepProfile, list[tuple[int, Any]]] | None = None   # (profile, (slot, system)s)
        prev = esper.current_world
        esper.switch_world(self.name)  # creates it
        esper.switch_world(prev)

    @contextmanager
    def active(self) -> Iterator[None]:
        """Make this world esper's current one for the duration of the block."""
        if self._closed:
            raise RuntimeError(f"esper world {self.name} is closed")
        prev = esper.current_world
        if prev == self.name:
            yield
            return
        esper.switch_world(self.name)
        try:
            yield
        finally:
            esper.switch_world(prev)

    def add_system(self, system: Any) -> None:
        """Add ``system`` at the priority given by its ``phase`` and ``order`` attributes.

        Only one instance per system class is allowed (esper keys processors by type).
        """
        phase = getattr(system, "phase", None)
        if not isinstance(phase, Phase):
            raise ValueError(f"system {type(system).__name__} must declare a `phase` (a Phase member)")
        if any(type(s) is type(system) for _, s in self._systems):
            raise ValueError(f"a {type(system).__name__} is already in this world")
        prio = priority(phase, int(getattr(system, "order", 0)))
        with self.active():
            esper.add_processor(system, priority=prio)
        self._systems.append((prio, system))
        self._systems.sort(key=lambda ps: -ps[0])
        self._profile_plan = None

    def remove_system(self, system_type: type) -> None:
        """Take the system of class ``system_type`` out of this world (``ValueError`` if it has none)."""
        found = [(prio, s) for prio, s in self._systems if type(s) is system_type]
        if not found:
            raise ValueError(f"no {system_type.__name__} in this world")
        with self.active():
            esper.remove_processor(system_type)
        self._systems.remove(found[0])
        self._profile_plan = None

    @property
    def systems(self) -> list[Any]:
        """Systems in the order they run."""
        return [s for _, s in self._systems]

    def process(self, ctx: StepContext) -> None:
        """Run every system once, in phase order (the world must be active); timed per system while a
        :class:`StepProfile` is attached (``profile``)."""
        profile = self.profile
        if profile is None:
            esper.process(ctx)
            return
        esper.clear_dead_entities()
        plan = self._profile_plan
        if plan is None or plan[0] is not profile:
            systems = [system for _, system in self._systems]
            plan = self._profile_plan = (profile, list(zip(profile.slots([type(s) for s in systems]), systems)))
        spent, clock = profile.spent_s, time.perf_counter
        t0 = clock()
        for slot, system in plan[1]:
            system.process(ctx)
            t1 = clock()
            spent[slot] += t1 - t0
            t0 = t1
        profile.steps += 1

    def close(self) -> None:
        """Delete the esper world; further use raises."""
        if self._closed:
            return
        if esper.current_world == self.name:
            esper.switch_world("default")
        esper.delete_world(self.name)
        self._closed = True
