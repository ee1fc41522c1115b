"""The edge contract between the simulation loop and its transports (ROS 2, MAVLink, recorders, live views).

A transport never runs on the simulation thread and never reads the ECS or PyBullet. Once per step
the OUTPUTS phase builds one immutable :class:`Snapshot` of what transports need and hands it to
every started transport with :meth:`Transport.offer`, which only appends it to the transport's own
bounded drop-oldest queue; the transport serialises and sends from its own thread. A slow or dead
peer therefore fills (and overflows) only its own queue: the loop never waits for it.

The other direction goes through a :class:`CommandPort`: a transport builds a command (the frozen
messages of :mod:`unetyemu_ecs.transport.bus`, validated by :mod:`unetyemu_ecs.command_checks`),
submits it and gets its id back. The command system that applies it reports a
:class:`CommandResult` for that id, which comes back in a later snapshot's ``results``; so a
MAVLink endpoint answers COMMAND_ACK truthfully and ROS 2 reports rejections without reading the
event log's text. Events (rare notices) are an append-only list: a transport keeps its own cursor
and reads ``snapshot.events[cursor:snapshot.events_end]``, so a dropped snapshot never loses an
event or a result (results are also kept in that list's order, see :class:`Snapshot`).

Transports are plugins: entry-point group ``unetyemu_ecs.transports``, value a
:class:`TransportPlugin` whose ``create`` returns a transport for this world and these options, or
None when it is not enabled (ROS 2 off, no drone with a ``mavlink`` component).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from enum import IntEnum
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol, runtime_checkable

import numpy as np

if TYPE_CHECKING:
    from ..config.world_file import WorldDefinition


class TransportError(RuntimeError):
    """A transport could not start (a port in use, a backend missing); the message names which and why."""


class CommandStatus(IntEnum):
    """What became of a submitted command."""

    ACCEPTED = 0           # applied; a long action (takeoff, land, RTL, a mission) has started
    REJECTED_INVALID = 1   # a value is wrong (NaN, out of range, unknown mode or vehicle): nothing applied
    REJECTED_STATE = 2     # valid, but not now (disarmed, in the air, no setpoint stream): nothing applied
    IN_PROGRESS = 3        # still being carried out (reported by long actions that say so)
    DONE = 4               # a long action finished as asked
    FAILED = 5             # tried and failed (nothing in reach of the gripper, no progress)


@dataclass(frozen=True, slots=True)
class CommandResult:
    """The answer to one submitted command.

    command_id : the id :meth:`CommandPort.submit` returned (0: a command submitted without one)
    vehicle : the vehicle it was for
    kind : the command's ``kind`` (``arm``, ``target``, ``nav_mode`` ...)
    source : who sent it (``api``, ``ros2``, ``mavlink``, or a transport's own name)
    status : :class:`CommandStatus`
    reason : machine-readable why for a rejection or failure (``not_armed``, ``low_battery``,
        ``in_air``, ``no_setpoint_stream``, ``overweight`` ...), "" when accepted
    text : the same for people (also in the event log)
    sim_time_s : when it was decided [s, sim time]
    """

    command_id: int
    vehicle: str
    kind: str
    source: str
    status: CommandStatus
    reason: str = ""
    text: str = ""
    sim_time_s: float = 0.0

    @property
    def ok(self) -> bool:
        return self.status in (CommandStatus.ACCEPTED, CommandStatus.IN_PROGRESS, CommandStatus.DONE)


@runtime_checkable
class CommandPort(Protocol):
    """Where a transport submits commands (thread-safe; the simulation's inbox implements it)."""

    def submit(self, command: Any) -> int:
        """Queue ``command`` for the next step; returns its id (> 0), which its result will carry."""
        ...

    def reject(self, vehicle: str, kind: str, text: str, source: str) -> int:
        """Report a sample that could not become a command (undecodable, wrong shape, a value out of
        range: ``text`` says why; ``kind`` names what it came as, e.g. the ROS 2 topic). It gets a
        REJECTED_INVALID result (reason ``invalid``) and an event at the next step, like a command
        refused there; returns its id."""
        ...


@dataclass(frozen=True, slots=True)
class Snapshot:
    """What transports see of one step, immutable (arrays are read-only copies, one row per vehicle).

    Times: ``sim_time_s`` is the end of the step (the stamp of everything measured in it).
    Rows follow ``vehicles`` (names, world-file order); ``kinds`` gives each one's kind
    (``quadrotor``, ``car``). Frames are the engine's: ENU metres, body FLU, quaternions xyzw.
    Per-vehicle arrays (N = len(vehicles)); rows of cars hold the fill values of the drone-only ones:

    pos_enu_m (N,3) · vel_enu_m_s (N,3) · acc_enu_m_s2 (N,3) · quat_enu_flu_xyzw (N,4) ·
    rate_flu_rad_s (N,3) · flight_mode (N,) int (FlightMode) · nav_state (N,) int (NavState) ·
    armed (N,) bool · landed_state (N,) int (LandedState) · home_enu_m (N,3) · home_set (N,) bool ·
    soc_frac (N,) · energy_j (N,) left [J] · energy_used_j (N,) · power_w (N,) · remaining_time_s (N,) ·
    low_battery (N,) bool · pack_voltage_v (N,) [V] · pack_current_a (N,) [A, + discharging] ·
    payload_kg (N,) · mission_step (N,) int (-1 none) ·
    mission_state (N,) int (MissionState) · speed_limit_m_s (N,3) ·
    arm_block (N,) int (ArmBlock: why arming would be refused now, 0 = it would arm).

    ``sensors``: the sensor samples measured this step (``SensorSample``: vehicle, key, topic, msg,
    ros2 flag). ``events``: the simulation's append-only event list (time, vehicle, text) — read
    ``events[cursor:events_end]``; ``results``: the append-only list of :class:`CommandResult`
    likewise, read ``results[cursor:results_end]``. Both lists are shared with the loop, which only
    appends; never modify them. ``mission_status``: vehicle -> the mission's status dict
    (:meth:`MissionRuntime.status`) for drones whose status changed this step (empty most steps).
    ``params``: vehicle -> read-only mapping of flight parameter name -> value (the same object
    until a parameter changes; ``params_version`` counts the changes).
    """

    step: int
    sim_time_s: float
    dt_s: float
    vehicles: tuple[str, ...]
    kinds: tuple[str, ...]
    arrays: Mapping[str, np.ndarray]
    sensors: tuple[Any, ...]
    events: Sequence[tuple[float, str, str]]
    events_end: int
    results: Sequence[CommandResult]
    results_end: int
    mission_status: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)
    params: Mapping[str, Mapping[str, float]] = field(default_factory=dict)
    params_version: int = 0

    def row(self, vehicle: str) -> int:
        """Row of ``vehicle`` in the arrays (``ValueError`` for a name not in this snapshot)."""
        return self.vehicles.index(vehicle)

    def __getattr__(self, name: str) -> np.ndarray:
        try:
            return self.arrays[name]
        except KeyError:
            raise AttributeError(f"Snapshot has no field or array {name!r}") from None


@dataclass(frozen=True)
class TransportOptions:
    """What the user asked for when the simulation was built (``Simulation(...)`` / CLI switches).

    ros2 : ROS 2 backend already resolved: ``off``, ``dds`` or ``rclpy``
    mavlink : give every drone a MAVLink endpoint even without a ``mavlink`` component (``--mavlink``)
    mavlink_bind : address to bind when ``mavlink`` is forced (default loopback)
    out_dir : the run's output directory (None: write nothing), e.g. for persisted parameters
    extra : switches of transports from other packages (name -> value)
    record : the rosbag2 directory to record into (None: no recording)
    record_topics : the topics to record, as glob patterns (``/drone1/*``, ``/tf``); empty: every topic
    foxglove : TCP port of the Foxglove WebSocket server on 127.0.0.1 (0: any free port; None: no server)
    view : TCP port of the built-in 3D web view on 127.0.0.1 (0: any free port; None: no view)
    """

    ros2: str = "off"
    mavlink: bool = False
    mavlink_bind: str = "127.0.0.1"
    out_dir: Path | None = None
    extra: Mapping[str, Any] = field(default_factory=dict)
    record: Path | None = None
    record_topics: tuple[str, ...] = ()
    foxglove: int | None = None
    view: int | None = None


class Transport(Protocol):
    """One transport of one simulation (ROS 2 bridge, MAVLink endpoints, a recorder, a live view)."""

    name: str

    def start(self, port: CommandPort, first: Snapshot) -> None:
        """Open sockets and start threads; ``first`` is the snapshot of the built world (step 0).
        Raises :class:`TransportError` with a clear message when it cannot start."""
        ...

    def offer(self, snapshot: Snapshot) -> None:
        """Called on the simulation thread once per step: O(1), never blocks, never raises."""
        ...

    def flush(self, timeout_s: float = 2.0) -> bool:
        """Wait until everything offered so far is handled (tests, close); True when it was."""
        ...

    def stop(self, timeout_s: float = 2.0) -> None:
        """Stop threads and close sockets; idempotent."""
        ...

    def counters(self) -> dict[str, Any]:
        """Figures for the run summary (``summary.json`` ``transports.<name>``): messages, drops, errors."""
        ...


@dataclass(frozen=True)
class TransportPlugin:
    """Entry-point value of group ``unetyemu_ecs.transports``.

    create(world, options) returns a :class:`Transport` for this world, or None when the transport is
    not enabled for it. It must not open sockets or threads (``start`` does).
    """

    create: Callable[[WorldDefinition, TransportOptions], Transport | None]
    summary: str = ""

    def __post_init__(self) -> None:
        if not callable(self.create):
            raise TypeError(f"TransportPlugin.create must be callable, got {self.create!r}")


__all__ = ["CommandPort", "CommandResult", "CommandStatus", "Snapshot", "Transport", "TransportError",
           "TransportOptions", "TransportPlugin"]
