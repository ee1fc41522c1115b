"""The sweep's table of runs: one row per run (CSV and printed), and a plot of a figure against a parameter."""

from __future__ import annotations

import csv
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from .figures import FIGURES, NUMERIC_FIGURES

RUN_COLUMNS = ("run", "status")
TAIL_COLUMNS = ("error",)
MAX_PRINTED_ROWS = 60


def columns(parameter_keys: Sequence[str]) -> list[str]:
    """Column order: run, status, each parameter, seed, the figures, error."""
    return [*RUN_COLUMNS, *parameter_keys, "seed", *FIGURES, *TAIL_COLUMNS]


def write_csv(path: Path, parameter_keys: Sequence[str], rows: list[dict[str, Any]]) -> Path:
    """Write the rows (missing figures empty) to ``path`` atomically (a reader never sees half a table)."""
    tmp = path.with_name(path.name + ".tmp")
    with tmp.open("w", newline="", encoding="utf-8") as f:
        writer = csv.DictWriter(f, fieldnames=columns(parameter_keys), extrasaction="ignore")
        writer.writeheader()
        for row in rows:
            writer.writerow({k: ("" if v is None else v) for k, v in row.items()})
    tmp.replace(path)
    return path


def read_csv(path: Path) -> list[dict[str, str]]:
    with path.open(newline="", encoding="utf-8") as f:
        return list(csv.DictReader(f))


def _cell(value: Any) -> str:
    if value is None or value == "":
        return "-"
    if isinstance(value, float):
        return f"{value:.4g}" if abs(value) < 1e5 else f"{value:.3e}"
    text = str(value).splitlines()[0] if str(value) else ""
    return text if len(text) <= 48 else text[:45] + "..."


def format_table(parameter_keys: Sequence[str], rows: list[dict[str, Any]], limit: int = MAX_PRINTED_ROWS) -> str:
    """The table as aligned text (the first ``limit`` rows; the CSV has them all, with each run's id)."""
    keys = ["status", *parameter_keys, "seed", "mission", "energy_used_wh", "distance_m", "impacts",
            "wall_time_s", "real_time_factor"]
    shown = [k.rsplit(".", 1)[-1] for k in keys]            # a parameter by its last key
    cells = [[_cell(row.get(k)) for k in keys] for row in rows[:limit]]
    widths = [max([len(h), *(len(line[i]) for line in cells)]) for i, h in enumerate(shown)]
    lines = ["  ".join(h.ljust(w) for h, w in zip(shown, widths))]
    lines += ["  ".join(c.ljust(w) for c, w in zip(line, widths)) for line in cells]
    if len(rows) > limit:
        lines.append(f"... {len(rows) - limit} more runs in the CSV")
    return "\n".join(lines)


def _number(value: Any) -> float | None:
    try:
        x = float(value)
    except (TypeError, ValueError):
        return None
    return x if math.isfinite(x) else None


def _finished(rows: list[dict[str, Any]], figure: str) -> tuple[list[dict[str, Any]], int]:
    """The rows to plot (finished runs with the figure, not those whose mission failed) and how many
    finished runs were left out for a failed mission (an overweight pickup would read as a cheap delivery)."""
    done = [r for r in rows if r.get("status") == "ok" and _number(r.get(figure)) is not None]
    kept = [r for r in done if not str(r.get("mission", "")).startswith(("failed", "cancelled"))]
    return kept, len(done) - len(kept)


def _figure_axes(figure: str) -> tuple[Any, Any]:
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    if figure not in NUMERIC_FIGURES:
        raise ValueError(f"cannot plot {figure!r}: choose one of {', '.join(NUMERIC_FIGURES)}")
    fig = Figure(figsize=(7.0, 4.5), dpi=110)
    return fig, fig.add_subplot(1, 1, 1)


def _finish(fig: Any, ax: Any, path: Path, left_out: int, empty: bool) -> Path:
    if left_out:
        fig.text(0.01, 0.01, f"left out: {left_out} run{'s' * (left_out != 1)} whose mission failed", fontsize=8,
                 color="0.35")
    ax.grid(True, alpha=0.3)
    if empty:
        ax.text(0.5, 0.5, "no finished runs", ha="center", va="center", transform=ax.transAxes)
    fig.tight_layout()
    fig.savefig(path)
    return path


def plot_histogram(path: Path, rows: list[dict[str, Any]], figure: str, title: str = "") -> Path:
    """A Monte-Carlo campaign without parameters: the spread of ``figure`` over the seeds."""
    fig, ax = _figure_axes(figure)
    done, left_out = _finished(rows, figure)
    values = [float(r[figure]) for r in done]
    if values:
        ax.hist(values, bins=min(30, max(5, len(values) // 3)))
        ax.axvline(float(np.mean(values)), color="k", linestyle="--", linewidth=1)
    unit = FIGURES.get(figure, "")
    ax.set_xlabel(f"{figure} [{unit}]" if unit else figure)
    ax.set_ylabel("runs")
    ax.set_title(f"{title + ': ' if title else ''}{figure} over {len(values)} seeds\n"
                 f"mean {np.mean(values) if values else float('nan'):.4g}, standard deviation "
                 f"{np.std(values) if values else float('nan'):.3g}", fontsize=10)
    return _finish(fig, ax, path, left_out, not values)


def plot_figure(path: Path, rows: list[dict[str, Any]], parameter_keys: Sequence[str], figure: str, against: str,
                title: str = "") -> Path:
    """Plot ``figure`` (mean and standard deviation over seeds) against parameter ``against``: one line per
    combination of the other parameters. Only finished runs count, and not those whose mission failed
    (an overweight pickup would read as a cheap delivery): the plot says how many it left out.
    Non-numeric parameter values are placed in the order given; ``title`` (the world's name) heads the title."""
    fig, ax = _figure_axes(figure)
    if against not in parameter_keys:
        raise ValueError(f"cannot plot against {against!r}: not a swept parameter ({', '.join(parameter_keys)})")
    others = [k for k in parameter_keys if k != against]
    done, left_out = _finished(rows, figure)
    xs_text: list[str] = []
    for r in rows:
        if str(r[against]) not in xs_text:
            xs_text.append(str(r[against]))
    numeric = all(_number(x) is not None for x in xs_text)
    position = {x: (_number(x) if numeric else i) for i, x in enumerate(xs_text)}
    groups: dict[tuple[str, ...], dict[str, list[float]]] = {}
    for r in done:
        key = tuple(str(r[k]) for k in others)
        groups.setdefault(key, {}).setdefault(str(r[against]), []).append(float(r[figure]))
    order = {}                                          # the other parameters' values in the order given
    for r in rows:
        order.setdefault(tuple(str(r[k]) for k in others), len(order))
    for key in sorted(groups, key=lambda k: order.get(k, 0)):
        points = sorted((position[x], float(np.mean(v)), float(np.std(v)), len(v)) for x, v in groups[key].items())
        x, mean, std = [p[0] for p in points], [p[1] for p in points], [p[2] for p in points]
        label = ", ".join(f"{k.rsplit('.', 1)[-1]}={v}" for k, v in zip(others, key)) or figure
        ax.errorbar(x, mean, yerr=std, marker="o", capsize=3, label=label)
    if not numeric:
        ax.set_xticks(range(len(xs_text)), xs_text)
    unit = FIGURES.get(figure, "")
    ax.set_xlabel(against)
    ax.set_ylabel(f"{figure} [{unit}]" if unit else figure)
    n_seeds = max((len(v) for g in groups.values() for v in g.values()), default=0)
    ax.set_title(f"{title + ': ' if title else ''}{figure} vs {against.rsplit('.', 1)[-1]}\n"
                 f"mean and standard deviation over {n_seeds} seed{'s' * (n_seeds != 1)}", fontsize=10)
    if groups:
        ax.legend(fontsize=8)
    return _finish(fig, ax, path, left_out, not groups)


__all__ = ["columns", "format_table", "plot_figure", "plot_histogram", "read_csv", "write_csv"]
