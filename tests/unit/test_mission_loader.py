"""Missions load from our JSON and the paper's Unity JSON; a bad mission is rejected whole, naming step and field."""

from __future__ import annotations

import json

import pytest

from unetyemu_ecs.config.schema import ConfigError
from unetyemu_ecs.mission import MissionSpec, MissionStep, Waypoint, mission_to_json, parse_mission

from ..conftest import REPO_ROOT

GOOD = {
    "name": "square",
    "cruise_speed": 6.0,
    "steps": [
        {"type": "takeoff", "altitude_m": 12.0, "wait_after": 1.0},
        {"type": "cruise", "waypoints": [{"x": 20.0, "y": 0.0, "z": 12.0},
                                         {"x": 20.0, "y": 20.0, "z": 12.0, "yaw_deg": 90.0, "cruise_speed": 4.0}]},
        {"type": "land", "pad": "home"},
        {"type": "recharge", "target_soc_frac": 0.8},
        {"type": "idle", "duration_s": 5.0},
    ],
}


def _with_step(i: int, **changes: object) -> str:
    """GOOD with step ``i`` updated by ``changes`` (a value of None deletes the key), as JSON."""
    doc = json.loads(json.dumps(GOOD))
    for key, value in changes.items():
        if value is None:
            doc["steps"][i].pop(key, None)
        else:
            doc["steps"][i][key] = value
    return json.dumps(doc, indent=2)


def _issues(text: str) -> list[str]:
    with pytest.raises(ConfigError) as info:
        parse_mission(text, source="m.json")
    return [str(issue) for issue in info.value.issues]


# -- our format ----------------------------------------------------------------------------------
def test_a_good_mission_parses_with_defaults_applied():
    # GIVEN our JSON with some fields left out
    # WHEN it is parsed
    spec = parse_mission(json.dumps(GOOD))
    # THEN the given values are kept and the rest take the schema defaults
    assert spec.name == "square" and spec.cruise_speed == 6.0
    assert (spec.climb_speed, spec.descent_speed) == (3.0, 1.5)
    takeoff, cruise, land, recharge, idle = spec.steps
    assert takeoff == MissionStep(type="takeoff", altitude_m=12.0, wait_after=1.0)
    assert takeoff.wait_before == 0.0 and takeoff.waypoints == []
    assert cruise.waypoints[0] == Waypoint(x=20.0, y=0.0, z=12.0)
    assert cruise.waypoints[0].yaw_deg is None and cruise.waypoints[0].cruise_speed is None
    assert cruise.waypoints[1].yaw_deg == 90.0 and cruise.waypoints[1].cruise_speed == 4.0
    assert land.pad == "home"
    assert recharge.target_soc_frac == 0.8 and recharge.charge_power_w is None
    assert idle.duration_s == 5.0


def test_a_bare_list_of_steps_is_a_mission_with_default_speeds():
    # GIVEN only the steps, as a JSON list
    # WHEN parsed
    spec = parse_mission(json.dumps(GOOD["steps"]))
    # THEN it is the same mission with the default name and speeds
    assert spec == MissionSpec(steps=parse_mission(json.dumps(GOOD)).steps)


def test_string_instead_of_number_names_step_waypoint_field_and_line():
    # GIVEN a waypoint height given as a word
    doc = json.loads(json.dumps(GOOD))
    doc["steps"][1]["waypoints"][0]["z"] = "high"
    text = json.dumps(doc, indent=2)
    line = next(n for n, s in enumerate(text.splitlines(), 1) if '"high"' in s)
    # WHEN parsed THEN the one issue names the source, its line, the step, the waypoint and the field
    assert _issues(text) == [f"m.json:{line}: steps[1].waypoints[0].z: expected a number, got string 'high'"]


def test_unknown_step_type_lists_the_valid_ones():
    # GIVEN a step of a type we do not have
    issues = _issues(_with_step(4, type="hover"))
    # THEN the issue names the step's type field and lists every valid type
    assert len(issues) == 1 and "steps[4].type: unknown value 'hover'" in issues[0]
    assert "takeoff, cruise, land, pickup, deliver, recharge, idle" in issues[0]


def test_cruise_without_waypoints_or_pad_is_rejected():
    # GIVEN a cruise step with nowhere to go
    issues = _issues(_with_step(1, waypoints=None))
    # THEN the issue points at its waypoints
    assert len(issues) == 1 and "steps[1].waypoints: a cruise step needs at least 1 waypoint or a pad" in issues[0]


def test_negative_wait_is_rejected():
    issues = _issues(_with_step(2, wait_before=-1.0))
    assert len(issues) == 1 and issues[0].endswith("steps[2].wait_before: must be >= 0, got -1.0")


@pytest.mark.parametrize("nan", ["NaN", "Infinity", "-Infinity"])
def test_non_finite_json_coordinate_is_rejected(nan):
    # GIVEN a waypoint x written as JSON's non-finite constant (what json.dumps writes for nan/inf)
    text = _with_step(1).replace('"x": 20.0', f'"x": {nan}', 1)
    assert nan in text
    # THEN it is rejected at that coordinate
    issues = _issues(text)
    assert len(issues) == 1 and "steps[1].waypoints[0].x: must be a finite number" in issues[0]


def test_non_finite_yaml_number_is_rejected():
    # GIVEN YAML (JSON's superset) with .nan as the takeoff altitude
    issues = _issues("steps:\n  - {type: takeoff, altitude_m: .nan}\n")
    # THEN it is rejected at that field and line
    assert issues == ["m.json:2: steps[0].altitude_m: must be a finite number, got nan"]


def test_unknown_field_is_rejected_with_the_allowed_ones():
    # GIVEN a misspelt key on a step
    issues = _issues(_with_step(0, altitude=12.0))
    # THEN the issue names it and says what is allowed
    assert len(issues) == 1 and "steps[0].altitude: unknown key 'altitude' (allowed: altitude_m," in issues[0]


def test_field_meaningless_for_the_step_type_is_rejected():
    # GIVEN a package on a cruise step (it would be silently ignored)
    issues = _issues(_with_step(1, package="parcel"))
    assert len(issues) == 1 and "steps[1].package: not used by a cruise step (used by: pickup)" in issues[0]


def test_climb_speed_above_8_m_s_is_an_error_not_a_clamp():
    # GIVEN a waypoint climbing at 9 m/s, and a mission default of 9 m/s
    doc = json.loads(json.dumps(GOOD))
    doc["climb_speed"] = 9.0
    doc["steps"][1]["waypoints"][1]["climb_speed"] = 9.0
    issues = _issues(json.dumps(doc))
    # THEN both are reported, the waypoint one with its step and field
    assert [i.split(": ", 1)[1] for i in issues] == [
        "climb_speed: must be <= 8, got 9.0",
        "steps[1].waypoints[1].climb_speed: must be <= 8, got 9.0",
    ]


def test_descent_and_cruise_speed_caps_are_5_and_30_m_s():
    doc = json.loads(json.dumps(GOOD))
    doc["descent_speed"], doc["cruise_speed"] = 5.0, 30.0
    assert parse_mission(json.dumps(doc)).descent_speed == 5.0
    doc["descent_speed"], doc["cruise_speed"] = 5.5, 31.0
    assert [i.split(": ", 1)[1] for i in _issues(json.dumps(doc))] == [
        "cruise_speed: must be <= 30, got 31.0", "descent_speed: must be <= 5, got 5.5"]


def test_empty_steps_is_rejected():
    assert _issues('{"steps": []}') == ["m.json:1: steps: must not be empty"]


def test_malformed_json_is_a_config_error_with_its_line():
    # GIVEN JSON with a missing comma on line 4
    text = '{\n  "steps": [\n    {"type": "takeoff"}\n    {"type": "land"}\n  ]\n}'
    # WHEN parsed THEN a ConfigError (no other exception type) gives line 4
    issues = _issues(text)
    assert len(issues) == 1 and issues[0].startswith("m.json:4: ") and "invalid JSON" in issues[0]


@pytest.mark.parametrize("text", ["", "42", '"takeoff"', "null", "[1, 2]", "a: &a [*a]", '{"steps": "takeoff"}'])
def test_text_that_is_not_a_mission_is_a_config_error(text):
    with pytest.raises(ConfigError):
        parse_mission(text)


def test_yaml_alias_bombs_are_refused_before_expansion():
    # GIVEN a few lines of YAML whose aliases would expand to 10^9 nodes
    text = "a: &a [x,x,x,x,x,x,x,x,x,x]\n"
    for prev, name in zip("abcdefgh", "bcdefghi"):
        text += f"{name}: &{name} [" + ",".join([f"*{prev}"] * 10) + "]\n"
    # THEN it is rejected at the first alias instead of being expanded
    assert _issues(text) == ["m.json:2: <root>: YAML anchors and aliases are not allowed in a mission"]


def test_deep_nesting_is_refused_at_the_nesting_limit():
    # GIVEN 20 000 nested lists (PyYAML's scanner is quadratic in flow depth, libyaml refuses more than
    # 1000 levels before its first event, json recurses)
    text = "[" * 20000 + "]" * 20000
    # WHEN parsed THEN it is refused at the mission's nesting limit, not as a parser's recursion failure
    assert _issues(text) == ["m.json:1: <root>: mission is nested more than 16 levels deep"]
    # AND so is a mission whose deep nesting starts on a later line, inside an object
    deep = '{"name": "x",\n "steps": ' + "[" * 1500 + "]" * 1500 + "}"
    assert _issues(deep) == ["m.json:2: <root>: mission is nested more than 16 levels deep"]


def test_all_issues_of_a_mission_are_reported_at_once():
    # GIVEN three independent mistakes in three steps
    doc = json.loads(json.dumps(GOOD))
    doc["steps"][0]["wait_after"] = -1
    doc["steps"][1]["waypoints"][0]["y"] = "north"
    doc["steps"][4]["type"] = "sleep"
    # THEN all three are reported, each at its step
    paths = [i.split(": ")[1] for i in _issues(json.dumps(doc))]
    assert paths == ["steps[0].wait_after", "steps[1].waypoints[0].y", "steps[4].type"]


def test_step_rules_hold_for_missions_built_in_python():
    # GIVEN / WHEN steps built directly that break a type rule THEN construction fails
    with pytest.raises(ValueError, match="idle step needs duration_s"):
        MissionStep(type="idle")
    with pytest.raises(ValueError, match="at most 1 waypoint"):
        MissionStep(type="takeoff", waypoints=[Waypoint(x=0, y=0, z=5), Waypoint(x=0, y=0, z=6)])
    with pytest.raises(ValueError, match="not used by a takeoff step"):
        MissionStep(type="takeoff", target_soc_frac=0.5)


# -- the paper's (Unity) format -----------------------------------------------------------------
PAPER = [
    {"movementId": 2, "x": 1.0, "y": 20.0, "z": 3.0, "yaw": 0.0, "speed": 2.0, "waitAfter": 1.5},
    {"movementId": 1, "x": 10.0, "y": 20.0, "z": 3.0, "yaw": 90.0, "speed": 7.0},
    {"movementId": 1, "x": 10.0, "y": 25.0, "z": 40.0, "yaw": 180.0, "waitAfter": 2.0},
    {"movementId": 3, "x": 10.0, "y": 0.0, "z": 40.0, "speed": 1.0},
    {"movementId": 4, "x": 12.0, "y": 0.0, "z": 41.0, "waitBefore": 0.5},
    {"movementId": 5, "x": -5.0, "y": 0.0, "z": -6.0},
]


def test_paper_mission_converts_axes_yaw_speeds_waits_and_merges_cruise_items():
    # GIVEN the paper's takeoff / cruise / cruise / land / pickup / deliver items
    # WHEN parsed
    spec = parse_mission(json.dumps(PAPER))
    # THEN the two cruise items are one cruise step, and every item has its step type
    assert [s.type for s in spec.steps] == ["takeoff", "cruise", "land", "pickup", "deliver"]
    takeoff, cruise, land, pickup, deliver = spec.steps
    # AND Unity (x right, y up, z forward=north) maps to ENU (x, z, y); the takeoff's y is its altitude
    # AND unity yaw (clockwise from north) 0 -> ENU 90, 90 -> 0, 180 -> -90
    # AND speed lands in climb / cruise / descent speed by step type
    assert takeoff.waypoints == [Waypoint(x=1.0, y=3.0, z=20.0, yaw_deg=90.0, climb_speed=2.0)]
    assert takeoff.wait_after == 1.5
    assert cruise.waypoints == [Waypoint(x=10.0, y=3.0, z=20.0, yaw_deg=0.0, cruise_speed=7.0),
                                Waypoint(x=10.0, y=40.0, z=25.0, yaw_deg=-90.0)]
    assert (cruise.wait_before, cruise.wait_after) == (0.0, 2.0)
    assert land.waypoints == [Waypoint(x=10.0, y=40.0, z=0.0, descent_speed=1.0)]
    assert pickup.waypoints == [Waypoint(x=12.0, y=41.0, z=0.0)] and pickup.package is None
    assert pickup.wait_before == 0.5
    assert deliver.waypoints == [Waypoint(x=-5.0, y=-6.0, z=0.0)]


def test_paper_wrappers_give_the_same_mission_as_a_bare_list():
    bare = parse_mission(json.dumps(PAPER))
    assert parse_mission(json.dumps({"missions": PAPER})) == bare
    assert parse_mission(json.dumps({"steps": PAPER})) == bare


def test_a_wait_inside_a_run_of_paper_cruise_items_splits_the_route_there():
    # GIVEN three cruise items, the middle one waiting 3 s after arriving
    items = [{"movementId": 1, "x": float(i), "y": 10.0, "z": 0.0} for i in range(3)]
    items[1]["waitAfter"] = 3.0
    # WHEN parsed
    steps = parse_mission(json.dumps(items)).steps
    # THEN the drone stops at the middle point: two cruise steps, the first waits 3 s after
    assert [len(s.waypoints) for s in steps] == [2, 1] and steps[0].wait_after == 3.0


def test_paper_yaw_wraps_into_minus_180_to_180():
    # GIVEN unity yaws 270 and -90 (both facing west, ENU 180) and 45 (north-east)
    items = [{"movementId": 1, "x": 0.0, "y": 5.0, "z": float(i), "yaw": yaw} for i, yaw in enumerate((270.0, -90.0, 45.0))]
    yaws = [wp.yaw_deg for wp in parse_mission(json.dumps(items)).steps[0].waypoints]
    # THEN they are in (-180, 180]
    assert yaws == [180.0, 180.0, 45.0]


def test_unknown_movement_id_is_rejected_naming_the_item():
    # GIVEN a paper mission whose 4th item has movementId 7
    items = json.loads(json.dumps(PAPER))
    items[3]["movementId"] = 7
    issues = _issues(json.dumps(items, indent=1))
    # THEN the issue names that item and lists the known ids
    assert len(issues) == 1
    assert "steps[3].movementId: unknown movementId 7 (expected one of: 1 cruise, 2 takeoff, 3 land" in issues[0]


def test_paper_speed_above_the_step_cap_is_rejected_naming_the_item():
    # GIVEN a takeoff item climbing at 9 m/s
    items = json.loads(json.dumps(PAPER))
    items[0]["speed"] = 9.0
    issues = _issues(json.dumps({"missions": items}))
    assert len(issues) == 1 and "missions[0].speed: must be <= 8" in issues[0]


def test_paper_item_with_a_non_finite_coordinate_is_rejected():
    text = json.dumps(PAPER).replace('"z": 40.0', '"z": NaN', 1)
    issues = _issues(text)
    assert len(issues) == 1 and "steps[2].z: must be a finite number" in issues[0]


# -- writing ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("text", [json.dumps(GOOD), json.dumps(PAPER)])
def test_mission_to_json_round_trips(text):
    # GIVEN a parsed mission (ours, and one converted from the paper's format)
    spec = parse_mission(text)
    # WHEN written and read back
    again = parse_mission(mission_to_json(spec))
    # THEN it is the same mission
    assert again == spec


def test_mission_to_json_round_trips_numbers_json_writes_in_exponent_form():
    # GIVEN coordinates that JSON writes as 1e-07 and -1e-05 (YAML 1.1 would read those as strings)
    spec = MissionSpec(steps=[MissionStep(type="cruise", waypoints=[Waypoint(x=1e-7, y=-1e-5, z=3.0)])])
    # THEN they come back as the same numbers
    assert parse_mission(mission_to_json(spec)) == spec


def test_the_readme_mission_example_parses():
    readme = (REPO_ROOT / "README.md").read_text(encoding="utf-8")
    block = readme.split("```json\n", 1)[1].split("```", 1)[0]
    spec = parse_mission(block, source="README.md")
    assert [s.type for s in spec.steps] == ["pickup", "takeoff", "cruise", "land", "deliver", "recharge", "idle"]
    assert spec.steps[2].pad == "roof_1" and spec.steps[2].waypoints[0].cruise_speed == 6.0

