"""Frozen command messages that cross into the simulation loop, and the inbox that carries them.

Any producer (the Python API, the ROS 2 bridge, MAVLink endpoints, teleop) puts messages in the
:class:`Inbox`; the COMMANDS phase drains it once per step, keeping for each vehicle and kind only
the newest message (a teleop stream at 50 Hz must not queue up). Messages use the engine's units and
frames (ENU metres, radians) and name the vehicle; they are validated again when applied.

Streamed commands (teleop sticks, cmd_vel) carry ``hold_s``: a command from a stream (ROS 2
topics) lapses when no newer one arrives within the vehicle's command timeout, and the vehicle
then holds (a drone hovers where it is, a car brakes to a stop), as robot drivers do when their
publisher goes quiet. ``None`` holds the command until the next one (Python API calls).
"""

from __future__ import annotations

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


@dataclass(frozen=True, slots=True)
class LoadMission:
    """Replace the vehicle's mission with ``mission`` (a validated MissionSpec) and start it."""

    vehicle: str
    mission: Any
    kind: str = "mission"


@dataclass(frozen=True, slots=True)
class Teleop:
    """Manual sticks ``[throttle, pitch, roll, yaw]`` in [-1, 1]; switches the drone to MANUAL."""

    vehicle: str
    stick: tuple[float, float, float, float]
    hold_s: float | None = None      # lapses this long [s, sim time] after it is applied (None: held)
    kind: str = "teleop"


@dataclass(frozen=True, slots=True)
class Arm:
    """Arm or disarm the motors."""

    vehicle: str
    armed: bool
    kind: str = "arm"


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


Command = SetTarget | LoadMission | Teleop | Arm | Drive | CmdVel | DriveRoute


class Inbox:
    """Thread-safe queue of commands for the simulation loop."""

    def __init__(self) -> None:
        self._q: queue.SimpleQueue[Command] = queue.SimpleQueue()

    def put(self, msg: Command) -> None:
        self._q.put(msg)

    def drain_latest(self) -> list[Command]:
        """Take everything queued; keep the newest per (vehicle, kind), in arrival order of those."""
        latest: dict[tuple[str, str], tuple[int, Command]] = {}
        n = 0
        while True:
            try:
                msg = self._q.get_nowait()
            except queue.Empty:
                break
            latest[(msg.vehicle, msg.kind)] = (n, msg)
            n += 1
        return [m for _, m in sorted(latest.values(), key=lambda nm: nm[0])]
