"""unetyemu_ecs: mixed fleets of drones and ground vehicles in urban worlds (public API)."""

from .app import RunStats, Simulation
from .config.schema import ConfigError
from .config.world_file import WorldDefinition, load_world, load_world_text
from .phases import Phase
from .plugins import ComponentPlugin, Registry, SensorPlugin, SystemPlugin
from .world import StepContext

__all__ = [
    "ComponentPlugin",
    "ConfigError",
    "Phase",
    "Registry",
    "RunStats",
    "SensorPlugin",
    "Simulation",
    "StepContext",
    "SystemPlugin",
    "WorldDefinition",
    "load_world",
    "load_world_text",
]
__version__ = "0.1.0"
