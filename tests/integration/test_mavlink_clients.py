"""Real MAVLink clients against `unetyemu run` with the shipped two-drone MAVLink world, on loopback.

The simulator runs as the user runs it (``unetyemu run worlds/mavlink_pair.yaml``, real-time pace,
ports moved to free ones); the clients are the real programs: the repository's pymavlink and
MAVSDK-Python examples and MAVProxy. What the clients saw is compared with the simulator's own
CSV logs, events and summary.
"""

from __future__ import annotations

import csv
import json
import math
import os
import random
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from pymavlink.dialects.v20 import common as mavlink2

from unetyemu_ecs.navigation.params import PX4_PARAMS
from unetyemu_ecs.units import GRAVITY_M_S2
from unetyemu_ecs.vehicles.presets import preset

from ..conftest import REPO_ROOT, WORLDS, unetyemu_command
from .mavlink_client import Client, free_ports

EXAMPLES = REPO_ROOT / "examples"
NATIVE_FLIGHT = Path(__file__).with_name("mavsdk_native_flight.py")
MAVSDK_NATIVE = "mavsdk==4.1.0"      # MAVSDK-Python's native (ctypes) binding; the test extra pins the gRPC 3.x
PX4_AUTO_LOITER = 3 << 24 | 4 << 16      # PX4 custom mode AUTO.LOITER (HOLD): sub 3, main 4


def pair_world(tmp_path: Path, ports: dict[str, int]) -> Path:
    """worlds/mavlink_pair.yaml with its MAVLink ports moved to ``ports`` (free ones)."""
    text = (WORLDS / "mavlink_pair.yaml").read_text(encoding="utf-8")
    for i in range(2):
        old = f"mavlink: {{instance: {i}}}"
        assert old in text
        text = text.replace(old, f"mavlink: {{instance: {i}, api_local_base: {ports['api_local']}, "
                                 f"api_remote_base: {ports['api_remote']}, gcs_local_base: {ports['gcs_local']}, "
                                 f"gcs_remote: {ports['gcs_remote']}}}")
    path = tmp_path / "mavlink_pair.yaml"
    path.write_text(text, encoding="utf-8")
    return path


class RunningSim:
    """``unetyemu run WORLD`` in its own process group; stop() ends it with Ctrl-C and reads its outputs."""

    def __init__(self, world: Path, out: Path, duration_s: float) -> None:
        self.out = out
        self.proc = subprocess.Popen([*unetyemu_command(), "run", str(world), "--duration", str(duration_s),
                                      "--out", str(out), "--quiet"], cwd=REPO_ROOT, stdout=subprocess.PIPE,
                                     stderr=subprocess.STDOUT, text=True, start_new_session=True)

    def stop(self) -> dict:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
        try:
            output, _ = self.proc.communicate(timeout=60)
        except subprocess.TimeoutExpired:
            os.killpg(self.proc.pid, signal.SIGKILL)
            output, _ = self.proc.communicate()
        assert self.proc.returncode in (0, 130), output
        return json.loads((self.out / "summary.json").read_text())

    def log(self, vehicle: str) -> list[dict[str, str]]:
        with open(self.out / f"{vehicle}.csv", newline="", encoding="utf-8") as fh:
            return list(csv.DictReader(fh))


def run_client(args: list[str], timeout_s: float) -> subprocess.CompletedProcess:
    """Run a client script in its own process group (MAVSDK starts mavsdk_server children); on a
    timeout the whole group is killed so nothing is left listening."""
    proc = subprocess.Popen([sys.executable, *args], cwd=REPO_ROOT, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        out, err = proc.communicate(timeout=timeout_s)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        out, err = proc.communicate()
        pytest.fail(f"{args[0]} did not finish within {timeout_s:g} s:\n{out}\n{err[-3000:]}")
    finally:
        try:
            os.killpg(proc.pid, signal.SIGKILL)      # mavsdk_server children, if any are left
        except ProcessLookupError:
            pass
    return subprocess.CompletedProcess(args, proc.returncode, out, err)


@pytest.fixture
def pair(tmp_path):
    ports = free_ports(2)
    sims: list[RunningSim] = []

    def start(duration_s: float) -> RunningSim:
        sim = RunningSim(pair_world(tmp_path, ports), tmp_path / "out", duration_s)
        sims.append(sim)
        return sim

    yield ports, start
    for sim in sims:
        if sim.proc.poll() is None:
            os.killpg(sim.proc.pid, signal.SIGKILL)
            sim.proc.wait()


def test_pymavlink_example_sets_parameters_and_round_trips_fence_rally_and_mission(pair):
    # GIVEN the two-drone world running with its MAVLink endpoints
    ports, start = pair
    sim = start(120.0)
    # WHEN the pymavlink example talks to drone 0's API link
    res = run_client([str(EXAMPLES / "pymavlink_mission.py"), "--connect", f"udpin:127.0.0.1:{ports['api_remote']}"],
                     timeout_s=90.0)
    summary = sim.stop()
    # THEN every check of the example passed: a PX4 autopilot, every parameter listed, a float and
    # an integer parameter set and read back, and fence, rally and mission downloads equal their uploads
    assert res.returncode == 0, res.stdout + res.stderr[-3000:]
    report = json.loads(res.stdout.strip().splitlines()[-1])
    assert report["ok"] and report["autopilot"] == mavlink2.MAV_AUTOPILOT_PX4
    assert report["param_count"] == len(PX4_PARAMS)
    # AND the simulator agrees: three lists accepted, the parameters changed and persisted for the run
    missions = summary["transports"]["mavlink"]["drone_a"]["missions"]
    assert missions["uploads_accepted"] == 3 and missions["uploads_rejected"] == 0
    events = [e["text"] for e in summary["events"] if e["entity"] == "drone_a"]
    assert "parameter MIS_TAKEOFF_ALT set to 7.5" in events and "parameter GF_ACTION set to 3" in events
    params = (sim.out / "mavlink" / "drone_a.params").read_text()
    assert "1\t1\tMIS_TAKEOFF_ALT\t7.5\t9" in params and "1\t1\tGF_ACTION\t3\t6" in params


def test_mavproxy_arms_takes_off_and_lands_a_drone_over_the_gcs_link(pair):
    # GIVEN the two-drone world running, and a ground-station listener where the GCS links send (14550)
    ports, start = pair
    sim = start(200.0)
    gcs = Client(ports["gcs_remote"])
    try:
        # WHEN MAVProxy (headless, commands on stdin) connects to drone 0's GCS link, arms it, takes
        # off to MIS_TAKEOFF_ALT and lands
        proxy = subprocess.Popen([sys.executable, "-m", "MAVProxy.mavproxy",
                                  f"--master=udpout:127.0.0.1:{ports['gcs_local']}", "--target-system=1",
                                  "--no-state", "--default-modules=cmdlong,arm"],
                                 stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                 text=True, start_new_session=True, cwd=sim.out.parent)
        seen: dict[int, list] = {1: [], 2: []}
        rel_alt_mm: list[int] = [0]

        def watch(until, timeout_s: float = 60.0) -> bool:
            """Read the GCS port until ``until()`` holds (True) or ``timeout_s`` of wall time passed (False)."""
            deadline = time.monotonic() + timeout_s
            while time.monotonic() < deadline:
                gcs.poll()
                for hb in iter(lambda: gcs.take("HEARTBEAT"), None):
                    seen.setdefault(hb.get_srcSystem(), []).append(hb)
                for pos in iter(lambda: gcs.take("GLOBAL_POSITION_INT", lambda m: m.get_srcSystem() == 1), None):
                    rel_alt_mm.append(pos.relative_alt)
                if until():
                    return True
                time.sleep(0.05)
            return False

        def armed(sysid: int = 1) -> bool:
            return bool(seen[sysid]) and bool(seen[sysid][-1].base_mode & mavlink2.MAV_MODE_FLAG_SAFETY_ARMED)

        def send(line: str) -> None:
            proxy.stdin.write(line + "\n")
            proxy.stdin.flush()

        assert watch(lambda: seen[1] and seen[2]), "no HEARTBEAT from both drones on the GCS port"
        time.sleep(3.0)                               # MAVProxy has found the vehicle (it waits for a HEARTBEAT)
        send("arm throttle")
        assert watch(armed), "drone 0 did not arm"
        send("long MAV_CMD_NAV_TAKEOFF 0 0 0 nan nan nan nan")
        assert watch(lambda: max(rel_alt_mm) > 2000 and seen[1][-1].custom_mode == PX4_AUTO_LOITER), \
            "drone 0 did not climb above 2 m and hold (the end of a PX4 takeoff)"
        send("long MAV_CMD_NAV_LAND 0 0 0 nan nan nan 0")
        assert watch(lambda: not armed(), timeout_s=90.0), "drone 0 did not land and disarm"
        send("exit")
        output, _ = proxy.communicate(timeout=30)
    finally:
        gcs.close()
        if proxy.poll() is None:
            os.killpg(proxy.pid, signal.SIGKILL)
            proxy.wait()
    summary = sim.stop()
    # THEN MAVProxy saw the commands accepted, and the simulator flew them: up to about 2.5 m
    # (MIS_TAKEOFF_ALT), down again, disarmed 2 s after touchdown; drone 1 never moved
    assert "COMPONENT_ARM_DISARM: ACCEPTED" in output and "NAV_TAKEOFF: ACCEPTED" in output
    assert "NAV_LAND: ACCEPTED" in output
    rows = sim.log("drone_a")
    z = [float(r["z_m"]) for r in rows]
    assert 2.2 < max(z) < 3.2 and z[-1] < 0.3
    assert {"takeoff", "land"} <= {r["nav_state"] for r in rows} and rows[-1]["mode"] == "disarmed"
    assert rows[-1]["landed_state"] == "on_ground"
    assert any("disarmed: landed 2 s ago" in e["text"] for e in summary["events"] if e["entity"] == "drone_a")
    assert max(float(r["z_m"]) for r in sim.log("drone_b")) < 0.5


def _fuzz(port: int, count: int, stop: threading.Event, sent: list[int]) -> None:
    """Send ``count`` datagrams that are not valid MAVLink to 127.0.0.1:``port``, about 300 per second:
    random bytes, valid frames with a flipped bit (the CRC then fails), truncated frames, glued junk,
    stray start bytes, frames of unknown message ids. Never a valid frame (that would be a command)."""
    rng = random.Random(7)
    enc = mavlink2.MAVLink(None, 200, 190)
    good = [enc.heartbeat_encode(6, 8, 0, 0, 0).pack(enc),
            enc.command_long_encode(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0).pack(enc),
            enc.param_request_list_encode(1, 1).pack(enc)]
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        for k in range(count):
            if stop.is_set():
                break
            frame = bytearray(rng.choice(good))
            kind = k % 6
            if kind == 0:
                data = rng.randbytes(rng.randrange(1, 300))
            elif kind == 1:
                i = rng.randrange(len(frame))
                frame[i] ^= 1 << rng.randrange(8)
                data = bytes(frame)
            elif kind == 2:
                data = bytes(frame[:rng.randrange(1, len(frame) - 1)])
            elif kind == 3:
                data = rng.randbytes(rng.randrange(1, 40)) + bytes(frame[:-1])
            elif kind == 4:
                data = bytes([rng.choice((0xFD, 0xFE))]) * rng.randrange(1, 4)
            else:
                frame[7:10] = (0xFFFE00 + rng.randrange(200)).to_bytes(3, "little")     # an id nobody defines
                data = bytes(frame)
            sock.sendto(data, ("127.0.0.1", port))
            sent[0] += 1
            if k % 15 == 0:
                time.sleep(0.05)          # about 300 per second: the garbage spans the first half minute of flight
    finally:
        sock.close()


def test_mavsdk_native_binding_takes_off_flies_offboard_attitude_lands_and_disarms_a_drone(pair, tmp_path):
    # GIVEN MAVSDK-Python's native binding (4.x) in a private folder (it shares the name `mavsdk` with
    # the gRPC 3.x the test extra pins), and the two-drone world running
    site = tmp_path / "mavsdk4"
    pip = subprocess.run([sys.executable, "-m", "pip", "install", "--quiet", "--no-deps", "--target", str(site),
                          MAVSDK_NATIVE], capture_output=True, text=True, timeout=600)
    assert pip.returncode == 0, pip.stderr[-2000:]
    ports, start = pair
    sim = start(150.0)
    # WHEN it connects to drone 0's API link, sets the takeoff altitude, arms, takes off, tilts 8 deg nose
    # down for 2 s in offboard attitude at the thrust whose vertical part carries the weight, and lands
    medium = preset("quadrotor", "medium")
    hover = medium["mass_kg"] * GRAVITY_M_S2 / (4.0 * medium["motors"]["max_thrust_per_motor_n"])
    env = {**os.environ, "PYTHONPATH": str(site)}
    proc = subprocess.run([sys.executable, str(NATIVE_FLIGHT), str(ports["api_remote"]), str(hover)], env=env,
                          capture_output=True, text=True, timeout=180, start_new_session=True)
    summary = sim.stop()
    # THEN every step was reached, and the simulator flew it: up to MIS_TAKEOFF_ALT = 4 m (set by
    # MAVSDK), down again, disarmed two seconds after touchdown
    assert proc.returncode == 0, proc.stdout + proc.stderr[-3000:]
    steps = {s["step"]: s for s in map(json.loads, (line for line in proc.stdout.splitlines() if line.startswith("{")))}
    assert list(steps) == ["connected", "took_off", "offboard_attitude", "landed_and_disarmed"]
    assert steps["connected"]["system_id"] == 1 and steps["took_off"]["in_air"]
    # the tilt drove it forward along its heading (2 s or a little more at g tan 8 deg = 1.38 m/s^2, less
    # drag), not sideways
    att = steps["offboard_attitude"]
    north, east, _ = att["vel_ned_m_s"]
    yaw = math.radians(att["heading_deg"])
    along, across = north * math.cos(yaw) + east * math.sin(yaw), -north * math.sin(yaw) + east * math.cos(yaw)
    assert att["mode"] == "OFFBOARD" and along > 1.5 and abs(across) < 0.3, att
    rows = sim.log("drone_a")
    modes = [r["mode"] for r in rows]
    assert "attitude" in modes                               # the attitude path flew it, not the position one
    before_offboard = rows[:modes.index("attitude")]
    assert 3.5 < max(float(r["z_m"]) for r in before_offboard) < 4.6 and rows[-1]["mode"] == "disarmed"
    events = [e["text"] for e in summary["events"] if e["entity"] == "drone_a"]
    assert "parameter MIS_TAKEOFF_ALT set to 4" in events and "disarmed: landed 2 s ago (COM_DISARM_LAND)" in events


@pytest.mark.slow
def test_mavsdk_flies_two_drones_at_once_through_takeoff_goto_mission_rtl_offboard_and_landing(pair):
    # GIVEN the two-drone world running in real time
    ports, start = pair
    sim = start(500.0)
    # WHEN the MAVSDK-Python example flies both drones concurrently
    res = run_client([str(EXAMPLES / "mavsdk_two_drones.py"), "--drones", "2", "--udp-base", str(ports["api_remote"]),
                      "--grpc-base", str(free_ports(2)["api_local"])], timeout_s=450.0)
    summary = sim.stop()
    assert res.returncode == 0, res.stdout + res.stderr[-3000:]
    steps = [json.loads(line) for line in res.stdout.splitlines() if line.startswith("{")]
    for i, name in enumerate(("drone_a", "drone_b")):
        mine = {s["step"]: s for s in steps if s["drone"] == i}
        # THEN every step was reached, in the order of the script
        assert list(mine) == ["healthy", "takeoff", "goto", "mission_done", "rtl_landed", "offboard_position",
                              "offboard_velocity_ned", "offboard_velocity_body", "landed"]
        start_enu = next(e["start_enu_m"] for e in summary["entities"] if e["name"] == name)
        final_enu = next(e["final_enu_m"] for e in summary["entities"] if e["name"] == name)
        # AND what MAVSDK saw is what the simulator did: RTL landed at home, offboard reached its
        # NED target, the NED velocity was flown east, the body yaw rate turned the drone right
        assert abs(mine["rtl_landed"]["ned_m"][0]) < 1.0 and abs(mine["rtl_landed"]["ned_m"][1]) < 1.0
        n, e, d = mine["offboard_position"]["ned_m"]
        assert abs(n - 5) < 0.7 and abs(e - 5) < 0.7 and abs(d + 6) < 0.7
        vn, ve, vd = mine["offboard_velocity_ned"]["vel_ned_m_s"]
        assert abs(ve - 2.0) < 0.3 and abs(vn) < 0.3 and abs(vd) < 0.3
        turned = (mine["offboard_velocity_body"]["heading_after_deg"]
                  - mine["offboard_velocity_body"]["heading_before_deg"]) % 360.0
        assert 45.0 < turned < 180.0
        ned = mine["landed"]["ned_m"]
        assert abs(start_enu[0] + ned[1] - final_enu[0]) < 0.3 and abs(start_enu[1] + ned[0] - final_enu[1]) < 0.3
        # AND the simulator's log shows the PX4 modes it flew, ending landed and disarmed
        rows = sim.log(name)
        assert {"takeoff", "goto", "mission", "offboard", "land"} <= {r["nav_state"] for r in rows}
        assert rows[-1]["mode"] == "disarmed" and rows[-1]["landed_state"] == "on_ground"
        yaw_offboard = [float(r["yaw_deg"]) for r in rows if r["nav_state"] == "offboard"]
        assert max(yaw_offboard) - min(yaw_offboard) > 45.0
        assert next(e for e in summary["entities"] if e["name"] == name)["mission"]["state"] == "completed"


@pytest.mark.slow
def test_a_mavsdk_flight_completes_while_10000_garbage_datagrams_hit_its_port(pair):
    # GIVEN the two-drone world running, and MAVSDK flying drone 0
    ports, start = pair
    sim = start(500.0)
    gcs = Client(ports["gcs_remote"])
    try:                                    # the endpoints are up (a datagram sent earlier would just be lost)
        deadline = time.monotonic() + 60.0
        while gcs.take("HEARTBEAT") is None and time.monotonic() < deadline:
            time.sleep(0.1)
            gcs.poll()
    finally:
        gcs.close()
    stop, sent = threading.Event(), [0]
    fuzzer = threading.Thread(target=_fuzz, args=(ports["api_local"], 10_000, stop, sent), daemon=True)
    fuzzer.start()
    # WHEN 10 000 invalid datagrams arrive at drone 0's API port during the flight
    res = run_client([str(EXAMPLES / "mavsdk_two_drones.py"), "--drones", "1", "--udp-base", str(ports["api_remote"]),
                      "--grpc-base", str(free_ports(1)["api_local"])], timeout_s=450.0)
    fuzzer.join(timeout=60)
    stop.set()
    summary = sim.stop()
    # THEN the flight completed, every garbage datagram was counted as dropped, and no junk sender became a peer
    assert res.returncode == 0, res.stdout + res.stderr[-3000:]
    assert '"step": "landed"' in res.stdout
    assert sent[0] == 10_000
    api = summary["transports"]["mavlink"]["drone_a"]["api"]
    dropped = sum(api[k] for k in ("bad_prefix", "bad_crc", "truncated", "unknown_id", "oversize", "bad_signature",
                                   "unsigned_rejected", "parser_errors"))
    assert dropped >= sent[0] and api["rx_datagrams"] >= sent[0] and api["peers"] <= 1
