"""``unetyemu`` command line: run, sweep, validate, plugins, plot, teleop, view.

Exit codes: 0 success, 1 runtime failure, 2 bad input (arguments or world file), 130 interrupted.
"""

from __future__ import annotations

import argparse
import os
import signal
import sys
import time
from pathlib import Path
from typing import Any, TextIO

from .config.limits import MAX_DURATION_S

EXIT_OK = 0
EXIT_FAILURE = 1
EXIT_BAD_INPUT = 2
EXIT_INTERRUPTED = 130          # 128 + SIGINT; SIGTERM ends with 143, SIGHUP with 129

# --rate: slower than 1/100 of real time is a frozen picture, faster than 1000x is "max"
MIN_RATE = 0.01
MAX_RATE = 1000.0
FOXGLOVE_PORT = 8765                # Foxglove's default WebSocket port
VIEW_PORT = 8080                    # the built-in web view's default HTTP port
# signals that end a run cleanly (logs kept, summary written): Ctrl-C, and how `timeout`, `docker stop`,
# systemd and `ros2 launch` (SIGTERM) or a closed terminal (SIGHUP) stop a process
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


def _rate(text: str) -> float:
    """Parse ``--rate``: a positive real-time multiple, or 'max' (returned as infinity)."""
    if text.strip().lower() == "max":
        return float("inf")
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive number or 'max', got {text!r}") from None
    if not MIN_RATE <= value <= MAX_RATE:
        raise argparse.ArgumentTypeError(f"rate must be between {MIN_RATE:g} and {MAX_RATE:g} times real time, "
                                         f"or 'max', got {text!r}")
    return value


def _positive_seconds(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected seconds as a number, got {text!r}") from None
    if not 0 < value <= MAX_DURATION_S:
        raise argparse.ArgumentTypeError(f"duration must be a positive number of seconds up to {MAX_DURATION_S:g} "
                                         f"(one week), got {text!r}")
    return value


def _seed(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"seed must be a non-negative integer, got {text!r}") from None
    if not 0 <= value < 2**63:
        raise argparse.ArgumentTypeError(f"seed must be an integer in [0, 2**63), got {text!r}")
    return value


def _vehicle_name(text: str) -> str:
    """A vehicle name as world files allow it (it is the prefix of the vehicle's ROS 2 topics)."""
    import re

    from .config.limits import MAX_NAME_LEN

    if not re.fullmatch(r"[A-Za-z][A-Za-z0-9_]*", text) or len(text) > MAX_NAME_LEN:
        raise argparse.ArgumentTypeError(f"{text!r} is not a vehicle name (a letter, then letters, digits and _; "
                                         f"at most {MAX_NAME_LEN} characters)")
    return text


def _bind_address(text: str) -> str:
    import ipaddress

    try:
        return str(ipaddress.ip_address(text))
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not an IP address (e.g. 127.0.0.1, or 0.0.0.0 for "
                                         "every interface)") from None


def _tcp_port(text: str) -> int:
    """A TCP port for a server on 127.0.0.1 (0: any free port)."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a TCP port (an integer from 0 to 65535)") from None
    if not 0 <= value <= 65535:
        raise argparse.ArgumentTypeError(f"port {value} is out of range (0 to 65535; 0 picks a free port)")
    return value


def _out_dir(text: str) -> Path:
    if not text.strip():
        raise argparse.ArgumentTypeError("the output directory must not be empty (omit --out for the default)")
    return Path(text)


def _count(text: str) -> int:
    """A positive count (seeds, workers), at most 100 000."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}") from None
    if not 1 <= value <= 100_000:
        raise argparse.ArgumentTypeError(f"must be from 1 to 100000, got {text!r}")
    return value


def _sweep_parameter(text: str) -> Any:
    from .sweep.overrides import OverrideError, parse_set

    try:
        return parse_set(text)
    except OverrideError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _ray_address(text: str) -> str:
    import re

    text = text.strip()
    match = re.fullmatch(r"(ray://)?[A-Za-z0-9.\-\[\]:]+:(\d{1,5})", text)
    if text == "auto" or (match and 1 <= int(match.group(2)) <= 65535):
        return text
    raise argparse.ArgumentTypeError(f"{text!r} is not a Ray address (ray://HOST:PORT, HOST:PORT with a port from 1 "
                                     "to 65535, or auto)")


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("unetyemu_ecs")
    except PackageNotFoundError:  # run from a source tree that is not installed
        return "unknown (not installed)"


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="unetyemu", description="Simulate drones and ground vehicles in urban worlds.")
    parser.add_argument("--version", action="version", version=f"unetyemu_ecs {_version()}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    run = sub.add_parser("run", help="load a world file and run it")
    run.add_argument("world", type=Path, help="world file (YAML), e.g. worlds/urban_delivery.yaml")
    run.add_argument("--duration", type=_positive_seconds, default=None, metavar="S",
                     help="simulated seconds to run (default: the world file's world.duration_s)")
    run.add_argument("--rate", type=_rate, default=None, metavar="X|max",
                     help="pace: X times real time, or 'max' for as fast as possible "
                          "(default: 1 with --gui, ROS 2, MAVLink endpoints, --foxglove or --view; max otherwise, "
                          "also with only --record)")
    run.add_argument("--seed", type=_seed, default=None, metavar="N", help="override the world file's seed")
    run.add_argument("--gui", action="store_true", help="open the PyBullet window")
    run.add_argument("--out", type=_out_dir, default=None, metavar="DIR",
                     help="output directory, new or empty (default: runs/<world>-<date>-<time>)")
    run.add_argument("--overwrite", action="store_true", help="allow --out to name a directory that holds files")
    run.add_argument("--quiet", action="store_true", help="no progress display")
    run.add_argument("--profile", action="store_true",
                     help="time every system of every step; print the per-phase and per-system table at the end "
                          "(also in summary.json under step_profile)")
    run.add_argument("--ros2", choices=["off", "auto", "rclpy", "dds"], default="off",
                     help="be a ROS 2 node: publish sensors, TF, /clock and mission status, take commands "
                          "(dds: built in, no ROS needed; rclpy: the sourced ROS 2; auto: rclpy if it imports, "
                          "else dds; default off). With ROS 2 on, the default pace is real time")
    run.add_argument("--mavlink", action="store_true",
                     help="give every drone a MAVLink endpoint (PX4 SITL ports: API link 14540+i, GCS link "
                          "14550), also drones without a mavlink component; the default pace is then real time")
    run.add_argument("--mavlink-bind", type=_bind_address, default="127.0.0.1", metavar="ADDR",
                     help="address the --mavlink endpoints bind (default 127.0.0.1: this machine only)")
    run.add_argument("--record", nargs="?", const="", default=None, type=str, metavar="PATH",
                     help="record every topic ROS 2 would publish into a rosbag2 with MCAP storage at PATH "
                          "(a new directory; default: 'recording' in the run's output directory, next to its "
                          "logs); no ROS 2 needed")
    run.add_argument("--record-topics", nargs="+", default=None, metavar="PATTERN",
                     help="with --record: record only the topics matching these patterns ('/drone1/*' /tf /clock; "
                          "quote them for the shell); default every topic")
    run.add_argument("--foxglove", nargs="?", const=FOXGLOVE_PORT, default=None, type=_tcp_port, metavar="PORT",
                     help=f"serve the Foxglove WebSocket protocol on 127.0.0.1:PORT (default {FOXGLOVE_PORT}; 0: any "
                          "free port) so Foxglove or Lichtblick watch the run live; no ROS 2 needed")
    run.add_argument("--view", nargs="?", const=VIEW_PORT, default=None, type=_tcp_port, metavar="PORT",
                     help=f"serve the built-in 3D web view at http://127.0.0.1:PORT/ (default {VIEW_PORT}; 0: any "
                          "free port)")

    val = sub.add_parser("validate", help="check world files without running them")
    val.add_argument("worlds", type=Path, nargs="+", metavar="WORLD")

    sub.add_parser("plugins", help="list installed components, systems, sensors, controllers and transports")

    tele = sub.add_parser("teleop", help="drive a vehicle from the keyboard over ROS 2 (DDS)")
    tele.add_argument("vehicle", metavar="VEHICLE", type=_vehicle_name,
                      help="the vehicle's name (its ROS 2 topics start with /VEHICLE)")
    tele.add_argument("--layout", choices=["drone", "car"], default="drone",
                      help="stick layout: drone [throttle, pitch, roll, yaw] or car [throttle, brake, steering]")

    view = sub.add_parser("view", help="replay a recording (--record) in the built-in 3D web view")
    view.add_argument("recording", type=Path, metavar="RECORDING",
                      help="the rosbag2 directory written by --record, or its .mcap file")
    view.add_argument("--port", type=_tcp_port, default=VIEW_PORT, metavar="PORT",
                      help=f"serve the page at http://127.0.0.1:PORT/ (default {VIEW_PORT}; 0: any free port)")
    view.add_argument("--world", type=Path, default=None, metavar="WORLD",
                      help="the world file the recording was made from, for the city (default: the one named by "
                           "summary.json of the run the recording is in)")

    sweep = sub.add_parser("sweep", help="run a world many times over parameter values and seeds, on Ray",
                           description="Run the cartesian product of --set values x seeds, each an independent "
                                       "simulation on one core of a local (default) or remote Ray cluster; write "
                                       "each run's outputs, one table of their figures (CSV and printed) and a plot.")
    sweep.add_argument("world", type=Path, help="world file (YAML), e.g. worlds/parcel_sweep.yaml")
    sweep.add_argument("--set", dest="sets", action="append", default=[], type=_sweep_parameter,
                       metavar="KEY.PATH=V1,V2,...",
                       help="a world-file value to sweep: keys joined by dots, list items by name or index "
                            "(packages.parcel.mass_kg=0.5,1.0 or vehicles.drone1.preset=small,medium,large); "
                            "values are YAML; repeat for more parameters")
    sweep.add_argument("--seeds", type=_count, default=1, metavar="N",
                       help="seeds per parameter combination (default 1): the world's seed and the N-1 after it")
    sweep.add_argument("--first-seed", type=_seed, default=None, metavar="S",
                       help="the first seed (default: the world file's world.seed)")
    sweep.add_argument("--workers", type=_count, default=None, metavar="K",
                       help="runs at once, one core each (default: every core here, or every CPU of --address)")
    sweep.add_argument("--address", type=_ray_address, default=None, metavar="ADDR",
                       help="an existing Ray cluster (ray://HOST:10001, HOST:6379, or auto for `ray start` here); "
                            "default: start a local one")
    sweep.add_argument("--duration", type=_positive_seconds, default=None, metavar="S",
                       help="simulated seconds per run (default: the world file's world.duration_s)")
    sweep.add_argument("--timeout", type=_positive_seconds, default=None, metavar="S",
                       help="wall-clock seconds a run may take; then it is stopped and reported (default: no limit)")
    sweep.add_argument("--vehicle", type=_vehicle_name, default=None, metavar="NAME",
                       help="table figures of this vehicle (default: totals of the world's vehicles)")
    sweep.add_argument("--plot", default="energy_used_wh", metavar="FIGURE",
                       help="the figure to plot (default energy_used_wh; any numeric column of the table)")
    sweep.add_argument("--against", default=None, metavar="KEY.PATH",
                       help="the parameter on the plot's x axis (default: the first --set)")
    sweep.add_argument("--out", type=_out_dir, default=None, metavar="DIR",
                       help="the sweep's directory, new or empty (default: sweeps/<world>-<date>-<time>)")
    sweep.add_argument("--resume", action="store_true",
                       help="finish the sweep in --out DIR: runs finished there are not run again")
    sweep.add_argument("--ros2", choices=["off", "auto", "rclpy", "dds"], default="off",
                       help="make every run a ROS 2 node (default off); each worker's runs on their own domain, "
                            "ROS_DOMAIN_ID + worker")
    sweep.add_argument("--mavlink", action="store_true",
                       help="give every drone a MAVLink endpoint; each worker's runs on their own PX4 SITL instances")
    sweep.add_argument("--quiet", action="store_true", help="no progress bar")

    plot = sub.add_parser("plot", help="write PNG plots of a run's drone logs")
    plot.add_argument("run_dir", type=Path, metavar="RUN_DIR", help="a directory written by `unetyemu run`")
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run the command line ``argv`` (None: this process's own arguments, as the ``unetyemu``
    executable does; the process then ends, so ``run`` leaves its signal handlers in place and a
    late second Ctrl-C cannot turn the clean exit into a death by signal)."""
    parser = build_parser()
    args = parser.parse_args(argv)  # exits 2 on bad arguments
    try:
        if args.command == "run":
            return cmd_run(args, restore_signals=argv is not None)
        if args.command == "validate":
            return cmd_validate(args)
        if args.command == "plot":
            return cmd_plot(args)
        if args.command == "teleop":
            return cmd_teleop(args)
        if args.command == "view":
            return cmd_view(args)
        if args.command == "sweep":
            return cmd_sweep(args)
        return cmd_plugins()
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except BrokenPipeError:
        # the reader of our output went away (`unetyemu plugins | head`): stop quietly, as Unix tools do
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return EXIT_FAILURE


class _StopOnSignal:
    """Turn SIGINT, SIGTERM and SIGHUP into a clean stop of the run (logs kept, summary written).

    The first signal asks the simulation to stop after its current step; later ones (a second Ctrl-C
    50 ms after the first) change nothing, so the summary is always written. The exit code is
    128 + the first signal's number (130 for Ctrl-C), as a shell reports a process ended by it.
    """

    def __init__(self, restore: bool = True) -> None:
        self.signum: int | None = None
        self.sim: Any = None
        self.restore = restore          # False: ignore stop signals from the end of the run until the process ends
        self._old: dict[int, Any] = {}

    def __enter__(self) -> _StopOnSignal:
        for sig in STOP_SIGNALS:
            self._old[sig] = signal.signal(sig, self._handle)
        return self

    def _handle(self, signum: int, frame: object) -> None:
        if self.signum is None:
            self.signum = signum
        if self.sim is not None:
            self.sim.stop()

    def __exit__(self, *exc: object) -> None:
        self.sim = None
        for sig, old in self._old.items():
            # the process is about to end: ignore, do not just keep our handler (Python's shutdown
            # resets handled signals to their default action, which would end the process by signal)
            signal.signal(sig, old if self.restore else signal.SIG_IGN)

    @property
    def exit_code(self) -> int | None:
        return None if self.signum is None else 128 + self.signum


class _Progress:
    """Progress for headless runs: a live line on a terminal, a line every 5 s otherwise."""

    def __init__(self, stream: TextIO, delay_s: float = 2.0) -> None:
        self.stream = stream
        self.delay_s = delay_s
        self.tty = stream.isatty()
        self._last_line = 0.0
        self._shown = False

    def __call__(self, sim_s: float, end_s: float, wall_s: float) -> None:
        if wall_s < self.delay_s:
            return
        frac = min(1.0, sim_s / end_s) if end_s > 0 else 1.0
        rtf = sim_s / wall_s if wall_s > 0 else 0.0
        eta = (end_s - sim_s) / rtf if rtf > 0 else float("inf")
        bar = "#" * int(frac * 20)
        line = f"[{bar:<20}] {100 * frac:5.1f}%  sim {sim_s:8.2f}/{end_s:.2f} s  RTF {rtf:6.2f}x  ETA {eta:6.1f} s"
        if self.tty:
            self.stream.write("\r" + line)
            self.stream.flush()
            self._shown = True
        elif wall_s - self._last_line >= 5.0:
            self.stream.write(line + "\n")
            self.stream.flush()
            self._last_line = wall_s

    def done(self) -> None:
        if self._shown:
            self.stream.write("\n")
            self.stream.flush()


def _file_name(name: str) -> str:
    """A world's name as one safe path component (a name like ``../x`` must not leave ``runs/``)."""
    import re

    return re.sub(r"[^A-Za-z0-9_.-]+", "_", name).lstrip(".") or "world"


def _fresh_out_dir(args: argparse.Namespace, world_name: str) -> Path | str:
    """Where this run writes; a message (str) if ``--out`` names a directory that already holds files."""
    if args.out is not None:
        out = args.out
        if out.exists() and not out.is_dir():
            return f"--out {out}: exists and is not a directory"
        if out.is_dir() and any(out.iterdir()) and not args.overwrite:
            return (f"--out {out}: directory already holds files (an earlier run?); choose a new directory "
                    "or pass --overwrite")
        return out
    return _default_out_dir("runs", world_name)


def _default_out_dir(root: str, world_name: str) -> Path:
    """``<root>/<world>-<date>-<time>``, with ``-2``, ``-3``... when one started in the same second exists."""
    base = Path(root) / f"{_file_name(world_name)}-{time.strftime('%Y%m%d-%H%M%S')}"
    out, k = base, 1
    while out.exists():
        k += 1
        out = base.with_name(f"{base.name}-{k}")
    return out


def cmd_run(args: argparse.Namespace, restore_signals: bool = True) -> int:
    with _StopOnSignal(restore=restore_signals) as stop:
        code = _run(args, stop)
    return code


def _run(args: argparse.Namespace, stop: _StopOnSignal) -> int:
    from .app import Simulation
    from .config.schema import ConfigError
    from .config.world_file import load_world
    from .physics.client import PhysicsError
    from .sensors.raycast import SensorUnavailable
    from .summary import format_summary
    from .transport.api import TransportError
    from .transport.ros2.dds_backend import discovery_description, domain_from_env

    if args.record_topics and args.record is None:
        print("error: --record-topics needs --record (the recording they select from)", file=sys.stderr)
        return EXIT_BAD_INPUT
    try:
        world = load_world(args.world, seed=args.seed)
    except ConfigError as exc:
        print(f"error: invalid world file:\n{exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    duration = args.duration if args.duration is not None else world.spec.world.duration_s
    out = _fresh_out_dir(args, world.name)
    if isinstance(out, str):
        print(f"error: {out}", file=sys.stderr)
        return EXIT_BAD_INPUT
    try:
        record = None if args.record is None else (Path(args.record) if args.record else Path(out) / "recording")
        sim = Simulation(world, gui=args.gui, out_dir=out, ros2=args.ros2, mavlink=args.mavlink,
                         mavlink_bind=args.mavlink_bind, record=record,
                         record_topics=args.record_topics, foxglove=args.foxglove, view=args.view)
    except (PhysicsError, SensorUnavailable, TransportError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_FAILURE
    except OSError as exc:
        print(f"error: cannot write outputs to {out}: {exc}", file=sys.stderr)
        return EXIT_FAILURE
    stop.sim = sim
    if args.profile:
        sim.profile_steps()
    if args.rate is None:       # a window or a live transport (ROS 2, MAVLink, a viewer) means someone is watching
        rate = 1.0 if (args.gui or any(name != "record" for name in sim.transports)) else None
    else:
        rate = None if args.rate == float("inf") else args.rate
    if stop.signum is not None:             # stopped while the world was being built
        sim.stop()
    if sim.ros2_backend != "off" and not args.quiet:
        print(f"ROS 2: node /unetyemu_sim on the {sim.ros2_backend} backend, ROS_DOMAIN_ID {domain_from_env()}"
              + (f", {discovery_description()}" if sim.ros2_backend == "dds" else ""), file=sys.stderr)
    for transport in sim.transports.values():       # servers say where to connect (printed even with --quiet)
        if getattr(transport, "url", None):
            print(f"{transport.name}: {transport.url}", file=sys.stderr, flush=True)
    try:
        if stop.signum is None:
            progress = None if args.quiet else _Progress(sys.stderr)
            sim.run(duration=duration, rate=rate, progress=progress)
            if progress is not None:
                progress.done()
        if stop.signum is not None:
            sim.interrupted = True
        summary = sim.summary()
    finally:
        sim.close()                          # writes summary.json and closes the CSV logs
    print(format_summary(summary))
    if sim.step_profile is not None:
        print(sim.step_profile.table())
    print(f"outputs: {out} ({len(summary['logs'])} vehicle logs, summary.json)")
    if stop.exit_code is not None:
        return stop.exit_code
    return EXIT_INTERRUPTED if summary["interrupted"] else EXIT_OK


def cmd_validate(args: argparse.Namespace) -> int:
    from .config.schema import ConfigError
    from .config.world_file import load_world
    from .plugins import Registry

    registry = Registry.discover()
    status = EXIT_OK
    for path in args.worlds:
        try:
            world = load_world(path, registry=registry)
        except ConfigError as exc:
            print(str(exc), file=sys.stderr)
            print(f"{path}: INVALID ({len(exc.issues)} problem{'s' if len(exc.issues) != 1 else ''})",
                  file=sys.stderr)
            status = EXIT_BAD_INPUT
            continue
        print(f"{path}: OK ({len(world.vehicles)} vehicles, {len(world.packages)} packages, "
              f"{len(world.layout.objects)} scene objects, {len(world.layout.pads)} pads)")
    return status


def cmd_teleop(args: argparse.Namespace) -> int:
    from .teleop_keyboard import run_teleop
    from .transport.ros2.dds_backend import Ros2Error

    try:
        return run_teleop(args.vehicle, args.layout)
    except Ros2Error as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_FAILURE


def cmd_view(args: argparse.Namespace) -> int:
    """Serve a recording in the web view until Ctrl-C (or SIGTERM, SIGHUP): then exit 0."""
    import threading

    from .view.replay import ReplayError, serve_replay
    from .view.server import ServerError

    try:
        server, source = serve_replay(args.recording, port=args.port, world=args.world)
    except ReplayError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except ServerError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_FAILURE
    done = threading.Event()
    old = {sig: signal.signal(sig, lambda signum, frame: done.set()) for sig in STOP_SIGNALS}
    try:
        rec = source.rec
        print(f"view: {server.url}", file=sys.stderr, flush=True)
        print(f"replaying {args.recording} ({rec.end_s - rec.start_s:.1f} s, {len(rec.tracks)} vehicles"
              + (f"; {source.scene.note}" if source.scene.note else "") + "); Ctrl-C to stop", file=sys.stderr, flush=True)
        while not done.wait(0.5):
            pass
    finally:
        for sig, handler in old.items():
            signal.signal(sig, handler)
        server.stop()
        source.rec.close()
    print("view: stopped", file=sys.stderr)
    return EXIT_OK


def cmd_sweep(args: argparse.Namespace) -> int:
    """Run a sweep; exit 0 when every run finished, 1 when some failed or timed out, 2 for bad input
    (nothing ran), 130 (or 128 + the signal) when stopped: finished runs are kept, --resume goes on."""
    from .config.schema import ConfigError
    from .sweep import OverrideError, SweepError, SweepOptions, build_plan, run_sweep
    from .sweep.ray_runner import RayUnavailable
    from .sweep.table import format_table

    if args.resume and args.out is None:
        print("error: --resume needs --out DIR (the sweep to finish)", file=sys.stderr)
        return EXIT_BAD_INPUT
    try:
        plan = build_plan(args.world, args.sets, seeds=args.seeds, first_seed=args.first_seed)
    except ConfigError as exc:
        print(f"error: invalid world file:\n{exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except (OverrideError, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    out = args.out if args.out is not None else _default_out_dir("sweeps", plan.world_name)
    options = SweepOptions(workers=args.workers, address=args.address, duration_s=args.duration,
                           timeout_s=args.timeout, vehicle=args.vehicle, plot=args.plot, against=args.against,
                           ros2=args.ros2, mavlink=args.mavlink, resume=args.resume)
    stop = _StopOnSignal()
    with stop:
        try:
            result = run_sweep(plan, out, options, sys.stderr, should_stop=lambda: stop.signum is not None,
                               quiet=args.quiet)
        except SweepError as exc:
            print(f"error: {exc}", file=sys.stderr)
            return EXIT_BAD_INPUT
        except RayUnavailable as exc:
            print(f"error: {exc}", file=sys.stderr)
            return EXIT_FAILURE
        except OSError as exc:              # the disk filled or went away under the sweep
            print(f"error: cannot write the sweep's outputs in {out}: {exc}", file=sys.stderr)
            return EXIT_FAILURE
    print(format_table([p.key for p in plan.parameters], result.rows))
    ok, failed, timeout = result.count("ok"), result.count("failed"), result.count("timeout")
    print(f"{ok} of {len(plan.runs)} runs finished" + (f" ({result.skipped} in an earlier session)" if result.skipped
                                                      else "")
          + (f", {failed} failed" if failed else "") + (f", {timeout} timed out" if timeout else ""))
    if result.ran:
        print(f"this session: {result.ran} runs in {result.running_s:.1f} s ({result.runs_per_minute:.1f} runs/min) on "
              f"{result.cluster}, after {result.cluster_start_s:.1f} s to start it")
    for row in result.rows:
        if row["status"] != "ok":
            print(f"  {row['status']}: {row['run']}: {row['error']}")
    print(f"table: {result.csv_path}")
    if result.plot_path is not None:
        print(f"plot: {result.plot_path}")
    if result.unfinished:
        print(f"stopped: {len(result.unfinished)} runs not finished; finish them with: unetyemu sweep "
              f"{args.world} ... --out {out} --resume", file=sys.stderr)
        return stop.exit_code or EXIT_INTERRUPTED
    return EXIT_FAILURE if failed or timeout else EXIT_OK


def cmd_plot(args: argparse.Namespace) -> int:
    from .plot import PlotError, plot_run

    try:
        paths = plot_run(args.run_dir)
    except PlotError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    for path in paths:
        print(path)
    for note in paths.skipped:                    # what a damaged log did not let us plot
        print(f"warning: {note}", file=sys.stderr)
    return EXIT_OK


def _preset_values(key: str) -> dict[str, dict[str, Any]]:
    """Field -> {preset: value} for component ``key`` as the vehicle presets fill it."""
    from .vehicles.presets import VEHICLE_TYPES, component_tables, preset, presets_for

    out: dict[str, dict[str, Any]] = {}
    for vtype in VEHICLE_TYPES:
        for name in presets_for(vtype):
            for field, value in component_tables(preset(vtype, name)).get(key, {}).items():
                out.setdefault(field, {})[name] = value
    return out


def _default_text(default: str, from_presets: dict[str, Any] | None) -> str:
    """How ``unetyemu plugins`` shows a field's default: its own, or what each preset gives it."""
    if from_presets is None or default != "(required)":
        return default
    values = list(from_presets.values())
    if all(v == values[0] for v in values):
        return f"{values[0]!r} (from the vehicle preset)"
    return "per preset: " + ", ".join(f"{name} {v!r}" for name, v in from_presets.items())


def cmd_plugins() -> int:
    from .config.schema import describe_schema
    from .plugins import GROUPS, Registry

    reg = Registry.discover()
    for group in GROUPS:
        print(f"{group}:")
        entries = reg.entries[group]
        if not entries:
            print("  (none)")
        for key, entry in sorted(entries.items()):
            spec = entry.spec
            schema = getattr(spec, "component", None) or getattr(spec, "config", None) or getattr(spec, "params", None)
            layer = getattr(spec, "layer", None)
            summary = (f" - {layer} layer:" if layer else " -") + (f" {spec.summary}" if spec.summary else "")
            print(f"  {key:<18} [{entry.provider}]{summary}")
            presets = {} if layer else _preset_values(key)
            for name, tname, default in (describe_schema(schema) if schema is not None else []):
                print(f"      {name}: {tname} = {_default_text(default, presets.get(name))}")
    if reg.failures:
        print("failed to load:")
        for (group, key), why in sorted(reg.failures.items()):
            print(f"  {group}:{key}: {why}")
    return EXIT_OK


if __name__ == "__main__":
    sys.exit(main())
