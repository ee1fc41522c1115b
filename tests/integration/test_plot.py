"""``unetyemu plot``: what the figures show, and what happens with damaged or odd logs.

The logs are written here with the exact header of ``TrajectoryLogSystem`` (``systems/outputs.py``)
and the csv module's default row end, so no simulator runs; one test in test_delivery_scenario.py
plots a real run.
"""

from __future__ import annotations

import csv
import itertools
import json
import math

import numpy as np
import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.colors import to_rgb
from matplotlib.legend import Legend

from unetyemu_ecs.cli import main as cli_main
from unetyemu_ecs.mission.spec import STEP_TYPES
from unetyemu_ecs.plot import PlotError, build_figure, load_context, plot_run
from unetyemu_ecs.plot_log import read_log
from unetyemu_ecs.systems.outputs import CAR_COLUMNS, FLIGHT_COLUMNS, POSE_COLUMNS

LOG_HZ = 10.0


def _pose(t: float, x: float, y: float, z: float, v: tuple[float, float, float]) -> list[str]:
    speed = math.sqrt(sum(c * c for c in v))
    return [f"{t:.4f}", f"{x:.4f}", f"{y:.4f}", f"{z:.4f}", "0.000", "0.000", "90.000", "40.415692419",
            "-3.705443450", f"{650 + z:.4f}", *(f"{c:.4f}" for c in v), f"{speed:.4f}"]


def drone_rows(steps=("takeoff", "cruise", "land"), seconds_per_step: float = 3.0) -> list[list[str]]:
    """Rows of a drone flying ``steps`` in turn (one row at t = 0 before the mission starts)."""
    rows = []
    n = int(len(steps) * seconds_per_step * LOG_HZ) + 1
    for k in range(n):
        t = k / LOG_HZ
        idx = -1 if k == 0 else min(int(t / seconds_per_step), len(steps) - 1)
        x, y, z = -100.0 + 2.0 * t, -50.0 + 1.0 * t, 10.0 * math.sin(math.pi * t / (n / LOG_HZ))
        payload = 2.5 if steps[max(idx, 0)] in ("pickup", "cruise") else 0.0
        rows.append(_pose(t, x, y, z, (2.0, 1.0, 0.5)) + [
            "auto", "mission", "in_air", "20.0000", "20.5000", "21.0000", "21.5000", "83.0000", "1500.000", f"{t * 0.4:.5f}",
            f"{500 - t * 0.4:.5f}", f"{1 - t * 0.0008:.6f}", f"{24.6 - t * 0.01:.4f}", "61.0000", "1200.0", f"{payload:.3f}", str(idx),
            "" if idx < 0 else steps[idx]])
    return rows


def car_rows(n: int = 60) -> list[list[str]]:
    """Rows of a car parked for 1 s, then driving a route in a quarter circle of radius 30 m."""
    rows = []
    for k in range(n):
        t = k / LOG_HZ
        a = max(0.0, t - 1.0) * 0.25
        mode = "parked" if t < 1.0 else "route"
        rows.append(_pose(t, 30 * math.sin(a), 30 * (1 - math.cos(a)), 0.9, (7.0, 0.0, 0.0)) + [
            mode, "0.0000" if mode == "parked" else "0.4000", "1.0000" if mode == "parked" else "0.0000",
            f"{8.0 * (mode == 'route'):.3f}", f"{min(7.5, max(0.0, t - 1) * 3):.4f}",
            f"{8.0 * (mode == 'route'):.4f}"])
    return rows


def write_log(path, header, rows, tail: bytes = b"") -> None:
    with open(path, "w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)          # default row end "\r\n", as the logger writes
        w.writerow(header)
        w.writerows(rows)
    if tail:
        with open(path, "ab") as fh:
            fh.write(tail)


DRONE_HEADER = POSE_COLUMNS + FLIGHT_COLUMNS
CAR_HEADER = POSE_COLUMNS + CAR_COLUMNS


def _lab(colour) -> np.ndarray:
    """CIELAB (D65) of an sRGB colour: distances in it follow what the eye sees."""
    rgb = np.array(to_rgb(colour))
    lin = np.where(rgb <= 0.04045, rgb / 12.92, ((rgb + 0.055) / 1.055) ** 2.4)
    xyz = np.array([[0.4124, 0.3576, 0.1805], [0.2126, 0.7152, 0.0722], [0.0193, 0.1192, 0.9505]]) @ lin
    xyz /= np.array([0.95047, 1.0, 1.08883])
    f = np.where(xyz > (6 / 29) ** 3, np.cbrt(xyz), xyz / (3 * (6 / 29) ** 2) + 4 / 29)
    return np.array([116 * f[1] - 16, 500 * (f[0] - f[1]), 200 * (f[1] - f[2])])


def _over_white(rgba) -> tuple[float, float, float]:
    r, g, b, a = rgba
    return (r * a + 1 - a, g * a + 1 - a, b * a + 1 - a)


def _drawn(fig):
    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    return canvas.get_renderer()


def _all_legends(fig) -> list[Legend]:
    found = list(fig.legends)
    for ax in fig.axes:
        found += [a for a in ax.get_children() if isinstance(a, Legend)]
    return found


def _shade_legend(fig) -> Legend:
    (legend,) = [lg for lg in _all_legends(fig) if lg.get_title().get_text().startswith(("mission step", "drive mode"))]
    return legend


def _track_axes(fig):
    (ax,) = [ax for ax in fig.axes if ax.get_title().startswith("track")]
    return ax


# --- damaged logs (issue 11, item 12) ---------------------------------------------------------------------------

def test_truncated_last_row_is_skipped_and_named_while_the_rest_is_plotted(tmp_path):
    # GIVEN a drone log whose last row was cut off mid-write, as SIGKILL leaves it (no row end)
    rows = drone_rows()
    write_log(tmp_path / "drone1.csv", DRONE_HEADER, rows, tail=b"9.1000,-81.8000,-40.9")
    # WHEN the run directory is plotted
    result = plot_run(tmp_path)
    # THEN the PNG is written and the skipped line is named by file, number and reason
    assert result == [tmp_path / "drone1.png"] and (tmp_path / "drone1.png").stat().st_size > 20_000
    last_line = len(rows) + 2
    (note,) = result.skipped
    assert "drone1.csv" in note and f"line {last_line}" in note and "incomplete" in note
    assert len(read_log(tmp_path / "drone1.csv")) == len(rows)


def test_binary_garbage_file_is_reported_and_the_other_logs_are_plotted(tmp_path):
    # GIVEN one good drone log and one CSV of random bytes
    write_log(tmp_path / "drone1.csv", DRONE_HEADER, drone_rows())
    (tmp_path / "junk.csv").write_bytes(np.random.default_rng(1234).bytes(4096))
    # WHEN plotted
    result = plot_run(tmp_path)
    # THEN the good log is plotted and the garbage file is named as skipped, with why
    assert result == [tmp_path / "drone1.png"]
    assert any("junk.csv" in s and "not" in s for s in result.skipped)
    assert not (tmp_path / "junk.png").exists()


def test_garbage_lines_inside_a_log_are_skipped_by_line_number(tmp_path):
    # GIVEN a log with non-UTF-8 bytes on line 4 and a row of text in numeric columns on line 6
    rows = drone_rows()
    lines = (tmp_path / "x").with_suffix(".csv")
    write_log(lines, DRONE_HEADER, rows)
    body = lines.read_bytes().split(b"\r\n")
    body[3] = b"\xff\xfe\x00garbage\x80"
    body[5] = b",".join([b"oops"] * len(DRONE_HEADER))
    lines.write_bytes(b"\r\n".join(body))
    # WHEN it is read and plotted
    log = read_log(lines)
    result = plot_run(lines)
    # THEN both lines are named with their reason and every other row is kept
    assert len(log) == len(rows) - 2
    assert any("line 4" in n and "UTF-8" in n for n in log.notes)
    assert any("line 6" in n and "not a number" in n for n in log.notes)
    assert result == [lines.with_suffix(".png")]


def test_nan_and_inf_values_are_left_out_of_the_curves_and_reported(tmp_path):
    # GIVEN a log with nan altitude on line 3 and inf power on lines 10-11
    rows = drone_rows()
    rows[1][DRONE_HEADER.index("z_m")] = "nan"
    rows[8][DRONE_HEADER.index("power_w")] = "inf"
    rows[9][DRONE_HEADER.index("power_w")] = "-inf"
    write_log(tmp_path / "d.csv", DRONE_HEADER, rows)
    # WHEN plotted
    result = plot_run(tmp_path)
    # THEN it plots, naming the columns and lines whose values were not drawn
    assert result == [tmp_path / "d.png"]
    assert any("z_m" in s and "line 3" in s for s in result.skipped)
    assert any("power_w" in s and "lines 10-11" in s for s in result.skipped)


def test_log_without_motor_columns_still_plots_and_says_what_is_missing(tmp_path):
    # GIVEN a drone log whose thrust columns are missing
    keep = [j for j, h in enumerate(DRONE_HEADER) if not h.startswith("thrust_")]
    write_log(tmp_path / "d.csv", [DRONE_HEADER[j] for j in keep], [[r[j] for j in keep] for r in drone_rows()])
    # WHEN its figure is built
    fig = build_figure(read_log(tmp_path / "d.csv"))
    # THEN the thrust panel says which columns are missing instead of failing
    texts = [t.get_text() for ax in fig.axes for t in ax.texts]
    assert any("thrust_fl_n" in t and "missing" in t for t in texts)
    assert plot_run(tmp_path) == [tmp_path / "d.png"]


@pytest.mark.parametrize("content, why", [
    (b"", "empty"),
    (",".join(DRONE_HEADER).encode() + b"\r\n", "no usable data rows"),
    (b"\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR", "not UTF-8"),
    (b"hello,world\r\n1,2\r\n", "not a vehicle log header"),
])
def test_directory_with_nothing_plottable_is_an_error_naming_each_file_and_why(tmp_path, content, why):
    # GIVEN a run directory whose only CSV cannot be plotted
    (tmp_path / "v.csv").write_bytes(content)
    # WHEN plotted THEN PlotError names the file and the reason
    with pytest.raises(PlotError, match="nothing plottable") as err:
        plot_run(tmp_path)
    assert "v.csv" in str(err.value) and why in str(err.value)


def test_one_row_log_and_a_header_with_a_byte_order_mark_still_plot(tmp_path):
    # GIVEN a log with a single row, and a log re-saved by a spreadsheet (BOM before the header)
    write_log(tmp_path / "one.csv", DRONE_HEADER, drone_rows()[:1])
    write_log(tmp_path / "bom.csv", DRONE_HEADER, drone_rows())
    (tmp_path / "bom.csv").write_bytes(b"\xef\xbb\xbf" + (tmp_path / "bom.csv").read_bytes())
    # WHEN plotted THEN both get a PNG and nothing is reported skipped
    result = plot_run(tmp_path)
    assert sorted(result) == [tmp_path / "bom.png", tmp_path / "one.png"] and not result.skipped


def test_cli_exits_2_with_a_message_for_a_missing_or_empty_directory(tmp_path, capsys):
    # GIVEN a path that does not exist and a directory with no CSV
    # WHEN `unetyemu plot` is run on each THEN it exits 2 and says what is wrong, without a traceback
    assert cli_main(["plot", str(tmp_path / "nope")]) == 2
    assert "no such directory" in capsys.readouterr().err
    assert cli_main(["plot", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "no vehicle logs" in err and "Traceback" not in err


def test_broken_summary_json_is_reported_and_logs_still_plotted(tmp_path):
    # GIVEN a run directory with a good log and a summary.json cut short
    write_log(tmp_path / "drone1.csv", DRONE_HEADER, drone_rows())
    (tmp_path / "summary.json").write_text('{"world": "x", "entities": [')
    # WHEN plotted THEN the log is plotted and the summary named as unusable
    result = plot_run(tmp_path)
    assert result == [tmp_path / "drone1.png"]
    assert any("summary.json" in s for s in result.skipped)


# --- what the figures show (issue 11, item 6) -----------------------------------------------------------------

def test_every_mission_step_type_is_shaded_in_its_own_clearly_distinct_colour(tmp_path):
    # GIVEN a drone log that goes through every mission step type
    write_log(tmp_path / "d.csv", DRONE_HEADER, drone_rows(steps=STEP_TYPES, seconds_per_step=1.0))
    fig = build_figure(read_log(tmp_path / "d.csv"))
    # WHEN the shaded spans are collected by the step type they mark
    spans: dict[str, set] = {}
    for ax in fig.axes:
        for artist in [*ax.patches, *ax.collections]:
            if (artist.get_gid() or "").startswith("shade:"):
                for rgba in np.atleast_2d(artist.get_facecolor()):
                    spans.setdefault(artist.get_gid()[6:], set()).add(_over_white(rgba))
    # THEN every type has one colour, the legend names every type in that colour,
    assert set(spans) == set(STEP_TYPES) and all(len(c) == 1 for c in spans.values())
    colour = {k: next(iter(c)) for k, c in spans.items()}
    legend = _shade_legend(fig)
    shown = {t.get_text(): _over_white(h.get_facecolor()) for t, h in zip(legend.get_texts(), legend.legend_handles)}
    assert shown == colour
    # AND every two colours are clearly different to the eye (CIELAB distance > 15; "land" and "deliver"
    # were 8 apart as shaded before)
    for a, b in itertools.combinations(colour, 2):
        assert np.linalg.norm(_lab(colour[a]) - _lab(colour[b])) > 15.0, (a, b)


@pytest.mark.parametrize("kind", ["drone", "car"])
def test_no_legend_overlaps_the_data_area_of_any_axes(tmp_path, kind):
    # GIVEN the figure of a drone log (mission steps, motors) or of a car log (drive modes, setpoint)
    header, rows = (DRONE_HEADER, drone_rows(STEP_TYPES, 1.0)) if kind == "drone" else (CAR_HEADER, car_rows())
    write_log(tmp_path / "v.csv", header, rows)
    fig = build_figure(read_log(tmp_path / "v.csv"))
    # WHEN it is drawn with the Agg renderer
    renderer = _drawn(fig)
    legends = _all_legends(fig)
    # THEN there are legends, and none of them overlaps the area of any axes
    assert len(legends) >= 3
    for legend in legends:
        box = legend.get_window_extent(renderer).padded(-1.0)
        for ax in fig.axes:
            assert not box.overlaps(ax.get_window_extent(renderer)), (legend.get_title().get_text(), ax.get_ylabel())


def test_track_panel_has_equal_axis_scaling_and_marks_start_end_and_nearby_packages_and_pads(tmp_path):
    # GIVEN a drone log and a summary with a package and a pad on its track, and another of each far away
    write_log(tmp_path / "drone1.csv", DRONE_HEADER, drone_rows())
    (tmp_path / "summary.json").write_text(json.dumps({"world": "w", "entities": [
        {"name": "drone1", "kind": "quadrotor", "distance_m": 20.0, "impacts": 0},
        {"name": "package1", "kind": "package", "start_enu_m": [-98.0, -49.0, 0.3], "final_enu_m": [-85.0, -43.0, 9.0]},
        {"name": "far", "kind": "package", "start_enu_m": [2000.0, 0.0, 0.3], "final_enu_m": [2000.0, 0.0, 0.3]},
    ], "pads": {"roof_1": [-86.0, -44.0, 20.0], "start_9": [900.0, 900.0, 0.0]}}))
    ctx, notes = load_context(tmp_path)
    fig = build_figure(read_log(tmp_path / "drone1.csv"), ctx)
    _drawn(fig)
    # WHEN the track panel is looked up
    ax = _track_axes(fig)
    # THEN its x and y scales are equal, start and end are marked, the near package is named and the far one not
    assert not notes
    assert ax.get_aspect() == 1.0
    x0, x1 = ax.get_xlim()
    y0, y1 = ax.get_ylim()
    box = ax.get_window_extent()
    assert (x1 - x0) / box.width == pytest.approx((y1 - y0) / box.height, rel=0.02)
    labels = [line.get_label() for line in ax.lines]
    assert any(lab.startswith("start") for lab in labels) and any(lab.startswith("end") for lab in labels)
    names = [t.get_text() for t in ax.texts]
    assert "package1" in names and "far" not in names
    assert "roof_1" in names and "start_9" not in names


def test_car_log_gets_speed_against_setpoint_pedals_steering_and_track(tmp_path):
    # GIVEN a car log next to a drone log
    write_log(tmp_path / "car1.csv", CAR_HEADER, car_rows())
    write_log(tmp_path / "drone1.csv", DRONE_HEADER, drone_rows())
    # WHEN the run is plotted
    result = plot_run(tmp_path)
    fig = build_figure(read_log(tmp_path / "car1.csv"))
    # THEN the car has its PNG, with speed and setpoint, throttle and brake, steering, drive modes and a track
    assert sorted(result) == [tmp_path / "car1.png", tmp_path / "drone1.png"] and not result.skipped
    ylabels = [ax.get_ylabel() for ax in fig.axes]
    assert any("speed" in y for y in ylabels) and any("pedal" in y for y in ylabels)
    assert any("steering" in y for y in ylabels)
    line_labels = {line.get_label() for ax in fig.axes for line in ax.lines}
    assert {"measured", "setpoint", "throttle", "brake", "steer angle"} <= line_labels
    assert [t.get_text() for t in _shade_legend(fig).get_texts()] == ["parked", "route"]
    assert _track_axes(fig).get_aspect() == 1.0
