"""Discovery in a network namespace: does a DEFAULT-configured DDS participant find the simulator, and
does any packet of the simulator's go out on the "LAN"?

Usage (as root, inside a fresh `unshare -n`): python3 netns_discovery.py SECONDS [FASTDDS_PEER_EXE]
Sets up `lo` (multicast on) and a veth pair: v0 (10.9.0.1/24) is this host's LAN interface, v1 its
far end, where every packet that leaves the host through v0 is captured. Then runs, for SECONDS:
a peer with cyclonedds' defaults (no CYCLONEDDS_URI, no configuration: what rmw_cyclonedds_cpp
uses with ROS 2's default discovery range) subscribed to /clock and ros_discovery_info, and the
simulator (`Simulation(..., ros2="dds")`, the environment as given). Prints one JSON object: the
simulator's and the peer's GUID prefixes, what the peer received, and per GUID prefix the IP TTLs
of the RTPS packets captured on v1. With FASTDDS_PEER_EXE (tests/fastdds_peer), the Fast DDS peer
runs too, with Fast DDS' defaults (FASTDDS_PEER_DEFAULTS), and its report is under "fastdds".

`python3 netns_discovery.py peer SECONDS` is the peer itself.
"""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
import threading
import time

WORLD = """
world: {name: netns, physics_hz: 240, seed: 3}
scene: {generator: none, ground_size_m: 100}
vehicles:
  - {name: d1, type: quadrotor, preset: medium, pose: {position_m: [0.0, 0.0, 0.3]}, components: {imu: {}}}
"""


def peer(seconds: float) -> None:
    from cyclonedds.core import Policy
    from cyclonedds.domain import DomainParticipant
    from cyclonedds.qos import Qos
    from cyclonedds.sub import DataReader
    from cyclonedds.topic import Topic
    from cyclonedds.util import duration

    from listen import idl, qos_for  # noqa: E402  (same folder)

    dp = DomainParticipant(0)                 # cyclonedds' defaults: no configuration at all
    clock = DataReader(dp, Topic(dp, "rt/clock", idl("rosgraph_msgs/msg/Clock")), qos=qos_for("/clock"))
    graph_qos = Qos(Policy.Reliability.Reliable(duration(seconds=1)), Policy.Durability.TransientLocal,
                    Policy.History.KeepLast(1))
    graph = DataReader(dp, Topic(dp, "ros_discovery_info", idl("rmw_dds_common/msg/ParticipantEntitiesInfo")),
                       qos=graph_qos)
    print(json.dumps({"guid_prefix": bytes(dp.guid.bytes[:12]).hex()}), flush=True)
    clocks, nodes = 0, []
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        clocks += len([s for s in clock.take(N=100) if hasattr(s, "clock")])
        nodes += [n.node_name for g in graph.take(N=10) if hasattr(g, "node_entities_info_seq")
                  for n in g.node_entities_info_seq]
        time.sleep(0.02)
    print(json.dumps({"clock_samples": clocks, "nodes": sorted(set(nodes))}), flush=True)


def capture(interface: str, seconds: float, seen: dict) -> None:
    """Record (GUID prefix -> IP TTLs) of every RTPS packet on ``interface`` (IPv4/UDP)."""
    s = socket.socket(socket.AF_PACKET, socket.SOCK_RAW, socket.ntohs(0x0003))
    s.bind((interface, 0))
    s.settimeout(0.2)
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        try:
            frame = s.recv(65535)
        except socket.timeout:
            continue
        if frame[12:14] != b"\x08\x00" or frame[23] != 17:              # IPv4, UDP
            continue
        ihl = (frame[14] & 0x0F) * 4
        rtps = frame[14 + ihl + 8:]
        if rtps[:4] == b"RTPS":
            seen.setdefault(rtps[8:20].hex(), set()).add(frame[22])        # GUID prefix -> TTLs


def main() -> None:
    if sys.argv[1] == "peer":
        peer(float(sys.argv[2]))
        return
    seconds = float(sys.argv[1])
    for cmd in ("ip link set lo up", "ip link set lo multicast on", "ip link add v0 type veth peer name v1",
                "ip addr add 10.9.0.1/24 dev v0", "ip link set v0 up", "ip link set v1 up"):
        subprocess.run(cmd.split(), check=True)
    time.sleep(1.0)                                          # the veth link comes up
    seen: dict[str, set] = {}
    cap = threading.Thread(target=capture, args=("v1", seconds + 4.0, seen), daemon=True)
    cap.start()
    env = {k: v for k, v in os.environ.items() if not k.startswith(("CYCLONEDDS_", "ROS_"))}
    other = subprocess.Popen([sys.executable, __file__, "peer", str(seconds + 2.0)], env=env,
                             cwd=os.path.dirname(os.path.abspath(__file__)), stdout=subprocess.PIPE, text=True)
    peer_prefix = json.loads(other.stdout.readline())["guid_prefix"]
    fast = None
    if len(sys.argv) > 2:
        fast = subprocess.Popen([sys.argv[2], "/d1/imu/data", "/d1/lidar/points", "/d1/camera/image_raw"],
                                env=env | {"FASTDDS_PEER_DEFAULTS": "1"}, stdin=subprocess.PIPE,
                                stdout=subprocess.PIPE, text=True)
        assert fast.stdout.readline().strip() == "ready"
    from unetyemu_ecs import Simulation, load_world_text

    with Simulation(load_world_text(WORLD), ros2="dds") as sim:
        sim_prefix = bytes(sim.transports["ros2"].bridge.publisher.participant.guid.bytes[:12]).hex()
        sim.run(duration=seconds, rate=1.0)
    fast_report = None
    if fast is not None:
        fast.stdin.write("report\n")
        fast.stdin.flush()
        fast_report = json.loads(fast.stdout.readline())
        fast.stdin.write("quit\n")
        fast.stdin.flush()
        fast.wait(timeout=10)
    got = json.loads(other.communicate(timeout=30)[0].strip().splitlines()[-1])
    cap.join()
    print(json.dumps({"sim": sim_prefix, "peer": peer_prefix, "received": got, "fastdds": fast_report,
                      "on_the_lan": {k: sorted(v) for k, v in seen.items()}}), flush=True)


if __name__ == "__main__":
    main()
