"""Frozen command messages that cross into the simulation loop, and the inbox that carries them.

Any producer (the Python API, the ROS 2 bridge, MAVLink endpoints, teleop) puts messages in the
:class:`Inbox` (:meth:`Inbox.submit` gives each its id); the COMMANDS phase drains it once per
step in arrival order, keeping of the streamed kinds (:data:`STREAM_KINDS`: sticks, cmd_vel,
offboard setpoints) only the newest per vehicle and kind (a teleop stream at 50 Hz must not queue
up); every other command is applied, in order, and gets a result. Messages use the engine's units and
frames (ENU metres, radians) and name the vehicle; their values are checked once, by :mod:`unetyemu_ecs.command_checks`, before
they are queued (the command systems check only what depends on the vehicle's state).

Streamed commands (teleop sticks, cmd_vel) carry ``hold_s``: a command from a stream (ROS 2
topics) lapses when no newer one arrives within the vehicle's command timeout, and the vehicle
then holds (a drone hovers where it is, a car brakes to a stop), as robot drivers do when their
publisher goes quiet. ``None`` holds the command until the next one (Python API calls).
"""

from __future__ import annotations

import dataclasses
import itertools
import queue
from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True, slots=True)
class SetTarget:
    """Fly to one position (AUTO mode); ``yaw_rad`` None keeps the heading, ``speed_m_s`` None = default."""

    vehicle: str
    pos_enu_m: tuple[float, float, float]
    yaw_rad: float | None
    speed_m_s: float | None
    kind: str = "target"
    command_id: int = 0              # set by Inbox.submit; its CommandResult carries it
    source: str = "api"              # who sent it: api, ros2, mavlink, ...


@dataclass(frozen=True, slots=True)
class LoadMission:
    """Replace the vehicle's mission with ``mission`` (a validated MissionSpec) and start it."""

    vehicle: str
    mission: Any
    kind: str = "mission"
    command_id: int = 0              # set by Inbox.submit; its CommandResult carries it
    source: str = "api"              # who sent it: api, ros2, mavlink, ...


@dataclass(frozen=True, slots=True)
class Teleop:
    """Manual sticks ``[throttle, pitch, roll, yaw]`` in [-1, 1]; switches the drone to MANUAL."""

    vehicle: str
    stick: tuple[float, float, float, float]
    hold_s: float | None = None      # lapses this long [s, sim time] after it is applied (None: held)
    kind: str = "teleop"
    command_id: int = 0              # set by Inbox.submit; its CommandResult carries it
    source: str = "api"              # who sent it: api, ros2, mavlink, ...


@dataclass(frozen=True, slots=True)
class Arm:
    """Arm or disarm the motors."""

    vehicle: str
    armed: bool
    force: bool = False              # skip the arming checks (PX4: param2 = 21196)
    kind: str = "arm"
    command_id: int = 0              # set by Inbox.submit; its CommandResult carries it
    source: str = "api"              # who sent it: api, ros2, mavlink, ...


@dataclass(frozen=True, slots=True)
class Drive:
    """Car teleop: ``throttle`` in [-1, 1] (negative = reverse), ``brake`` in [0, 1], ``steering`` in
    [-1, 1] (+1 = full left at the current speed's limit); switches the car to MANUAL."""

    vehicle: str
    throttle: float
    brake: float
    steering: float
    hold_s: float | None = None      # lapses this long [s, sim time] after it is applied (None: held)
    kind: str = "teleop"
    command_id: int = 0              # set by Inbox.submit; its CommandResult carries it
    source: str = "api"              # who sent it: api, ros2, mavlink, ...


@dataclass(frozen=True, slots=True)
class CmdVel:
    """Body-frame velocity command (ROS ``cmd_vel``): forward speed [m/s] (negative = reverse) and
    yaw rate [rad/s] (CCW); a drone also takes ``left_m_s`` and ``up_m_s`` (VELOCITY mode), a car
    ignores them."""

    vehicle: str
    forward_m_s: float
    yaw_rate_rad_s: float
    left_m_s: float = 0.0
    up_m_s: float = 0.0
    hold_s: float | None = None      # lapses this long [s, sim time] after it is applied (None: held)
    kind: str = "cmd_vel"
    command_id: int = 0              # set by Inbox.submit; its CommandResult carries it
    source: str = "api"              # who sent it: api, ros2, mavlink, ...


@dataclass(frozen=True, slots=True)
class DriveRoute:
    """Car route: ENU ``(x, y)`` waypoints [m] driven in order at ``speed_m_s`` (None = default),
    stopping at the last, or round and round with ``loop`` (``laps`` 0 = forever)."""

    vehicle: str
    waypoints: tuple[tuple[float, float], ...]
    speed_m_s: float | None
    loop: bool = False
    laps: int = 0
    kind: str = "target"
    command_id: int = 0              # set by Inbox.submit; its CommandResult carries it
    source: str = "api"              # who sent it: api, ros2, mavlink, ...


# -- PX4-style flight modes (docs/architecture.md §7). Positions and velocities in ENU metres, yaw in
# radians ENU (0 = east, CCW), like every command here; NED/FRD exist only inside the MAVLink package.


@dataclass(frozen=True, slots=True)
class SetNavMode:
    """Switch a drone's navigation mode (``NavState``: HOLD, TAKEOFF, LAND, RTL, MISSION, OFFBOARD,
    POSCTL, MANUAL ...), with PX4's preconditions (OFFBOARD needs a fresh setpoint stream, MISSION an
    uploaded mission, TAKEOFF an armed drone on the ground)."""

    vehicle: str
    nav_state: int
    kind: str = "nav_mode"
    command_id: int = 0
    source: str = "api"


@dataclass(frozen=True, slots=True)
class Takeoff:
    """Climb vertically to ``alt_enu_m`` (world z [m]; None: home + MIS_TAKEOFF_ALT), then HOLD;
    ``yaw_rad`` None keeps the heading."""

    vehicle: str
    alt_enu_m: float | None = None
    yaw_rad: float | None = None
    kind: str = "takeoff"
    command_id: int = 0
    source: str = "api"


@dataclass(frozen=True, slots=True)
class Land:
    """Descend and land at ``xy_enu_m`` (None: straight below), detect touchdown, disarm after COM_DISARM_LAND."""

    vehicle: str
    xy_enu_m: tuple[float, float] | None = None
    kind: str = "land"
    command_id: int = 0
    source: str = "api"


@dataclass(frozen=True, slots=True)
class ReturnToLaunch:
    """RTL: climb to RTL_RETURN_ALT above the destination (home or the closest rally point), fly there, land."""

    vehicle: str
    kind: str = "rtl"
    command_id: int = 0
    source: str = "api"


@dataclass(frozen=True, slots=True)
class SetParam:
    """Set flight parameter ``name`` (``navigation.params``) of a drone to ``value`` (range-checked)."""

    vehicle: str
    name: str
    value: float
    kind: str = "param"
    command_id: int = 0
    source: str = "api"


@dataclass(frozen=True, slots=True)
class SetHome:
    """Set the home position to ``pos_enu_m`` (None: where the drone is now)."""

    vehicle: str
    pos_enu_m: tuple[float, float, float] | None = None
    kind: str = "home"
    command_id: int = 0
    source: str = "api"


@dataclass(frozen=True, slots=True)
class ChangeSpeed:
    """Change the cruise (``which`` = "ground"), climb or descent speed [m/s] of the current and later legs."""

    vehicle: str
    which: str
    speed_m_s: float
    kind: str = "speed"
    command_id: int = 0
    source: str = "api"


@dataclass(frozen=True, slots=True)
class StoreMission:
    """Keep ``mission`` (a validated MissionSpec) as the drone's uploaded mission without starting it
    (MAVLink upload; MISSION mode or :class:`StartMission` runs it). None clears it."""

    vehicle: str
    mission: Any
    kind: str = "mission_store"
    command_id: int = 0
    source: str = "api"


@dataclass(frozen=True, slots=True)
class StartMission:
    """Run the uploaded mission from step ``first_step`` (MISSION mode); armed on the ground, it takes off first."""

    vehicle: str
    first_step: int = 0
    kind: str = "mission_start"
    command_id: int = 0
    source: str = "api"


@dataclass(frozen=True, slots=True)
class SetMissionCurrent:
    """Make ``step`` the mission's current step (it is flown next, or now when the mission runs)."""

    vehicle: str
    step: int
    kind: str = "mission_current"
    command_id: int = 0
    source: str = "api"


@dataclass(frozen=True, slots=True)
class PauseMission:
    """``resume`` False: pause the running mission and HOLD; True: continue it."""

    vehicle: str
    resume: bool
    kind: str = "mission_pause"
    command_id: int = 0
    source: str = "api"


@dataclass(frozen=True, slots=True)
class Gripper:
    """``grab`` True: pick up the package in reach (a mission pickup step's check); False: release it."""

    vehicle: str
    grab: bool
    kind: str = "gripper"
    command_id: int = 0
    source: str = "api"


@dataclass(frozen=True, slots=True)
class Terminate:
    """Flight termination: motors off now, wherever the drone is."""

    vehicle: str
    kind: str = "terminate"
    command_id: int = 0
    source: str = "api"


@dataclass(frozen=True, slots=True)
class OffboardSetpoint:
    """One setpoint of an OFFBOARD stream (PX4: SET_POSITION_TARGET_*, SET_ATTITUDE_TARGET). Each part
    None = not set.

    pos_enu_m : position [m]; vel_enu_m_s : world-frame velocity [m/s]; vel_flu_m_s : body-frame
    velocity [m/s] (forward, left, up), rotated with the heading each step; yaw_rad : heading;
    yaw_rate_rad_s : CCW; attitude_rp_rad : (roll, pitch) of FLU in ENU (ZYX Euler, right side down and
    nose down positive), flown with ``thrust_frac`` (collective thrust as a fraction of the four motors'
    maximum) by the attitude layer, bypassing the position layer. The stream keeps OFFBOARD alive; it
    lapses after COM_OF_LOSS_T.
    """

    vehicle: str
    pos_enu_m: tuple[float, float, float] | None = None
    vel_enu_m_s: tuple[float, float, float] | None = None
    vel_flu_m_s: tuple[float, float, float] | None = None
    yaw_rad: float | None = None
    yaw_rate_rad_s: float | None = None
    attitude_rp_rad: tuple[float, float] | None = None
    thrust_frac: float | None = None
    kind: str = "offboard"
    command_id: int = 0
    source: str = "api"


@dataclass(frozen=True, slots=True)
class ManualControl:
    """Sticks of a MANUAL_CONTROL stream, each in [-1, 1] (``throttle`` in [0, 1], 0.5 = centre):
    ``pitch`` forward, ``roll`` right, ``yaw`` clockwise, as a transmitter gives them. Flown as
    POSCTL (velocity) or MANUAL (attitude) by the drone's navigation mode."""

    vehicle: str
    pitch: float
    roll: float
    throttle: float
    yaw: float
    kind: str = "manual_control"
    command_id: int = 0
    source: str = "api"


@dataclass(frozen=True, slots=True)
class Orbit:
    """Circle ``center_enu_m`` at ``radius_m`` (> 0 clockwise seen from above, < 0 counter-clockwise)
    at ``speed_m_s`` tangential; ``yaw_behaviour`` as MAVLink ORBIT_YAW_BEHAVIOUR (0: face the centre)."""

    vehicle: str
    center_enu_m: tuple[float, float, float]
    radius_m: float
    speed_m_s: float
    yaw_behaviour: int = 0
    kind: str = "orbit"
    command_id: int = 0
    source: str = "api"


@dataclass(frozen=True, slots=True)
class FollowTargetFix:
    """One fix of a target to follow (FOLLOW_TARGET stream): position [m] and velocity [m/s], ENU."""

    vehicle: str
    pos_enu_m: tuple[float, float, float]
    vel_enu_m_s: tuple[float, float, float] | None = None
    kind: str = "follow_target"
    command_id: int = 0
    source: str = "api"


@dataclass(frozen=True, slots=True)
class SetGeofence:
    """Replace the drone's geofence (``navigation.geofence.Geofence``; None: none)."""

    vehicle: str
    fence: Any
    kind: str = "fence"
    command_id: int = 0
    source: str = "api"


@dataclass(frozen=True, slots=True)
class SetFenceEnabled:
    """Enable (True) or disable (False) the enforcement of the drone's geofence (MAV_CMD_DO_FENCE_ENABLE)."""

    vehicle: str
    enabled: bool
    kind: str = "fence_enable"
    command_id: int = 0
    source: str = "api"


@dataclass(frozen=True, slots=True)
class SetRallyPoints:
    """Replace the drone's rally points (ENU [m]); RTL goes to the closest of home and these."""

    vehicle: str
    points_enu_m: tuple[tuple[float, float, float], ...]
    kind: str = "rally"
    command_id: int = 0
    source: str = "api"


NAV_COMMANDS = (SetNavMode, Takeoff, Land, ReturnToLaunch, SetParam, SetHome, ChangeSpeed, StoreMission,
                StartMission, SetMissionCurrent, PauseMission, Gripper, Terminate, OffboardSetpoint,
                ManualControl, Orbit, FollowTargetFix, SetGeofence, SetFenceEnabled, SetRallyPoints)

# Streamed kinds: only the newest per vehicle and kind matters (a 50 Hz stick stream must not queue up);
# every other command is applied in order, so none is silently superseded.
STREAM_KINDS = frozenset({"teleop", "cmd_vel", "offboard", "manual_control", "follow_target"})


Command = (SetTarget | LoadMission | Teleop | Arm | Drive | CmdVel | DriveRoute | SetNavMode | Takeoff
           | Land | ReturnToLaunch | SetParam | SetHome | ChangeSpeed | StoreMission | StartMission
           | SetMissionCurrent | PauseMission | Gripper | Terminate | OffboardSetpoint | ManualControl
           | Orbit | FollowTargetFix | SetGeofence | SetFenceEnabled | SetRallyPoints)


@dataclass(frozen=True, slots=True)
class Rejected:
    """A sample a transport could not turn into a command (undecodable, wrong shape, out of range):
    queued by :meth:`Inbox.reject` so that it gets a :class:`~.api.CommandResult` (REJECTED_INVALID,
    reason ``invalid``) and an event like any refused command. ``kind`` names what it came as (a
    ROS 2 topic, a MAVLink message name)."""

    vehicle: str
    kind: str
    text: str
    command_id: int = 0
    source: str = "api"


class Inbox:
    """Thread-safe queue of commands for the simulation loop (the :class:`~.api.CommandPort` of every
    transport and of the Python API)."""

    def __init__(self) -> None:
        self._q: queue.SimpleQueue[Command | Rejected] = queue.SimpleQueue()
        self._ids = itertools.count(1)         # next() is atomic under the GIL: ids are unique across threads

    def put(self, msg: Command) -> None:
        """Queue ``msg`` as it is (its ``command_id`` unchanged; prefer :meth:`submit`)."""
        self._q.put(msg)

    def submit(self, msg: Command) -> int:
        """Queue ``msg`` with a fresh id (thread-safe); returns the id its CommandResult will carry."""
        command_id = next(self._ids)
        self._q.put(dataclasses.replace(msg, command_id=command_id))
        return command_id

    def reject(self, vehicle: str, kind: str, text: str, source: str) -> int:
        """Report a sample from ``source`` that could not become a command (thread-safe): at the next
        step it gets a REJECTED_INVALID result with ``text`` and an event; returns its id."""
        command_id = next(self._ids)
        self._q.put(Rejected(vehicle, kind, text, command_id, source))
        return command_id

    def drain(self) -> list[Command | Rejected]:
        """Take everything queued, in arrival order, except that of the streamed kinds
        (:data:`STREAM_KINDS`) only the newest per vehicle and kind is kept, at the place of the
        first of them: the stream existed from then on, so a mode change that followed its first
        setpoint (MAVSDK's offboard start) still finds a setpoint before it."""
        if self._q.empty():                         # the usual step: nothing came (no exception raised and caught)
            return []
        taken: list[Command | Rejected] = []
        slot: dict[tuple[str, str], int] = {}       # (vehicle, kind) -> index of the stream's first message
        while True:
            try:
                msg = self._q.get_nowait()
            except queue.Empty:
                return taken
            if msg.kind in STREAM_KINDS and not isinstance(msg, Rejected):
                key = (msg.vehicle, msg.kind)
                if key in slot:
                    taken[slot[key]] = msg
                    continue
                slot[key] = len(taken)
            taken.append(msg)
