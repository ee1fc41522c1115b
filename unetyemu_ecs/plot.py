"""``unetyemu plot RUN_DIR``: one PNG per drone log (altitude, speed, motor thrust, power, state of charge).

Mission steps are shaded so that the effect of a pickup (thrust and power step up) and of a
delivery (back down) can be seen at a glance.
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

STEP_COLOURS = {"takeoff": "#c6dbef", "cruise": "#d9f0d3", "land": "#fdd0a2", "pickup": "#e5c1e5",
                "deliver": "#fcbba1", "recharge": "#ffffb2", "idle": "#eeeeee"}


class PlotError(ValueError):
    """The run directory holds nothing that can be plotted."""


def read_log(path: Path) -> dict[str, np.ndarray]:
    """Read a vehicle CSV log into columns (numbers as float arrays, text as object arrays)."""
    with open(path, newline="", encoding="utf-8") as fh:
        rows = list(csv.reader(fh))
    if len(rows) < 2:
        raise PlotError(f"{path}: no data rows")
    header, data = rows[0], rows[1:]
    cols: dict[str, np.ndarray] = {}
    for j, name in enumerate(header):
        values = [r[j] if j < len(r) else "" for r in data]
        try:
            cols[name] = np.array([float(v) for v in values])
        except ValueError:
            cols[name] = np.array(values, dtype=object)
    return cols


def _shade_steps(ax, t: np.ndarray, step: np.ndarray, step_type: np.ndarray) -> None:
    start = 0
    for k in range(1, len(t) + 1):
        if k == len(t) or step[k] != step[start]:
            if step[start] >= 0:
                kind = str(step_type[start])
                ax.axvspan(t[start], t[min(k, len(t) - 1)], color=STEP_COLOURS.get(kind, "#eeeeee"), alpha=0.6, lw=0)
            start = k


def plot_drone_log(path: Path, out_png: Path) -> Path:
    """Write the five-panel plot of one drone log; return the PNG path."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Patch

    c = read_log(path)
    t = c["time_s"]
    fig, axes = plt.subplots(5, 1, figsize=(10, 12), sharex=True)
    panels = [
        ("altitude [m]", [("z_m", "z (ENU)")]),
        ("speed [m/s]", [("speed_m_s", "speed")]),
        ("motor thrust [N]", [("thrust_fl_n", "FL"), ("thrust_fr_n", "FR"), ("thrust_br_n", "BR"), ("thrust_bl_n", "BL")]),
        ("power [W]", [("power_w", "electrical power")]),
        ("state of charge [-]", [("soc_frac", "SoC")]),
    ]
    for ax, (label, series) in zip(axes, panels):
        _shade_steps(ax, t, c["mission_step"], c["mission_step_type"])
        for key, name in series:
            ax.plot(t, c[key], lw=1.2, label=name)
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
        if len(series) > 1:
            ax.legend(loc="upper right", fontsize=8, ncol=4)
    payload = c["payload_kg"]
    if np.any(payload > 0):
        on = t[payload > 0]
        axes[3].set_title(f"payload {payload.max():g} kg carried from t = {on[0]:.1f} s to {on[-1]:.1f} s", fontsize=9)
    kinds = [k for k in STEP_COLOURS if k in set(map(str, c["mission_step_type"]))]
    if kinds:
        axes[0].legend(handles=[Patch(color=STEP_COLOURS[k], label=k) for k in kinds], loc="upper right",
                       fontsize=8, ncol=len(kinds), title="mission step", title_fontsize=8)
    axes[-1].set_xlabel("sim time [s]")
    fig.suptitle(path.stem)
    fig.tight_layout()
    fig.savefig(out_png, dpi=90)
    plt.close(fig)
    return out_png


def plot_run(run_dir: Path) -> list[Path]:
    """Plot every drone log (CSV with motor columns) in ``run_dir``; return the PNG paths."""
    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        raise PlotError(f"{run_dir}: not a directory")
    written = []
    for path in sorted(run_dir.glob("*.csv")):
        with open(path, encoding="utf-8") as fh:
            header = fh.readline()
        if "thrust_fl_n" not in header:
            continue      # not a drone
        written.append(plot_drone_log(path, path.with_suffix(".png")))
    if not written:
        raise PlotError(f"{run_dir}: no drone logs (CSV files with motor columns) found")
    return written
