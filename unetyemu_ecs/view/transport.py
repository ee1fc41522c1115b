"""The live web view as a transport (entry point ``view``): ``--view [PORT]`` / ``Simulation(view=PORT)``.

The simulation offers every step's snapshot to :meth:`ViewTransport.offer`, which only appends it to
a bounded drop-oldest :class:`~unetyemu_ecs.transport.snapshot.SnapshotQueue` (O(1), never blocks);
the view server (:mod:`.server`, its own thread) drains that queue only while a page is connected
and keeping up, at most ``STATE_HZ`` times a second of wall time. With no page connected nothing
drains it and nothing is computed: the queue just keeps the newest snapshots (and, through its
drops, every mission status change), so a page that connects later starts from the present.

In a run the view lives in a worker process of its own (:func:`create_view_transport`): there this
transport is fed by a :class:`~unetyemu_ecs.transport.worker.ProcessTransport`, to which it says what
its pages want (:meth:`ViewTransport.wanted`), so that nothing else leaves the simulation's process.

:class:`LiveSource` turns the drained snapshots into what the page shows: the newest pose, speed,
altitude, battery, mode and mission step of each vehicle, the real-time factor (sim time over wall
time of the snapshots it received, over the last :data:`RTF_WINDOW_S` seconds), the newest events,
and for each vehicle its newest LiDAR cloud (moved into ENU with the pose of the step it was
measured in and the sensor's mount) and camera image, built only when a page asks for them.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Mapping
from functools import partial
from typing import Any

import numpy as np

from ..systems.flight_state import NavState
from ..transport.api import CommandPort, Snapshot, TransportError, TransportOptions
from ..transport.snapshot import SnapshotQueue
from ..transport.worker import ProcessTransport, Wants
from . import frames
from .scene import VIEW_SENSORS, SceneInfo, scene_from_world
from .server import ServerError, Update, ViewServer
from .wire import STATE_HZ

QUEUE_DEPTH = 64             # snapshots (a quarter second at 240 Hz): the view needs only the newest
RTF_WINDOW_S = 2.0           # [s, wall] the real-time factor is measured over
EVENTS_SHOWN = 8
_NAV_NAMES = {int(s): s.name for s in NavState}
Mount = tuple[tuple[float, float, float], tuple[float, float, float, float]]
# the snapshot arrays the page's state is made of (all that crosses to the worker of them)
VIEW_ARRAYS = ("pos_enu_m", "quat_enu_flu_xyzw", "vel_enu_m_s", "soc_frac", "armed", "nav_state")


class RealTimeFactor:
    """Sim time over wall time of the last ``window_s`` seconds of samples.

    None until 0.5 s of samples are in; after a gap longer than the window (no page was polling,
    or a replay was seeked back) it starts afresh and reports the last value meanwhile."""

    def __init__(self, window_s: float = RTF_WINDOW_S) -> None:
        self.window_s = window_s
        self._samples: deque[tuple[float, float]] = deque()
        self.value: float | None = None

    def sample(self, wall_s: float, sim_s: float) -> float | None:
        s = self._samples
        if s and (sim_s < s[-1][1] or wall_s - s[-1][0] > self.window_s):
            s.clear()
        s.append((wall_s, sim_s))
        while len(s) > 2 and wall_s - s[1][0] >= self.window_s:
            s.popleft()
        span = wall_s - s[0][0]
        if span >= 0.5:
            self.value = (sim_s - s[0][1]) / span
        return self.value


class LiveSource:
    """The view's frames from the simulation's snapshots (every method on the server's thread)."""

    def __init__(self, scene: SceneInfo, mounts: Mapping[tuple[str, str], Mount], queue: SnapshotQueue) -> None:
        self.scene = scene
        self.mounts = mounts
        self.queue = queue
        self._snap: Snapshot | None = None
        self._status: dict[str, Any] = {}                    # vehicle -> newest mission status
        self._events: deque[tuple[float, str, str]] = deque(maxlen=EVENTS_SHOWN)
        self._events_seen = 0
        self._lidar: dict[str, frames.LazyFrame] = {}
        self._images: dict[tuple[str, str], frames.LazyFrame] = {}
        self._seq = 0
        self.rtf = RealTimeFactor()

    def hello(self) -> list[str | bytes]:
        return [self.scene.scene_message("live"), self.scene.mesh_message()]

    def control(self, msg: dict[str, Any]) -> None:
        """A live run has no player: play, pause and seek are for recordings."""

    def poll(self, now_s: float) -> Update | None:
        items = self.queue.get_all(0)
        try:
            for _, snap in items:
                self._absorb(snap)
        finally:
            if items:
                self.queue.task_done(items[-1][0])
        snap = self._snap
        if snap is None:
            return None
        rtf = self.rtf.sample(now_s, snap.sim_time_s)
        images: dict[str, frames.LazyFrame] = {}
        for (vehicle, sensor), frame in self._images.items():      # an RGB camera before a depth camera
            if sensor == "camera" or vehicle not in images:
                images[vehicle] = frame
        return Update(frames.state_message(snap.sim_time_s, rtf, self._rows(snap), list(self._events)),
                      dict(self._lidar), images)

    def _absorb(self, snap: Snapshot) -> None:
        if snap.arrays:                  # from a worker process, a step carries them only when they are wanted
            self._snap = snap
        if snap.mission_status:
            self._status.update(snap.mission_status)
        if snap.events_end > self._events_seen:
            self._events.extend(snap.events[max(self._events_seen, snap.events_end - EVENTS_SHOWN):snap.events_end])
            self._events_seen = snap.events_end
        for sample in snap.sensors:
            sensor = sample.sensor
            if sensor not in VIEW_SENSORS or sample.vehicle not in snap.vehicles or not snap.arrays:
                continue
            self._seq += 1
            if sensor == "lidar":
                row = snap.row(sample.vehicle)
                mount = self.mounts.get((sample.vehicle, sensor), ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0)))
                self._lidar[sample.vehicle] = frames.LazyFrame(self._seq, sample.time_s, partial(
                    _lidar, sample, snap.pos_enu_m[row], snap.quat_enu_flu_xyzw[row], mount))
            else:
                self._images[(sample.vehicle, sensor)] = frames.LazyFrame(self._seq, sample.time_s,
                                                                           partial(_image, sample))

    def _rows(self, snap: Snapshot) -> list[frames.VehicleRow]:
        pos = snap.pos_enu_m.tolist()
        quat = snap.quat_enu_flu_xyzw.tolist()
        speed = np.linalg.norm(snap.vel_enu_m_s, axis=1).tolist()
        soc = snap.soc_frac.tolist()
        armed = snap.armed.tolist()
        nav = snap.nav_state.tolist()
        rows = []
        for i, (name, kind) in enumerate(zip(snap.vehicles, snap.kinds)):
            if kind == "quadrotor":
                mode = _NAV_NAMES.get(int(nav[i]), str(nav[i])) if armed[i] else "DISARMED"
                battery, mission = soc[i], frames.mission_text(self._status.get(name))
            else:
                mode, battery, mission = ("driving" if armed[i] else "parked"), None, ""
            rows.append(frames.VehicleRow(name, pos[i], quat[i], speed[i], pos[i][2], battery, mode, mission))
        return rows


def _lidar(sample: Any, pos_enu_m: np.ndarray, quat_enu_flu_xyzw: np.ndarray, mount: Mount) -> bytes:
    points = frames.cloud_points_enu(frames.cloud_xyz(sample.msg), pos_enu_m, quat_enu_flu_xyzw, *mount)
    return frames.lidar_message(sample.vehicle, sample.time_s, points)


def _image(sample: Any) -> bytes | None:
    rgb = frames.image_rgb8(sample.msg)
    return None if rgb is None else frames.image_message(sample.vehicle, sample.sensor, sample.time_s, rgb)


def sensor_mounts(world: Any) -> dict[tuple[str, str], Mount]:
    """(vehicle, sensor key) -> the sensor's mount on base_link (xyz [m], quaternion xyzw) of every
    sensor the page shows."""
    mounts: dict[tuple[str, str], Mount] = {}
    for e in world.entities:
        for key, comp in e.components.items():
            if key in VIEW_SENSORS and hasattr(comp, "mount_quat_xyzw"):
                q = np.asarray(comp.mount_quat_xyzw(), dtype=float).reshape(4)
                mounts[(e.name, key)] = (tuple(float(v) for v in comp.mount_xyz_m),   # type: ignore[assignment]
                                         tuple(float(v) for v in q))
    return mounts


class ViewTransport:
    """The built-in 3D web view, behind the transport seam: read-only (it submits no commands)."""

    name = "view"

    def __init__(self, world: Any, port: int) -> None:
        self.requested_port = port
        self._scene = scene_from_world(world)
        self._mounts = sensor_mounts(world)
        self._vehicles = tuple(e.name for e in world.entities if e.kind != "package")
        self._queue = SnapshotQueue(QUEUE_DEPTH)
        self.server: ViewServer | None = None
        # set by the worker process (worker_main.WantsReporter): called when what wanted() says may have changed
        self.on_wants_changed: Any = None

    @property
    def url(self) -> str:
        """``http://127.0.0.1:<port>/`` once started."""
        return self.server.url if self.server is not None else ""

    @property
    def port(self) -> int | None:
        """The port served once started (the OS's choice for 0)."""
        return self.server.port if self.server is not None else None

    def start(self, port: CommandPort, first: Snapshot) -> None:
        self._queue.put(first)
        server = ViewServer(LiveSource(self._scene, self._mounts, self._queue), self.requested_port, name=self.name)
        server.on_change = self._pages_changed
        try:
            server.start()
        except ServerError as exc:
            raise TransportError(str(exc)) from exc
        self.server = server

    def offer(self, snapshot: Snapshot) -> None:
        self._queue.put(snapshot)

    def wanted(self) -> Wants:
        """What of the snapshots the pages need now (this view runs in a worker process, :mod:`..transport.worker`):
        nothing while no page watches (none connected, or every one stalled); else the vehicle arrays
        (at STATE_HZ, and with every LiDAR cloud: it is drawn with the pose of its step), the camera and
        depth images of the vehicles the pages selected and the LiDAR clouds they show."""
        server = self.server
        if server is None:
            return Wants()
        watching, images_of, lidar_all, lidar_of = server.demand()
        if not watching:
            return Wants()
        samples = {(v, "lidar") for v in (self._vehicles if lidar_all else lidar_of)}
        samples.update((v, key) for v in images_of for key in VIEW_SENSORS if key != "lidar")
        return Wants(arrays=True, samples=frozenset(samples))

    def _pages_changed(self) -> None:
        if self.on_wants_changed is not None:
            self.on_wants_changed()

    def flush(self, timeout_s: float = 2.0) -> bool:
        """True once a page keeping up has received what was offered so far; True at once with none."""
        server = self.server
        if server is None or not server.has_ready_pages():
            return True
        return self._queue.wait_done(timeout_s)

    def stop(self, timeout_s: float = 2.0) -> None:
        if self.server is not None:
            self.server.stop(timeout_s)

    def counters(self) -> dict[str, Any]:
        counters = self.server.counters() if self.server is not None else {"url": ""}
        counters.update(snapshots_offered=self._queue.offered, snapshots_dropped=self._queue.dropped)
        return counters


def create_view_transport(world: Any, options: TransportOptions) -> ProcessTransport | None:
    """The ``view`` transport plugin's ``create``: a web view when ``options.view`` names a port, run in a
    worker process (:mod:`..transport.worker`) as a selective transport: the server's thread in the
    simulation's process (building the page's frames, sending them) cost the delivery scenario about a
    tenth of its real-time factor on 2 cores with a page showing every LiDAR cloud."""
    port = getattr(options, "view", None)
    if port is None:
        return None
    if isinstance(port, bool) or not isinstance(port, int) or not 0 <= port <= 65535:
        raise TransportError(f"view: port must be an integer from 0 to 65535 (0: any free port), got {port!r}")
    return ProcessTransport("view", f"{__name__}:view_in_this_process", world, options, arrays=VIEW_ARRAYS,
                            queue_depth=QUEUE_DEPTH, arrays_hz=STATE_HZ, arrays_with_samples=True)


def view_in_this_process(world: Any, options: TransportOptions) -> ViewTransport:
    """The view itself (what the worker process runs)."""
    return ViewTransport(world, int(options.view))


__all__ = ["LiveSource", "QUEUE_DEPTH", "RealTimeFactor", "VIEW_ARRAYS", "ViewTransport", "create_view_transport",
           "sensor_mounts", "view_in_this_process"]
