"""Static urban scene: world-file schema, procedural city, layout, triangle mesh (no PyBullet here)."""

from .config import BuildingSpec, PadSpec, RoadSpec, SceneConfig, TreeSpec, UrbanParams
from .layout import build_layout
from .mesh import SceneMesh, triangulate
from .primitives import (
    PAD_THICKNESS_M,
    ROAD_TOP_Z_M,
    Box,
    Cylinder,
    Pad,
    ParkingSpot,
    SceneClass,
    SceneLayout,
    SceneObject,
    Sphere,
)
from .urban import generate_urban

__all__ = [
    "PAD_THICKNESS_M",
    "ROAD_TOP_Z_M",
    "Box",
    "BuildingSpec",
    "Cylinder",
    "Pad",
    "PadSpec",
    "ParkingSpot",
    "RoadSpec",
    "SceneClass",
    "SceneConfig",
    "SceneLayout",
    "SceneMesh",
    "SceneObject",
    "Sphere",
    "TreeSpec",
    "UrbanParams",
    "build_layout",
    "generate_urban",
    "triangulate",
]
