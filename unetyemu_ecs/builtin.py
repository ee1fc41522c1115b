"""Built-in parts, registered through this project's own entry points exactly like plugins."""

from __future__ import annotations

from .components.aero import AeroDrag
from .plugins import ComponentPlugin
from .systems.actuate import AeroDragSystem

AERO_DRAG = ComponentPlugin(
    component=AeroDrag,
    systems=(AeroDragSystem,),
    summary="quadratic air drag per body axis, relative to the local wind",
)
