"""Simulation: build a world from its definition, then step or run it; no physics or maths here."""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import esper
import numpy as np

from .command_checks import (check_armed, check_cmd_vel, check_drive, check_drive_route, check_flag, check_mission,
                             check_set_target, check_teleop, is_real)
from .components.mission import MissionRuntime
from .config.schema import ConfigError, Issue
from .config.world_file import EntityDefinition, WorldDefinition, load_world
from .fleet import FleetState
from .geodesy import GeodeticOrigin
from .physics.client import PhysicsClient
from .physics.static_scene import build_static_scene
from .plugins import Registry
from .sensors.base import SensorSpec
from .sensors.tf import TransformSystem
from .systems.blackboard import declare_shared_arrays
from .systems.car_state import DriveMode
from .systems.controllers import controller_system
from .systems.fleet_system import FleetSystem
from .systems.commands import InboxSystem, UnclaimedCommandSystem
from .systems.impacts import ImpactMonitorSystem
from .systems.outputs import TrajectoryLogSystem
from .systems.physics import PhysicsStepSystem
from .systems.state import StateReadbackSystem
from .systems.wind import WindFieldSystem
from .config.limits import MAX_DURATION_S
from .mission import MissionSpec
from .navigation.commands_api import NavigationApi
from .transport.api import CommandResult, Transport, TransportOptions
from .transport.bus import Arm, CmdVel, Drive, DriveRoute, Inbox, LoadMission, SetTarget, Teleop
from .transport.ros2.bridge import resolve_backend
from .transport.snapshot import SnapshotBuilder, TransportSnapshotSystem
from .vehicles.factory import spawn_entity
from .world import EcsWorld, SimServices, StepContext


CLOSE_FLUSH_S = 1.0     # close() lets each transport send what it was offered for at most this [s, wall]
CLOSE_STOP_S = 2.0      # then waits at most this for its threads to end [s, wall]


def _check_mavlink(mavlink: object) -> bool:
    if not isinstance(mavlink, (bool, np.bool_)):
        raise ValueError(f"mavlink must be True or False, got {mavlink!r}")
    return bool(mavlink)


def _check_record(record: Any) -> Path | None:
    """The bag directory of ``record`` (a path, or None); a bad value raises ``ValueError`` naming it."""
    if record is None:
        return None
    if isinstance(record, bool) or not isinstance(record, (str, Path)) or not str(record).strip():
        raise ValueError(f"record must be the path of a new rosbag2 directory (or None), got {record!r}")
    from .transport.record import bag_directory

    return bag_directory(record)


def _check_record_topics(patterns: Any, record: Path | None) -> tuple[str, ...]:
    """Glob patterns of topic names to record (``/drone1/*``); a bad value raises ``ValueError`` naming it."""
    if patterns is None:
        return ()
    if isinstance(patterns, str) or not isinstance(patterns, (list, tuple)):
        raise ValueError(f"record_topics must be a list of topic patterns such as ['/drone1/*', '/tf'], "
                         f"got {patterns!r}")
    for pattern in patterns:
        if not isinstance(pattern, str) or not pattern.startswith(("/", "*")) or any(c.isspace() for c in pattern):
            raise ValueError(f"record_topics: {pattern!r} is not a topic pattern (a ROS 2 topic name such as "
                             "'/drone1/imu/data', '*' and '?' as wildcards)")
    if patterns and record is None:
        raise ValueError("record_topics was given without record (the path of the bag to record into)")
    return tuple(patterns)


def _check_port(name: str, port: Any) -> int | None:
    """A TCP port for a server on 127.0.0.1 (0: any free port), or None; a bad value raises ``ValueError``."""
    if port is None:
        return None
    if isinstance(port, (bool, np.bool_)) or not isinstance(port, (int, np.integer)) or not 0 <= int(port) <= 65535:
        raise ValueError(f"{name} must be a TCP port from 0 (any free port) to 65535, or None; got {port!r}")
    return int(port)


def _check_bind(address: object) -> str:
    import ipaddress

    try:
        return str(ipaddress.ip_address(address))  # type: ignore[arg-type]
    except ValueError:
        raise ValueError(f"mavlink_bind must be an IPv4 or IPv6 address such as 127.0.0.1, got {address!r}") from None


class UnknownEntityError(ValueError, KeyError):
    """No vehicle or package of that name in this simulation (a ``ValueError``, and a ``KeyError``
    for code that looks names up)."""

    __str__ = ValueError.__str__     # not KeyError's quoted repr


class SimulationClosedError(RuntimeError):
    """A :class:`Simulation` was used after :meth:`Simulation.close`."""


@dataclass(frozen=True)
class RunStats:
    """What one call to :meth:`Simulation.run` did."""

    sim_time_s: float        # simulated time at the end of the run
    sim_elapsed_s: float     # simulated time covered by this run
    wall_time_s: float       # wall-clock time it took
    steps: int               # physics steps taken by this run
    interrupted: bool        # stopped by Ctrl-C or stop()
    cpu_time_s: float = 0.0  # CPU time of this process meanwhile (all its threads) [s]

    @property
    def real_time_factor(self) -> float:
        """Simulated seconds per wall-clock second."""
        return self.sim_elapsed_s / self.wall_time_s if self.wall_time_s > 0 else float("inf")

    @property
    def cpu_real_time_factor(self) -> float:
        """Simulated seconds per CPU second: what the machine's speed allows, whatever else runs on it
        (the wall-clock factor falls on a busy machine, this one does not)."""
        return self.sim_elapsed_s / self.cpu_time_s if self.cpu_time_s > 0 else float("inf")


ProgressFn = Callable[[float, float, float], None]   # (sim_time_s, end_time_s, wall_elapsed_s)
MAX_BLAS_THREADS = 256


def _check_blas_threads(threads: Any) -> None:
    if threads is not None and (isinstance(threads, bool) or not isinstance(threads, int)
                                or not 1 <= threads <= MAX_BLAS_THREADS):
        raise ValueError(f"blas_threads must be None or an integer in [1, {MAX_BLAS_THREADS}], got {threads!r}")


def _limit_blas_threads(threads: int | None) -> Any:
    """Limit BLAS to ``threads`` threads (threadpoolctl); the limiter, to restore them, or None when nothing
    was changed (no limit asked, or BLAS already within it: e.g. another open simulation limited it, and
    then only that one restores it, so simulations closed in any order leave BLAS as it was)."""
    if threads is None:
        return None
    from threadpoolctl import threadpool_info, threadpool_limits

    if all(lib["num_threads"] <= threads for lib in threadpool_info() if lib["user_api"] == "blas"):
        return None

    return threadpool_limits(limits=threads, user_api="blas")


class Simulation(NavigationApi):
    """One simulated world: an esper world, a PyBullet client, the sim clock and the fleet arrays.

    Parameters
    ----------
    world : a validated :class:`WorldDefinition` (see :func:`load_world`)
    gui : open the PyBullet GUI instead of running headless
    out_dir : where to write logs; ``None`` writes nothing
    ros2 : ``"off"`` (default): no ROS 2; ``"dds"``: the simulator is a ROS 2 node over its own DDS
        participant (no ROS install needed); ``"rclpy"``: a node of the sourced ROS 2; ``"auto"``:
        rclpy when it imports, else dds. It publishes every sensor message, TF, ``/clock`` and
        mission status and listens to each vehicle's command topics (docs/architecture.md §6).
    mavlink : give every drone a MAVLink endpoint, also those without a ``mavlink`` component
        (``unetyemu run --mavlink``; docs/architecture.md §7)
    mavlink_bind : the address those endpoints bind (default loopback only)
    record : record every topic the ROS 2 transport would publish into a rosbag2 (MCAP storage) at this
        new directory (``ros2 bag info`` / ``play`` and Foxglove read it; no ROS 2 needed); None: no recording
    record_topics : record only the topics matching these glob patterns (``["/drone1/*", "/tf", "/clock"]``);
        None (default): every topic
    foxglove : serve the Foxglove WebSocket protocol on 127.0.0.1 at this TCP port (0: any free port), so
        Foxglove or Lichtblick watch the run live; None (default): no server
    view : serve the built-in 3D web view on 127.0.0.1 at this TCP port (0: any free port); None (default): none
    blas_threads : threads numpy's BLAS (OpenBLAS) may use while the simulation is open (default 1; None
        leaves them as they are). The sensors' products are small: with more threads BLAS spins on the
        other cores, and on a 2-core machine running the transports beside it that cost 44 % more CPU
        time for the same frames. The previous limit comes back at :meth:`close`.
    raycast_threads : threads each LiDAR and camera ray cast (Open3D) may use; 0 (default): every core.
        1 keeps a simulation on one core, as ``unetyemu sweep`` runs it beside others.

    Transports (ROS 2, MAVLink, and those of other packages: entry-point group
    ``unetyemu_ecs.transports``) are created from these options and started with the world; one
    that cannot start raises :class:`~unetyemu_ecs.transport.api.TransportError` (nothing is left
    open). They publish from their own threads; :meth:`flush_transports` waits for them.
    """

    def __init__(self, world: WorldDefinition, *, gui: bool = False, out_dir: str | Path | None = None,
                 ros2: str = "off", mavlink: bool = False, mavlink_bind: str = "127.0.0.1",
                 record: str | Path | None = None, record_topics: list[str] | tuple[str, ...] | None = None,
                 foxglove: int | None = None, view: int | None = None,
                 blas_threads: int | None = 1, raycast_threads: int = 0) -> None:
        spec = world.spec.world
        self.definition = world
        self._blas_limit: Any = None
        _check_blas_threads(blas_threads)
        if isinstance(raycast_threads, bool) or not isinstance(raycast_threads, int) \
                or not 0 <= raycast_threads <= MAX_BLAS_THREADS:
            raise ValueError(f"raycast_threads must be an integer in [0, {MAX_BLAS_THREADS}] (0: every core), "
                             f"got {raycast_threads!r}")
        self.ros2 = ros2
        self.ros2_backend = resolve_backend(ros2)        # "off", "rclpy" or "dds"
        self._options = TransportOptions(self.ros2_backend, _check_mavlink(mavlink), _check_bind(mavlink_bind),
                                         Path(out_dir) if out_dir is not None else None,
                                         record=_check_record(record),
                                         record_topics=_check_record_topics(record_topics, _check_record(record)),
                                         foxglove=_check_port("foxglove", foxglove),
                                         view=_check_port("view", view))
        self._transports: list[Transport] = []
        self._result_index: dict[int, CommandResult] = {}
        self._results_indexed = 0
        self.dt_s = 1.0 / spec.physics_hz
        self.seed = spec.seed
        self.rng = np.random.default_rng(spec.seed)
        self.fleet = FleetState()
        declare_shared_arrays(self.fleet)
        self.step_count = 0
        self.out_dir = Path(out_dir) if out_dir is not None else None
        self._stop_requested = False
        self._closed = False
        self._profile: Any = None           # StepProfile of profile_steps()
        self._built = False             # construction finished (close() then writes the summary)
        self.wall_time_s = 0.0          # wall-clock time spent in step() and run() so far [s]
        self.cpu_time_s = 0.0           # CPU time of this process meanwhile [s]
        self.interrupted = False        # a run() was stopped by Ctrl-C or stop()
        self._entities: dict[str, int] = {}
        self._log: TrajectoryLogSystem | None = None
        self.inbox = Inbox()
        self.services = SimServices(world.layout, self.inbox, self._entities, [],
                                    gravity_enu_m_s2=tuple(spec.gravity_m_s2),
                                    origin=GeodeticOrigin(spec.origin.lat_deg, spec.origin.lon_deg, spec.origin.alt_m),
                                    air_density_kg_m3=spec.air_density_kg_m3(), raycast_threads=raycast_threads)
        self.ecs = EcsWorld(label=world.name)
        self.physics: PhysicsClient | None = None
        self._blas_limit = _limit_blas_threads(blas_threads)
        try:
            self.physics = PhysicsClient(self.dt_s, spec.gravity_m_s2, gui=gui)
            self.static_body_ids = build_static_scene(self.physics.id, world.layout)
            with self.ecs.active():
                for ent in world.entities:
                    self._entities[ent.name] = spawn_entity(self.physics, self.fleet, ent)
            self._add_systems(world)
            self.physics.finish_loading()
            with self.ecs.active():
                self._state.prime(self._context())
                for system in self._fleet_systems:   # their state at t = 0 (battery full, power drawn)
                    system.refresh(self._context())
                if self._log is not None:
                    self._log.write_rows(self._context(), 0.0)
                self._start_transports(world)
            self._built = True
        except BaseException:
            self.close()
            raise

    @classmethod
    def from_file(cls, path: str | Path, *, seed: int | None = None, registry: Registry | None = None,
                  **kwargs: Any) -> Simulation:
        """Load, validate and build the world in ``path``."""
        return cls(load_world(path, registry=registry, seed=seed), **kwargs)

    # -- building ----------------------------------------------------------------------------
    def _add_systems(self, world: WorldDefinition) -> None:
        self._state = StateReadbackSystem()
        systems: list[Any] = [InboxSystem(), UnclaimedCommandSystem(), PhysicsStepSystem(), self._state,
                              ImpactMonitorSystem(self.static_body_ids, world.layout), TransformSystem()]
        classes: list[type] = []
        for ent in world.entities:
            for key in ent.components:
                for cls in world.registry.component_entry(key).spec.systems:
                    if cls not in classes:
                        classes.append(cls)
        systems += [cls() for cls in classes]
        in_use = dict.fromkeys(name for ent in world.entities for name, _params in ent.controllers.values())
        systems += [controller_system(name, world.registry.controller_entry(name).spec) for name in in_use]
        if world.spec.world.wind is not None:
            systems.append(WindFieldSystem(world.spec.world.wind, world.spec.world.seed))
        for key, cfg in world.systems.items():
            systems.append(world.registry.system_entry(key).spec.system(cfg))
        if self.out_dir is not None:
            self.out_dir.mkdir(parents=True, exist_ok=True)
            spec = world.spec.world
            self._log = TrajectoryLogSystem(self.out_dir, round(spec.physics_hz / spec.log_hz), self.services.origin)
            systems.append(self._log)
        for s in systems:
            self.ecs.add_system(s)
        self._fleet_systems = [s for s in systems if isinstance(s, FleetSystem)]

    def _start_transports(self, world: WorldDefinition) -> None:
        """Create every installed transport enabled for this world and these options, and start each
        with the snapshot of the built world; a :class:`TransportError` propagates (the caller closes)."""
        created = []
        for entry in world.registry.transports():
            transport = entry.spec.create(world, self._options)
            if transport is not None:
                created.append(transport)
        if not created:
            return
        builder = SnapshotBuilder([(e.name, e.kind) for e in world.vehicles])
        first = builder.build(self._context(), self.step_count, self.sim_time_s, first=True)
        self.ecs.add_system(TransportSnapshotSystem(builder, self._transports))
        for transport in created:
            self._transports.append(transport)         # stopped by close() even if start fails half-way
            transport.start(self.inbox, first)

    def transport_counters(self) -> dict[str, dict[str, Any]]:
        """Each transport's counters (messages, drops, errors), by name: ``summary.json["transports"]``."""
        return {t.name: t.counters() for t in self._transports}

    @property
    def transports(self) -> dict[str, Transport]:
        """The started transports by name (``ros2``, ``mavlink``, ...)."""
        return {t.name: t for t in self._transports}

    def flush_transports(self, timeout_s: float = 2.0) -> bool:
        """Wait until every transport has handled what the simulation offered it so far (published,
        sent): at most ``timeout_s`` seconds of wall time per transport; True when all had."""
        if not (is_real(timeout_s) and math.isfinite(timeout_s) and 0 <= timeout_s <= 600):
            raise ValueError(f"flush_transports(): timeout_s must be a number of seconds in [0, 600], "
                             f"got {timeout_s!r}")
        return all([t.flush(float(timeout_s)) for t in self._transports])

    @property
    def ros2_topics(self) -> list[str]:
        """The ROS 2 topics this simulation has published so far (empty with ROS 2 off)."""
        ros2 = self.transports.get("ros2")
        return list(getattr(ros2, "topics", [])) if ros2 is not None else []

    # -- clock -------------------------------------------------------------------------------
    @property
    def sim_time_s(self) -> float:
        """Simulated time now [s] (exact multiple of the physics step)."""
        return self.step_count * self.dt_s

    def _context(self) -> StepContext:
        assert self.physics is not None
        return StepContext(self.step_count, self.step_count * self.dt_s, self.dt_s, self.rng, self.fleet,
                           self.physics, self.services)

    def step(self, n: int = 1) -> None:
        """Advance ``n`` physics steps (an integer >= 0), running every phase in order each step."""
        self._require_open()
        if isinstance(n, (bool, np.bool_)) or not isinstance(n, (int, np.integer)) or n < 0:
            raise ValueError(f"step(n): n must be an integer >= 0 (physics steps of {self.dt_s:g} s), got {n!r}")
        wall0, cpu0 = time.perf_counter(), time.process_time()
        try:
            with self.ecs.active():
                for _ in range(int(n)):
                    self._step_once()
        finally:
            self.wall_time_s += time.perf_counter() - wall0
            self.cpu_time_s += time.process_time() - cpu0

    def _step_once(self) -> None:
        """One physics step through every phase (the esper world must be active)."""
        self.services.sensors.this_step.clear()
        self.ecs.process(self._context())
        self.step_count += 1

    def stop(self) -> None:
        """Ask a running :meth:`run` to return after the current step (thread-safe)."""
        self._stop_requested = True

    def run(self, until: float | None = None, *, duration: float | None = None, rate: float | None = None,
            progress: ProgressFn | None = None, progress_interval_s: float = 0.5) -> RunStats:
        """Run until sim time ``until`` (or for ``duration`` seconds of sim time).

        ``rate`` paces simulated time to ``rate`` x wall-clock time (1.0 = real time); ``None`` runs
        as fast as possible. ``progress`` is called about every ``progress_interval_s`` of wall time.
        Ctrl-C ends the run cleanly (``interrupted`` is set) and leaves the logs intact.
        """
        self._require_open()
        if (until is None) == (duration is None):
            raise ValueError("give exactly one of until= or duration=")
        given = until if until is not None else duration
        if not is_real(given) or not math.isfinite(given):
            raise ValueError(f"run(): {'until' if until is not None else 'duration'} must be a finite number of "
                             f"seconds, got {given!r}")
        if duration is not None and duration <= 0:
            raise ValueError(f"run(): duration must be > 0 s, got {duration!r}")
        end_s = float(until) if until is not None else self.sim_time_s + float(duration)  # type: ignore[arg-type]
        if end_s < self.sim_time_s:
            raise ValueError(f"run(): until={until!r} s is before the current sim time {self.sim_time_s:g} s")
        if end_s - self.sim_time_s > MAX_DURATION_S:
            raise ValueError(f"run(): at most {MAX_DURATION_S:g} s (a week) of sim time per call, got "
                             f"{end_s - self.sim_time_s:g} s")
        if rate is not None and not (is_real(rate) and math.isfinite(rate) and rate > 0):
            raise ValueError(f"rate must be a finite number > 0 or None (as fast as possible), got {rate!r}")
        end_step = int(round(end_s / self.dt_s))
        start_step = self.step_count
        self._stop_requested = False
        wall0, cpu0 = time.perf_counter(), time.process_time()
        next_report = wall0 + progress_interval_s
        interrupted = False
        try:
            with self.ecs.active():
                while self.step_count < end_step and not self._stop_requested:
                    self._step_once()
                    now = time.perf_counter()
                    if rate is not None:
                        ahead_s = wall0 + (self.step_count - start_step) * self.dt_s / rate - now
                        if ahead_s > 0.001:
                            time.sleep(ahead_s)
                    if progress is not None and now >= next_report:
                        progress(self.sim_time_s, end_step * self.dt_s, now - wall0)
                        next_report = now + progress_interval_s
        except KeyboardInterrupt:
            interrupted = True
        interrupted = interrupted or self._stop_requested
        wall_s, cpu_s = time.perf_counter() - wall0, time.process_time() - cpu0
        self.wall_time_s += wall_s
        self.cpu_time_s += cpu_s
        self.interrupted = self.interrupted or interrupted
        return RunStats(self.sim_time_s, (self.step_count - start_step) * self.dt_s, wall_s,
                        self.step_count - start_step, interrupted, cpu_s)

    # -- commands (applied at the next step's COMMANDS phase) ---------------------------------
    # Each returns the command's id; command_result(id) says what became of it after the next step.
    def _drone(self, name: str) -> int:
        return self._of_kind(name, "quadrotor", "a drone")

    def _car(self, name: str) -> int:
        return self._of_kind(name, "car", "a car")

    def _of_kind(self, name: str, kind: str, what: str) -> int:
        ent = self.entity(name)
        actual = self.definition_of(name).kind
        if actual != kind:
            raise ValueError(f"{name!r} is a {actual}, not {what}")
        return ent

    def set_target(self, name: str, x: float, y: float, z: float = 0.0, yaw_deg: float | None = None,
                   speed: float | None = None) -> int:
        """Send vehicle ``name`` to ENU ``(x, y, z)`` [m] at ``speed`` [m/s] (None = its default).

        A drone flies there (cancelling a running mission) and faces ``yaw_deg`` (ENU, None = keep);
        a car drives there on the ground (``z`` and ``yaw_deg`` are ignored) and stops. Raises
        ``ValueError`` for non-finite values, a non-positive speed, or a package.
        """
        kind = self.definition_of(name).kind
        if kind == "package":
            raise ValueError(f"{name!r} is a package, not a vehicle")
        pos_enu_m, yaw_rad, speed_m_s = check_set_target(name, kind, self.layout, x, y, z, yaw_deg, speed)
        return self.inbox.submit(SetTarget(name, pos_enu_m, yaw_rad, speed_m_s))

    def command_timeout_s(self, name: str) -> float:
        """How long a streamed teleop/cmd_vel for vehicle ``name`` holds without a newer one [s] (0 = forever);
        the world file's ``command_timeout_s`` (default 0.5 s)."""
        self.definition_of(name)
        spec = next(v for v in self.definition.spec.vehicles if v.name == name)
        return spec.command_timeout_s

    def load_mission(self, name: str, mission: str | MissionSpec) -> int:
        """Load a mission (JSON text in our or the paper's format, or a MissionSpec) and start it.

        A bad mission is rejected whole with a :class:`ConfigError` naming the step and field; the
        drone keeps doing what it was doing. Returns the command id (:meth:`command_result`).
        """
        self._drone(name)
        spec = check_mission(name, "load_mission", self.layout, self.package_names, mission)
        return self.inbox.submit(LoadMission(name, spec))

    def teleop(self, name: str, throttle: float, pitch: float, roll: float, yaw: float, *,
               hold_s: float | None = None) -> int:
        """Fly drone ``name`` by sticks in [-1, 1] (MANUAL mode; see the stabilizer for the mapping).

        The sticks are held until the next command, or for ``hold_s`` seconds of sim time, after
        which the drone hovers where it is (commands from ROS 2 topics hold for the vehicle's
        :meth:`command_timeout_s`).
        """
        self._drone(name)
        return self.inbox.submit(Teleop(name, *check_teleop(name, throttle, pitch, roll, yaw, hold_s)))

    def arm(self, name: str, armed: bool = True, *, force: bool = False) -> int:
        """Arm (hold position) or disarm (motors off) drone ``name``, with PX4's checks: arming is
        refused (REJECTED_STATE) with reason ``low_battery``, ``overweight``, ``motors_disabled``,
        ``outside_fence`` or ``in_air``, disarming in the air with ``in_air``; ``force`` skips the
        checks (MAVLink param2 = 21196). For a car: release the parking brake and hold still under
        speed control, or park it (brakes on). Returns the command id."""
        if self.definition_of(name).kind == "package":
            raise ValueError(f"{name!r} is a package, not a vehicle")
        return self.inbox.submit(Arm(name, check_armed(name, armed), check_flag("force", force)))

    def drive(self, name: str, throttle: float, brake: float, steering: float, *,
              hold_s: float | None = None) -> int:
        """Drive car ``name`` by hand (MANUAL): ``throttle`` in [-1, 1] (negative = reverse), ``brake``
        in [0, 1], ``steering`` in [-1, 1] (+1 = full left; the limit shrinks with speed). Held until
        the next command, or for ``hold_s`` seconds of sim time (then the car brakes to a stop)."""
        self._car(name)
        return self.inbox.submit(Drive(name, *check_drive(name, throttle, brake, steering, hold_s)))

    def cmd_vel(self, name: str, forward_m_s: float, yaw_rate_rad_s: float, left_m_s: float = 0.0,
                up_m_s: float = 0.0, *, hold_s: float | None = None) -> int:
        """Body-frame velocity command (ROS ``cmd_vel``), held until the next command or for ``hold_s``
        seconds of sim time (then a drone hovers, a car brakes to a stop).

        ``forward_m_s`` [m/s] (negative = backwards) and ``yaw_rate_rad_s`` [rad/s], CCW positive
        (``linear.x`` and ``angular.z``). A drone switches to VELOCITY mode (cancelling a running
        mission) and also flies ``left_m_s`` and ``up_m_s`` (``linear.y``, ``linear.z``; climb and
        descent and yaw rate clamped to its limits); a car drives at the speed and yaw rate and
        ignores the sideways and vertical parts.
        """
        kind = self.definition_of(name).kind
        if kind not in ("quadrotor", "car"):
            raise ValueError(f"cmd_vel({name!r}): {name!r} is a {kind}, not a vehicle")
        return self.inbox.submit(CmdVel(name, *check_cmd_vel(name, forward_m_s, yaw_rate_rad_s, left_m_s, up_m_s,
                                                             hold_s)))

    def drive_route(self, name: str, waypoints: list[tuple[float, float]], speed: float | None = None,
                    loop: bool = False, laps: int = 0) -> int:
        """Drive car ``name`` through ENU ``(x, y)`` waypoints [m] in order at ``speed`` [m/s] (slower
        in corners), stopping at the last; with ``loop`` go round ``laps`` times (0 = forever)."""
        self._car(name)
        return self.inbox.submit(DriveRoute(name, *check_drive_route(name, self.layout, waypoints, speed, loop, laps)))

    def command_result(self, command_id: int) -> CommandResult | None:
        """The newest result of the command with id ``command_id`` (what a command method returned):
        accepted, or rejected with a machine reason and a text (``CommandResult``); None while it
        waits for the next step (or for an id never given out)."""
        self._require_open()
        results = self.services.results
        for res in results[self._results_indexed:]:
            self._result_index[res.command_id] = res
        self._results_indexed = len(results)
        return self._result_index.get(command_id)

    def mission_status(self, name: str) -> dict[str, Any] | None:
        """Status of the drone's mission (step, step type, state, reason), or None without one."""
        self._require_open()
        with self.ecs.active():
            rt = esper.try_component(self.entity(name), MissionRuntime)
            return None if rt is None else rt.status()

    def drive_status(self, name: str) -> dict[str, Any]:
        """Status of car ``name``: drive mode, route state ("driving", "done" or "" without one), laps done."""
        self._car(name)
        f, row = self.fleet, self.row(name)
        mode = DriveMode(int(f.drive_mode[row]))
        route = "done" if f.path_done[row] else ("driving" if mode == DriveMode.ROUTE else "")
        return {"mode": mode.name.lower(), "route": route, "laps": int(f.path_laps[row])}

    def sensor(self, vehicle: str, key: str) -> Any:
        """The newest message of sensor ``key`` (``imu``, ``gps``, ``lidar``...) on ``vehicle``, or None
        before its first sample. A ROS 2 Jazzy message object (see :mod:`unetyemu_ecs.sensors.messages`)."""
        self.entity(vehicle)
        mounted = self.sensor_keys(vehicle)
        if key not in mounted:
            raise ValueError(f"{vehicle!r} has no sensor {key!r} (it has: {', '.join(mounted) or 'none'})")
        sample = self.services.sensors.latest.get((vehicle, key))
        return None if sample is None else sample.msg

    def sensor_keys(self, vehicle: str) -> list[str]:
        """The keys :meth:`sensor` answers for ``vehicle``: the sensors it carries now (attached in the
        world file or by :meth:`attach`), and ``<camera>_info`` for each camera's CameraInfo."""
        keys = []
        for key, comp in self.components_of(vehicle).items():
            if isinstance(comp, SensorSpec):
                keys.append(key)
                if comp.OPTICAL:
                    keys.append(f"{key}_info")
        return keys

    def components_of(self, name: str) -> dict[str, Any]:
        """World-file key -> component that vehicle or package ``name`` carries now (plugins included)."""
        eid = self.entity(name)
        reg = self.definition.registry
        with self.ecs.active():
            have = {type(c): c for c in esper.components_for_entity(eid)}
        found = {}
        for entry in reg.all_entries():
            comp_type = getattr(entry.spec, "component", None)
            if comp_type is not None and comp_type in have:
                found[entry.key] = have[comp_type]
        if MissionRuntime in have:
            found["mission"] = have[MissionRuntime].spec
        in_file = [k for k in self.definition_of(name).components if k in found]    # world-file order first
        return {k: found[k] for k in [*in_file, *(k for k in found if k not in in_file)]}

    def attach(self, name: str, key: str, **params: Any) -> Any:
        """Give vehicle or package ``name`` the component or sensor ``key`` (a world-file key: ``aero_drag``,
        ``imu``, ``lidar``, a plugin's...) from the next step on, with ``params`` checked like the
        world file's block (a vehicle's preset values fill what is not given). An existing component
        of that key is replaced. The systems that act on it are added if the world had none.
        Returns the component. Bad keys and parameters raise :class:`ConfigError` naming them."""
        from dataclasses import replace

        from .config.schema import INVALID, SourceMap
        from .config.world_file import resolve_component
        from .vehicles.presets import component_tables

        ent = self.definition_of(name)
        where = f"attach({name!r}, {key!r})"
        if key == "mission":
            raise ConfigError([Issue(where, None, (key,), "a mission is started with load_mission(), not attached")])
        block = {**component_tables(ent.params).get(key, {}), **params} if ent.kind != "package" else dict(params)
        issues: list[Issue] = []
        comp = resolve_component(key, block, ent.kind, self.definition.registry, (key,), SourceMap(where), issues)
        if comp is INVALID:
            raise ConfigError(issues)
        entry = self.definition.registry.component_entry(key)
        if isinstance(comp, SensorSpec) and not ent.ros2:
            comp = replace(comp, ros2=False)
        eid = self.entity(name)
        with self.ecs.active():
            esper.add_component(eid, comp)
            present = {type(s) for s in self.ecs.systems}
            for cls in entry.spec.systems:
                if cls not in present:
                    self.ecs.add_system(cls())
        return comp

    def detach(self, name: str, key: str) -> None:
        """Take component or sensor ``key`` off vehicle or package ``name`` from the next step on (the
        systems that act on it stop acting on it). A key it does not carry raises ``ValueError``."""
        carried = self.components_of(name)
        if key not in carried or key == "mission":
            raise ValueError(f"detach({name!r}, {key!r}): {name!r} carries no {key!r} (it carries: "
                             f"{', '.join(k for k in carried if k != 'mission') or 'none'})")
        with self.ecs.active():
            esper.remove_component(self.entity(name), type(carried[key]))
        self.services.sensors.latest.pop((name, key), None)

    def transforms(self) -> tuple[Any, Any]:
        """The newest ``/tf`` and ``/tf_static`` TFMessages (None before the first step)."""
        self._require_open()
        latest = self.services.sensors.latest
        tf, static = latest.get(("", "tf")), latest.get(("", "tf_static"))
        return (None if tf is None else tf.msg), (None if static is None else static.msg)

    @property
    def events(self) -> list[tuple[float, str, str]]:
        """Rare events so far (mission steps, pickups, rejected commands): (sim time, vehicle, text)."""
        return list(self.services.events)

    # -- queries -----------------------------------------------------------------------------
    def definition_of(self, name: str) -> EntityDefinition:
        """The world-file definition of vehicle or package ``name``; :class:`UnknownEntityError` if none."""
        self._require_open()
        for ent in self.definition.entities:
            if ent.name == name:
                return ent
        raise UnknownEntityError(self._unknown(name))

    @property
    def vehicle_names(self) -> list[str]:
        return [e.name for e in self.definition.vehicles]

    @property
    def package_names(self) -> list[str]:
        return [e.name for e in self.definition.packages]

    def entity(self, name: str) -> int:
        """esper entity id of the vehicle or package ``name``; :class:`UnknownEntityError` if none."""
        self._require_open()
        try:
            return self._entities[name]
        except (KeyError, TypeError):
            raise UnknownEntityError(self._unknown(name)) from None

    def _unknown(self, name: object) -> str:
        return f"no vehicle or package named {name!r} (have: {', '.join(self._entities)})"

    def _require_open(self) -> None:
        if self._closed:
            raise SimulationClosedError("this Simulation is closed; create a new one")

    def row(self, name: str) -> int:
        """Fleet row of ``name``."""
        return self.fleet.row_of(self.entity(name))

    def position_enu_m(self, name: str) -> np.ndarray:
        """Centre of ``name`` in ENU [m], (3,) copy."""
        return self.fleet.pos_enu_m[self.row(name)].copy()

    def attitude_enu_flu_xyzw(self, name: str) -> np.ndarray:
        """Attitude quaternion of ``name`` (body FLU in ENU), xyzw, (4,) copy."""
        return self.fleet.quat_enu_flu_xyzw[self.row(name)].copy()

    def velocity_enu_m_s(self, name: str) -> np.ndarray:
        """Velocity of ``name`` in ENU [m/s], (3,) copy."""
        return self.fleet.vel_enu_m_s[self.row(name)].copy()

    def component(self, name: str, component_type: type) -> Any:
        """The ``component_type`` component of entity ``name``."""
        self._require_open()
        with self.ecs.active():
            return esper.component_for_entity(self.entity(name), component_type)

    @property
    def layout(self):
        """The scene layout (objects, pads, parking spots)."""
        return self.definition.layout

    @property
    def scene_mesh(self):
        """The static scene as one triangle mesh with per-triangle object ids and classes (cached)."""
        return self.services.scene_mesh()

    @property
    def log_paths(self) -> dict[str, Path]:
        """CSV log per vehicle name (empty without ``out_dir``)."""
        return dict(self._log.paths) if self._log is not None else {}

    # -- profiling -------------------------------------------------------------------------------
    def profile_steps(self, enabled: bool = True) -> None:
        """Time every system of every following step (a fresh :class:`~unetyemu_ecs.world.StepProfile`,
        read with :attr:`step_profile`); ``enabled=False`` stops timing (the profile stays readable).
        Costs about a microsecond per system per step."""
        self._require_open()
        if enabled:
            from .world import StepProfile

            self._profile = self.ecs.profile = StepProfile()
        else:
            self.ecs.profile = None

    @property
    def step_profile(self) -> Any:
        """The :class:`~unetyemu_ecs.world.StepProfile` of :meth:`profile_steps` (None before it)."""
        return self._profile

    # -- life cycle --------------------------------------------------------------------------
    def summary(self) -> dict[str, Any]:
        """The run summary so far (what ``summary.json`` holds): world, seed, sim and wall time,
        real-time factor, every vehicle's distance, energy, impacts, final position and mission or
        route, and every event."""
        from .summary import build_summary

        self._require_open()
        sim_s = self.sim_time_s
        return build_summary(self, RunStats(sim_s, sim_s, self.wall_time_s, self.step_count, self.interrupted,
                                            self.cpu_time_s))

    def close(self) -> None:
        """Write ``summary.json`` (with ``out_dir``), flush and close logs, disconnect PyBullet and
        delete the esper world; safe to call twice. Any later use raises :class:`SimulationClosedError`."""
        if self._closed:
            return
        for transport in self._transports:      # first: no command arrives while the rest shuts down
            try:
                transport.flush(CLOSE_FLUSH_S)
            finally:
                transport.stop(CLOSE_STOP_S)
        if self._built and self.out_dir is not None:
            from .summary import write_summary

            try:
                write_summary(self.summary(), self.out_dir)
            except OSError as exc:
                self.services.note(self.sim_time_s, "", f"cannot write summary.json: {exc}")
        self._closed = True
        self._transports.clear()
        if self._blas_limit is not None:
            self._blas_limit.restore_original_limits()
            self._blas_limit = None
        if self._log is not None:
            self._log.close()
        if self.physics is not None:
            self.physics.close()
        self.ecs.close()

    def __enter__(self) -> Simulation:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
