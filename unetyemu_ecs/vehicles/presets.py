"""Vehicle presets read from ``params/*.toml`` (each file cites its sources)."""

from __future__ import annotations

import tomllib
from functools import cache
from importlib import resources
from typing import Any

VEHICLE_TYPES = ("quadrotor", "car")


@cache
def presets_for(vehicle_type: str) -> dict[str, dict[str, Any]]:
    """Return ``{preset name: parameters}`` for ``vehicle_type`` (read once, then cached)."""
    if vehicle_type not in VEHICLE_TYPES:
        raise ValueError(f"unknown vehicle type {vehicle_type!r} (expected one of: {', '.join(VEHICLE_TYPES)})")
    text = resources.files("unetyemu_ecs.vehicles").joinpath("params", f"{vehicle_type}.toml").read_text("utf-8")
    return tomllib.loads(text)


def preset(vehicle_type: str, name: str) -> dict[str, Any]:
    """Return the parameters of preset ``name``; ``ValueError`` listing the known ones otherwise."""
    table = presets_for(vehicle_type)
    if name not in table:
        raise ValueError(f"unknown {vehicle_type} preset {name!r} (expected one of: {', '.join(sorted(table))})")
    return dict(table[name])
