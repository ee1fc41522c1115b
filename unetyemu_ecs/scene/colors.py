"""Colours of the static scene, by scene class: one table for PyBullet's visuals, the cameras and the web view.

``SCENE_RGBA`` holds RGBA in [0, 1] for the ground plane, each :class:`SceneClass` that has a single
colour, and a tree's two parts (``trunk``, ``crown``). :func:`class_rgb` turns it into the lookup
table ray-cast cameras and the web view colour triangles with: row ``cls`` is the RGB of class
``cls`` (trees take the crown's colour: their crowns are what is seen from above and around).
"""

from __future__ import annotations

import numpy as np

from .primitives import SceneClass

SCENE_RGBA: dict[object, tuple[float, float, float, float]] = {
    "ground": (0.45, 0.55, 0.40, 1.0),
    SceneClass.ROAD: (0.25, 0.25, 0.27, 1.0),
    SceneClass.SIDEWALK: (0.60, 0.60, 0.60, 1.0),
    SceneClass.BUILDING: (0.82, 0.82, 0.80, 1.0),
    SceneClass.PAD: (1.00, 0.55, 0.10, 1.0),
    "trunk": (0.45, 0.30, 0.15, 1.0),
    "crown": (0.20, 0.55, 0.20, 1.0),
}


def class_rgb() -> np.ndarray:
    """RGB in [0, 1] of every scene class, as a (256, 3) float64 table indexed by the class number
    (rows of numbers that are no class are black)."""
    table = np.zeros((256, 3))
    table[int(SceneClass.GROUND)] = SCENE_RGBA["ground"][:3]
    for cls in (SceneClass.ROAD, SceneClass.SIDEWALK, SceneClass.BUILDING, SceneClass.PAD):
        table[int(cls)] = SCENE_RGBA[cls][:3]
    table[int(SceneClass.TREE)] = SCENE_RGBA["crown"][:3]
    return table


__all__ = ["SCENE_RGBA", "class_rgb"]
