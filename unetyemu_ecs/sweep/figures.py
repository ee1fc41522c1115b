"""A run's summary figures for the sweep table, computed from its ``summary.json`` alone.

With no vehicle chosen the figures are the world's totals: missions completed of those flown, energy
used by every drone, distance covered by every vehicle, impacts of every body. With a vehicle chosen
(``--vehicle drone1``) they are that vehicle's own.
"""

from __future__ import annotations

from typing import Any

# the figures of the table, in column order, with their units (plot labels)
FIGURES: dict[str, str] = {
    "mission": "",
    "missions_completed": "",
    "missions": "",
    "energy_used_wh": "Wh",
    "distance_m": "m",
    "impacts": "",
    "final_soc_frac": "",
    "sim_time_s": "s",
    "wall_time_s": "s",
    "real_time_factor": "x",
}
NUMERIC_FIGURES = tuple(name for name in FIGURES if name != "mission")


def mission_text(status: dict[str, Any] | None) -> str:
    """``completed``, ``running (step 3/8)`` or ``failed at step 4: <reason>``; ``-`` without a mission."""
    if not status:
        return "-"
    state = status.get("state", "?")
    if state == "running":
        return f"running (step {status.get('step', 0) + 1}/{status.get('steps', '?')})"
    if state in ("failed", "cancelled"):
        return f"{state} at step {status.get('step', 0) + 1}: {status.get('reason', '')}".rstrip(": ")
    return str(state)


def run_figures(summary: dict[str, Any], vehicle: str | None = None) -> dict[str, Any]:
    """The table's figures of one run (see :data:`FIGURES`).

    Raises
    ------
    KeyError
        ``vehicle`` is not a vehicle of this run.
    """
    entities = summary["entities"]
    if vehicle is not None:
        chosen = [e for e in entities if e["name"] == vehicle and e["kind"] != "package"]
        if not chosen:
            names = ", ".join(e["name"] for e in entities if e["kind"] != "package")
            raise KeyError(f"no vehicle {vehicle!r} in this run (vehicles: {names})")
    else:
        chosen = [e for e in entities if e["kind"] != "package"]
    flown = [e["mission"] for e in chosen if e.get("mission")]
    completed = sum(1 for m in flown if m.get("state") == "completed")
    if vehicle is not None or len(flown) == 1:
        mission = mission_text(chosen[0].get("mission") if vehicle is not None else flown[0])
    elif flown:
        mission = "completed" if completed == len(flown) else f"{completed}/{len(flown)} completed"
    else:
        mission = "-"
    socs = [e["soc_frac"] for e in chosen if "soc_frac" in e]
    bodies = chosen if vehicle is not None else entities             # packages hit things too
    return {
        "mission": mission,
        "missions_completed": completed,
        "missions": len(flown),
        "energy_used_wh": round(sum(e.get("energy_used_wh", 0.0) for e in chosen), 4),
        "distance_m": round(sum(e["distance_m"] for e in chosen), 3),
        "impacts": sum(e["impacts"] for e in bodies),
        "final_soc_frac": min(socs) if socs else None,
        "sim_time_s": summary["sim_time_s"],
        "wall_time_s": summary["wall_time_s"],
        "real_time_factor": summary["real_time_factor"],
    }


__all__ = ["FIGURES", "NUMERIC_FIGURES", "mission_text", "run_figures"]
