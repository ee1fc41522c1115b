"""The public plugin API: one module exports what a plugin may use, and the example plugins use nothing else."""

from __future__ import annotations

import ast

import pytest

import unetyemu_ecs.plugin_api as api

from ..conftest import REPO_ROOT


def test_every_exported_name_exists():
    missing = [name for name in api.__all__ if not hasattr(api, name)]
    assert missing == []


@pytest.mark.parametrize("plugin", ["wind_gust", "px4_attitude"])
def test_the_example_plugins_import_only_the_public_plugin_api(plugin):
    imported = set()
    for path in (REPO_ROOT / "plugins" / plugin).glob("unetyemu_*/*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("unetyemu_ecs"):
                imported.add(node.module)
            elif isinstance(node, ast.Import):
                imported |= {a.name for a in node.names if a.name.startswith("unetyemu_ecs")}
    assert imported == {"unetyemu_ecs.plugin_api"}


def test_rows_and_vehicle_names_map_both_ways():
    from unetyemu_ecs import Simulation, load_world_text

    world = """
scene: {generator: none}
packages:
  - {name: box, mass_kg: 1.0, pose: {position_m: [3.0, 0.0, 0.15]}}
vehicles:
  - {name: d1, type: quadrotor, pose: {position_m: [0.0, 0.0, 0.09]}}
"""
    with Simulation(load_world_text(world)) as sim:
        ctx = sim._context()
        for name in ("d1", "box"):
            assert api.vehicle_of_row(ctx, api.row_of_vehicle(ctx, name)) == name
        with pytest.raises(KeyError):
            api.row_of_vehicle(ctx, "nobody")
