"""Fly the delivery scenario from Python: run it, send a drone on a mission from a file, watch it land.

    .venv/bin/python examples/api_quickstart.py            (from the repository's top folder)

Writes its CSV logs and summary.json to runs/quickstart/ (a new folder each time).
"""

from __future__ import annotations

import time
from pathlib import Path

from unetyemu_ecs import Simulation

HERE = Path(__file__).resolve().parent
WORLD = HERE.parent / "worlds" / "urban_delivery.yaml"


def main() -> None:
    out = Path("runs") / f"quickstart-{time.strftime('%Y%m%d-%H%M%S')}"
    with Simulation.from_file(WORLD, out_dir=out) as sim:
        sim.run(duration=2.0)                                         # everyone starts their own job
        mission = (HERE / "missions" / "street_hop.json").read_text()
        sim.load_mission("drone3", mission)                           # takes drone3 off its teleop script
        while sim.mission_status("drone3") is None or sim.mission_status("drone3")["state"] == "running":
            sim.run(duration=5.0)
            status = sim.mission_status("drone3")
            print(f"t = {sim.sim_time_s:5.1f} s  drone3 at {sim.position_enu_m('drone3').round(1)} m  "
                  f"step {status['step'] + 1}/{status['steps']} {status['step_type']}: {status['state']}")
            if sim.sim_time_s > 300.0:
                break
        print("drone3:", sim.mission_status("drone3")["state"])
        print("events:", *(f"  t={t:.1f} s {who}: {text}" for t, who, text in sim.events if who == "drone3"),
              sep="\n")
    print(f"logs and summary.json in {out}")


if __name__ == "__main__":
    main()
