"""The transport seam: what building the per-step snapshot costs (2 and 100 drones), and the real-time
factor (wall clock and per CPU second) of a 2-drone world run as fast as it goes with ROS 2 off, on
without a subscriber, and on with a reliable subscriber of the IMU topic that is SIGSTOPped for the
whole run (a dead peer: the simulation must not wait for it). Besides the process's CPU time (all
threads: the loop, the ROS 2 publishing thread, cyclonedds' own) it reports the CPU time of the
loop's thread alone, which a slow peer must not change.

Run: python3 -m pytest benchmarks/test_bench_transport.py --benchmark-only --benchmark-columns=mean,stddev,rounds -s
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from unetyemu_ecs import Simulation, load_world_text
from unetyemu_ecs.transport.snapshot import SnapshotBuilder

ROOT = Path(__file__).resolve().parent.parent
LISTENER = ROOT / "tests" / "ros2_peer" / "listen.py"
RUN_S = 20.0           # simulated seconds per run (well inside the stopped reader's 10 s lease at these speeds)


def world(drones: int) -> str:
    rows = "\n".join(f"  - {{name: d{i}, type: quadrotor, preset: small, pose: {{position_m: [{2.0 * (i % 10)}, "
                     f"{2.0 * (i // 10)}, 0.2]}}, components: {{imu: {{}}, battery: {{}}}}}}" for i in range(drones))
    return f"""
world: {{name: bench_transport, physics_hz: 240, seed: 1}}
scene: {{generator: none, ground_size_m: 400}}
vehicles:
{rows}
"""


@pytest.mark.parametrize("drones", [2, 100])
def test_snapshot_build(benchmark, drones):
    """One snapshot of a flying fleet: array copies, sensor samples, mission and parameter changes."""
    with Simulation(load_world_text(world(drones))) as sim:
        for i in range(drones):
            sim.arm(f"d{i}")
            sim.set_target(f"d{i}", 2.0 * (i % 10), 2.0 * (i // 10) + 5.0, 4.0)
        sim.step(24)
        builder = SnapshotBuilder([(e.name, e.kind) for e in sim.definition.vehicles])
        with sim.ecs.active():
            ctx = sim._context()
            builder.build(ctx, sim.step_count, sim.sim_time_s, first=True)
            benchmark(lambda: builder.build(ctx, sim.step_count, sim.sim_time_s))
    benchmark.extra_info["us_per_step"] = round(benchmark.stats.stats.mean * 1e6, 1)
    print(f"\nsnapshot of {drones} drones: {benchmark.stats.stats.mean * 1e6:.1f} us")


def _fly(sim: Simulation) -> None:
    for name in sim.vehicle_names:
        sim.arm(name)
    sim.set_target("d0", 30.0, 0.0, 10.0)
    sim.set_target("d1", -30.0, 10.0, 12.0)


@pytest.mark.parametrize("ros2, subscriber", [("off", False), ("dds", False), ("dds", True)],
                         ids=["ros2-off", "ros2-dds", "ros2-dds-stopped-reliable-subscriber"])
def test_two_drones_real_time_factor(benchmark, ros2, subscriber):
    """20 simulated seconds of two flying drones (IMU 200 Hz, battery), as fast as it goes."""
    peers: list[subprocess.Popen] = []
    stats: list = []

    def setup():
        sim = Simulation(load_world_text(world(2)), ros2=ros2)
        _fly(sim)
        if subscriber:
            peer = subprocess.Popen([sys.executable, str(LISTENER), "120.0", "/d0/imu/data=sensor_msgs/msg/Imu",
                                     "/d1/imu/data=sensor_msgs/msg/Imu"], cwd=LISTENER.parent,
                                    stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
            assert peer.stdout.readline().strip() == "ready"
            peers.append(peer)
            sim.run(duration=1.5, rate=1.0)              # discovery and matching, in real time
            os.kill(peer.pid, signal.SIGSTOP)            # from now on it never reads or acknowledges
        return (sim,), {}

    def run(sim):
        thread0 = time.thread_time()
        stats.append(sim.run(duration=RUN_S))
        stats.append(time.thread_time() - thread0)           # CPU of the loop's own thread
        stats.append(sim.transport_counters())
        sim.close()

    try:
        benchmark.pedantic(run, setup=setup, rounds=1, iterations=1)
    finally:
        for peer in peers:
            os.kill(peer.pid, signal.SIGKILL)
            peer.wait(timeout=10)
    run_stats, loop_cpu_s, counters = stats
    benchmark.extra_info["real_time_factor"] = round(run_stats.real_time_factor, 2)
    benchmark.extra_info["cpu_real_time_factor"] = round(run_stats.cpu_real_time_factor, 2)
    benchmark.extra_info["loop_thread_cpu_s"] = round(loop_cpu_s, 2)
    ros = counters.get("ros2", {})
    benchmark.extra_info["snapshots_dropped"] = ros.get("snapshots_dropped", 0)
    benchmark.extra_info["publish_errors"] = ros.get("publish_errors", 0)
    print(f"\n{ros2}{' + stopped subscriber' if subscriber else ''}: {RUN_S:.0f} s simulated in "
          f"{run_stats.wall_time_s:.2f} s wall, {run_stats.cpu_time_s:.2f} s CPU: real-time factor "
          f"{run_stats.real_time_factor:.2f} (per CPU second {run_stats.cpu_real_time_factor:.2f}; the loop's "
          f"thread {loop_cpu_s:.2f} s CPU); "
          f"ROS 2 counters {ros}")


FLOODER = r"""
import os, socket, sys, time
ports = [int(p) for p in sys.argv[1].split(",")]
until = time.monotonic() + float(sys.argv[2])
sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
junk = [os.urandom(n) for n in (8, 40, 120, 280)] + [bytes([0xFD]) + os.urandom(60)]
sent = 0
while time.monotonic() < until:
    for port in ports:
        try:
            sock.sendto(junk[sent % len(junk)], ("127.0.0.1", port))
        except OSError:
            pass
        sent += 1
print(sent, flush=True)
"""


def mavlink_world(ports: dict[str, int]) -> str:
    rows = "\n".join(f"  - {{name: d{i}, type: quadrotor, preset: small, pose: {{position_m: [{2.0 * i}, 0.0, 0.2]}}, "
                     f"components: {{imu: {{}}, battery: {{}}, mavlink: {{instance: {i}, "
                     f"api_local_base: {ports['api_local']}, api_remote_base: {ports['api_remote']}, "
                     f"gcs_local_base: {ports['gcs_local']}, gcs_remote: {ports['gcs_remote']}}}}}}}"
                     for i in range(2))
    return f"""
world: {{name: bench_mavlink, physics_hz: 240, seed: 1}}
scene: {{generator: none, ground_size_m: 400}}
vehicles:
{rows}
"""


@pytest.mark.parametrize("mavlink, flood", [(False, False), (True, False), (True, True)],
                         ids=["mavlink-off", "mavlink-on", "mavlink-on-flooded"])
def test_two_drones_mavlink_real_time_factor(benchmark, mavlink, flood):
    """20 simulated seconds of two flying drones as fast as they go, without MAVLink, with an endpoint
    per drone (PX4 telemetry streams to ports nobody reads), and with every endpoint port flooded by
    a child process sending junk datagrams as fast as it can for the whole run."""
    sys.path.insert(0, str(ROOT))
    from tests.integration.mavlink_client import free_ports

    ports = free_ports(2)
    text = mavlink_world(ports) if mavlink else world(2)
    stats: list = []
    floods: list[subprocess.Popen] = []

    def setup():
        sim = Simulation(load_world_text(text))
        _fly(sim)
        if flood:
            targets = [ports["api_local"], ports["api_local"] + 1, ports["gcs_local"], ports["gcs_local"] + 1]
            floods.append(subprocess.Popen([sys.executable, "-c", FLOODER, ",".join(map(str, targets)), "600"],
                                           stdout=subprocess.PIPE, text=True))
            time.sleep(1.0)
        return (sim,), {}

    def run(sim):
        thread0 = time.thread_time()
        stats.append(sim.run(duration=RUN_S))
        stats.append(time.thread_time() - thread0)
        stats.append(sim.transport_counters())
        sim.close()

    try:
        benchmark.pedantic(run, setup=setup, rounds=1, iterations=1)
    finally:
        for proc in floods:
            proc.kill()
            proc.wait(timeout=10)
    run_stats, loop_cpu_s, counters = stats
    links = [drone[name] for drone in counters.get("mavlink", {}).values() if isinstance(drone, dict)
             for name in ("api", "gcs")]
    junk = sum(link["bad_prefix"] + link["bad_crc"] + link["truncated"] + link["unknown_id"] + link["oversize"]
               for link in links)
    benchmark.extra_info.update(real_time_factor=round(run_stats.real_time_factor, 2),
                                cpu_real_time_factor=round(run_stats.cpu_real_time_factor, 2),
                                loop_thread_cpu_s=round(loop_cpu_s, 2), junk_dropped=junk,
                                rx_rate_limited=sum(link["rx_rate_limited"] for link in links))
    print(f"\nmavlink {'on' if mavlink else 'off'}{' + flood' if flood else ''}: {RUN_S:.0f} s simulated in "
          f"{run_stats.wall_time_s:.2f} s wall: real-time factor {run_stats.real_time_factor:.2f} (per CPU second "
          f"{run_stats.cpu_real_time_factor:.2f}; the loop's thread {loop_cpu_s:.2f} s CPU); junk datagrams "
          f"dropped {junk}, receive turns cut short {benchmark.extra_info['rx_rate_limited']}")
