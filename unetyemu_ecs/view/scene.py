"""The static part of the view: the city as one coloured triangle mesh, and how each vehicle looks.

The city is :func:`unetyemu_ecs.scene.mesh.triangulate` of the world's layout, sent once per page
as a binary ``mesh`` message (ENU vertices, indices, one RGB per triangle from the scene classes'
colours, :func:`unetyemu_ecs.scene.colors.class_rgb`); the page builds one three.js geometry from it.
The ground slab is left out: the page draws the ground as a large plane a little below z = 0, since
the roads' tops lie only millimetres above the slab's and would flicker against it from afar.
Vehicles are described by their world-file definition: kind, colour and body half extents, and the
sensors the page can show (``lidar``, ``camera``, ``depth_camera``).
"""

from __future__ import annotations

import threading
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..scene.colors import SCENE_RGBA, class_rgb
from ..scene.primitives import SceneClass
from . import wire

VIEW_SENSORS = ("lidar", "camera", "depth_camera")      # sensor keys the page shows
DEFAULT_RGB = (0.8, 0.8, 0.8)
DEFAULT_HALF_EXTENTS_M = {"quadrotor": (0.25, 0.25, 0.08), "car": (2.25, 0.9, 0.7)}


@dataclass(frozen=True)
class VehicleLook:
    """How the page draws a vehicle: kind (``quadrotor``, ``car``, or ``vehicle`` when unknown), RGB in
    [0, 1], body half extents [m] along FLU, and the sensors it carries that the page can show."""

    name: str
    kind: str
    rgb: tuple[float, float, float] = DEFAULT_RGB
    half_extents_m: tuple[float, float, float] = (0.5, 0.5, 0.5)
    sensors: tuple[str, ...] = ()

    def as_json(self) -> dict[str, Any]:
        return {"name": self.name, "kind": self.kind, "rgb": list(self.rgb), "half_extents_m": list(self.half_extents_m),
                "sensors": list(self.sensors)}


@dataclass
class SceneInfo:
    """The world as the page needs it once: its name, the city (None: ground only), the vehicles."""

    world: str
    layout: Any | None
    vehicles: Sequence[VehicleLook]
    note: str = ""                                  # shown by the page (e.g. why there is no city)
    _mesh: bytes | None = field(default=None, repr=False)
    _bounds: list[list[float]] | None = field(default=None, repr=False)
    _lock: threading.Lock = field(default_factory=threading.Lock, repr=False)

    def _build(self) -> None:
        from ..scene.mesh import triangulate

        if self.layout is not None:
            mesh = triangulate(self.layout)
            keep = mesh.cls != int(SceneClass.GROUND)       # the page draws the ground as a plane of its own
            vertices = np.ascontiguousarray(mesh.vertices_m, dtype="<f4")
            triangles = np.ascontiguousarray(mesh.triangles[keep], dtype="<u4")
            rgb = np.clip(class_rgb()[mesh.cls[keep].astype(np.intp)] * 255.0 + 0.5, 0, 255).astype(np.uint8)
        else:
            vertices, triangles = np.zeros((0, 3), "<f4"), np.zeros((0, 3), "<u4")
            rgb = np.zeros((0, 3), np.uint8)
        colours = rgb.tobytes() + b"\0" * (-rgb.size % 4)
        self._mesh = wire.binary({"type": "mesh", "vertices": len(vertices), "triangles": len(triangles)},
                                 vertices.tobytes(), triangles.tobytes(), colours)
        if len(vertices):
            lo, hi = vertices.min(axis=0).astype(float), vertices.max(axis=0).astype(float)
        else:
            lo, hi = np.array([-100.0, -100.0, 0.0]), np.array([100.0, 100.0, 10.0])
        self._bounds = [[round(float(v), 2) for v in lo], [round(float(v), 2) for v in hi]]

    def mesh_message(self) -> bytes:
        """The binary ``mesh`` message (built once, on first use)."""
        with self._lock:
            if self._mesh is None:
                self._build()
            return self._mesh  # type: ignore[return-value]

    def scene_message(self, mode: str, **extra: Any) -> str:
        """The ``scene`` text message for a page of this ``mode`` (``live`` / ``replay``)."""
        self.mesh_message()
        msg = {"type": "scene", "protocol": wire.PROTOCOL_VERSION, "mode": mode, "world": self.world,
               "bounds_m": self._bounds, "ground_rgb": list(SCENE_RGBA["ground"][:3]),
               "vehicles": [v.as_json() for v in self.vehicles], "note": self.note}
        msg.update(extra)
        return wire.text(msg)


def vehicle_look(entity: Any) -> VehicleLook:
    """The look of a world file's vehicle (an ``EntityDefinition``)."""
    params = entity.params or {}
    rgb = tuple(float(c) for c in params.get("rgba", DEFAULT_RGB)[:3])
    half = params.get("body_half_extents_m") or DEFAULT_HALF_EXTENTS_M.get(entity.kind, (0.5, 0.5, 0.5))
    sensors = tuple(key for key in VIEW_SENSORS if key in entity.components)
    return VehicleLook(entity.name, entity.kind, rgb, tuple(float(v) for v in half), sensors)   # type: ignore[arg-type]


def scene_from_world(world: Any, note: str = "") -> SceneInfo:
    """The scene of a ``WorldDefinition``: its city and its vehicles (packages are not drawn)."""
    return SceneInfo(world.name, world.layout, [vehicle_look(e) for e in world.entities if e.kind != "package"], note)


__all__ = ["DEFAULT_HALF_EXTENTS_M", "SceneInfo", "VIEW_SENSORS", "VehicleLook", "scene_from_world", "vehicle_look"]
