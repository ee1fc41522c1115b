"""unetyemu_ecs: mixed fleets of drones and ground vehicles in urban worlds (public API).

Names are imported lazily so that light commands (``unetyemu validate``) do not load PyBullet.
"""

from __future__ import annotations

import importlib
from typing import Any

_EXPORTS = {
    "Simulation": "app",
    "RunStats": "app",
    "ConfigError": "config.schema",
    "WorldDefinition": "config.world_file",
    "load_world": "config.world_file",
    "load_world_text": "config.world_file",
    "Phase": "phases",
    "ComponentPlugin": "plugins",
    "Registry": "plugins",
    "SensorPlugin": "plugins",
    "SystemPlugin": "plugins",
    "StepContext": "world",
}

__all__ = sorted(_EXPORTS)
__version__ = "0.1.0"


def __getattr__(name: str) -> Any:
    if name in _EXPORTS:
        return getattr(importlib.import_module(f".{_EXPORTS[name]}", __name__), name)
    raise AttributeError(f"module 'unetyemu_ecs' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted([*globals(), *_EXPORTS])
