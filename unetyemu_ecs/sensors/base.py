"""What every sensor shares: mount, rate, topic and frame names, its schedule on the sim clock, where
its messages go, and its own seeded noise stream.

A sensor is a component (the world-file block under a vehicle's ``components``, e.g. ``imu: {}``)
whose dataclass extends :class:`SensorSpec`, plus one SENSORS-phase system that measures every
sensor of its kind that is due, in one vectorised pass. Outputs are ROS 2 Jazzy messages
(:mod:`unetyemu_ecs.sensors.messages`), kept in :class:`SensorOutputs`: the newest per vehicle and
sensor for the Python API, and the list of this step's messages for publishers.

Frames (docs/architecture.md §3): the vehicle body is ``<vehicle>/base_link`` (FLU); a sensor sits at
``mount_xyz_m`` in it, rotated by ``mount_rpy_deg`` (roll, pitch, yaw about FLU x, y, z).
"""

from __future__ import annotations

import re
import zlib
from dataclasses import dataclass, field
from typing import Annotated, Any, Callable, ClassVar

import numpy as np

from ..components.body import Identity
from ..config.limits import MAX_MOUNT_M, MAX_TOPIC_LEN, Deg, SensorRate
from ..config.schema import FieldError, Ge, Le, MaxLen, NonEmpty
from ..frames import quat_xyzw_from_euler_rpy
from ..systems.fleet_system import FleetSystem
from ..world import StepContext


# an absolute ROS 2 topic name: /token[/token...], tokens of letters, digits and _, not starting with a digit
Mount = Annotated[float, Ge(-MAX_MOUNT_M), Le(MAX_MOUNT_M)]   # [m]
ROS_TOPIC_RE = re.compile(r"^(/[A-Za-z_][A-Za-z0-9_]*)+$")


@dataclass(frozen=True, kw_only=True)
class SensorSpec:
    """Fields every sensor has (its subclass sets the default rate and its frame names).

    ``LINK``: the sensor's frame under ``<vehicle>/`` (mounted on base_link, published on /tf_static);
    ``OPTICAL``: for cameras, the optical frame under the link (z forward, x right, y down) that the
    images are stamped with; empty when the sensor has no frame of its own (battery, odometry).
    """

    LINK: ClassVar[str] = ""
    OPTICAL: ClassVar[str] = ""

    rate_hz: SensorRate = 10.0                                       # [Hz], config.limits
    # a sensor sits on its vehicle: within 10 m of base_link (config.limits.MAX_MOUNT_M)
    mount_xyz_m: tuple[Mount, Mount, Mount] = (0.0, 0.0, 0.0)        # in base_link (FLU) [m]
    mount_rpy_deg: tuple[Deg, Deg, Deg] = (0.0, 0.0, 0.0)            # sensor axes relative to base_link
    # ROS 2 names: rmw refuses topic names longer than 255 characters
    topic: Annotated[str, NonEmpty(), MaxLen(MAX_TOPIC_LEN)] | None = None      # None: /<vehicle>/<default suffix>
    frame_id: Annotated[str, NonEmpty(), MaxLen(MAX_TOPIC_LEN)] | None = None   # None: <vehicle>/<default link>
    ros2: bool = True          # publish on ROS 2 when the bridge is on (False: Python API and logs only)

    def __post_init__(self) -> None:
        if self.topic is not None and not ROS_TOPIC_RE.match(self.topic):
            raise FieldError("topic", f"{self.topic!r} is not an absolute ROS 2 topic name (/a/b_1: "
                                      f"letters, digits and _, tokens not starting with a digit)")

    def frame_name(self, vehicle: str, fallback_link: str = "base_link") -> str:
        """The frame this sensor's messages are stamped with: ``frame_id`` if given, else
        ``<vehicle>/<OPTICAL or LINK>``, else ``<vehicle>/<fallback_link>`` (sensors without a frame)."""
        return self.frame_id or f"{vehicle}/{self.OPTICAL or self.LINK or fallback_link}"

    def mount_quat_xyzw(self) -> np.ndarray:
        """Rotation of the sensor frame in base_link, xyzw."""
        r, p, y = np.deg2rad(self.mount_rpy_deg)
        return np.asarray(quat_xyzw_from_euler_rpy(r, p, y), dtype=float).reshape(4)


class SensorSample:
    """One measurement: when (sim time [s]), which vehicle and sensor key, the topic, the message,
    and whether the ROS 2 bridge publishes it.

    A sample may be built from ``build`` (a function of no arguments returning the message) instead of
    ``msg``: the message is then made the first time someone reads ``msg`` (a transport on its own
    thread, or :meth:`~unetyemu_ecs.app.Simulation.transforms`), so that a message nobody reads costs
    the loop nothing. ``build`` must depend only on what it captured (copies, not live fleet arrays).
    """

    __slots__ = ("time_s", "vehicle", "sensor", "topic", "ros2", "_msg", "_build")

    def __init__(self, time_s: float, vehicle: str, sensor: str, topic: str, msg: Any = None, ros2: bool = True,
                 *, build: Callable[[], Any] | None = None) -> None:
        self.time_s, self.vehicle, self.sensor, self.topic, self.ros2 = time_s, vehicle, sensor, topic, ros2
        self._msg, self._build = msg, build

    @property
    def msg(self) -> Any:
        build = self._build
        if build is not None:             # two readers at once may both build it: the same message
            self._msg = build()
            self._build = None
        return self._msg

    def __repr__(self) -> str:
        return (f"SensorSample(time_s={self.time_s!r}, vehicle={self.vehicle!r}, sensor={self.sensor!r}, "
                f"topic={self.topic!r}, ros2={self.ros2!r})")


@dataclass
class SensorOutputs:
    """Sensor messages of one simulation: newest per (vehicle, sensor key), and this step's in order."""

    latest: dict[tuple[str, str], SensorSample] = field(default_factory=dict)
    this_step: list[SensorSample] = field(default_factory=list)

    def put(self, sample: SensorSample) -> None:
        self.latest[(sample.vehicle, sample.sensor)] = sample
        self.this_step.append(sample)


@dataclass
class MountedSensor:
    """One sensor instance as its system sees it (gathered again whenever the ECS or the fleet changes;
    ``next_due_s`` stays with the sensor's entity across gathers)."""

    entity: int
    row: int
    vehicle: str
    kind: str              # the vehicle's kind: quadrotor, car
    spec: Any
    topic: str
    frame_id: str
    next_due_s: float = 0.0


class SensorSystemBase(FleetSystem):
    """Gathering, scheduling and noise streams for a SENSORS-phase system of one sensor kind.

    Subclasses set ``spec_type``, ``key`` (the world-file key), ``topic_suffix``, and ``link`` only
    when the spec has no frame of its own (``SensorSpec.LINK``), and implement
    ``measure(ctx, due, time_s)`` for the list of sensors due this step. The sensors are the
    vehicles carrying an :class:`~unetyemu_ecs.components.body.Identity` and a ``spec_type``
    component (``requires``): one added after spawn starts measuring on the next step, one removed
    stops. A subclass that prepares per-sensor data extends :meth:`gather` (``super().gather(ctx)``
    first, then ``self.sensors``).
    """

    spec_type: type = SensorSpec
    key = "sensor"
    topic_suffix = "sensor"
    link = "base_link"
    requires = (Identity, SensorSpec)

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        cls.requires = (Identity, cls.spec_type)

    def __init__(self) -> None:
        super().__init__()
        self.sensors: list[MountedSensor] = []
        self._rng: dict[str, np.random.Generator] = {}

    def gather(self, ctx: StepContext) -> None:
        due_of = {s.entity: s.next_due_s for s in self.sensors}      # a sensor keeps its schedule
        self.sensors = []
        for row, ent, ident, spec in zip(self.rows.tolist(), self.entities.tolist(), *self.components):
            topic = spec.topic or f"/{ident.name}/{self.topic_suffix}"
            frame = spec.frame_name(ident.name, self.link)
            self.sensors.append(MountedSensor(ent, row, ident.name, ident.kind, spec, topic, frame,
                                              due_of.get(ent, 0.0)))

    def rng_for(self, ctx: StepContext, sensor: MountedSensor) -> np.random.Generator:
        """This sensor's own noise stream: seeded by the world seed and the sensor's name, so that
        adding a sensor never changes another one's noise (nor anything else's randomness)."""
        name = f"{self.key}/{sensor.vehicle}"
        gen = self._rng.get(name)
        if gen is None:
            entropy = ctx.rng.bit_generator.seed_seq.entropy
            gen = np.random.default_rng(np.random.SeedSequence(entropy, spawn_key=(zlib.crc32(name.encode()),)))
            self._rng[name] = gen
        return gen

    def update(self, ctx: StepContext) -> None:
        time_s = ctx.sim_time_s + ctx.dt_s                 # measured at the end of this step
        eps = 1e-9
        due = [s for s in self.sensors if time_s + eps >= s.next_due_s]
        if not due:
            return
        for s in due:
            period = 1.0 / s.spec.rate_hz
            s.next_due_s += period * (np.floor((time_s + eps - s.next_due_s) / period) + 1)
        self.measure(ctx, due, time_s)

    def measure(self, ctx: StepContext, due: list[MountedSensor], time_s: float) -> None:
        raise NotImplementedError

    def publish(self, ctx: StepContext, sensor: MountedSensor, time_s: float, msg: Any = None, *,
                key: str | None = None, topic: str | None = None, build: Callable[[], Any] | None = None) -> None:
        """Put ``msg`` in the outputs under this system's key and the sensor's topic (or ``key`` /
        ``topic`` for a companion message such as a camera's CameraInfo), on ROS 2 if the sensor is.
        With ``build`` instead of ``msg`` the message is made when first read (:class:`SensorSample`):
        the measurement is taken now, its message costs the loop nothing when nobody listens."""
        ctx.services.sensors.put(SensorSample(time_s, sensor.vehicle, key or self.key, topic or sensor.topic, msg,
                                              sensor.spec.ros2, build=build))


__all__ = ["MountedSensor", "SensorOutputs", "SensorSample", "SensorSpec", "SensorSystemBase"]
