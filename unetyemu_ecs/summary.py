"""The run summary: what ran, how fast, and where every vehicle and package ended up."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from .app import RunStats, Simulation


def build_summary(sim: Simulation, stats: RunStats) -> dict[str, Any]:
    """Return a JSON-ready summary of ``sim`` after a run described by ``stats``."""
    d = sim.definition
    entities = []
    for ent in d.entities:
        row = sim.row(ent.name)
        item: dict[str, Any] = {
            "name": ent.name,
            "kind": ent.kind,
            "preset": ent.preset,
            "start_enu_m": [round(float(x), 3) for x in ent.pos_enu_m],
            "final_enu_m": [round(float(x), 3) for x in sim.fleet.pos_enu_m[row]],
            "distance_m": round(float(sim.fleet.odometer_m[row]), 3),
            "impacts": int(sim.fleet.impacts[row]),
        }
        if ent.kind == "quadrotor":
            status = sim.mission_status(ent.name)
            item["mission"] = status
            item["energy_used_wh"] = round(float(sim.fleet.energy_used_j[row]) / 3600.0, 4)
            item["soc_frac"] = round(float(sim.fleet.soc_frac[row]), 5)
        if ent.kind == "car":
            item["drive"] = sim.drive_status(ent.name)
        entities.append(item)
    out = {
        "world": d.name,
        "world_file": d.file,
        "seed": sim.seed,
        "physics_hz": d.spec.world.physics_hz,
        "steps": sim.step_count,
        "sim_time_s": round(stats.sim_time_s, 6),
        "wall_time_s": round(stats.wall_time_s, 3),
        "real_time_factor": _finite_or_none(stats.real_time_factor),
        "cpu_time_s": round(stats.cpu_time_s, 3),
        "cpu_real_time_factor": _finite_or_none(stats.cpu_real_time_factor),
        "interrupted": stats.interrupted,
        "entities": entities,
        "pads": {name: [round(float(v), 3) for v in pad.center_enu_m] for name, pad in sim.layout.pads.items()},
        "transports": sim.transport_counters(),
        "events": [{"time_s": t, "entity": name, "text": text} for t, name, text in sim.events],
        "logs": {name: str(p) for name, p in sim.log_paths.items()},
    }
    profile = sim.step_profile
    if profile is not None:
        out["step_profile"] = {"steps": profile.steps,
                               "systems": [{"phase": phase, "system": name, "us_per_step": round(us, 2),
                                            "share": round(share, 4)} for phase, name, us, share in profile.rows()]}
    return out


def _finite_or_none(x: float) -> float | None:
    """Round a figure for JSON; None where it is undefined (no time spent: 0 steps)."""
    return round(x, 3) if math.isfinite(x) else None


def _factor(x: float | None) -> str:
    return "-" if x is None else f"{x:.2f}x"


def format_summary(summary: dict[str, Any]) -> str:
    """Render a summary as a short terminal report."""
    ents = summary["entities"]
    counts: dict[str, int] = {}
    for e in ents:
        counts[e["kind"]] = counts.get(e["kind"], 0) + 1
    fleet = ", ".join(f"{n} {k}{'s' if n != 1 else ''}" for k, n in counts.items()) or "no vehicles"
    lines = [
        f"world {summary['world']} (seed {summary['seed']}): {fleet}",
        f"sim time {summary['sim_time_s']:.2f} s | wall {summary['wall_time_s']:.2f} s | "
        f"real-time factor {_factor(summary['real_time_factor'])} (per CPU second "
        f"{_factor(summary['cpu_real_time_factor'])}) | {summary['steps']} steps at "
        f"{summary['physics_hz']:g} Hz" + (" | INTERRUPTED" if summary["interrupted"] else ""),
    ]
    if ents:
        w = max(len("name"), *(len(e["name"]) for e in ents))
        lines.append(f"  {'name':<{w}}  {'kind':<9}  {'preset':<7}  {'distance_m':>10}  {'energy_Wh':>9}  "
                     f"{'impacts':>7}  {'final ENU [m]':<26}  mission")
        for e in ents:
            x, y, z = e["final_enu_m"]
            energy = f"{e['energy_used_wh']:>9.2f}" if "energy_used_wh" in e else f"{'-':>9}"
            lines.append(f"  {e['name']:<{w}}  {e['kind']:<9}  {e['preset'] or '-':<7}  "
                         f"{e['distance_m']:>10.2f}  {energy}  {e['impacts']:>7}  {f'({x:.2f}, {y:.2f}, {z:.2f})':<26}  "
                         f"{_mission_text(e.get('mission')) if 'drive' not in e else _drive_text(e['drive'])}")
    impacts = [e for e in summary.get("events", []) if e["text"].startswith("impact")]
    for e in impacts[:10]:
        lines.append(f"  t={e['time_s']:.2f} s {e['entity']}: {e['text']}")
    if len(impacts) > 10:
        lines.append(f"  ... {len(impacts) - 10} more impacts in summary.json")
    return "\n".join(lines)


def _mission_text(status: dict[str, Any] | None) -> str:
    if status is None:
        return "-"
    text = f"{status['mission']}: {status['state']}"
    if status["state"] == "running":
        text += f" (step {status['step'] + 1}/{status['steps']} {status['step_type']})"
    elif status["state"] in ("failed", "cancelled"):
        text += f" at step {status['step'] + 1} {status['step_type']}: {status['reason']}"
    return text


def _drive_text(status: dict[str, Any]) -> str:
    text = f"{status['mode']}"
    if status["route"]:
        text += f" ({status['route']}, {status['laps']} laps)" if status["laps"] else f" ({status['route']})"
    return text


def write_summary(summary: dict[str, Any], out_dir: Path) -> Path:
    """Write ``summary.json`` under ``out_dir`` and return its path."""
    path = Path(out_dir) / "summary.json"
    path.write_text(json.dumps(summary, indent=2) + "\n", encoding="utf-8")
    return path
