"""Every number of a world or mission file has a physically meaningful range, input is bounded before it
is parsed, and worlds that would blow up at t = 0 (bodies inside buildings, missions naming nothing) are
refused at load with file:line."""

from __future__ import annotations

import dataclasses
import json
import os
import re
import types
from typing import Annotated, Any, Literal, Union, get_args, get_origin, get_type_hints

import pytest

from unetyemu_ecs import ConfigError, load_world, load_world_text
from unetyemu_ecs.config.limits import MAX_WORLD_FILE_BYTES
from unetyemu_ecs.config.schema import Each, Ge, Gt, Le, Lt
from unetyemu_ecs.config.world_file import WorldFile
from unetyemu_ecs.mission import parse_mission
from unetyemu_ecs.plugins import Registry

from ..conftest import WORLDS

BASE = """\
world: {name: t, physics_hz: 240}
scene:
  generator: none
  pads:
    - {name: home, position_m: [0, 0]}
  buildings:
    - {name: tower, center_m: [20, 0], size_m: [10, 10], height_m: 30}
packages:
  - {name: p1, mass_kg: 1.0, pose: {pad: home, offset_m: [1, 0]}}
vehicles:
  - name: d1
    type: quadrotor
    preset: small
    pose: {pad: home}
"""


def _issues(text: str) -> list[str]:
    with pytest.raises(ConfigError) as info:
        load_world_text(text, "w.yaml")
    return [str(i) for i in info.value.issues]


def _one_issue(text: str) -> str:
    issues = _issues(text)
    assert len(issues) == 1, issues
    return issues[0]


def test_the_base_world_loads():
    assert [v.name for v in load_world_text(BASE).vehicles] == ["d1"]


# ---------------------------------------------------------------------------------------------
# Every numeric field has both bounds
# ---------------------------------------------------------------------------------------------
def _unbounded(tp: Any, where: str, inherited: tuple = ()) -> list[str]:
    """Numeric leaves of a schema type lacking a lower or an upper bound."""
    origin = get_origin(tp)
    if origin is Annotated:
        base, *markers = get_args(tp)
        each = tuple(m.inner for m in markers if isinstance(m, Each))
        direct = tuple(m for m in markers if not isinstance(m, Each))
        if get_origin(base) in (tuple, list):
            return _unbounded(base, where, inherited + each)
        return _unbounded(base, where, inherited + direct)
    if origin in (Union, types.UnionType):
        return [p for a in get_args(tp) if a is not type(None) for p in _unbounded(a, where, inherited)]
    if origin in (tuple, list):
        return [p for a in get_args(tp) if a is not Ellipsis for p in _unbounded(a, where + "[]", inherited)]
    if origin is dict:
        return _unbounded(get_args(tp)[1], where + "{}", inherited)
    if origin is Literal or tp is bool or tp is str or tp is Any:
        return []
    if tp in (int, float):
        low = any(isinstance(m, (Ge, Gt)) for m in inherited)
        high = any(isinstance(m, (Le, Lt)) for m in inherited)
        return [] if low and high else [f"{where}: {'no lower bound' if not low else 'no upper bound'}"]
    if dataclasses.is_dataclass(tp):
        hints = get_type_hints(tp, include_extras=True)
        return [p for f in dataclasses.fields(tp) if f.init
                for p in _unbounded(hints[f.name], f"{tp.__name__}.{f.name}")]
    return []


def test_every_number_of_the_world_schema_and_of_every_component_and_sensor_has_a_range():
    # GIVEN the world schema and every installed component, sensor and world system
    registry = Registry.discover()
    schemas = [WorldFile]
    for entries in registry.entries.values():
        for entry in entries.values():
            schemas.append(getattr(entry.spec, "component", None) or getattr(entry.spec, "config", None))
    # THEN every integer and float in them has a lower and an upper bound
    missing = sorted({p for cls in schemas if cls is not None for p in _unbounded(cls, cls.__name__)})
    assert missing == []


# ---------------------------------------------------------------------------------------------
# Item 10: values that validated but blew up later
# ---------------------------------------------------------------------------------------------
URBAN = """\
world: {name: city}
scene:
  generator: urban
  urban: {blocks_x: 2, blocks_y: 2}
"""

CAR_ROUTE = """\
world: {name: t}
scene: {generator: none}
vehicles:
  - name: c1
    type: car
    pose: {position_m: [0, 0, 1.31]}
    components:
      route: {loop: true, laps: LAPS, waypoints: [{x: 10, y: 0}, {x: 10, y: 10}, {x: 0, y: 10}]}
"""


@pytest.mark.parametrize("text, expected", [
    (URBAN.replace("blocks_x: 2", "blocks_x: 1000"), "w.yaml:4: scene.urban.blocks_x: must be <= 16, got 1000"),
    (URBAN.replace("blocks_x: 2", "block_size_m: 1180591620717411303424"),
     "w.yaml:4: scene.urban.block_size_m: must be <= 500, got 1.1805916207174113e+21"),
    (URBAN.replace("blocks_x: 2", "tree_spacing_m: 0.000001"), "w.yaml:4: scene.urban.tree_spacing_m: must be >= 2"),
    (CAR_ROUTE.replace("LAPS", str(2**70)), "w.yaml:8: vehicles[0].components.route.laps: must be <= 10000"),
    (BASE.replace("pose: {pad: home}", "pose: {pad: home}\n    components: {camera: {width: 20000, height: 480}}"),
     "w.yaml:15: vehicles[0].components.camera.width: must be <= 1920, got 20000"),
    (BASE.replace("pose: {pad: home}", "pose: {position_m: [1.0e+300, 0, 10]}"),
     "w.yaml:14: vehicles[0].pose.position_m[0]: must be <= 20000, got 1e+300"),
    (BASE.replace("pose: {pad: home}", "pose: {position_m: [0, 0, -1000000]}"),
     "w.yaml:14: vehicles[0].pose.position_m[2]: must be >= -100, got -1000000.0"),
    (BASE.replace("physics_hz: 240", "physics_hz: 0.001"), "w.yaml:1: world.physics_hz: must be >= 50, got 0.001"),
    (BASE.replace("physics_hz: 240", "duration_s: 1.0e+300"), "w.yaml:1: world.duration_s: must be <= 604800"),
    (BASE.replace("name: d1", "name: d" + "x" * 5000),
     "w.yaml:11: vehicles[0].name: must have at most 64 characters, got 5001"),
    (BASE.replace("mass_kg: 1.0", "mass_kg: " + "9" * 400),
     "w.yaml:9: packages[0].mass_kg: must be a finite number, got an integer beyond 1.8e308"),
], ids=["blocks_x", "block_size_m", "tree_spacing_m", "laps", "camera", "position_x", "position_z", "physics_hz",
        "duration_s", "long_name", "huge_int"])
def test_values_that_used_to_blow_up_at_run_time_are_refused_at_load(text, expected):
    # WHEN a world with the value is loaded THEN the one issue names the file, line, key and range
    assert _one_issue(text).startswith(expected)


def test_mission_waypoints_must_lie_in_the_world():
    mission = "{steps: [{type: takeoff}, {type: cruise, waypoints: [{x: 1.0e+308, y: 0, z: 10}]}]}"
    text = BASE.replace("pose: {pad: home}", f"pose: {{pad: home}}\n    components:\n      mission: {mission}")
    assert _one_issue(text).startswith("w.yaml:16: vehicles[0].components.mission.steps[1].waypoints[0].x: "
                                       "must be <= 20000, got 1e+308")
    with pytest.raises(ConfigError, match=r"steps\[0\].waypoints\[0\].z: must be <= 10000"):
        parse_mission('{"steps": [{"type": "cruise", "waypoints": [{"x": 0, "y": 0, "z": 1e308}]}]}')


def test_a_100k_step_mission_is_refused_by_its_size_before_it_is_parsed():
    steps = [{"type": "idle", "duration_s": 1.0}] * 100_000
    with pytest.raises(ConfigError, match="mission text is longer than 1048576 characters"):
        parse_mission(json.dumps({"steps": steps}))
    # AND a mission that fits the text limit but has too many steps is refused before its steps are read
    with pytest.raises(ConfigError, match="steps: must have at most 1000 elements, got 2000"):
        parse_mission(json.dumps({"steps": [{"type": "land"}] * 2000}))


# ---------------------------------------------------------------------------------------------
# Item 9: bounded input
# ---------------------------------------------------------------------------------------------
def test_a_yaml_alias_bomb_in_a_world_is_refused_before_it_is_expanded():
    lines = ["a0: &a0 [x, x, x, x, x, x, x, x, x, x]"]
    lines += [f"a{k}: &a{k} [*a{k - 1}, *a{k - 1}, *a{k - 1}, *a{k - 1}, *a{k - 1}, *a{k - 1}, *a{k - 1}, "
              f"*a{k - 1}, *a{k - 1}, *a{k - 1}]" for k in range(1, 9)]
    issue = _one_issue("\n".join(lines) + "\n")
    assert issue.startswith("w.yaml:6: <root>: world file has more than 200000 values (after expanding aliases)")


def test_a_self_referencing_anchor_is_refused():
    assert _one_issue("world: &w {name: t, again: *w}\n") == (
        "w.yaml:1: <root>: alias *w refers to its own anchor (a structure that contains itself)")


def test_500_levels_of_nesting_are_refused_without_recursion_error():
    assert _one_issue("world: " + "[" * 500 + "]" * 500 + "\n") == (
        "w.yaml:1: <root>: world file is nested more than 32 levels deep")
    block = "".join("  " * k + f"k{k}:\n" for k in range(500)) + "  " * 500 + "v: 1\n"
    assert _one_issue(block) == "w.yaml:33: <root>: world file is nested more than 32 levels deep"


def test_a_small_anchor_for_shared_component_blocks_still_works():
    # GIVEN two drones sharing their sensor block through an anchor
    text = BASE + """\
    components: &sensors {imu: {rate_hz: 50.0}, gps: {}}
  - name: d2
    type: quadrotor
    preset: small
    pose: {position_m: [0, 5, 0.1]}
    components: *sensors
"""
    world = load_world_text(text)
    # THEN both carry the same sensors
    assert [v.components["imu"].rate_hz for v in world.vehicles] == [50.0, 50.0]


def test_dev_zero_and_a_fifo_are_refused_without_hanging(tmp_path):
    with pytest.raises(ConfigError, match=r"^/dev/zero: <root>: is larger than 1048576 bytes"):
        load_world("/dev/zero")
    fifo = tmp_path / "fifo.yaml"
    os.mkfifo(fifo)
    with pytest.raises(ConfigError, match=r"is a FIFO \(named pipe\); a world file must be a regular file"):
        load_world(fifo)
    with pytest.raises(ConfigError, match=r"is a directory"):
        load_world(tmp_path)


def test_a_file_over_the_size_limit_is_refused_before_parsing(tmp_path):
    big = tmp_path / "trees.yaml"
    tree = "    - {position_m: [1.0, 2.0]}\n"
    big.write_text("scene:\n  trees:\n" + tree * (MAX_WORLD_FILE_BYTES // len(tree) + 1))
    with pytest.raises(ConfigError, match=r"trees.yaml: <root>: is larger than 1048576 bytes"):
        load_world(big)


def test_too_many_scene_objects_are_refused_before_the_scene_is_built():
    trees = "".join(f"    - {{position_m: [{k % 100}, {k // 100}]}}\n" for k in range(20_001))
    issue = _one_issue("scene:\n  generator: none\n  trees:\n" + trees)
    assert issue.startswith("w.yaml:3: scene.trees: must have at most 20000 elements, got 20001")
    issue = _one_issue(URBAN.replace("blocks_x: 2, blocks_y: 2", "blocks_x: 16, blocks_y: 16, block_size_m: 400"))
    assert issue.startswith("w.yaml:4: scene.urban: this city could hold up to")


# ---------------------------------------------------------------------------------------------
# Item 11: semantic checks at load
# ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize("text", ["", "# only a comment\n\n# and another\n", "---\n", "{}\n"])
def test_an_empty_world_file_is_an_error(text):
    assert re.match(r"w\.yaml(:\d+)?: <root>: the world file is empty", _one_issue(text))


def test_dev_null_is_an_empty_world_file():
    with pytest.raises(ConfigError, match=r"^/dev/null: <root>: the world file is empty"):
        load_world("/dev/null")


def test_a_mission_naming_a_missing_pad_or_package_fails_at_load_with_its_line():
    mission = """\
      mission:
        steps:
          - {type: pickup, package: nope}
          - {type: takeoff}
          - {type: land, pad: nowhere}
"""
    text = BASE.replace("pose: {pad: home}", "pose: {pad: home}\n    components:\n" + mission)
    assert _issues(text) == [
        "w.yaml:18: vehicles[0].components.mission.steps[0].package: unknown package 'nope' "
        "(packages in this world: p1)",
        "w.yaml:20: vehicles[0].components.mission.steps[2].pad: unknown pad 'nowhere' (pads in this world: home)"]


def test_a_vehicle_inside_a_building_is_refused_naming_the_building():
    text = BASE.replace("pose: {pad: home}", "pose: {position_m: [20, 0, 10]}")
    assert _one_issue(text).startswith("w.yaml:14: vehicles[0].pose: d1 starts inside building 'tower'")


def test_a_vehicle_underground_is_refused():
    text = BASE.replace("pose: {pad: home}", "pose: {position_m: [-10, -10, -2]}")
    assert _one_issue(text).startswith("w.yaml:14: vehicles[0].pose: d1 starts underground: its bottom is at "
                                       "z = -2.08 m")


def test_a_car_sunk_into_the_ground_is_refused():
    # the car's wheels reach 1.1 m below its centre (0.7 m half height + 0.2 m clearance + ...)
    text = CAR_ROUTE.replace("LAPS", "1").replace("[0, 0, 1.31]", "[0, 0, 0.5]")
    assert _one_issue(text).startswith("w.yaml:6: vehicles[0].pose: c1 starts underground")


def test_overlapping_bodies_are_refused_naming_both():
    text = BASE + """\
  - name: d2
    type: quadrotor
    preset: small
    pose: {pad: home, offset_m: [0.2, 0.0]}
"""
    assert _one_issue(text) == "w.yaml:18: vehicles[1].pose: d2 overlaps d1 at spawn (vehicles[0], line 11)"
    on_package = BASE.replace("pose: {pad: home}", "pose: {pad: home, offset_m: [1.1, 0.1]}")
    assert _one_issue(on_package) == "w.yaml:9: packages[0].pose: p1 overlaps d1 at spawn (vehicles[0], line 11)"


def test_bodies_standing_side_by_side_on_a_pad_and_parked_cars_load():
    # GIVEN the shipped delivery world: a drone and a package on one pad, cars on parking spots, a truck on the road
    world = load_world(WORLDS / "urban_delivery.yaml")
    # THEN it loads with every body
    assert len(world.vehicles) == 7 and len(world.packages) == 1


def test_a_vehicle_off_the_edge_of_the_ground_is_refused():
    text = BASE.replace("pose: {pad: home}", "pose: {position_m: [5000, 0, 2]}")
    assert _one_issue(text).startswith("w.yaml:14: vehicles[0].pose: d1 starts off the ground at (5000, 0) m")
