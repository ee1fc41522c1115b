"""Stress cases of the simulator, one comparable row each: real-time factor (wall and CPU), ms per step
of every phase, peak memory.

Usage:
    python3 benchmarks/stress.py                      # every case (several minutes on 2 cores)
    python3 benchmarks/stress.py flight-1 lidar-60    # the named cases
    python3 benchmarks/stress.py --list               # the case names
    python3 benchmarks/stress.py --seconds 5 --json   # longer runs; one JSON object per row
    python3 benchmarks/stress.py lidar-10 --seconds 600 --rss-every 60 --json   # memory over 10 simulated minutes

Each case runs in a fresh interpreter (so peak RSS is that case's alone): it builds its world, lets
it settle, then simulates ``--seconds`` of sim time with the per-system profile on (see
``unetyemu run --profile``) and prints

    case  drones  sim_s  rtf_wall  rtf_cpu  ms/step  <ms per step of each phase>  peak_rss_mb

Cases:
    flight-N        N medium drones (1, 10, 100, 250, 1000) shuttling between two points 20 m apart,
                    full flight stack at 240 Hz, no sensors, flat ground
    lidar-N[-ros2]  N drones (10, 30, 60, 100) with a 360x16 LiDAR at 10 Hz over the default city
                    streets, hovering; -ros2: the built-in ROS 2 node publishes their point clouds
    camera-K-WxH    K drones (1, 5) in the city, each with an RGB camera at 320x240 or 640x480, 10 Hz
    delivery        worlds/urban_delivery.yaml from t = 0 with all its sensors and CSV logs
    delivery-record the same, recording every topic into a rosbag2 (MCAP) as `--record` does
"""

from __future__ import annotations

import argparse
import json
import math
import resource
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_worlds import city_with_lidar_drones  # noqa: E402

PHASES = ("COMMANDS", "MISSION", "GUIDANCE", "STABILIZE", "ACTUATE", "PHYSICS", "STATE", "PAYLOAD_ENERGY",
          "SENSORS", "OUTPUTS")
SECONDS_MIN, SECONDS_MAX = 0.1, 3600.0          # simulated seconds a case may be measured for
CASES = ([f"flight-{n}" for n in (1, 10, 100, 250, 1000)]
         + [f"lidar-{n}{ros}" for n in (10, 30, 60, 100) for ros in ("", "-ros2")]
         + [f"camera-{k}-{w}x{h}" for k in (1, 5) for w, h in ((320, 240), (640, 480))]
         + ["delivery", "delivery-record"])


def flight_world(n: int) -> str:
    side = math.ceil(math.sqrt(n))
    lines = ["world: {name: stress_flight, physics_hz: 240, seed: 1}",
             "scene: {generator: none, ground_size_m: 1000}", "vehicles:"]
    for i in range(n):
        x, y = -side * 2.0 + 4.0 * (i % side), -side * 2.0 + 4.0 * (i // side)
        lines.append(f"  - {{name: d{i}, type: quadrotor, preset: medium, pose: {{position_m: [{x}, {y}, 0.3]}}}}")
    return "\n".join(lines) + "\n"


def camera_world(k: int, width: int, height: int) -> str:
    lines = ["world: {name: stress_camera, physics_hz: 240, seed: 42}", "scene: {generator: urban}", "vehicles:"]
    for j in range(k):
        lines.append(f"  - {{name: d{j}, type: quadrotor, preset: medium, pose: {{position_m: [0.0, {-60.0 + 8.0 * j}, "
                     f"15.0]}}, components: {{camera: {{width: {width}, height: {height}, rate_hz: 10, "
                     f"mount_rpy_deg: [0.0, 20.0, 90.0]}}}}}}")
    return "\n".join(lines) + "\n"


def rss_mb() -> float:
    """Resident set size of this process now [MB] (Linux /proc; the peak where /proc is missing)."""
    try:
        with open("/proc/self/statm", encoding="ascii") as fh:
            return int(fh.read().split()[1]) * resource.getpagesize() / 2**20
    except OSError:
        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def run_case(case: str, seconds: float, rss_every_s: float = 0.0) -> dict:
    """Build and run one case in this process; return its row."""
    from unetyemu_ecs import Simulation, load_world_text
    from unetyemu_ecs.config.world_file import load_world

    kind, *rest = case.split("-")
    ros2 = "off"
    shuttle: list[str] = []
    if kind == "flight":
        n = int(rest[0])
        world = load_world_text(flight_world(n))
        shuttle = [f"d{i}" for i in range(n)]
    elif kind == "lidar":
        n = int(rest[0])
        ros2 = "dds" if rest[1:] == ["ros2"] else "off"
        world = load_world_text(city_with_lidar_drones(n))
    elif kind == "camera":
        n, (w, h) = int(rest[0]), map(int, rest[1].split("x"))
        world = load_world_text(camera_world(n, w, h))
    elif kind == "delivery":
        world = load_world(REPO / "worlds" / "urban_delivery.yaml")
        n = sum(1 for e in world.entities if e.kind == "quadrotor")
    else:
        raise SystemExit(f"unknown case {case!r}; --list shows them")
    out = Path("/tmp") / f"stress-{case}-{time.time_ns()}" if kind == "delivery" else None
    record = out / "recording" if kind == "delivery" and rest == ["record"] else None    # the rosbag2 recorder
    with Simulation(world, ros2=ros2, out_dir=out, record=record) as sim:
        if shuttle:
            starts = {name: sim.position_enu_m(name).copy() for name in shuttle}
            for name in shuttle:
                sim.set_target(name, starts[name][0], starts[name][1], 10.0)
            sim.run(duration=6.0)                       # climbed
        elif kind != "delivery":
            sim.run(duration=1.0)                       # sensors warmed up (scene meshes built)
        sim.profile_steps()
        wall0, cpu0, t0 = time.perf_counter(), time.process_time(), sim.sim_time_s
        leg = 0
        rss_samples: list[list[float]] = [[0.0, round(rss_mb(), 1)]]
        while sim.sim_time_s - t0 < seconds - 1e-9:
            if shuttle and (sim.sim_time_s - t0) >= 5.0 * leg:      # a new 20 m leg every 5 s
                for name in shuttle:
                    x, y, _ = starts[name]
                    sim.set_target(name, x + (20.0 if leg % 2 == 0 else 0.0), y, 10.0)
                leg += 1
            sim.run(duration=min(1.0, seconds - (sim.sim_time_s - t0), rss_every_s or math.inf))
            elapsed = sim.sim_time_s - t0
            if rss_every_s > 0 and elapsed + 1e-9 >= rss_samples[-1][0] + rss_every_s:
                rss_samples.append([round(elapsed, 3), round(rss_mb(), 1)])
        wall, cpu = time.perf_counter() - wall0, time.process_time() - cpu0
        profile = sim.step_profile
        steps = max(profile.steps, 1)
        phase_ms = {p: 0.0 for p in PHASES}
        for phase, _name, us, _share in profile.rows():
            phase_ms[phase] = phase_ms.get(phase, 0.0) + us / 1000.0
        sim_s = sim.sim_time_s - t0
    return {"case": case, "drones": n, "sim_s": round(sim_s, 3), "rtf_wall": round(sim_s / wall, 3),
            "rtf_cpu": round(sim_s / cpu, 3), "ms_per_step": round(1000.0 * wall / steps, 3),
            "phase_ms_per_step": {k: round(v, 3) for k, v in phase_ms.items()},
            "peak_rss_mb": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0, 1),
            **({"rss_mb_at_sim_s": rss_samples} if rss_every_s > 0 else {})}


def run_case_isolated(case: str, seconds: float, rss_every_s: float = 0.0) -> dict:
    """Run one case in a fresh interpreter (so its peak RSS is its own); return its row. RuntimeError, with the
    end of the case's stderr, if it failed."""
    res = subprocess.run([sys.executable, __file__, "--in-process", case, "--seconds", str(seconds),
                          "--rss-every", str(rss_every_s)],
                         capture_output=True, text=True, cwd=REPO)
    if res.returncode != 0:
        raise RuntimeError(f"{case}: failed\n{res.stderr[-2000:]}")
    return json.loads(res.stdout.strip().splitlines()[-1])


def format_row(row: dict) -> str:
    phases = " ".join(f"{row['phase_ms_per_step'].get(p, 0.0):7.3f}" for p in PHASES)
    return (f"{row['case']:<20} {row['drones']:>6} {row['sim_s']:>6.1f} {row['rtf_wall']:>8.2f} {row['rtf_cpu']:>8.2f} "
            f"{row['ms_per_step']:>8.3f}  {phases}  {row['peak_rss_mb']:>8.1f}")


def header() -> str:
    phases = " ".join(f"{p[:7]:>7}" for p in PHASES)
    return (f"{'case':<20} {'drones':>6} {'sim_s':>6} {'rtf_wall':>8} {'rtf_cpu':>8} {'ms/step':>8}  {phases}  "
            f"{'rss_mb':>8}")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("cases", nargs="*", help="case names (default: all; --list shows them)")
    parser.add_argument("--seconds", type=float, default=2.0, help="simulated seconds measured per case (default 2)")
    parser.add_argument("--json", action="store_true", help="print one JSON object per row instead of a table")
    parser.add_argument("--rss-every", type=float, default=0.0, metavar="S",
                        help="also sample the resident memory every S simulated seconds (memory growth; with --json)")
    parser.add_argument("--list", action="store_true", help="list the case names and exit")
    parser.add_argument("--in-process", metavar="CASE", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.list:
        print("\n".join(CASES))
        return 0
    if not (math.isfinite(args.seconds) and SECONDS_MIN <= args.seconds <= SECONDS_MAX):
        parser.error(f"--seconds must be in [{SECONDS_MIN:g}, {SECONDS_MAX:g}], got {args.seconds}")
    if not (math.isfinite(args.rss_every) and 0.0 <= args.rss_every <= args.seconds):
        parser.error(f"--rss-every must be in [0, --seconds], got {args.rss_every}")
    if args.in_process:
        print(json.dumps(run_case(args.in_process, args.seconds, args.rss_every)))
        return 0
    unknown = [c for c in args.cases if c not in CASES]
    if unknown:
        parser.error(f"unknown case(s) {', '.join(unknown)}; --list shows them")
    if not args.json:
        print(header(), flush=True)
    failed = 0
    for case in args.cases or CASES:
        try:
            row = run_case_isolated(case, args.seconds, args.rss_every)
        except RuntimeError as exc:
            print(exc, file=sys.stderr)
            failed += 1
            continue
        print(json.dumps(row) if args.json else format_row(row), flush=True)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
