"""Every code block of the README runs as written: Python is executed, world files load, missions
parse and name things that exist, and each shell block is run here or by the test named for it."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys

import pytest

from unetyemu_ecs import load_world_text
from unetyemu_ecs.mission import mission_reference_issues, parse_mission
from unetyemu_ecs.plugins import GROUP_SYSTEMS, Registry

from ..conftest import REPO_ROOT, WORLDS

README = (REPO_ROOT / "README.md").read_text(encoding="utf-8")
BLOCKS = [(m.group(1), m.group(2)) for m in re.finditer(r"^```(\w*)\n(.*?)^```", README, re.S | re.M)]

# shell blocks checked elsewhere, by what they start with -> the test that runs them
SHELL_BLOCKS_TESTED_BY = {
    "apt-get update": "tests/install (the test command is what .ci/run runs; the first command: slow test)",
    "# load and start a mission": "tests/integration/test_ros2_readme.py (each ros2 topic pub sent to a running "
                                  "simulation by a DDS peer)",
    "export RMW_IMPLEMENTATION": "tests/integration/test_ros2_*.py (discovery and topics by DDS peers; "
                                            "ros2 and rviz2 themselves need a ROS 2 install)",
    "unetyemu run worlds/urban_delivery.yaml --view --foxglove --record": "tests/integration/test_view.py, "
        "test_foxglove.py and test_record.py (each switch through the CLI on a free port or a temporary path; "
        "the replay command on a recording)",
    "unetyemu run worlds/mavlink_pair.yaml": "tests/integration/test_mavlink_clients.py (the world with both "
                                             "examples; the MAVSDK flight is a slow test)",
    "unetyemu sweep worlds/parcel_sweep.yaml": "tests/integration/test_sweep.py (the worked example as written: a "
                                              "slow test; smaller sweeps of the same world in the default run)",
    "ray start --head": "tests/integration/test_sweep.py (a head from `ray start --head` on a free loopback port "
                        "and a sweep given its --address; joining a second machine is not tested)",
}


def blocks(lang: str) -> list[str]:
    return [code for kind, code in BLOCKS if kind == lang]


def registry_with_example_plugin() -> Registry:
    """The installed plugins plus plugins/wind_gust (the README's world example uses it)."""
    reg = Registry.discover()
    if "wind_gust" not in reg.entries[GROUP_SYSTEMS]:
        sys.path.insert(0, str(REPO_ROOT / "plugins" / "wind_gust"))
        try:
            import unetyemu_wind_gust
        finally:
            sys.path.pop(0)
        reg.add(GROUP_SYSTEMS, "wind_gust", unetyemu_wind_gust.WIND_GUST, "plugins/wind_gust")
    return reg


def test_every_block_has_a_language_and_every_shell_block_is_covered():
    assert all(kind for kind, _ in BLOCKS), "a README code block without a language"
    for code in blocks("sh"):
        first = code.lstrip().splitlines()[0]
        assert any(first.startswith(k) for k in SHELL_BLOCKS_TESTED_BY), f"no test runs this README block:\n{code}"
    assert blocks("python") and blocks("yaml") and blocks("json")


@pytest.mark.parametrize("code", blocks("yaml"), ids=lambda c: c.split("\n", 1)[0][:40])
def test_every_yaml_block_is_a_world_file_that_loads(code):
    world = load_world_text(code, file="README.md", registry=registry_with_example_plugin())
    assert world.vehicles


@pytest.mark.parametrize("code", blocks("json"), ids=lambda c: c.split("\n", 1)[0][:40])
def test_every_json_block_is_a_mission_for_the_delivery_world(code):
    world = load_world_text((WORLDS / "urban_delivery.yaml").read_text(), file="urban_delivery.yaml")
    spec = parse_mission(code, source="README.md")
    assert mission_reference_issues(spec, world.layout, [p.name for p in world.packages]) == []


@pytest.mark.parametrize("code", blocks("python"), ids=lambda c: c.split("\n", 1)[0][:40])
def test_every_python_block_runs_as_written(code, tmp_path):
    # GIVEN a fresh folder that looks like the repository's top (worlds/ and examples/ in it)
    for name in ("worlds", "examples"):
        (tmp_path / name).symlink_to(REPO_ROOT / name)
    # WHEN the block runs there as a script
    res = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True, timeout=900,
                         env={**os.environ, "PYTHONPATH": str(REPO_ROOT)})
    # THEN it succeeds; if it wrote a run directory, the summary says no vehicle hit anything and no
    # command it sent was rejected or warned about
    assert res.returncode == 0, res.stderr
    for summary_path in tmp_path.glob("runs/*/summary.json"):
        summary = json.loads(summary_path.read_text())
        assert all(e["impacts"] == 0 for e in summary["entities"]), summary["events"]
        bad = [e for e in summary["events"] if e["text"].startswith(("rejected", "warning"))]
        assert bad == [], bad
    if "street_hop" in code:             # the API example: what its comments promise
        assert "'mission': 'street_hop'" in res.stdout and "'state': 'running'" in res.stdout
        assert re.search(r"^\d+ LiDAR points$", res.stdout, re.M)
        summary = json.loads((tmp_path / "runs" / "demo" / "summary.json").read_text())
        assert summary["sim_time_s"] == pytest.approx(30.0 + 1 / 240)
        assert {p.stem for p in (tmp_path / "runs" / "demo").glob("*.csv")} >= {"drone1", "drone2", "drone3", "car2"}
