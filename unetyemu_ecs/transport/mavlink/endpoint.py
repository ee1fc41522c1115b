"""One drone's MAVLink endpoint: two links (api, gcs), telemetry, commands, parameters, missions.

Runs only on the transport's thread. Commands go to the simulation as bus commands (source
``mavlink``); COMMAND_ACK is sent when the command's :class:`CommandResult` comes back, with the
MAV_RESULT that result says (never an invented success).
"""

from __future__ import annotations

import math
import struct
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from pymavlink.dialects.v20 import common as mavlink2

from ...command_checks import (check_change_speed, check_in_world, check_land_xy, check_mission_step,
                               check_offboard_attitude, check_offboard_setpoint, check_position, check_set_target,
                               check_takeoff)
from ...frames import (euler_rpy_from_quat_xyzw, frd_to_flu, ned_to_enu, quat_ned_frd_to_enu_flu,
                       quat_wxyz_to_xyzw, yaw_ned_to_enu_rad)
from ...geodesy import GeodeticOrigin, enu_to_geodetic, geodetic_to_enu
from ...navigation.params import PARAM_BY_NAME, PX4_PARAMS, check_param, default_values
from ...systems.flight_state import ARM_BLOCK_TEXT, ArmBlock, NavState
from .. import bus
from ..api import CommandResult, CommandStatus, Snapshot
from . import px4
from .codec import SignatureChecker, addressed_to
from .component import COMPONENT_ID, MavlinkEndpoint
from .link import Link
from .missions import MissionService
from .telemetry import RowView, build

PARAM_REAL32, PARAM_INT32 = 9, 6
PENDING_TIMEOUT_S = 10.0                  # wall clock: a command whose result never comes is forgotten
MAX_Z_M = 10_000.0
MAX_SPEED_M_S = 100.0
STATUSTEXT_LEN = 50
SEVERITY_CRITICAL, SEVERITY_WARNING, SEVERITY_INFO = 2, 4, 6
INT32_MAX = 2**31 - 1

# MAV_CMD numbers
CMD_NAV_WAYPOINT, CMD_LOITER_UNLIM, CMD_RTL, CMD_LAND, CMD_TAKEOFF, CMD_ORBIT = 16, 17, 20, 21, 22, 34
CMD_DO_SET_MODE, CMD_DO_CHANGE_SPEED, CMD_DO_SET_HOME, CMD_DO_FLIGHTTERMINATION = 176, 178, 179, 185
CMD_DO_REPOSITION, CMD_DO_PAUSE_CONTINUE, CMD_DO_GRIPPER, CMD_DO_SET_MISSION_CURRENT = 192, 193, 211, 224
CMD_DO_FENCE_ENABLE, CMD_MISSION_START, CMD_ARM_DISARM, CMD_RUN_PREARM_CHECKS = 207, 300, 400, 401
CMD_GET_MESSAGE_INTERVAL, CMD_SET_MESSAGE_INTERVAL, CMD_REQUEST_MESSAGE = 510, 511, 512
CMD_REQUEST_AUTOPILOT_CAPABILITIES = 520

# SET_ATTITUDE_TARGET type_mask bits (ATTITUDE_TARGET_TYPEMASK)
ATT_THRUST_BODY_SET, ATT_IGNORE_THRUST, ATT_IGNORE_ATTITUDE = 32, 64, 128

GLOBAL_FRAMES = {0: "amsl", 3: "relative", 5: "amsl", 6: "relative"}    # GLOBAL, GLOBAL_RELATIVE_ALT, *_INT

STATUS_TO_RESULT = {CommandStatus.ACCEPTED: px4.ACCEPTED, CommandStatus.IN_PROGRESS: px4.ACCEPTED,
                    CommandStatus.DONE: px4.ACCEPTED, CommandStatus.REJECTED_STATE: px4.TEMPORARILY_REJECTED,
                    CommandStatus.REJECTED_INVALID: px4.DENIED, CommandStatus.FAILED: px4.FAILED}


class Denied(Exception):
    """A command value is NaN, out of range or not one we know: COMMAND_ACK DENIED, nothing submitted."""


def mav_result(result: CommandResult) -> int:
    if result.status == CommandStatus.REJECTED_INVALID and result.reason == "unsupported":
        return px4.UNSUPPORTED
    return STATUS_TO_RESULT.get(result.status, px4.FAILED)


def encode_param(value: float, is_int: bool) -> float:
    """PX4 bytewise encoding: INT32 bits carried in the float field."""
    if is_int:
        return struct.unpack("<f", struct.pack("<i", int(value)))[0]
    return float(value)


def decode_param(raw: float, is_int: bool) -> float:
    if is_int:
        return float(struct.unpack("<i", struct.pack("<f", raw))[0])
    return float(raw)


def _yaw_enu_deg(yaw_ned_deg: float | None) -> float | None:
    """A MAVLink heading (deg, NED: 0 north, clockwise) as degrees ENU (0 east, counter-clockwise) in (-180, 180]."""
    if yaw_ned_deg is None:
        return None
    enu = math.degrees(float(yaw_ned_to_enu_rad(math.radians(yaw_ned_deg))))
    return -((-enu + 180.0) % 360.0 - 180.0)


def _finite(*values: float) -> bool:
    return all(isinstance(v, (int, float)) and math.isfinite(v) for v in values)


@dataclass
class Pending:
    link: Link
    addr: tuple[str, int]
    src: tuple[int, int]
    command: int
    since_s: float
    kind: str = "command"          # "command" (COMMAND_ACK) or "param" (PARAM_VALUE)
    param: str = ""
    value: float = 0.0


class DroneEndpoint:
    """The MAVLink face of one drone."""

    def __init__(self, vehicle: str, cfg: MavlinkEndpoint, origin: GeodeticOrigin, layout: Any,
                 submit: Callable[[Any], int], physics_dt_s: float, out_dir: Path | None,
                 signing_key: bytes | None) -> None:
        self.vehicle = vehicle
        self.cfg = cfg
        self.sysid = cfg.system_id
        self.compid = COMPONENT_ID
        self.origin = origin
        self.layout = layout
        self._submit = submit
        self.dt_s = physics_dt_s
        self.params_path = None if out_dir is None else Path(out_dir) / "mavlink" / f"{vehicle}.params"
        host = cfg.remote_host
        self.links = [
            Link("api", vehicle, cfg.bind, cfg.api_local_port, (host, cfg.api_remote_port), self.sysid, self.compid,
                 signing_key),
            Link("gcs", vehicle, cfg.bind, cfg.gcs_local_port, (host, cfg.gcs_remote), self.sysid, self.compid,
                 signing_key),
        ]
        self.signature = SignatureChecker(signing_key) if signing_key is not None else None
        self.signing_required = bool(cfg.signing and cfg.signing.required and signing_key is not None)
        rates = px4.STREAM_RATES_HZ[cfg.streams]
        self.intervals: list[dict[int, float]] = [
            {mid: (1.0 / hz[k] if hz[k] > 0 else 0.0) for mid, hz in rates.items()} for k in range(2)]
        self.due: list[dict[int, float]] = [dict.fromkeys(rates, 0.0) for _ in range(2)]
        self.defaults = [dict(d) for d in self.intervals]
        self.pending: dict[int, Pending] = {}
        self.params: dict[str, float] = default_values()
        self.params_version = -1
        self.local_origin_enu: np.ndarray | None = None
        self.view: RowView | None = None
        self.view_snapshot: tuple[Snapshot, int] | None = None     # newest snapshot not yet turned into a view
        self.imu: Any = None
        self.statustext_id = 0
        self.commands = {"accepted": 0, "rejected": 0, "unsupported": 0, "denied": 0, "expired": 0}
        self.unhandled_messages = 0
        self.setpoints_rejected = 0
        self.said_attitude_refusal = False
        self.mission_ids: set[int] = set()
        self.missions = MissionService(vehicle, self.sysid, self.compid, origin, layout, self._submit_mission)

    # -- life cycle (transport thread) ---------------------------------------------------------------

    def open(self) -> None:
        try:
            for link in self.links:
                link.open()
        except Exception:
            self.close()
            raise

    def close(self) -> None:
        for link in self.links:
            link.close()
        self.write_params()

    def _submit_mission(self, command: Any) -> int:
        command_id = self._submit(command)
        self.mission_ids.add(command_id)
        return command_id

    def submit(self, command: Any) -> int:
        return self._submit(command)

    # -- receive --------------------------------------------------------------------------------------

    def on_datagram(self, link: Link, data: bytes, addr: tuple[str, int], now_s: float) -> None:
        for msg, frame, signed in link.parser.frames(data):
            if self.signature is not None and signed:
                if not self.signature.check(frame):
                    link.rx.bad_signature += 1
                    continue
            elif self.signing_required:
                link.rx.unsigned_rejected += 1
                continue
            if not addressed_to(msg, self.sysid, self.compid):
                link.rx.not_for_us += 1
                continue
            link.adopt(addr, now_s)
            try:
                self.handle(msg, link, addr, now_s)
            except Exception:              # noqa: BLE001 - one bad message must not end the endpoint
                link.rx.parser_errors += 1

    def handle(self, msg: Any, link: Link, addr: tuple[str, int], now_s: float) -> None:
        mid = msg.get_msgId()
        if mid in MissionService.HANDLES:
            self.missions.handle(msg, link, now_s)
        elif mid in (75, 76):
            self.on_command(msg, link, addr, now_s)
        elif mid == 20:
            self.on_param_read(msg, link, addr)
        elif mid == 21:
            for index in range(len(PX4_PARAMS)):
                link.send(self.param_value(index), to=addr)
        elif mid == 23:
            self.on_param_set(msg, link, addr, now_s)
        elif mid == 11:
            nav = px4.nav_state_of(msg.custom_mode) if msg.base_mode & px4.FLAG_CUSTOM else None
            if nav is not None:
                self.submit(bus.SetNavMode(self.vehicle, int(nav), source="mavlink"))
        elif mid == 4:
            if msg.target_system == 0:
                link.send(mavlink2.MAVLink_ping_message(msg.time_usec, msg.seq, msg.get_srcSystem(),
                                                        msg.get_srcComponent()), to=addr)
        elif mid == 111:
            view = self.current_view()
            if msg.tc1 == 0 and view is not None:
                link.send(mavlink2.MAVLink_timesync_message(int(view.t_s * 1e9), msg.ts1), to=addr)
        elif mid == 84:
            self.on_position_target_local(msg)
        elif mid == 86:
            self.on_position_target_global(msg)
        elif mid == 82:
            self.on_attitude_target(msg, link)
        elif mid == 69:
            self.on_manual_control(msg)
        elif mid == 144:
            self.on_follow_target(msg)
        elif mid != 0:                   # HEARTBEAT of a GCS: only adopts the peer
            self.unhandled_messages += 1

    # -- commands -------------------------------------------------------------------------------------

    def ack(self, link: Link, addr: tuple[str, int], src: tuple[int, int], command: int, result: int,
            reason: str = "") -> None:
        counter = {px4.ACCEPTED: "accepted", px4.UNSUPPORTED: "unsupported", px4.DENIED: "denied"}.get(result,
                                                                                                    "rejected")
        self.commands[counter] += 1
        link.send(mavlink2.MAVLink_command_ack_message(command, result, 0, 0, src[0], src[1]), to=addr)
        if reason and result != px4.ACCEPTED:
            self.statustext(f"{command}: {reason}", SEVERITY_WARNING, links=[link])

    def on_command(self, msg: Any, link: Link, addr: tuple[str, int], now_s: float) -> None:
        src = (msg.get_srcSystem(), msg.get_srcComponent())
        cmd = int(msg.command)
        p = [msg.param1, msg.param2, msg.param3, msg.param4]
        if msg.get_msgId() == 75:                                  # COMMAND_INT: x, y degE7, z by frame
            frame = int(msg.frame)
            lat = math.nan if msg.x in (INT32_MAX,) else msg.x / 1e7
            lon = math.nan if msg.y in (INT32_MAX,) else msg.y / 1e7
            positional = cmd in (CMD_DO_REPOSITION, CMD_ORBIT, CMD_LAND, CMD_TAKEOFF, CMD_DO_SET_HOME)
            if positional and frame not in GLOBAL_FRAMES:
                self.ack(link, addr, src, cmd, px4.DENIED, f"frame {frame} is not a global frame")
                return
            alt = float(msg.z)
            if positional and GLOBAL_FRAMES.get(frame) == "relative" and math.isfinite(alt):
                alt += self.home_alt_amsl()
            p += [lat, lon, alt]
        else:
            p += [msg.param5, msg.param6, msg.param7]
        for key, pend in self.pending.items():
            if pend.kind == "command" and pend.command == cmd and pend.src == src and pend.link is link:
                return                   # a retry while the first one is pending: ACK when its result comes
        try:
            command = self.command_for(cmd, p, link, addr, src)
        except (Denied, ValueError) as exc:     # ValueError: a command_checks refusal
            self.ack(link, addr, src, cmd, px4.DENIED, str(exc))
            return
        if command is None:
            return                       # answered here (stateless) or unsupported
        command_id = self.submit(command)
        self.pending[command_id] = Pending(link, addr, src, cmd, now_s)

    def home_alt_amsl(self) -> float:
        view = self.current_view()
        return view.home_alt if view is not None else self.origin.alt_m

    def _enu(self, lat: float, lon: float, alt: float) -> tuple[float, float, float]:
        """ENU point of a geodetic one; NaN lat/lon keep the drone's position, NaN alt its height."""
        view = self.current_view()
        here = view.pos_enu if view is not None else np.zeros(3)
        if not _finite(lat, lon) and not (math.isnan(lat) and math.isnan(lon)):
            raise Denied("latitude/longitude must be finite")
        if math.isinf(alt):
            raise Denied("altitude must be finite")
        if math.isnan(lat):
            x, y = float(here[0]), float(here[1])
            z = float(here[2]) if math.isnan(alt) else float(alt - self.origin.alt_m)
        else:
            if not (-90.0 <= lat <= 90.0 and -180.0 <= lon <= 180.0):
                raise Denied(f"latitude/longitude ({lat}, {lon}) out of range")
            a = self.origin.alt_m + float(here[2]) if math.isnan(alt) else alt
            x, y, z = map(float, geodetic_to_enu(lat, lon, a, self.origin))
        if not _finite(x, y, z):
            raise Denied("position must be finite")
        if not 0.0 <= z <= MAX_Z_M:
            raise Denied(f"altitude {z:.1f} m above the ground plane is outside [0, {MAX_Z_M:g}] m")
        if self.layout is not None:
            try:
                check_in_world(f"{self.vehicle} position", self.layout, [(x, y)])
            except ValueError as exc:
                raise Denied(str(exc)) from None
        return x, y, z

    def command_for(self, cmd: int, p: list[float], link: Link, addr: tuple[str, int],
                    src: tuple[int, int]) -> Any:
        """The bus command for MAV_CMD ``cmd`` (params p1..p7), None when answered here; raises Denied."""
        v = self.vehicle
        mk = dict(source="mavlink")
        if cmd == CMD_ARM_DISARM:
            if p[0] not in (0.0, 1.0):
                raise Denied(f"param1 must be 1 (arm) or 0 (disarm), got {p[0]}")
            return bus.Arm(v, p[0] == 1.0, force=p[1] == px4.FORCE_ARM_MAGIC, **mk)
        if cmd == CMD_DO_SET_MODE:
            if not _finite(p[0], p[1], p[2]) or not int(p[0]) & px4.FLAG_CUSTOM:
                raise Denied("DO_SET_MODE needs base mode with MAV_MODE_FLAG_CUSTOM_MODE_ENABLED and PX4 modes")
            custom = (int(p[1]) & 0xFF) << 16 | (int(p[2]) & 0xFF) << 24
            nav = px4.nav_state_of(custom)
            if nav is None:
                raise Denied(f"PX4 mode {int(p[1])}.{int(p[2])} is not flown here")
            return bus.SetNavMode(v, int(nav), **mk)
        if cmd == CMD_TAKEOFF:
            yaw = None if math.isnan(p[3]) else p[3]
            if yaw is not None and not (_finite(yaw) and -360.0 <= yaw <= 360.0):
                raise Denied(f"yaw {p[3]} deg out of range")
            if math.isnan(p[6]):
                alt = None
            else:
                if not _finite(p[6]):
                    raise Denied("takeoff altitude must be finite")
                alt = float(p[6] - self.origin.alt_m)
                if not 0.0 < alt <= MAX_Z_M:
                    raise Denied(f"takeoff altitude {p[6]:.1f} m AMSL is outside the world")
            alt, yaw_rad = check_takeoff(v, alt, _yaw_enu_deg(yaw))
            return bus.Takeoff(v, alt, yaw_rad, **mk)
        if cmd == CMD_LAND:
            if math.isnan(p[4]) or math.isnan(p[5]) or (p[4] == 0 and p[5] == 0):
                return bus.Land(v, None, **mk)
            x, y, _ = self._enu(p[4], p[5], math.nan)
            return bus.Land(v, check_land_xy(v, self.layout, (x, y)), **mk)
        if cmd == CMD_RTL:
            return bus.ReturnToLaunch(v, **mk)
        if cmd == CMD_LOITER_UNLIM:
            return bus.SetNavMode(v, int(NavState.HOLD), **mk)
        if cmd == CMD_DO_REPOSITION:
            speed = None if (math.isnan(p[0]) or p[0] < 0) else p[0]
            if speed is not None and not (0.0 < speed <= MAX_SPEED_M_S):
                raise Denied(f"speed {p[0]} m/s out of range")
            yaw = None if math.isnan(p[3]) else p[3]
            if yaw is not None and not (_finite(yaw) and -360.0 <= yaw <= 360.0):
                raise Denied(f"yaw {p[3]} deg out of range")
            x, y, z = self._enu(p[4], p[5], p[6])
            pos, yaw_rad, speed = check_set_target(v, "quadrotor", self.layout, x, y, z, _yaw_enu_deg(yaw), speed)
            return bus.SetTarget(v, pos, yaw_rad, speed, **mk)
        if cmd == CMD_ORBIT:
            radius = p[0]
            speed = 1.0 if math.isnan(p[1]) else p[1]
            if not (_finite(radius, speed) and 1.0 <= abs(radius) <= 10_000.0 and 0.0 < abs(speed) <= MAX_SPEED_M_S):
                raise Denied(f"orbit radius {radius} m / speed {p[1]} m/s out of range")
            behaviour = 0 if math.isnan(p[2]) else int(p[2]) if _finite(p[2]) else -1
            if not 0 <= behaviour <= 4:
                raise Denied(f"orbit yaw behaviour {p[2]} unknown")
            center = check_position(f"orbit({v!r})", self.layout, self._enu(p[4], p[5], p[6]))
            return bus.Orbit(v, center, float(radius), float(abs(speed)), behaviour, **mk)
        if cmd == CMD_DO_CHANGE_SPEED:
            which = {0: "ground", 1: "ground", 2: "climb", 3: "descent"}.get(int(p[0]) if _finite(p[0]) else -1)
            if which is None:
                raise Denied(f"speed type {p[0]} unknown")
            which, speed = check_change_speed(v, which, float(p[1]))
            return bus.ChangeSpeed(v, which, speed, **mk)
        if cmd == CMD_DO_SET_HOME:
            if p[0] == 1.0:
                return bus.SetHome(v, None, **mk)
            if math.isnan(p[4]) or math.isnan(p[5]):
                raise Denied("DO_SET_HOME needs param1 = 1 or a latitude/longitude")
            return bus.SetHome(v, check_position(f"set_home({v!r})", self.layout, self._enu(p[4], p[5], p[6])), **mk)
        if cmd == CMD_MISSION_START:
            first = 0 if math.isnan(p[0]) else p[0]
            if not (_finite(first) and first >= 0 and first == int(first)):
                raise Denied(f"first item {p[0]} must be a whole number >= 0")
            step = self.missions.step_of_seq(int(first))
            if step is None and first != 0:
                raise Denied(f"the uploaded mission has no item {int(first)}")
            return bus.StartMission(v, check_mission_step(v, step or 0), **mk)        # no mission at all: the simulation refuses
        if cmd == CMD_DO_SET_MISSION_CURRENT:
            if not (_finite(p[0]) and p[0] >= 0 and p[0] == int(p[0])):
                raise Denied(f"mission item {p[0]} must be a whole number >= 0")
            step = self.missions.step_of_seq(int(p[0]))
            if step is None:
                raise Denied(f"the uploaded mission has no item {int(p[0])}")
            return bus.SetMissionCurrent(v, check_mission_step(v, step), **mk)
        if cmd == CMD_DO_PAUSE_CONTINUE:
            if p[0] not in (0.0, 1.0):
                raise Denied("param1 must be 0 (pause) or 1 (continue)")
            return bus.PauseMission(v, p[0] == 1.0, **mk)
        if cmd == CMD_DO_GRIPPER:
            if p[1] not in (0.0, 1.0):
                raise Denied("param2 must be 0 (release) or 1 (grab)")
            return bus.Gripper(v, p[1] == 1.0, **mk)
        if cmd == CMD_DO_FENCE_ENABLE:
            if p[0] == 2.0:
                raise Denied("disabling only the fence floor (param1 2) is not supported")
            if p[0] not in (0.0, 1.0):
                raise Denied(f"param1 must be 0 (disable) or 1 (enable), got {p[0]}")
            return bus.SetFenceEnabled(v, p[0] == 1.0, **mk)
        if cmd == CMD_RUN_PREARM_CHECKS:
            self.prearm_report(link, addr, src)
            return None
        if cmd == CMD_DO_FLIGHTTERMINATION:
            if p[0] != 1.0:
                raise Denied("param1 must be 1 to terminate the flight")
            return bus.Terminate(v, **mk)
        if cmd in (CMD_SET_MESSAGE_INTERVAL, CMD_GET_MESSAGE_INTERVAL, CMD_REQUEST_MESSAGE,
                   CMD_REQUEST_AUTOPILOT_CAPABILITIES):
            self.local_command(cmd, p, link, addr, src)
            return None
        self.ack(link, addr, src, cmd, px4.UNSUPPORTED)
        return None

    def prearm_report(self, link: Link, addr: tuple[str, int], src: tuple[int, int]) -> None:
        """MAV_CMD_RUN_PREARM_CHECKS: ACCEPTED, then the verdict of the simulation's arming checks in the
        newest snapshot (``arm_block``, the check the Arm command applies) as a STATUSTEXT, like PX4."""
        view = self.current_view()
        if view is None:
            self.ack(link, addr, src, CMD_RUN_PREARM_CHECKS, px4.TEMPORARILY_REJECTED, "no state yet")
            return
        self.ack(link, addr, src, CMD_RUN_PREARM_CHECKS, px4.ACCEPTED)
        if view.arm_block == ArmBlock.NONE:
            self.statustext("Preflight checks passed", SEVERITY_INFO)
            return
        why = ARM_BLOCK_TEXT.get(view.arm_block, f"arming check {view.arm_block}")
        self.statustext(f"Preflight Fail: {why}", SEVERITY_CRITICAL)

    def local_command(self, cmd: int, p: list[float], link: Link, addr: tuple[str, int],
                      src: tuple[int, int]) -> None:
        """Commands the endpoint answers itself (message intervals, requests for one message)."""
        k = self.links.index(link)
        if cmd == CMD_REQUEST_AUTOPILOT_CAPABILITIES:
            link.send(self.autopilot_version(), to=addr)
            self.ack(link, addr, src, cmd, px4.ACCEPTED)
            return
        if not _finite(p[0]) or p[0] != int(p[0]):
            raise Denied(f"message id {p[0]} must be a whole number")
        mid = int(p[0])
        if cmd == CMD_REQUEST_MESSAGE:
            msg = self.message(mid)
            if msg is None:
                self.ack(link, addr, src, cmd, px4.UNSUPPORTED)
                return
            self.ack(link, addr, src, cmd, px4.ACCEPTED)
            link.send(msg, to=addr)
            return
        if mid not in self.intervals[k]:
            self.ack(link, addr, src, cmd, px4.UNSUPPORTED if cmd == CMD_GET_MESSAGE_INTERVAL else px4.DENIED,
                     f"message {mid} is not streamed")
            return
        if cmd == CMD_GET_MESSAGE_INTERVAL:
            interval = self.intervals[k][mid]
            self.ack(link, addr, src, cmd, px4.ACCEPTED)
            link.send(mavlink2.MAVLink_message_interval_message(mid, int(interval * 1e6) if interval > 0 else -1),
                      to=addr)
            return
        if not _finite(p[1]) or p[1] < -1:
            raise Denied(f"interval {p[1]} us must be -1 (off), 0 (default) or > 0")
        if p[1] == -1:
            self.intervals[k][mid] = 0.0
        elif p[1] == 0:
            self.intervals[k][mid] = self.defaults[k][mid]
        else:
            self.intervals[k][mid] = max(p[1] * 1e-6, self.dt_s)
        self.due[k][mid] = 0.0
        self.ack(link, addr, src, cmd, px4.ACCEPTED)

    # -- streams ---------------------------------------------------------------------------------------

    def on_position_target_local(self, msg: Any) -> None:
        mask, frame = int(msg.type_mask), int(msg.coordinate_frame)
        body = frame in (8, 12)                    # MAV_FRAME_BODY_NED (MAVSDK), BODY_FRD
        if frame not in (1, 8, 12) or self.local_origin_enu is None:
            self.unhandled_messages += 1
            return
        pos = vel = vel_body = yaw = yaw_rate = None
        if not mask & 0x7:
            p_ned = np.array([msg.x, msg.y, msg.z], dtype=float)
            if body or not np.all(np.isfinite(p_ned)):
                self.unhandled_messages += 1
                return
            pos = tuple(map(float, self.local_origin_enu + ned_to_enu(p_ned)))
        if not mask & 0x38:
            v = np.array([msg.vx, msg.vy, msg.vz], dtype=float)
            if not np.all(np.isfinite(v)) or np.any(np.abs(v) > MAX_SPEED_M_S):
                self.unhandled_messages += 1
                return
            if body:
                vel_body = tuple(map(float, frd_to_flu(v)))
            else:
                vel = tuple(map(float, ned_to_enu(v)))
        if not mask & 0x400 and math.isfinite(msg.yaw):
            yaw = float(yaw_ned_to_enu_rad(msg.yaw))
        if not mask & 0x800 and math.isfinite(msg.yaw_rate):
            yaw_rate = -float(msg.yaw_rate)
        self.submit_setpoint(pos, vel, vel_body, yaw, yaw_rate)

    def on_position_target_global(self, msg: Any) -> None:
        mask, frame = int(msg.type_mask), int(msg.coordinate_frame)
        if frame not in GLOBAL_FRAMES:
            self.unhandled_messages += 1
            return
        pos = vel = yaw = yaw_rate = None
        try:
            if not mask & 0x7:
                alt = float(msg.alt) + (self.home_alt_amsl() if GLOBAL_FRAMES[frame] == "relative" else 0.0)
                pos = self._enu(msg.lat_int / 1e7, msg.lon_int / 1e7, alt)
        except Denied:
            self.unhandled_messages += 1
            return
        if not mask & 0x38:
            v = np.array([msg.vx, msg.vy, msg.vz], dtype=float)
            if not np.all(np.isfinite(v)) or np.any(np.abs(v) > MAX_SPEED_M_S):
                self.unhandled_messages += 1
                return
            vel = tuple(map(float, ned_to_enu(v)))
        if not mask & 0x400 and math.isfinite(msg.yaw):
            yaw = float(yaw_ned_to_enu_rad(msg.yaw))
        if not mask & 0x800 and math.isfinite(msg.yaw_rate):
            yaw_rate = -float(msg.yaw_rate)
        self.submit_setpoint(pos, vel, None, yaw, yaw_rate)

    def submit_setpoint(self, pos: Any, vel: Any, vel_body: Any, yaw: float | None, yaw_rate: float | None) -> None:
        """One OFFBOARD setpoint through the project's checks. PX4 takes a velocity with a position as
        feed-forward and a yaw with a yaw rate: here the position, and the yaw, win."""
        if pos is not None:
            vel = vel_body = None
        if yaw is not None:
            yaw_rate = None
        try:
            parts = check_offboard_setpoint(self.vehicle, self.layout, pos, vel, vel_body,
                                            None if yaw is None else math.degrees(yaw), yaw_rate)
        except ValueError:
            self.setpoints_rejected += 1
            return
        self.submit(bus.OffboardSetpoint(self.vehicle, *parts, source="mavlink"))

    def on_attitude_target(self, msg: Any, link: Link) -> None:
        """SET_ATTITUDE_TARGET: attitude ``q`` (FRD in NED, w x y z) with the normalised collective
        ``thrust`` is an OFFBOARD attitude setpoint; the heading comes from ``q``. Body-rate-only setpoints
        (attitude ignored), a missing thrust and a thrust vector (THRUST_BODY_SET: pymavlink's common
        dialect has no ``thrust_body`` field to read it from) are refused (counted, and said once in a
        STATUSTEXT): this stack's attitude layer takes angles and a collective thrust, not rates."""
        mask = int(msg.type_mask)
        if mask & (ATT_IGNORE_ATTITUDE | ATT_IGNORE_THRUST | ATT_THRUST_BODY_SET):
            self.setpoints_rejected += 1
            if not self.said_attitude_refusal:
                self.said_attitude_refusal = True
                self.statustext("SET_ATTITUDE_TARGET needs q and thrust (no rates)", SEVERITY_WARNING, links=[link])
            return
        q_wxyz = np.array(msg.q, dtype=float)
        norm = float(np.linalg.norm(q_wxyz)) if np.all(np.isfinite(q_wxyz)) else math.nan
        thrust = float(msg.thrust)
        if not 0.9 <= norm <= 1.1:
            self.setpoints_rejected += 1
            return
        roll, pitch, yaw = euler_rpy_from_quat_xyzw(quat_ned_frd_to_enu_flu(quat_wxyz_to_xyzw(q_wxyz / norm)))
        try:
            yaw_rad, yaw_rate, rp, thrust_frac = check_offboard_attitude(
                self.vehicle, math.degrees(float(roll)), math.degrees(float(pitch)), thrust,
                yaw_deg=math.degrees(float(yaw)))
        except ValueError:
            self.setpoints_rejected += 1
            return
        self.submit(bus.OffboardSetpoint(self.vehicle, yaw_rad=yaw_rad, yaw_rate_rad_s=yaw_rate, attitude_rp_rad=rp,
                                         thrust_frac=thrust_frac, source="mavlink"))

    def on_manual_control(self, msg: Any) -> None:
        axes = (msg.x, msg.y, msg.z, msg.r)
        if any(a == 32767 for a in axes) or not (-1000 <= msg.x <= 1000 and -1000 <= msg.y <= 1000
                                                 and 0 <= msg.z <= 1000 and -1000 <= msg.r <= 1000):
            self.unhandled_messages += 1
            return
        self.submit(bus.ManualControl(self.vehicle, msg.x / 1000.0, msg.y / 1000.0, msg.z / 1000.0, msg.r / 1000.0,
                                      source="mavlink"))

    def on_follow_target(self, msg: Any) -> None:
        if not msg.est_capabilities & 1:
            self.unhandled_messages += 1
            return
        try:
            pos = self._enu(msg.lat / 1e7, msg.lon / 1e7, float(msg.alt))
        except Denied:
            self.unhandled_messages += 1
            return
        vel = None
        if msg.est_capabilities & 2:
            v = np.array(msg.vel[:3], dtype=float)
            if np.all(np.isfinite(v)) and np.all(np.abs(v) <= MAX_SPEED_M_S):
                vel = tuple(map(float, ned_to_enu(v)))
        self.submit(bus.FollowTargetFix(self.vehicle, pos, vel, source="mavlink"))

    # -- parameters ------------------------------------------------------------------------------------

    def param_value(self, index: int) -> Any:
        spec = PX4_PARAMS[index]
        value = self.params.get(spec.name, spec.default)
        return mavlink2.MAVLink_param_value_message(
            spec.name.encode(), encode_param(value, spec.is_int), PARAM_INT32 if spec.is_int else PARAM_REAL32,
            len(PX4_PARAMS), index)

    @staticmethod
    def _param_name(raw: Any) -> str:
        if isinstance(raw, bytes):
            raw = raw.decode("ascii", "replace")
        return str(raw).split("\x00", 1)[0]

    def on_param_read(self, msg: Any, link: Link, addr: tuple[str, int]) -> None:
        if msg.param_index >= 0:
            if msg.param_index < len(PX4_PARAMS):
                link.send(self.param_value(msg.param_index), to=addr)
            return
        name = self._param_name(msg.param_id)
        if name in PARAM_BY_NAME:
            link.send(self.param_value(PX4_PARAMS.index(PARAM_BY_NAME[name])), to=addr)

    def on_param_set(self, msg: Any, link: Link, addr: tuple[str, int], now_s: float) -> None:
        name = self._param_name(msg.param_id)
        spec = PARAM_BY_NAME.get(name)
        if spec is None:
            self.statustext(f"unknown parameter {name[:16]!r}", SEVERITY_WARNING, links=[link])
            return
        index = PX4_PARAMS.index(spec)
        expected = PARAM_INT32 if spec.is_int else PARAM_REAL32
        error = "" if msg.param_type == expected else f"{name} has type {'INT32' if spec.is_int else 'REAL32'}"
        value = decode_param(msg.param_value, spec.is_int) if not error else math.nan
        error = error or check_param(name, value)
        if error:
            link.send(self.param_value(index), to=addr)
            self.statustext(error, SEVERITY_WARNING, links=[link])
            return
        command_id = self.submit(bus.SetParam(self.vehicle, name, value, source="mavlink"))
        self.pending[command_id] = Pending(link, addr, (msg.get_srcSystem(), msg.get_srcComponent()), 0, now_s,
                                           kind="param", param=name, value=value)

    def write_params(self) -> None:
        """``<out_dir>/mavlink/<vehicle>.params`` in QGroundControl's format."""
        if self.params_path is None:
            return
        lines = ["# Onboard parameters for Vehicle " + str(self.sysid),
                 "# Vehicle-Id Component-Id Name Value Type"]
        for spec in PX4_PARAMS:
            value = self.params.get(spec.name, spec.default)
            shown = str(int(value)) if spec.is_int else f"{value:.9g}"
            lines.append(f"{self.sysid}\t{self.compid}\t{spec.name}\t{shown}\t{PARAM_INT32 if spec.is_int else PARAM_REAL32}")
        try:
            self.params_path.parent.mkdir(parents=True, exist_ok=True)
            self.params_path.write_text("\n".join(lines) + "\n")
        except OSError:
            pass

    # -- results, events --------------------------------------------------------------------------------

    def on_result(self, result: CommandResult) -> None:
        if result.command_id in self.mission_ids:
            self.mission_ids.discard(result.command_id)
            self.missions.on_result(result)
            return
        pend = self.pending.pop(result.command_id, None)
        if pend is None:
            return
        if pend.kind == "param":
            if result.ok:
                self.params[pend.param] = pend.value
                for link in self.links:
                    link.send(self.param_value(PX4_PARAMS.index(PARAM_BY_NAME[pend.param])))
                self.write_params()
            else:
                pend.link.send(self.param_value(PX4_PARAMS.index(PARAM_BY_NAME[pend.param])), to=pend.addr)
                self.statustext(result.text or f"{pend.param} not set: {result.reason}", SEVERITY_WARNING,
                                links=[pend.link])
            return
        self.ack(pend.link, pend.addr, pend.src, pend.command, mav_result(result))   # refusals: STATUSTEXT from the event log

    def expire(self, now_s: float) -> None:
        for command_id in [i for i, p in self.pending.items() if now_s - p.since_s > PENDING_TIMEOUT_S]:
            del self.pending[command_id]
            self.commands["expired"] += 1
        for link in self.links:
            link.expire(now_s)

    def statustext(self, text: str, severity: int, links: list[Link] | None = None) -> None:
        """STATUSTEXT in 50-character chunks (id and chunk_seq when it takes more than one)."""
        data = text.encode("utf-8", "replace")[:STATUSTEXT_LEN * 20]
        chunks = [data[i:i + STATUSTEXT_LEN] for i in range(0, max(len(data), 1), STATUSTEXT_LEN)]
        ident = 0
        if len(chunks) > 1 or len(data) == STATUSTEXT_LEN:
            self.statustext_id = self.statustext_id % 65535 + 1
            ident = self.statustext_id
        for seq, chunk in enumerate(chunks):
            for link in links or self.links:
                link.send(mavlink2.MAVLink_statustext_message(severity, chunk, ident, seq))

    def on_event(self, text: str) -> None:
        low = text.lower()
        severity = SEVERITY_CRITICAL if any(w in low for w in ("crash", "empty", "terminat", "overweight")) else \
            SEVERITY_WARNING if any(w in low for w in ("refus", "reject", "denied", "fail", "low", "lost", "breach",
                                                       "timed out")) else \
            SEVERITY_INFO
        self.statustext(text, severity)

    # -- telemetry ---------------------------------------------------------------------------------------

    def autopilot_version(self) -> Any:
        return mavlink2.MAVLink_autopilot_version_message(
            px4.CAPABILITIES, px4.FLIGHT_SW_VERSION, 0, 0, 0, [0] * 8, [0] * 8, [0] * 8, 0, 0, self.sysid)

    def gps_global_origin(self) -> Any | None:
        view = self.current_view()
        if self.local_origin_enu is None or view is None:
            return None
        lat, lon, alt = enu_to_geodetic(self.local_origin_enu, self.origin)
        return mavlink2.MAVLink_gps_global_origin_message(int(round(float(lat) * 1e7)), int(round(float(lon) * 1e7)),
                                                          int(round(float(alt) * 1000)), view.time_usec)

    def message(self, mid: int) -> Any | None:
        """One message ``mid`` now (REQUEST_MESSAGE), None when we never produce it."""
        if mid == 148:
            return self.autopilot_version()
        if mid == 49:
            return self.gps_global_origin()
        view = self.current_view()
        if view is None:
            return None
        return build(mid, view, self.imu)

    def current_view(self) -> RowView | None:
        """The drone in the newest snapshot (built on first use after it arrived)."""
        if self.view_snapshot is not None:
            snap, row = self.view_snapshot
            self.view = RowView(snap, row, self.origin, self.local_origin_enu)
            self.view_snapshot = None
        return self.view

    def on_snapshot(self, snap: Snapshot, row: int) -> None:
        """Telemetry that is due at this snapshot's sim time, on each link."""
        if self.local_origin_enu is None:
            self.local_origin_enu = np.array(snap.arrays["pos_enu_m"][row], dtype=float)
        for sample in snap.sensors:
            if getattr(sample, "vehicle", None) == self.vehicle and hasattr(getattr(sample, "msg", None),
                                                                           "linear_acceleration"):
                self.imu = sample.msg
        t = snap.sim_time_s
        if self.view is not None and not any(0.0 < iv and t + 1e-9 >= self.due[k][mid]
                                             for k in range(len(self.links)) for mid, iv in self.intervals[k].items()):
            self.view_snapshot = (snap, row)     # nothing due: the view is built when a request needs it
        else:
            self.view_snapshot = None
            self.view = RowView(snap, row, self.origin, self.local_origin_enu)
        params = snap.params.get(self.vehicle) if snap.params else None
        if params is not None and snap.params_version != self.params_version:
            self.params_version = snap.params_version
            changed = {k: float(v) for k, v in params.items() if self.params.get(k) != float(v)}
            if changed:
                self.params.update(changed)
                self.write_params()
        built: dict[int, Any] = {}
        for k, link in enumerate(self.links):
            due = self.due[k]
            for mid, interval in self.intervals[k].items():
                if interval <= 0.0 or t + 1e-9 < due[mid]:
                    continue
                due[mid] = max(due[mid] + interval, t) if due[mid] > 0 else t + interval
                if mid not in built:
                    built[mid] = self.message(mid)
                    if mid == 105:
                        self.imu = None
                if built[mid] is not None:
                    link.send(built[mid])
        self.missions.on_snapshot(snap, row, self.links)

    def tick(self, now_s: float) -> None:
        self.missions.tick(now_s)

    def counters(self) -> dict[str, Any]:
        out: dict[str, Any] = {link.name: link.counters() for link in self.links}
        out["commands"] = dict(self.commands)
        out["unhandled_messages"] = self.unhandled_messages
        out["setpoints_rejected"] = self.setpoints_rejected
        out["system_id"] = self.sysid
        out["ports"] = {"api": [self.cfg.api_local_port, self.cfg.api_remote_port],
                        "gcs": [self.cfg.gcs_local_port, self.cfg.gcs_remote]}
        out["missions"] = self.missions.counters()
        return out


__all__ = ["DroneEndpoint", "decode_param", "encode_param", "mav_result"]
