"""Vehicle presets read from ``params/*.toml`` (each file cites its sources).

A preset is a table of body parameters (``mass_kg``, ``body_half_extents_m``, ``rgba``...) plus one
sub-table per built-in component (``motors``, ``energy``...). ``[defaults.<component>]`` tables apply
to every preset of the file and are overridden by the preset's own sub-table.
"""

from __future__ import annotations

import copy
import tomllib
from functools import cache
from importlib import resources
from typing import Any

VEHICLE_TYPES = ("quadrotor", "car")


@cache
def _read(vehicle_type: str) -> dict[str, Any]:
    if vehicle_type not in VEHICLE_TYPES:
        raise ValueError(f"unknown vehicle type {vehicle_type!r} (expected one of: {', '.join(VEHICLE_TYPES)})")
    text = resources.files("unetyemu_ecs.vehicles").joinpath("params", f"{vehicle_type}.toml").read_text("utf-8")
    return tomllib.loads(text)


def presets_for(vehicle_type: str) -> list[str]:
    """Names of the presets of ``vehicle_type``, sorted."""
    return sorted(k for k in _read(vehicle_type) if k != "defaults")


def preset(vehicle_type: str, name: str) -> dict[str, Any]:
    """Return a fresh copy of preset ``name`` with the file's defaults merged into its component tables."""
    table = _read(vehicle_type)
    if name not in table or name == "defaults":
        raise ValueError(f"unknown {vehicle_type} preset {name!r} (expected one of: "
                         f"{', '.join(presets_for(vehicle_type))})")
    out = copy.deepcopy(table[name])
    for comp, values in table.get("defaults", {}).items():
        merged = copy.deepcopy(values)
        merged.update(out.get(comp, {}))
        out[comp] = merged
    return out


def component_tables(params: dict[str, Any]) -> dict[str, dict[str, Any]]:
    """The component sub-tables of a preset (``{key: values}``)."""
    return {k: v for k, v in params.items() if isinstance(v, dict)}
