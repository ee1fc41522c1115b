"""Replaying a recording in the web view: ``unetyemu view RECORDING [--port PORT] [--world WORLD]``.

A recording is the rosbag2 (MCAP storage) that ``--record`` writes (:mod:`unetyemu_ecs.transport.record`);
the directory or its ``.mcap`` file may be given. :class:`Recording` reads it with ``rosbags``:

- at open, the light topics become per-vehicle timelines: poses from ``/tf``
  (``<v>/odom -> <v>/base_link``, with ``map -> <v>/odom`` the identity, read at most
  :data:`TRACK_HZ` times a second of sim time), speeds by differencing them, battery from
  ``/<v>/battery``, mission status from ``/<v>/mission/status``, sensor mounts from ``/tf_static``;
- LiDAR clouds and camera images stay in the file: the player reads forward from the play time and
  decodes only the newest of each that a page asks for.

:class:`ReplaySource` plays it to the pages at the pace of the wall clock times a speed, and obeys
the page's ``play``, ``pause``, ``seek`` and ``speed`` messages; the page is the live view's, with a
player bar. The city comes from the world file the recording was made from: ``--world``, or the one
named by ``summary.json`` of the run the recording sits in (``--record`` puts it next to the run's
logs); without one the page shows the vehicles over a plain ground.
"""

from __future__ import annotations

import json
import math
from bisect import bisect_right
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..frames import R_from_quat_xyzw
from . import frames
from .scene import DEFAULT_HALF_EXTENTS_M, SceneInfo, VehicleLook, scene_from_world, vehicle_look
from .server import Update, ViewServer
from .transport import EVENTS_SHOWN, RealTimeFactor

TRACK_HZ = 25.0              # poses kept per second of sim time (the recording has /tf at 50 Hz)
LOOKBACK_S = 1.0             # after a seek, the newest cloud and image are looked for this far back
MOVING_M_S = 0.2             # a replayed vehicle faster than this is shown as "moving"
_BASE = "/base_link"
_IDENTITY: tuple[np.ndarray, np.ndarray] = (np.eye(3), np.zeros(3))


class ReplayError(RuntimeError):
    """The recording cannot be replayed (missing, not a rosbag2, unreadable); the message says why."""


@dataclass
class Track:
    """One vehicle's recorded timeline: pose samples and the messages about it, in time order."""

    times_s: list[float] = field(default_factory=list)
    pos_enu_m: list[tuple[float, float, float]] = field(default_factory=list)
    quat_xyzw: list[tuple[float, float, float, float]] = field(default_factory=list)
    battery: list[tuple[float, float]] = field(default_factory=list)            # (t, state of charge)
    status: list[tuple[float, dict[str, Any]]] = field(default_factory=list)    # (t, mission status)
    speed_m_s: np.ndarray = field(default_factory=lambda: np.zeros(0))

    def finish(self) -> None:
        t = np.asarray(self.times_s)
        p = np.asarray(self.pos_enu_m, dtype=float).reshape(-1, 3)
        if len(t) >= 2 and np.all(np.diff(t) > 0):
            self.speed_m_s = np.linalg.norm(np.gradient(p, t, axis=0), axis=1)
        else:
            self.speed_m_s = np.zeros(len(t))


def bag_path(path: str | Path) -> Path:
    """What to open for ``path``: a rosbag2 directory, or a bare ``.mcap`` file (ReplayError otherwise)."""
    p = Path(path)
    if not p.exists():
        raise ReplayError(f"no recording at {p} (expected the rosbag2 directory written by --record, or its .mcap file)")
    if p.is_dir():
        if (p / "metadata.yaml").is_file():
            return p
        mcaps = sorted(p.glob("*.mcap"))
        if len(mcaps) == 1:
            return mcaps[0]
        raise ReplayError(f"{p} is not a recording: no metadata.yaml" + (f" and {len(mcaps)} .mcap files" if mcaps
                                                                            else " and no .mcap file"))
    if p.suffix == ".mcap" and (p.parent / "metadata.yaml").is_file():
        return p.parent
    return p


def _vehicle_of_topic(topic: str) -> str:
    return topic.strip("/").split("/", 1)[0]


def _rotation(q: Any) -> np.ndarray:
    return R_from_quat_xyzw(np.array([q.x, q.y, q.z, q.w], dtype=float))


class Recording:
    """A recording opened for replay (see the module docstring). ``close()`` it when done."""

    def __init__(self, path: str | Path) -> None:
        from rosbags.highlevel import AnyReader

        from ..sensors.messages import typestore

        self.path = Path(path)
        self._open = bag_path(path)
        try:
            self.reader = AnyReader([self._open], default_typestore=typestore())
            self.reader.open()
        except Exception as exc:
            raise ReplayError(f"cannot read the recording {self.path}: {exc}") from exc
        try:
            self._index()
        except Exception as exc:
            self.close()
            raise ReplayError(f"cannot read the recording {self.path}: {type(exc).__name__}: {exc}") from exc

    def _index(self) -> None:
        reader = self.reader
        self.start_s = reader.start_time / 1e9
        self.end_s = max(reader.end_time / 1e9, self.start_s)
        self.tracks: dict[str, Track] = {}
        self.static: dict[str, tuple[str, np.ndarray, np.ndarray]] = {}   # child -> (parent, R, t)
        self.events: list[tuple[float, str, str]] = []
        light, self.heavy = [], []
        for conn in reader.connections:
            if conn.topic in ("/tf", "/tf_static") or conn.msgtype in ("sensor_msgs/msg/BatteryState",) or \
                    (conn.topic.endswith("/mission/status") and conn.msgtype == "std_msgs/msg/String"):
                light.append(conn)
            elif conn.msgtype in ("sensor_msgs/msg/PointCloud2", "sensor_msgs/msg/Image"):
                self.heavy.append(conn)
        last_tf = -math.inf
        order: list[str] = []                      # vehicles in the order /tf lists them (the world file's)
        for conn, stamp, raw in reader.messages(connections=light):
            t = stamp / 1e9
            if conn.topic == "/tf":
                if t - last_tf < 1.0 / TRACK_HZ - 1e-9:
                    continue                       # thinned out: the page needs no more
                last_tf = t
                for tf in reader.deserialize(raw, conn.msgtype).transforms:
                    child = tf.child_frame_id
                    if child.endswith(_BASE):
                        tr, q = tf.transform.translation, tf.transform.rotation
                        name = child[:-len(_BASE)]
                        track = self.tracks.setdefault(name, Track())
                        if not track.times_s:
                            order.append(name)
                        track.times_s.append(t)
                        track.pos_enu_m.append((tr.x, tr.y, tr.z))
                        track.quat_xyzw.append((q.x, q.y, q.z, q.w))
            elif conn.topic == "/tf_static":
                for tf in reader.deserialize(raw, conn.msgtype).transforms:
                    tr = tf.transform.translation
                    self.static[tf.child_frame_id] = (tf.header.frame_id, _rotation(tf.transform.rotation),
                                                      np.array([tr.x, tr.y, tr.z]))
            elif conn.msgtype == "sensor_msgs/msg/BatteryState":
                msg = reader.deserialize(raw, conn.msgtype)
                vehicle = msg.header.frame_id.split("/", 1)[0] or _vehicle_of_topic(conn.topic)
                self.tracks.setdefault(vehicle, Track()).battery.append((t, float(msg.percentage)))
            else:
                try:
                    status = json.loads(reader.deserialize(raw, conn.msgtype).data)
                except ValueError:
                    continue
                if isinstance(status, dict):
                    vehicle = _vehicle_of_topic(conn.topic)
                    self.tracks.setdefault(vehicle, Track()).status.append((t, status))
                    self.events.append((t, vehicle, "mission: " + (frames.mission_text(status) or "?")))
        for track in self.tracks.values():
            track.finish()
        self.tracks = {name: self.tracks[name] for name in order}
        self.events.sort(key=lambda e: e[0])
        self._event_times = [e[0] for e in self.events]

    def close(self) -> None:
        try:
            self.reader.close()
        except Exception:
            pass

    # -- what the page shows at time t -----------------------------------------------------------
    def pose(self, vehicle: str, t_s: float) -> tuple[np.ndarray, np.ndarray]:
        """Position (linear between samples) and attitude (the nearer sample) of ``vehicle`` at ``t_s``."""
        tr = self.tracks[vehicle]
        k = bisect_right(tr.times_s, t_s) - 1
        if k < 0:
            return np.array(tr.pos_enu_m[0]), np.array(tr.quat_xyzw[0])
        if k >= len(tr.times_s) - 1:
            return np.array(tr.pos_enu_m[-1]), np.array(tr.quat_xyzw[-1])
        t0, t1 = tr.times_s[k], tr.times_s[k + 1]
        f = (t_s - t0) / (t1 - t0)
        p = (1.0 - f) * np.array(tr.pos_enu_m[k]) + f * np.array(tr.pos_enu_m[k + 1])
        return p, np.array(tr.quat_xyzw[k if f < 0.5 else k + 1])

    def rows(self, t_s: float, kinds: dict[str, str]) -> list[frames.VehicleRow]:
        rows = []
        for name, tr in self.tracks.items():
            p, q = self.pose(name, t_s)
            k = min(max(bisect_right(tr.times_s, t_s) - 1, 0), len(tr.times_s) - 1)
            speed = float(tr.speed_m_s[k]) if len(tr.speed_m_s) else 0.0
            battery = _last_before(tr.battery, t_s)
            status = _last_before(tr.status, t_s)
            mode = "moving" if speed > MOVING_M_S else "stopped"
            rows.append(frames.VehicleRow(name, p.tolist(), q.tolist(), speed, float(p[2]), battery, mode,
                                          frames.mission_text(status) if kinds.get(name) != "car" else ""))
        return rows

    def events_until(self, t_s: float, n: int = EVENTS_SHOWN) -> list[tuple[float, str, str]]:
        k = bisect_right(self._event_times, t_s)
        return self.events[max(0, k - n):k]

    def mount(self, frame: str) -> tuple[str, np.ndarray, np.ndarray] | None:
        """(vehicle, R, t) of ``frame`` in its vehicle's base_link from /tf_static (None: not a vehicle's frame)."""
        R, t = _IDENTITY
        for _ in range(8):
            if frame.endswith(_BASE):
                return frame[:-len(_BASE)], R, t
            parent = self.static.get(frame)
            if parent is None:
                return None
            frame, R_p, t_p = parent
            R, t = R_p @ R, R_p @ t + t_p
        return None

    def heavy_messages(self, start_s: float) -> Iterator[tuple[Any, int, bytes]]:
        """The LiDAR clouds and images from ``start_s`` on, raw, in time order."""
        return self.reader.messages(connections=self.heavy, start=int(max(start_s, self.start_s) * 1e9))

    def kinds(self) -> dict[str, str]:
        """Each vehicle's kind as far as the recording tells: a battery or a mission means a drone."""
        return {name: "quadrotor" if (tr.battery or tr.status) else "vehicle" for name, tr in self.tracks.items()}


def _last_before(samples: list[tuple[float, Any]], t_s: float) -> Any:
    value = None
    lo, hi = 0, len(samples)
    while lo < hi:                                  # the last sample at or before t_s
        mid = (lo + hi) // 2
        if samples[mid][0] <= t_s:
            lo = mid + 1
        else:
            hi = mid
    if lo:
        value = samples[lo - 1][1]
    return value


class ReplaySource:
    """The view's frames from a :class:`Recording`, played at ``speed`` times the wall clock (server's thread)."""

    def __init__(self, recording: Recording, scene: SceneInfo) -> None:
        self.rec = recording
        self.scene = scene
        self.kinds = {v.name: v.kind for v in scene.vehicles}
        self.playing = True
        self.speed = 1.0
        self.t_s = recording.start_s
        self._anchor: tuple[float, float] | None = None      # (wall, play time) while playing
        self.rtf = RealTimeFactor()
        self._heavy: Iterator[tuple[Any, int, bytes]] | None = None
        self._ahead: tuple[Any, int, bytes] | None = None
        self._read_to_s = -math.inf
        self._lidar: dict[str, frames.LazyFrame] = {}
        self._images: dict[tuple[str, str], frames.LazyFrame] = {}
        self._seq = 0

    def hello(self) -> list[str | bytes]:
        return [self.scene.scene_message("replay", start_s=self.rec.start_s, end_s=self.rec.end_s),
                self.scene.mesh_message()]

    def control(self, msg: dict[str, Any]) -> None:
        kind = msg["type"]
        if kind == "play":
            if self.t_s >= self.rec.end_s:             # at the end: play again from the start
                self._seek(self.rec.start_s)
            self.playing = True
        elif kind == "pause":
            self.playing = False
        elif kind == "seek":
            self._seek(msg["t"])
        elif kind == "speed":
            self.speed = float(msg["x"])
        self._anchor = None

    def _seek(self, t_s: float) -> None:
        self.t_s = min(max(float(t_s), self.rec.start_s), self.rec.end_s)
        self._heavy = None                             # read the sensors again from there

    def poll(self, now_s: float) -> Update | None:
        if self.playing:
            if self._anchor is None:
                self._anchor = (now_s, self.t_s)
            wall0, t0 = self._anchor
            self.t_s = min(t0 + (now_s - wall0) * self.speed, self.rec.end_s)
            if self.t_s >= self.rec.end_s:
                self.playing = False
                self._anchor = None
        self._read_sensors(self.t_s)
        rtf = self.rtf.sample(now_s, self.t_s)
        images: dict[str, frames.LazyFrame] = {}
        for (vehicle, sensor), frame in self._images.items():
            if sensor == "camera" or vehicle not in images:
                images[vehicle] = frame
        player = {"playing": self.playing, "speed": self.speed, "start": self.rec.start_s, "end": self.rec.end_s}
        state = frames.state_message(self.t_s, rtf, self.rec.rows(self.t_s, self.kinds), self.rec.events_until(self.t_s),
                                     replay=player)
        return Update(state, dict(self._lidar), images)

    def _read_sensors(self, t_s: float) -> None:
        """Read the clouds and images up to ``t_s``, keeping the newest of each (undecoded)."""
        if self._heavy is None or t_s < self._read_to_s or t_s - self._read_to_s > LOOKBACK_S:
            self._heavy = self.rec.heavy_messages(t_s - LOOKBACK_S)
            self._ahead = None
            self._lidar.clear()
            self._images.clear()
        self._read_to_s = t_s
        t_ns = int(t_s * 1e9)
        while True:
            item = self._ahead or next(self._heavy, None)
            self._ahead = None
            if item is None:
                return
            if item[1] > t_ns:
                self._ahead = item
                return
            self._keep(*item)

    def _keep(self, conn: Any, stamp: int, raw: bytes) -> None:
        vehicle = _vehicle_of_topic(conn.topic)
        self._seq += 1
        t_s = stamp / 1e9
        if conn.msgtype == "sensor_msgs/msg/PointCloud2":
            self._lidar[vehicle] = frames.LazyFrame(self._seq, t_s, lambda: self._lidar_message(conn, t_s, raw))
        else:
            sensor = "depth_camera" if "depth" in conn.topic else "camera"
            self._images[(vehicle, sensor)] = frames.LazyFrame(
                self._seq, t_s, lambda: self._image_message(conn, vehicle, sensor, t_s, raw))

    def _lidar_message(self, conn: Any, t_s: float, raw: bytes) -> bytes | None:
        msg = self.rec.reader.deserialize(raw, conn.msgtype)
        found = self.rec.mount(msg.header.frame_id)
        if found is None or found[0] not in self.rec.tracks:
            return None
        vehicle, R_mount, t_mount = found
        pos, quat = self.rec.pose(vehicle, t_s)
        R_body = R_from_quat_xyzw(quat)
        xyz = frames.cloud_xyz(msg).astype(np.float64) @ (R_body @ R_mount).T + (pos + R_body @ t_mount)
        return frames.lidar_message(vehicle, t_s, xyz.astype(np.float32))

    def _image_message(self, conn: Any, vehicle: str, sensor: str, t_s: float, raw: bytes) -> bytes | None:
        rgb = frames.image_rgb8(self.rec.reader.deserialize(raw, conn.msgtype))
        return None if rgb is None else frames.image_message(vehicle, sensor, t_s, rgb)


def find_world(recording: Path, world: Path | None = None) -> tuple[Any | None, str]:
    """The world a recording was made in, and a note for the page when there is none: ``world`` when
    given (ReplayError if it does not load), else the world file named by ``summary.json`` of the run
    the recording sits in, if it is still there."""
    from ..config.schema import ConfigError
    from ..config.world_file import load_world

    if world is not None:
        try:
            return load_world(world), ""
        except (ConfigError, OSError) as exc:
            raise ReplayError(f"--world {world}: {exc}") from exc
    rec = Path(recording).resolve()
    base = rec.parent if rec.is_file() else rec
    for summary in (base / "summary.json", base.parent / "summary.json"):
        if not summary.is_file():
            continue
        try:
            data = json.loads(summary.read_text(encoding="utf-8"))
            name, seed = data.get("world_file"), data.get("seed")
        except (OSError, ValueError, AttributeError):
            continue
        if not isinstance(name, str):
            continue
        for candidate in (Path(name), summary.parent / name):
            if candidate.is_file():
                try:
                    return load_world(candidate, seed=seed if isinstance(seed, int) else None), ""
                except Exception:
                    break
        return None, f"no city: the world file {name} of this run was not found (pass --world WORLD)"
    return None, "no city: pass --world WORLD (the world file the recording was made from)"


def replay_scene(recording: Recording, world: Any | None, note: str) -> SceneInfo:
    """The scene of a replay: the world's city and vehicle looks, for the vehicles the recording has."""
    looks: dict[str, VehicleLook] = {}
    if world is not None:
        looks = {e.name: vehicle_look(e) for e in world.entities if e.kind != "package"}
    kinds = recording.kinds()
    vehicles = []
    for name in recording.tracks:
        look = looks.get(name)
        if look is None:
            kind = kinds[name]
            look = VehicleLook(name, kind, half_extents_m=DEFAULT_HALF_EXTENTS_M.get(kind, (0.5, 0.5, 0.5)))
        vehicles.append(look)
    if world is not None:
        scene = scene_from_world(world, note)
        scene.vehicles = vehicles
        return scene
    return SceneInfo("recording", None, vehicles, note)


def open_replay(path: str | Path, world: str | Path | None = None) -> ReplaySource:
    """A replay source for the recording at ``path`` (ReplayError when it cannot be replayed)."""
    recording = Recording(path)
    if not recording.tracks:
        recording.close()
        raise ReplayError(f"{path}: the recording has no vehicle poses (no /tf with <vehicle>/base_link)")
    try:
        found, note = find_world(Path(path), Path(world) if world is not None else None)
    except ReplayError:
        recording.close()
        raise
    return ReplaySource(recording, replay_scene(recording, found, note))


def serve_replay(path: str | Path, port: int = 0, world: str | Path | None = None) -> tuple[ViewServer, ReplaySource]:
    """Open the recording and serve it on ``127.0.0.1:port``; the started server and its source
    (ReplayError: the recording; :class:`~.server.ServerError`: the port)."""
    source = open_replay(path, world)
    server = ViewServer(source, port, name="view")
    try:
        server.start()
    except Exception:
        source.rec.close()
        raise
    return server, source


__all__ = ["LOOKBACK_S", "Recording", "ReplayError", "ReplaySource", "TRACK_HZ", "bag_path", "find_world",
           "open_replay", "replay_scene", "serve_replay"]
