"""The files in examples/ work as their comments say."""

from __future__ import annotations

import subprocess
import sys

import pytest

from unetyemu_ecs import load_world
from unetyemu_ecs.mission import mission_reference_issues, parse_mission

from ..conftest import REPO_ROOT, WORLDS

EXAMPLES = REPO_ROOT / "examples"


@pytest.mark.parametrize("name", sorted(p.name for p in (EXAMPLES / "missions").glob("*.json")))
def test_example_missions_parse_and_name_only_what_the_delivery_world_has(name):
    world = load_world(WORLDS / "urban_delivery.yaml")
    spec = parse_mission((EXAMPLES / "missions" / name).read_text(), source=name)
    assert spec.steps[0].type == "takeoff" and spec.steps[-1].type == "land"
    assert mission_reference_issues(spec, world.layout, [p.name for p in world.packages]) == []


def test_the_paper_format_example_converts_unity_axes_to_enu():
    spec = parse_mission((EXAMPLES / "missions" / "paper_format.json").read_text())
    # Unity (x right, y up, z forward=north): item 2 at x=-115.6, y=15, z=-72 -> ENU (-115.6, -72, 15)
    cruise = spec.steps[1]
    assert cruise.type == "cruise" and (cruise.waypoints[0].x, cruise.waypoints[0].y, cruise.waypoints[0].z) == \
        (-115.6, -72.0, 15.0)
    assert cruise.waypoints[1].yaw_deg == 0.0          # Unity yaw 90 (east, clockwise from north) = ENU 0


@pytest.mark.slow
def test_api_quickstart_flies_the_street_hop_to_completion(tmp_path):
    res = subprocess.run([sys.executable, str(EXAMPLES / "api_quickstart.py")], cwd=tmp_path, capture_output=True,
                         text=True, timeout=1200)
    assert res.returncode == 0, res.stderr
    assert "drone3: completed" in res.stdout
    runs = list((tmp_path / "runs").glob("quickstart-*/summary.json"))
    assert len(runs) == 1
