"""Identity and rigid-body components shared by vehicles and packages."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

EntityKind = Literal["quadrotor", "car", "package"]


@dataclass(frozen=True, slots=True, kw_only=True)
class Identity:
    """Name and kind of a world-file entity (vehicle or package)."""

    name: str
    kind: EntityKind
    preset: str | None       # vehicle preset name; None for packages
    index: int               # position among entities of the same kind in the world file, from 0


@dataclass(frozen=True, slots=True, kw_only=True)
class FleetSlot:
    """Row of this entity in the fleet arrays."""

    row: int


@dataclass(frozen=True, slots=True, kw_only=True)
class RigidBody:
    """The PyBullet body of an entity and its nominal inertial data (body frame FLU)."""

    body_id: int
    mass_kg: float
    half_extents_m: np.ndarray   # (3,) [m] half size of the collision box, FLU


@dataclass(frozen=True, slots=True, kw_only=True)
class Appearance:
    """How a body looks to cameras: its colour (RGBA in [0, 1])."""

    rgba: tuple[float, float, float, float]
