"""``unetyemu plot RUN_DIR``: one PNG per vehicle log, time series beside a top-down track.

A drone's figure shows altitude, speed, per-motor thrust, electrical power and state of charge over
time with its mission steps shaded (one colour per step type, named in the legend at the top), so
that the effect of a pickup (thrust and power step up) and of a delivery (back down) can be seen at a
glance. A car's figure shows forward speed against its setpoint, throttle and brake, and steering,
with its drive mode shaded. Every figure has the vehicle's x-y track (equal axis scaling, start and
end marked, packages from ``summary.json`` when they lie near the track) and a short account taken
from ``summary.json``. Legends sit outside the data areas so that they never hide a curve.

Logs are read line by line (``plot_log.read_log``): what cannot be read is skipped and named in
``PlotResult.skipped``; only a directory with nothing plottable at all is an error.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .plot_log import LogError, LogTable, read_log

# (shade, line) colours: one clearly different hue per mission step type (spec.STEP_TYPES), every
# pair of shades at least 20 CIELAB units apart (ColorBrewer "Paired", light for the time-series
# shading, dark for the track).
STEP_COLOURS = {"takeoff": ("#9ecae1", "#1f78b4"), "cruise": ("#b2df8a", "#33a02c"), "land": ("#fdbf6f", "#ff7f00"),
                "pickup": ("#cab2d6", "#6a3d9a"), "deliver": ("#fb9a99", "#e31a1c"),
                "recharge": ("#ffff99", "#b15928"), "idle": ("#e0e0e0", "#737373")}
DRIVE_MODE_COLOURS = {"parked": STEP_COLOURS["idle"], "route": STEP_COLOURS["cruise"],
                      "velocity": STEP_COLOURS["takeoff"], "manual": STEP_COLOURS["land"]}
EXTRA_COLOURS = (("#8dd3c7", "#1b9e77"), ("#d9b38c", "#8c510a"), ("#f1b6da", "#c51b7d"),
                 ("#c2c2f0", "#3f3f9f"))   # for names outside the palette, in turn
INK = "#1a1a1a"     # curves are dark so that they read on every shade
MOTORS = (("thrust_fl_n", "FL", {"color": INK}),
          ("thrust_fr_n", "FR", {"color": "#b2182b", "ls": "--"}),
          ("thrust_br_n", "BR", {"color": "#2166ac", "ls": "-."}),
          ("thrust_bl_n", "BL", {"color": "#7b3294", "ls": ":"}))
DRONE_COLUMNS = frozenset({"mode", "mission_step", "mission_step_type", "soc_frac", "power_w", "thrust_fl_n"})
CAR_COLUMNS = frozenset({"drive_mode", "throttle", "brake", "steer_deg", "speed_fwd_m_s", "speed_sp_m_s"})
NEAR_TRACK_M = 30.0      # packages and pads this far outside the track's extent are left off its panel
MIN_TRACK_SPAN_M = 10.0  # a hover still gets a readable track panel
DPI = 90


class PlotError(ValueError):
    """The run directory holds nothing that can be plotted (the message says what was found)."""


class PlotResult(list):
    """The PNG paths written (a ``list[Path]``), with ``skipped``: one sentence per thing left out."""

    def __init__(self, paths=(), skipped=()) -> None:
        super().__init__(paths)
        self.skipped: list[str] = list(skipped)


@dataclass
class RunContext:
    """What ``summary.json`` tells about the run beyond one log (empty when it is absent)."""

    entities: dict[str, dict[str, Any]] = field(default_factory=dict)   # name -> summary entry
    pads_enu_m: dict[str, tuple[float, float]] = field(default_factory=dict)
    world: str = ""


def load_context(run_dir: Path) -> tuple[RunContext, list[str]]:
    """Read ``run_dir/summary.json`` if there is one; return the context and notes on what was unusable."""
    path = Path(run_dir) / "summary.json"
    if not path.is_file():
        return RunContext(), []
    try:
        data = json.loads(path.read_bytes())
    except (OSError, UnicodeDecodeError, ValueError) as exc:
        return RunContext(), [f"{path}: unreadable ({exc}); tracks drawn without packages or pads"]
    if not isinstance(data, dict):
        return RunContext(), [f"{path}: not a JSON object; tracks drawn without packages or pads"]
    ctx = RunContext(world=str(data.get("world", "")))
    for ent in data.get("entities", []) if isinstance(data.get("entities"), list) else []:
        if isinstance(ent, dict) and isinstance(ent.get("name"), str):
            ctx.entities[ent["name"]] = ent
    pads = data.get("pads")
    if isinstance(pads, dict):
        for name, pos in pads.items():
            xy = _xy(pos)
            if xy is not None:
                ctx.pads_enu_m[str(name)] = xy
    return ctx, []


def _xy(value: Any) -> tuple[float, float] | None:
    """Return the finite (x, y) of a JSON position ``[x, y, ...]``, or None."""
    if isinstance(value, list) and len(value) >= 2 and all(isinstance(v, (int, float)) for v in value[:2]):
        x, y = float(value[0]), float(value[1])
        if np.isfinite(x) and np.isfinite(y):
            return x, y
    return None


def vehicle_kind(log: LogTable) -> str:
    """Return ``drone``, ``car`` or ``vehicle`` (pose columns only) from the columns of ``log``."""
    if DRONE_COLUMNS & log.columns.keys():
        return "drone"
    if CAR_COLUMNS & log.columns.keys():
        return "car"
    return "vehicle"


def label_colours(labels, palette: dict[str, tuple[str, str]]) -> dict[str, tuple[str, str]]:
    """Give every label its palette colour, and labels outside the palette unused extra colours in turn."""
    colours: dict[str, tuple[str, str]] = {}
    spare = [c for c in EXTRA_COLOURS if c not in palette.values()]
    for lab in labels:
        if lab in palette:
            colours[lab] = palette[lab]
        elif lab not in colours:
            colours[lab] = spare[len([k for k in colours if k not in palette]) % len(spare)]
    return colours


def _runs(keys: np.ndarray) -> list[tuple[int, int]]:
    """Return [start, end) index pairs of the runs of equal consecutive ``keys``."""
    if keys.size == 0:
        return []
    change = np.flatnonzero(keys[1:] != keys[:-1]) + 1
    starts = np.concatenate(([0], change))
    ends = np.concatenate((change, [keys.size]))
    return list(zip(starts.tolist(), ends.tolist()))


def _segments(log: LogTable, kind: str) -> tuple[str, list[tuple[int, int, str]]]:
    """Return the shading title and the (start, end, label) row runs to shade for ``log``."""
    c = log.columns
    if kind == "drone" and "mission_step_type" in c:
        types = np.array([str(s) for s in c["mission_step_type"]], dtype=object)
        step = c["mission_step"] if "mission_step" in c else np.zeros(len(log))
        keys = np.array([f"{s:g}|{ty}" for s, ty in zip(step, types)], dtype=object)
        return "mission step", [(a, b, types[a]) for a, b in _runs(keys) if types[a] and not step[a] < 0]
    if kind == "car" and "drive_mode" in c:
        modes = np.array([str(m) for m in c["drive_mode"]], dtype=object)
        return "drive mode", [(a, b, modes[a]) for a, b in _runs(modes) if modes[a]]
    return "", []


def _shade(axes, t: np.ndarray, segments, colours: dict[str, tuple[str, str]]) -> None:
    """Shade each segment's time span over the full height of every axes, one collection per label.

    Each label's spans form one ``PolyCollection`` with ``gid = "shade:<label>"`` (one artist per
    label and axes, not per span: a long mission has hundreds of steps); a thin line in the label's
    dark colour marks where each segment starts.
    """
    from matplotlib.collections import LineCollection, PolyCollection

    boxes: dict[str, list] = {}
    starts, start_colours = [], []
    for a, b, lab in segments:
        t0, t1 = float(t[a]), float(t[b] if b < t.size else t[-1])
        boxes.setdefault(lab, []).append([(t0, 0.0), (t1, 0.0), (t1, 1.0), (t0, 1.0)])
        if a > 0:
            starts.append([(t0, 0.0), (t0, 1.0)])
            start_colours.append(colours[lab][1])
    for ax in axes:
        for lab, polys in boxes.items():
            ax.add_collection(PolyCollection(polys, facecolors=colours[lab][0], linewidths=0, zorder=0,
                                             transform=ax.get_xaxis_transform(), gid=f"shade:{lab}"),
                              autolim=False)
        if starts:
            ax.add_collection(LineCollection(starts, colors=start_colours, linewidths=0.8, alpha=0.6, zorder=0.5,
                                             transform=ax.get_xaxis_transform()), autolim=False)


def _series(ax, log: LogTable, t, series, ylabel: str, legend: bool = False, scale: float = 1.0) -> None:
    """Draw ``series`` [(column, label, style)] on ``ax``; note missing or empty columns in the panel."""
    missing = [col for col, _, _ in series if col not in log.columns]
    drawn = 0
    for col, label, style in series:
        if col in log.columns:
            y = log.columns[col] * scale
            ax.plot(t, y, label=label, lw=1.3, marker="." if y.size == 1 else None, **{"color": INK, **style})
            drawn += int(np.isfinite(y).any())
    ax.set_ylabel(ylabel)
    ax.grid(alpha=0.3)
    if missing or not drawn:
        why = f"column {', '.join(missing)} missing from the log" if missing else "no finite values"
        ax.text(0.5, 0.5, why, transform=ax.transAxes, ha="center", va="center", color="#a00000", fontsize=9)
    if legend and drawn:
        ax.legend(loc="center left", bbox_to_anchor=(1.01, 0.5), fontsize=8, frameon=False)


def _draw_track(ax, log: LogTable, t, segments, colours, ctx: RunContext) -> None:
    from matplotlib.collections import LineCollection

    ax.set_title("track (top-down, ENU)", fontsize=10)
    ax.set_xlabel("x east [m]")
    ax.set_ylabel("y north [m]")
    ax.set_aspect("equal", adjustable="box")
    ax.set_anchor("N")
    ax.grid(alpha=0.3)
    if not log.has("x_m", "y_m"):
        ax.text(0.5, 0.5, "column x_m or y_m missing from the log", transform=ax.transAxes, ha="center",
                va="center", color="#a00000", fontsize=9)
        return
    x, y = log.columns["x_m"], log.columns["y_m"]
    ok = np.isfinite(x) & np.isfinite(y)
    if not ok.any():
        ax.text(0.5, 0.5, "no finite position", transform=ax.transAxes, ha="center", va="center",
                color="#a00000", fontsize=9)
        return
    ax.plot(x, y, color="#303030", lw=1.0, zorder=2)
    colour_of_row = np.full(x.size, "", dtype=object)
    for a, b, lab in segments:
        colour_of_row[a:b] = colours[lab][1]
    pts = np.column_stack((x, y))
    seg_ok = ok[:-1] & ok[1:] & (colour_of_row[:-1] != "")
    if seg_ok.any():
        segs = np.stack((pts[:-1], pts[1:]), axis=1)[seg_ok]
        ax.add_collection(LineCollection(segs, colors=list(colour_of_row[:-1][seg_ok]), lw=3.0, zorder=3))
    i0, i1 = np.flatnonzero(ok)[[0, -1]]
    # the start ring is larger than the end square so that a hover (same start and end) shows both
    ax.plot(x[i0], y[i0], "o", ms=13, mfc="#1a9641", mec="k", zorder=5, label=f"start (t = {t[i0]:.1f} s)")
    ax.plot(x[i1], y[i1], "s", ms=7, mfc="#d7191c", mec="k", zorder=6, label=f"end (t = {t[i1]:.1f} s)")
    lo, hi = np.array([x[ok].min(), y[ok].min()]), np.array([x[ok].max(), y[ok].max()])
    near_lo, near_hi = lo - NEAR_TRACK_M, hi + NEAR_TRACK_M
    extra: list[tuple[float, float]] = []

    def near(p) -> bool:
        return p is not None and bool(np.all(np.asarray(p) >= near_lo) and np.all(np.asarray(p) <= near_hi))

    labelled: set[str] = set()

    def mark(p, fmt: str, style: dict, label: str, name: str, offset: tuple[int, int]) -> None:
        ax.plot(*p, fmt, ms=8, zorder=4, label=None if label in labelled else label, **style)
        ax.annotate(name, p, xytext=offset, textcoords="offset points", fontsize=8, color=style["mec"])
        labelled.add(label)
        extra.append(p)

    for name, ent in ctx.entities.items():
        if ent.get("kind") != "package":
            continue
        start, final = _xy(ent.get("start_enu_m")), _xy(ent.get("final_enu_m"))
        if near(start):
            mark(start, "D", {"mfc": "#a6611a", "mec": "#7a4510", "mew": 1.6}, "package at start", name, (5, 5))
        if near(final) and (start is None or np.hypot(*np.subtract(final, start)) >= 0.5):
            mark(final, "D", {"mfc": "none", "mec": "#7a4510", "mew": 1.6}, "package at end", name, (5, 5))
    for name, p in ctx.pads_enu_m.items():
        if near(p):
            mark(p, "^", {"mfc": "none", "mec": "#404040"}, "pad", name, (5, -10))
    allp = np.vstack([pts[ok], *(np.array([e]) for e in extra)])
    lo, hi = allp.min(axis=0), allp.max(axis=0)
    centre, half = (lo + hi) / 2, max(MIN_TRACK_SPAN_M, float((hi - lo).max()) * 1.1) / 2
    ax.set_xlim(centre[0] - half, centre[0] + half)
    ax.set_ylim(centre[1] - half, centre[1] + half)
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.12), ncol=2, fontsize=8, frameon=False)


def _info_text(name: str, log: LogTable, ctx: RunContext) -> str:
    ent = ctx.entities.get(name, {})
    t = log.columns["time_s"]
    preset = f", preset {ent['preset']}" if ent.get("preset") else ""
    lines = [f"{name}: {ent.get('kind', vehicle_kind(log))}{preset}"]
    lines.append(f"log: {len(log)} rows, t = {t[0]:.1f} to {t[-1]:.1f} s")
    if log.notes:
        lines.append(f"({len(log.notes)} problem{'s' if len(log.notes) > 1 else ''} reading the log: see the "
                     "plot command's output)")
    if isinstance(ent.get("distance_m"), (int, float)):
        lines.append(f"distance: {ent['distance_m']:.1f} m, impacts: {ent.get('impacts', '?')}")
    if isinstance(ent.get("energy_used_wh"), (int, float)):
        soc = ent.get("soc_frac")
        lines.append(f"energy used: {ent['energy_used_wh']:.2f} Wh"
                     + (f", charge left {100 * soc:.1f} %" if isinstance(soc, (int, float)) else ""))
    mission = ent.get("mission")
    if isinstance(mission, dict):
        step = mission.get("step")
        where = f", step {step + 1}/{mission.get('steps')} {mission.get('step_type')}" if isinstance(step, int) else ""
        lines.append(f"mission {mission.get('mission')}:")
        lines.append(f"  {mission.get('state')}{where}")
        if mission.get("reason"):
            lines.append(f"  reason: {mission['reason']}")
    drive = ent.get("drive")
    if isinstance(drive, dict):
        route = f", route {drive['route']}, laps {drive.get('laps')}" if drive.get("route") else ""
        lines.append(f"drive mode at end: {drive.get('mode')}{route}")
    return "\n".join(lines)


def build_figure(log: LogTable, ctx: RunContext | None = None, name: str | None = None):
    """Return the matplotlib Figure for one vehicle log (not yet saved).

    The left column holds the time series, sharing the time axis; the right column the x-y track and
    the summary. Shaded intervals carry ``gid = "shade:<label>"``; their legend sits above the first
    panel, titled "mission step ..." (drones) or "drive mode ..." (cars).
    """
    from matplotlib.figure import Figure
    from matplotlib.legend import Legend
    from matplotlib.patches import Patch

    ctx = ctx or RunContext()
    name = name or log.path.stem
    kind = vehicle_kind(log)
    t = log.columns["time_s"]
    if kind == "drone":
        panels = [
            ("altitude z [m]", [("z_m", "z", {})], False, 1.0),
            ("speed [m/s]", [("speed_m_s", "speed", {})], False, 1.0),
            ("motor thrust [N]", list(MOTORS), True, 1.0),
            ("electrical power [W]", [("power_w", "power", {})], False, 1.0),
            ("state of charge [%]", [("soc_frac", "SoC", {})], False, 100.0),
        ]
    elif kind == "car":
        panels = [
            ("forward speed [m/s]", [("speed_fwd_m_s", "measured", {}),
                                     ("speed_sp_m_s", "setpoint", {"ls": "--", "color": "#b2182b"})], True, 1.0),
            ("pedal [0-1]", [("throttle", "throttle", {}),
                             ("brake", "brake", {"color": "#b2182b", "ls": "--"})], True, 1.0),
            ("steering [deg]", [("steer_deg", "steer angle", {})], False, 1.0),
            ("altitude z [m]", [("z_m", "z", {})], False, 1.0),
        ]
    else:
        panels = [("altitude z [m]", [("z_m", "z", {})], False, 1.0),
                  ("speed [m/s]", [("speed_m_s", "speed", {})], False, 1.0)]
    n = len(panels)
    height_in = 2.1 * n + 1.6
    track_in = 5.8      # a square track ~4.4 in wide in the right column, plus its title, labels and legend
    fig = Figure(figsize=(15, height_in), layout="constrained")
    outer = fig.add_gridspec(1, 2, width_ratios=[2.2, 1.0])
    left, right = outer[0].subgridspec(n, 1), outer[1].subgridspec(
        2, 1, height_ratios=[track_in, max(1.5, height_in - 0.8 - track_in)])
    axes = [fig.add_subplot(left[0])]
    axes += [fig.add_subplot(left[i], sharex=axes[0]) for i in range(1, n)]
    ax_track, ax_info = fig.add_subplot(right[0]), fig.add_subplot(right[1])
    shade_title, segments = _segments(log, kind)
    palette = STEP_COLOURS if kind == "drone" else DRIVE_MODE_COLOURS
    colours = label_colours(sorted({lab for _, _, lab in segments}, key=lambda s: (s not in palette, s)), palette)
    _shade(axes, t, segments, colours)
    for ax, (ylabel, series, legend, scale) in zip(axes, panels):
        _series(ax, log, t, series, ylabel, legend, scale)
    for ax in axes[:-1]:
        ax.tick_params(labelbottom=False)
    axes[-1].set_xlabel("sim time [s]")
    if t[-1] > t[0]:
        axes[0].set_xlim(t[0], t[-1])
    if kind == "drone" and "payload_kg" in log.columns:
        payload = log.columns["payload_kg"]
        on = np.flatnonzero(payload > 0)
        if on.size:
            axes[2].set_title(f"payload {np.nanmax(payload):g} kg carried from t = {t[on[0]]:.1f} s "
                              f"to {t[on[-1]]:.1f} s", fontsize=9, loc="left")
    _draw_track(ax_track, log, t, segments, colours, ctx)
    ax_info.axis("off")
    ax_info.text(0.0, 1.0, _info_text(name, log, ctx), transform=ax_info.transAxes, va="top", ha="left",
                 fontsize=9, family="monospace", wrap=True)
    title = f"{name}" + (f"  ({ctx.world})" if ctx.world else "")
    fig.suptitle(title, fontsize=13)
    if colours:
        order = [lab for lab in palette if lab in colours] + [lab for lab in colours if lab not in palette]
        handles = [Patch(facecolor=colours[lab][0], edgecolor=colours[lab][1], label=lab) for lab in order]
        legend = Legend(axes[0], handles, [h.get_label() for h in handles], loc="lower left",
                        bbox_to_anchor=(0.0, 1.02), ncol=len(handles), fontsize=9, frameon=False,
                        title=f"{shade_title} (shaded here, same hue on the track)", title_fontsize=9,
                        alignment="left")
        axes[0].add_artist(legend)      # beside, not instead of, the panel's own legend
        legend.set_clip_on(False)       # unclipped, so that the constrained layout makes room for it
    return fig


def plot_log(path: Path, out_png: Path | None = None, ctx: RunContext | None = None) -> tuple[Path | None, list[str]]:
    """Plot one vehicle log to ``out_png`` (default: beside it); return the PNG (None if nothing to plot) and notes."""
    path = Path(path)
    try:
        log = read_log(path)
    except LogError as exc:
        return None, [f"{exc} (file skipped)"]
    notes = list(log.notes)
    if len(log) == 0:
        return None, notes
    out_png = Path(out_png) if out_png is not None else path.with_suffix(".png")
    fig = build_figure(log, ctx)
    try:
        fig.savefig(out_png, dpi=DPI)
    except OSError as exc:
        return None, [*notes, f"{out_png}: cannot write ({exc.strerror or exc})"]
    return out_png, notes


def plot_run(run_dir: Path) -> PlotResult:
    """Plot every vehicle log (``*.csv``) in ``run_dir`` (or one CSV file); return the PNG paths.

    The result is a list of the PNGs written; its ``skipped`` attribute holds one sentence per file,
    line range or column that was left out, naming the file and the reason.

    Raises
    ------
    PlotError
        If ``run_dir`` does not exist, holds no CSV file, or no CSV file has a plottable row.
    """
    run_dir = Path(run_dir)
    if run_dir.is_file() and run_dir.suffix.lower() == ".csv":
        paths, ctx_dir = [run_dir], run_dir.parent
    elif run_dir.is_dir():
        paths, ctx_dir = sorted(p for p in run_dir.glob("*.csv") if p.is_file()), run_dir
    elif run_dir.exists():
        raise PlotError(f"{run_dir}: neither a run directory nor a .csv log")
    else:
        raise PlotError(f"{run_dir}: no such directory")
    if not paths:
        raise PlotError(f"{run_dir}: no vehicle logs (*.csv, written by `unetyemu run`) in this directory")
    ctx, skipped = load_context(ctx_dir)
    written: list[Path] = []
    for path in paths:
        png, notes = plot_log(path, ctx=ctx)
        skipped += notes
        if png is not None:
            written.append(png)
    if not written:
        raise PlotError(f"{run_dir}: nothing plottable in {len(paths)} CSV file{'s' if len(paths) > 1 else ''}:\n  "
                        + "\n  ".join(skipped))
    return PlotResult(written, skipped)


__all__ = ["DRIVE_MODE_COLOURS", "STEP_COLOURS", "PlotError", "PlotResult", "RunContext", "build_figure",
           "load_context", "plot_log", "plot_run", "read_log"]
