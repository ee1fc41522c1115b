"""A sweep's plan without Ray: --set parsing, key paths, the product of values x seeds, up-front checks
that name the file, line and --set of every problem, per-worker isolation, the table and the progress line."""

from __future__ import annotations

import io
import json

import pytest

from unetyemu_ecs.sweep import OverrideError, build_plan, parse_set, run_figures, validate_plan
from unetyemu_ecs.sweep.isolation import (IsolationError, check_mavlink_instances, check_ros2_domains,
                                          mavlink_overrides)
from unetyemu_ecs.sweep.overrides import apply_overrides, resolve_key
from unetyemu_ecs.sweep.plan import explain_invalid, resolve_run
from unetyemu_ecs.sweep.progress import SweepProgress, eta_s
from unetyemu_ecs.sweep.table import columns, format_table, plot_figure, plot_histogram, read_csv, write_csv

from ..conftest import WORLDS

PARCEL = WORLDS / "parcel_sweep.yaml"


def _line_of(path, text):
    return next(i for i, line in enumerate(path.read_text().splitlines(), 1) if text in line)


# --- --set ---------------------------------------------------------------------------------------------
def test_values_are_yaml_split_at_top_level_commas():
    p = parse_set('vehicles.drone1.pose.offset_m=[1.0, 0.0],[0.5, 0.5],"a,b",true,2.5,small')
    assert p.key == "vehicles.drone1.pose.offset_m"
    assert p.values == ([1.0, 0.0], [0.5, 0.5], "a,b", True, 2.5, "small")
    assert p.texts[0] == "[1.0, 0.0]"


@pytest.mark.parametrize("text, words", [
    ("packages.parcel.mass_kg", "KEY.PATH=VALUE"),
    ("=1,2", "KEY.PATH=VALUE"),
    ("packages..mass_kg=1", "not a key path"),
    ("packages.parcel.mass kg=1", "not a key path"),
    ("packages.parcel.mass_kg=1,,2", "empty value"),
    ("packages.parcel.mass_kg=1,", "empty value"),
    ("packages.parcel.mass_kg=1,1", "given twice"),
    ("packages.parcel.mass_kg=[1,", "not YAML"),
    ("world.seed=1,2", "--seeds"),
])
def test_a_malformed_set_is_refused_with_what_is_wrong(text, words):
    with pytest.raises(OverrideError, match=words) as err:
        parse_set(text)
    assert repr(text) in str(err.value)


def test_key_paths_walk_lists_by_name_or_index():
    doc = {"vehicles": [{"name": "a", "x": 1}, {"name": "b"}], "world": {"name": "w"}}
    assert resolve_key(doc, "vehicles.b.preset", "w.yaml") == ("vehicles", 1, "preset")
    assert resolve_key(doc, "vehicles.0.x", "w.yaml") == ("vehicles", 0, "x")
    assert resolve_key(doc, "world.wind.speed_m_s", "w.yaml") == ("world", "wind", "speed_m_s")   # created
    with pytest.raises(OverrideError, match=r"no item named 'c' in vehicles of w.yaml \(names: a, b"):
        resolve_key(doc, "vehicles.c.preset", "w.yaml")
    with pytest.raises(OverrideError, match="has 2 items; there is no index 2"):
        resolve_key(doc, "vehicles.2.preset", "w.yaml")
    with pytest.raises(OverrideError, match=r"world.name in w.yaml is a value \('w'\), it has no 'x'"):
        resolve_key(doc, "world.name.x", "w.yaml")
    out = apply_overrides(doc, [(("world", "wind", "speed_m_s"), 5.0), (("vehicles", 1, "preset"), "large")])
    assert out["world"]["wind"] == {"speed_m_s": 5.0} and out["vehicles"][1]["preset"] == "large"
    assert "wind" not in doc["world"]                       # the parsed document itself is untouched


# --- the plan -------------------------------------------------------------------------------------------
def test_the_plan_is_every_combination_times_every_seed_each_in_its_own_directory():
    plan = build_plan(PARCEL, [parse_set("packages.parcel.mass_kg=0.5,1.0,1.5"),
                               parse_set("vehicles.drone1.preset=medium,large")], seeds=3)
    assert len(plan.runs) == 3 * 2 * 3
    assert len({r.run_id for r in plan.runs}) == len(plan.runs)
    assert plan.seeds == (1, 2, 3)                          # from the world file's seed (1)
    run = plan.runs[-1]
    assert run.run_id.startswith("mass_kg=1.5-preset=large-seed3-")
    world = resolve_run(plan, run)
    assert world.spec.world.seed == 3
    assert world.spec.packages[0].mass_kg == 1.5 and world.vehicles[0].preset == "large"
    assert build_plan(PARCEL, [], seeds=2, first_seed=100).seeds == (100, 101)


def test_run_ids_never_collide_and_do_not_depend_on_spelling_or_order():
    plan = build_plan(PARCEL, [parse_set("vehicles.drone1.pose.offset_m=[1, 0],[0, 1],'[1, 0]'")])
    assert len({r.run_id for r in plan.runs}) == 3                 # a list twice, and a string
    a = build_plan(PARCEL, [parse_set("packages.parcel.mass_kg=1,2"), parse_set("vehicles.drone1.preset=large")])
    b = build_plan(PARCEL, [parse_set("vehicles.drone1.preset=large"), parse_set("packages.parcel.mass_kg=2.0,1.00")])
    c = build_plan(PARCEL, [parse_set("vehicles.0.preset=large"), parse_set("packages.0.mass_kg=1,2")])
    assert {r.run_id for r in a.runs} == {r.run_id for r in b.runs} == {r.run_id for r in c.runs}   # resume finds them
    with pytest.raises(OverrideError, match=r"given twice \(1, 1.0 are the same value\)"):
        parse_set("packages.parcel.mass_kg=1,1.0")


def test_two_sets_of_one_value_or_of_a_block_and_its_value_are_refused():
    with pytest.raises(OverrideError, match="the same value as --set packages.parcel.mass_kg"):
        build_plan(PARCEL, [parse_set("packages.parcel.mass_kg=1"), parse_set("packages.0.mass_kg=2")])
    with pytest.raises(OverrideError, match="--set world.wind.speed_m_s lies inside --set world.wind"):
        build_plan(PARCEL, [parse_set("world.wind.speed_m_s=1,2"), parse_set("world.wind={speed_m_s: 3}")])


def test_a_value_nested_too_deep_or_too_long_is_refused():
    with pytest.raises(OverrideError, match="nested more than 16 levels"):
        parse_set("packages.parcel.mass_kg=" + "[" * 3000)
    with pytest.raises(OverrideError, match="at most 10000"):
        parse_set("packages.parcel.mass_kg=" + "1" * 20_000)
    with pytest.raises(OverrideError, match="aliases are not allowed"):
        parse_set("packages.parcel.size_m=[&a 1, *a, 1]")


def test_a_key_that_names_nothing_is_refused_before_anything_runs():
    with pytest.raises(OverrideError, match=r"no item named 'drone9' in vehicles of .*parcel_sweep.yaml "
                                            r"\(names: drone1"):
        build_plan(PARCEL, [parse_set("vehicles.drone9.preset=small")])
    with pytest.raises(OverrideError, match="the same value as"):
        build_plan(PARCEL, [parse_set("packages.parcel.mass_kg=1"), parse_set("packages.parcel.mass_kg=2")])


def test_every_invalid_combination_is_named_with_file_line_and_set_before_anything_runs():
    # GIVEN a negative mass and a preset that does not exist
    plan = build_plan(PARCEL, [parse_set("packages.parcel.mass_kg=-1,1.0,2.5"),
                               parse_set("vehicles.drone1.preset=medium,huge")], seeds=2)
    # WHEN the plan is checked
    bad = validate_plan(plan)
    text = explain_invalid(plan, bad)
    # THEN every problem is named with the world file's line and the --set that caused it
    print(text)
    assert text.startswith("4 of 6 parameter combinations give an invalid world (8 of 12 runs); nothing was run:")
    mass_line, preset_line = _line_of(PARCEL, "mass_kg: 1.0"), _line_of(PARCEL, "preset: medium")
    assert f"parcel_sweep.yaml:{mass_line}: packages[0].mass_kg: must be > 0, got -1.0  " \
           "(from --set packages.parcel.mass_kg=-1)" in text
    assert f"parcel_sweep.yaml:{preset_line}: vehicles[0].preset: " in text
    assert "(from --set vehicles.drone1.preset=huge)" in text
    assert {tuple(t for _k, _v, t in r.values) for r, _e in bad} == {("-1", "medium"), ("-1", "huge"),
                                                                     ("1.0", "huge"), ("2.5", "huge")}


def test_a_city_drawn_from_the_seed_is_checked_for_every_seed_and_a_fixed_one_once(tmp_path, monkeypatch):
    import unetyemu_ecs.sweep.plan as plan_module

    world = (WORLDS / "urban_delivery.yaml").read_text()
    calls = []
    real = plan_module.resolve_run
    monkeypatch.setattr(plan_module, "resolve_run", lambda plan, run, extra=(): calls.append(run.seed) or real(plan, run))
    (tmp_path / "city.yaml").write_text(world)
    assert validate_plan(build_plan(tmp_path / "city.yaml", [], seeds=2, first_seed=42)) == []
    assert calls == [42, 43]
    calls.clear()
    (tmp_path / "fixed.yaml").write_text(world.replace("  generator: urban\n", "  generator: urban\n  seed: 42\n"))
    plan = build_plan(tmp_path / "fixed.yaml", [], seeds=2)
    assert validate_plan(plan) == [] and calls == [42]
    assert resolve_run(plan, plan.runs[1]).layout.pads.keys() == resolve_run(plan, plan.runs[0]).layout.pads.keys()


# --- keeping concurrent runs apart ------------------------------------------------------------------
def test_each_worker_gets_its_own_px4_instances():
    doc = {"vehicles": [{"name": "d1", "type": "quadrotor"}, {"name": "car", "type": "car"},
                        {"name": "d2", "type": "quadrotor"}]}
    assert mavlink_overrides(doc, 0, forced=True) == ((("vehicles", 0, "components", "mavlink", "instance"), 0),
                                                      (("vehicles", 2, "components", "mavlink", "instance"), 1))
    assert [v for _p, v in mavlink_overrides(doc, 3, forced=True)] == [6, 7]
    assert mavlink_overrides(doc, 3, forced=False) == ()
    doc["vehicles"][2]["components"] = {"mavlink": {"instance": 5}}
    assert mavlink_overrides(doc, 2, forced=False) == ((("vehicles", 2, "components", "mavlink", "instance"), 17),)
    check_mavlink_instances(doc, forced=False, workers=42)              # instances up to 251
    with pytest.raises(IsolationError, match="system ids end at 255"):
        check_mavlink_instances(doc, forced=False, workers=43)
    check_ros2_domains(0, 102)
    with pytest.raises(IsolationError, match=r"domains 100\.\.102"):
        check_ros2_domains(100, 3)


# --- the table ------------------------------------------------------------------------------------------
def _summary(energy, mission_state="completed", impacts=0):
    return {"sim_time_s": 10.0, "wall_time_s": 2.0, "real_time_factor": 5.0,
            "entities": [{"name": "drone1", "kind": "quadrotor", "distance_m": 100.0, "impacts": impacts,
                          "energy_used_wh": energy, "soc_frac": 0.9,
                          "mission": {"mission": "m", "state": mission_state, "step": 2, "steps": 5,
                                      "step_type": "cruise", "reason": ""}},
                         {"name": "car1", "kind": "car", "distance_m": 50.0, "impacts": 0},
                         {"name": "parcel", "kind": "package", "distance_m": 100.0, "impacts": 1}]}


def test_figures_are_the_worlds_totals_or_one_vehicles_own():
    totals = run_figures(_summary(3.0))
    assert totals["energy_used_wh"] == 3.0 and totals["distance_m"] == 150.0     # vehicles, not the parcel
    assert totals["impacts"] == 1 and totals["mission"] == "completed"           # the parcel's impact counts
    assert run_figures(_summary(3.0, "running"))["mission"] == "running (step 3/5)"
    car = run_figures(_summary(3.0), vehicle="car1")
    assert car["distance_m"] == 50.0 and car["energy_used_wh"] == 0.0 and car["mission"] == "-"
    with pytest.raises(KeyError, match="vehicles: drone1, car1"):
        run_figures(_summary(3.0), vehicle="parcel")


def test_the_csv_keeps_every_row_and_the_plot_draws_mean_over_seeds(tmp_path):
    keys = ["packages.parcel.mass_kg", "vehicles.drone1.preset"]
    rows = []
    for mass in ("0.5", "1.0"):
        for preset in ("medium", "large"):
            for seed in (1, 2):
                fig = run_figures(_summary(float(mass) * (2 if preset == "large" else 1) + 0.01 * seed))
                rows.append({"run": f"{mass}-{preset}-{seed}", "status": "ok", keys[0]: mass, keys[1]: preset,
                             "seed": seed, **fig, "error": ""})
    rows.append({"run": "bad", "status": "failed", keys[0]: "1.5", keys[1]: "large", "seed": 1,
                 "error": "RuntimeError: boom"})
    path = write_csv(tmp_path / "results.csv", keys, rows)
    back = read_csv(path)
    assert list(back[0]) == columns(keys) and len(back) == 9
    assert back[-1]["status"] == "failed" and back[-1]["energy_used_wh"] == "" and back[-1]["error"] == "RuntimeError: boom"
    assert float(back[0]["energy_used_wh"]) == pytest.approx(0.51)
    text = format_table(keys, rows, limit=4)
    assert text.splitlines()[0].split()[:4] == ["status", "mass_kg", "preset", "seed"]
    assert text.endswith("... 5 more runs in the CSV")
    png = plot_figure(tmp_path / "p.png", back, keys, "energy_used_wh", keys[0])
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert plot_histogram(tmp_path / "h.png", back, "energy_used_wh").read_bytes()[:4] == b"\x89PNG"
    with pytest.raises(ValueError, match="cannot plot 'mission'"):
        plot_figure(tmp_path / "q.png", back, keys, "mission", keys[0])
    with pytest.raises(ValueError, match="not a swept parameter"):
        plot_figure(tmp_path / "q.png", back, keys, "energy_used_wh", "world.wind.speed_m_s")


def test_progress_counts_runs_and_estimates_the_time_left():
    assert eta_s(0, 10, 2, 5.0) is None
    assert eta_s(4, 4, 2, 60.0) == pytest.approx(75.0)      # 15 s a run; 4 to go and 2 half done
    stream = io.StringIO()
    progress = SweepProgress(stream, total=12, skipped=2)
    progress.update(3, 2, 1, force=True)
    line = stream.getvalue()
    assert "5/12 finished (2 from before), 2 running, 1 failed" in line and "ETA" in line


def test_a_sweep_record_is_plain_json(tmp_path):
    from unetyemu_ecs.sweep.campaign import SweepOptions, _sweep_record

    plan = build_plan(PARCEL, [parse_set("packages.parcel.mass_kg=0.5,1.0")], seeds=2)
    record = json.loads(json.dumps(_sweep_record(plan, SweepOptions())))
    assert record["parameters"] == [{"key": "packages.parcel.mass_kg", "values": ["0.5", "1.0"]}]
    assert record["runs"] == 4 and len(record["world_sha256"]) == 64
