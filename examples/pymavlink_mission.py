"""Talk to one simulated drone with plain pymavlink: parameters, geofence, rally points and a mission.

Start a simulation with MAVLink endpoints first, then run this against drone 0's API link:

    unetyemu run worlds/mavlink_pair.yaml --duration 600 &
    python examples/pymavlink_mission.py --connect udpin:127.0.0.1:14540

It lists every parameter, sets MIS_TAKEOFF_ALT (a float) and GF_ACTION (an integer, PX4's bytewise
encoding) and reads both back; uploads a geofence (an inclusion polygon and an exclusion circle),
two rally points and a mission (takeoff, three waypoints with a speed change, return to launch)
with the MAVLink mission protocol, downloads each again and checks that the download equals the
upload. It prints one JSON object with what it found and exits 0 when every check passed.
"""

from __future__ import annotations

import argparse
import json
import math
import struct
import sys
import time
from typing import Any

from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mav

TIMEOUT_S = 20.0


class Drone:
    """A pymavlink connection to one MAVLink system, with blocking request/answer helpers."""

    def __init__(self, address: str, system_id: int) -> None:
        self.conn = mavutil.mavlink_connection(address, source_system=255, source_component=190, dialect="common")
        self.conn.target_system, self.conn.target_component = system_id, 1
        self.system_id = system_id

    def wait_heartbeat(self) -> Any:
        msg = self.conn.recv_match(type="HEARTBEAT", blocking=True, timeout=TIMEOUT_S)
        if msg is None or msg.get_srcSystem() != self.system_id:
            raise TimeoutError(f"no HEARTBEAT from system {self.system_id} within {TIMEOUT_S:g} s")
        return msg

    def recv(self, types: str | list[str], check=lambda m: True) -> Any:
        """The next message of one of ``types`` from our system that satisfies ``check``."""
        deadline = time.monotonic() + TIMEOUT_S
        while time.monotonic() < deadline:
            msg = self.conn.recv_match(type=types, blocking=True, timeout=deadline - time.monotonic())
            if msg is not None and msg.get_srcSystem() == self.system_id and check(msg):
                return msg
        raise TimeoutError(f"no {types} from system {self.system_id} within {TIMEOUT_S:g} s")

    # -- parameters ------------------------------------------------------------------------------
    def param_list(self) -> dict[str, float]:
        self.conn.mav.param_request_list_send(self.system_id, 1)
        values: dict[str, float] = {}
        first = self.recv("PARAM_VALUE")
        count = first.param_count
        values[first.param_id] = first.param_value
        while len(values) < count:
            msg = self.recv("PARAM_VALUE")
            values[msg.param_id] = msg.param_value
        return values

    def param_set(self, name: str, value: float, is_int: bool = False) -> float:
        """Set a parameter and return the value the drone echoes (PX4 bytewise encoding for integers)."""
        ptype = mav.MAV_PARAM_TYPE_INT32 if is_int else mav.MAV_PARAM_TYPE_REAL32
        wire = struct.unpack("<f", struct.pack("<i", int(value)))[0] if is_int else float(value)
        self.conn.mav.param_set_send(self.system_id, 1, name.encode(), wire, ptype)
        return self._decode(self.recv("PARAM_VALUE", lambda m: m.param_id == name))

    def param_read(self, name: str) -> float:
        self.conn.mav.param_request_read_send(self.system_id, 1, name.encode(), -1)
        return self._decode(self.recv("PARAM_VALUE", lambda m: m.param_id == name))

    @staticmethod
    def _decode(msg: Any) -> float:
        if msg.param_type == mav.MAV_PARAM_TYPE_INT32:
            return float(struct.unpack("<i", struct.pack("<f", msg.param_value))[0])
        return msg.param_value

    # -- mission protocol (mission_type 0 mission, 1 fence, 2 rally) --------------------------------
    def upload(self, items: list[Any], mission_type: int) -> int:
        """Upload ``items`` (MISSION_ITEM_INT messages); returns the MISSION_ACK result (0 = accepted)."""
        self.conn.mav.mission_count_send(self.system_id, 1, len(items), mission_type)
        while True:
            msg = self.recv(["MISSION_REQUEST_INT", "MISSION_REQUEST", "MISSION_ACK"],
                            lambda m: m.mission_type == mission_type)
            if msg.get_type() == "MISSION_ACK":
                return msg.type
            self.conn.mav.send(items[msg.seq])

    def download(self, mission_type: int) -> list[Any]:
        self.conn.mav.mission_request_list_send(self.system_id, 1, mission_type)
        count = self.recv("MISSION_COUNT", lambda m: m.mission_type == mission_type).count
        items = []
        for seq in range(count):
            self.conn.mav.mission_request_int_send(self.system_id, 1, seq, mission_type)
            items.append(self.recv("MISSION_ITEM_INT", lambda m: m.seq == seq and m.mission_type == mission_type))
        self.conn.mav.mission_ack_send(self.system_id, 1, mav.MAV_MISSION_ACCEPTED, mission_type)
        return items


def item(system_id: int, seq: int, command: int, lat: float, lon: float, alt: float, *params: float,
         frame: int = mav.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, mission_type: int = 0) -> Any:
    p = [*params, 0.0, 0.0, 0.0, 0.0][:4]
    return mav.MAVLink_mission_item_int_message(system_id, 1, seq, frame, command, 0, 1, *p, round(lat * 1e7),
                                                round(lon * 1e7), alt, mission_type)


def same_items(sent: list[Any], got: list[Any]) -> bool:
    fields = ("seq", "frame", "command", "autocontinue", "param1", "param2", "param3", "param4", "x", "y", "z",
              "mission_type")

    def key(m: Any) -> tuple:
        return tuple("nan" if isinstance(v, float) and math.isnan(v) else v for v in (getattr(m, f) for f in fields))

    return [key(m) for m in sent] == [key(m) for m in got]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--connect", default="udpin:127.0.0.1:14540", help="pymavlink address (default: drone 0's API link)")
    parser.add_argument("--system", type=int, default=1, help="the drone's MAVLink system id (instance + 1)")
    args = parser.parse_args(argv)
    if not 1 <= args.system <= 255:
        parser.error(f"--system must be in [1, 255], got {args.system}")

    drone = Drone(args.connect, args.system)
    hb = drone.wait_heartbeat()
    home = drone.recv("HOME_POSITION")
    lat0, lon0 = home.latitude / 1e7, home.longitude / 1e7
    deg_n, deg_e = 1 / 111_320.0, 1 / (111_320.0 * math.cos(math.radians(lat0)))     # degrees per metre
    report: dict[str, Any] = {"autopilot": hb.autopilot, "custom_mode": hb.custom_mode}

    params = drone.param_list()
    report["param_count"] = len(params)
    report["MIS_TAKEOFF_ALT"] = drone.param_set("MIS_TAKEOFF_ALT", 7.5)
    report["MIS_TAKEOFF_ALT_read"] = drone.param_read("MIS_TAKEOFF_ALT")
    report["GF_ACTION"] = drone.param_set("GF_ACTION", 3, is_int=True)
    report["GF_ACTION_read"] = drone.param_read("GF_ACTION")

    s = args.system
    square = [(-50, -50), (-50, 50), (50, 50), (50, -50)]          # north, east [m]
    fence = [item(s, k, mav.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION, lat0 + n * deg_n, lon0 + e * deg_e, 0.0,
                  len(square), frame=mav.MAV_FRAME_GLOBAL, mission_type=1) for k, (n, e) in enumerate(square)]
    fence.append(item(s, len(square), mav.MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION, lat0 + 30 * deg_n, lon0, 0.0, 5.0,
                      frame=mav.MAV_FRAME_GLOBAL, mission_type=1))
    rally = [item(s, k, mav.MAV_CMD_NAV_RALLY_POINT, lat0 + n * deg_n, lon0 + e * deg_e, 10.0, mission_type=2)
             for k, (n, e) in enumerate([(20, 0), (0, 20)])]
    mission = [item(s, 0, mav.MAV_CMD_NAV_TAKEOFF, lat0, lon0, 8.0),
               item(s, 1, mav.MAV_CMD_NAV_WAYPOINT, lat0 + 20 * deg_n, lon0, 8.0),
               item(s, 2, mav.MAV_CMD_DO_CHANGE_SPEED, 0.0, 0.0, 0.0, 1.0, 3.0, -1.0),
               item(s, 3, mav.MAV_CMD_NAV_WAYPOINT, lat0 + 20 * deg_n, lon0 + 20 * deg_e, 8.0),
               item(s, 4, mav.MAV_CMD_NAV_WAYPOINT, lat0, lon0 + 20 * deg_e, 8.0),
               item(s, 5, mav.MAV_CMD_NAV_RETURN_TO_LAUNCH, 0.0, 0.0, 0.0)]
    checks = {}
    for name, items, mission_type in (("fence", fence, 1), ("rally", rally, 2), ("mission", mission, 0)):
        report[f"{name}_upload_result"] = drone.upload(items, mission_type)
        checks[f"{name}_round_trip"] = same_items(items, drone.download(mission_type))
    report.update(checks)
    ok = (report["MIS_TAKEOFF_ALT"] == report["MIS_TAKEOFF_ALT_read"] == 7.5
          and report["GF_ACTION"] == report["GF_ACTION_read"] == 3.0
          and all(report[f"{n}_upload_result"] == mav.MAV_MISSION_ACCEPTED for n in ("fence", "rally", "mission"))
          and all(checks.values()))
    report["ok"] = ok
    print(json.dumps(report, sort_keys=True))
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
