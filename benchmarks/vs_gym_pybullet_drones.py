"""Side by side with gym-pybullet-drones: CPU-time real-time factor of N drones flying, 240 Hz physics and
control, median of interleaved runs.

Usage:
    python3 benchmarks/vs_gym_pybullet_drones.py                  # N = 1, 10, 100, 250; 3 runs each
    python3 benchmarks/vs_gym_pybullet_drones.py --drones 1 10 --runs 1 --seconds 2

The peer (gym-pybullet-drones v2.1.0: ``CtrlAviary`` + one ``DSLPIDControl`` per drone, drones flying
circles as in its ``examples/pid.py``, control at the physics rate) is not on PyPI: install it from its
repository (``pip install -e .`` in a clone) to measure it in the same run. Without it the script
prints the peer's figures measured on the project's 2-core machine as the reference, next to ours
measured now (then compare ratios only roughly: the machines may differ).

Ours: ``benchmarks/stress.py flight-N`` (N medium drones shuttling 20 m legs, full flight stack, no
sensors), in its own interpreter.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import statistics
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
# gym-pybullet-drones v2.1.0, CPU-time real-time factor, median of 3 interleaved runs (issue 14's table)
REFERENCE_PEER_RTF_CPU = {1: 14.0, 10: 1.62, 100: 0.158, 250: 0.062}


def peer_available() -> bool:
    try:
        import gym_pybullet_drones.envs  # noqa: F401  (needs setuptools' pkg_resources)
    except ImportError:
        return False
    return True


def run_peer(n: int, seconds: float) -> float:
    """CPU-time real-time factor of gym-pybullet-drones with ``n`` drones flying circles for ``seconds``."""
    import numpy as np
    from gym_pybullet_drones.control.DSLPIDControl import DSLPIDControl
    from gym_pybullet_drones.envs.CtrlAviary import CtrlAviary
    from gym_pybullet_drones.utils.enums import DroneModel, Physics

    side = int(np.ceil(np.sqrt(n)))
    radius = 0.3
    init = np.array([[1.0 * (i % side), 1.0 * (i // side), 0.5] for i in range(n)])
    with contextlib.redirect_stdout(io.StringIO()):                   # the peer prints its URDF's parameters
        env = CtrlAviary(drone_model=DroneModel.CF2X, num_drones=n, initial_xyzs=init, initial_rpys=np.zeros((n, 3)),
                         physics=Physics.PYB, pyb_freq=240, ctrl_freq=240, gui=False, record=False, obstacles=False,
                         user_debug_gui=False)
        ctrl = [DSLPIDControl(drone_model=DroneModel.CF2X) for _ in range(n)]
    action = np.zeros((n, 4))
    steps = int(seconds * env.CTRL_FREQ)
    cpu0 = time.process_time()
    for i in range(steps):
        obs, _, _, _, _ = env.step(action)
        phase = 2.0 * np.pi * i / (10.0 * env.CTRL_FREQ)              # one circle in 10 s
        for j in range(n):
            target = init[j] + [radius * np.cos(phase) - radius, radius * np.sin(phase), 0.0]
            action[j, :], _, _ = ctrl[j].computeControlFromState(control_timestep=env.CTRL_TIMESTEP, state=obs[j],
                                                                 target_pos=target, target_rpy=np.zeros(3))
    cpu = time.process_time() - cpu0
    env.close()
    return steps / env.CTRL_FREQ / cpu


def run_ours(n: int, seconds: float) -> float:
    res = subprocess.run([sys.executable, str(HERE / "stress.py"), f"flight-{n}", "--seconds", str(seconds), "--json"],
                         capture_output=True, text=True, check=True)
    return float(json.loads(res.stdout.strip().splitlines()[-1])["rtf_cpu"])


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--drones", type=int, nargs="+", default=[1, 10, 100, 250], choices=[1, 10, 100, 250])
    parser.add_argument("--runs", type=int, default=3, help="interleaved runs per case, the median is shown (1-9)")
    parser.add_argument("--seconds", type=float, default=5.0, help="simulated seconds per run (0.5-600)")
    args = parser.parse_args(argv)
    if not 1 <= args.runs <= 9:
        parser.error(f"--runs must be in [1, 9], got {args.runs}")
    if not 0.5 <= args.seconds <= 600.0:
        parser.error(f"--seconds must be in [0.5, 600], got {args.seconds}")
    measure_peer = peer_available()
    print(f"peer: {'gym-pybullet-drones, measured in this run' if measure_peer else 'not installed: reference figures'}")
    print(f"{'drones':>6} {'peer rtf_cpu':>13} {'ours rtf_cpu':>13} {'ours / peer':>12}")
    for n in args.drones:
        peer, ours = [], []
        for _ in range(args.runs):                      # interleaved: both see the same machine state
            if measure_peer:
                peer.append(run_peer(n, args.seconds))
            ours.append(run_ours(n, args.seconds))
        p = statistics.median(peer) if peer else REFERENCE_PEER_RTF_CPU[n]
        o = statistics.median(ours)
        print(f"{n:>6} {p:>12.3f}{'' if peer else '*'} {o:>13.3f} {o / p:>12.2f}", flush=True)
    if not measure_peer:
        print("* measured on the project's 2-core machine with gym-pybullet-drones v2.1.0 (not in this run)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
