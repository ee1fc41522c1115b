"""Schema of the ``scene:`` section of a world file (docs/architecture.md §8).

The frozen dataclasses below *are* the schema: their ``Annotated`` type hints are checked by
:func:`unetyemu_ecs.config.schema.convert`, and ``__post_init__`` rejects cross-field problems with a
``ValueError`` that the loader reports at the path of the offending mapping. All positions are in the
world ENU frame (x east, y north) in metres; heights are above the ground plane z = 0.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Annotated, Literal

from unetyemu_ecs.config.schema import Each, Ge, Gt, Le, NonEmpty, Ordered

PositiveRange = Annotated[tuple[float, float], Each(Gt(0)), Ordered()]


@dataclass(frozen=True, kw_only=True)
class UrbanParams:
    """Parameters of the procedural street-grid city (``scene.urban``).

    The city is ``blocks_x`` x ``blocks_y`` square blocks separated by streets, with streets on the
    outer border too, centred on the world origin. Each block has a raised sidewalk ring; its inside
    is split into lots holding one building each, except the depot block (an open plaza with the
    start pads) and the target block (an open plaza with the ground target pads).
    """

    blocks_x: Annotated[int, Ge(1)] = 4
    blocks_y: Annotated[int, Ge(1)] = 4
    block_size_m: Annotated[float, Gt(0)] = 60.0          # edge of a square block, sidewalk included
    street_width_m: Annotated[float, Ge(4)] = 12.0         # kerb to kerb
    sidewalk_width_m: Annotated[float, Gt(0)] = 3.0
    curb_height_m: Annotated[float, Gt(0), Le(0.5)] = 0.15
    building_height_m: PositiveRange = (8.0, 60.0)
    lot_size_m: PositiveRange = (14.0, 26.0)              # edge length range of the lots a block splits into
    building_fill_frac: Annotated[tuple[float, float], Each(Gt(0)), Each(Le(1)), Ordered()] = (0.7, 1.0)
    building_gap_m: Annotated[float, Ge(0)] = 3.0          # minimum gap between neighbouring buildings
    empty_lot_frac: Annotated[float, Ge(0), Le(1)] = 0.1   # chance that a lot stays empty
    tree_spacing_m: Annotated[float, Gt(0)] = 10.0         # along the sidewalk centreline
    tree_height_m: PositiveRange = (5.0, 9.0)
    crown_radius_m: PositiveRange = (1.2, 2.2)
    start_pads: Annotated[int, Ge(0)] = 4
    target_pads: Annotated[int, Ge(0)] = 4
    roof_pads: Annotated[int, Ge(0)] = 2
    roof_pad_max_height_m: Annotated[float, Gt(0)] = 25.0  # roof pads prefer buildings at most this tall
    parking_spots: Annotated[int, Ge(0)] = 8
    pad_size_m: Annotated[float, Gt(0)] = 3.0              # edge of a square pad
    depot_block: Annotated[tuple[int, int], Each(Ge(0))] = (0, 0)
    target_block: Annotated[tuple[int, int], Each(Ge(0))] | None = None  # None: the opposite corner

    def __post_init__(self) -> None:
        for name in ("depot_block", "target_block"):
            ij = getattr(self, name)
            if ij is not None and (ij[0] >= self.blocks_x or ij[1] >= self.blocks_y):
                raise ValueError(
                    f"{name} {list(ij)} is outside the {self.blocks_x} x {self.blocks_y} block grid"
                )
        if 2.0 * self.sidewalk_width_m >= self.block_size_m:
            raise ValueError(
                f"sidewalk_width_m {self.sidewalk_width_m:g} leaves no room inside a block of "
                f"block_size_m {self.block_size_m:g}"
            )
        if self.tree_height_m[0] <= 2.0 * self.crown_radius_m[1]:
            raise ValueError(
                f"tree_height_m low {self.tree_height_m[0]:g} must exceed twice the largest crown radius "
                f"{self.crown_radius_m[1]:g} so that crowns clear the ground"
            )


@dataclass(frozen=True, kw_only=True)
class BuildingSpec:
    """One explicit building: a box standing on the ground (``scene.buildings[i]``)."""

    name: Annotated[str, NonEmpty()] | None = None        # None: building_<k>
    center_m: tuple[float, float]                         # footprint centre, ENU x/y
    size_m: Annotated[tuple[float, float], Each(Gt(0))]   # footprint edge lengths before yaw (x, y)
    height_m: Annotated[float, Gt(0)]
    yaw_deg: float = 0.0                                  # counter-clockwise from east


@dataclass(frozen=True, kw_only=True)
class TreeSpec:
    """One explicit tree: trunk cylinder plus crown sphere, standing on the ground."""

    position_m: tuple[float, float]
    height_m: Annotated[float, Gt(0)] = 6.0               # top of the crown
    crown_radius_m: Annotated[float, Gt(0)] = 2.0

    def __post_init__(self) -> None:
        if self.height_m <= 2.0 * self.crown_radius_m:
            raise ValueError(
                f"height_m {self.height_m:g} must exceed twice crown_radius_m {self.crown_radius_m:g}"
            )


@dataclass(frozen=True, kw_only=True)
class PadSpec:
    """One explicit landing pad (``scene.pads[i]``)."""

    name: Annotated[str, NonEmpty()]
    position_m: tuple[float, float]                       # pad centre, ENU x/y
    z_m: float | None = None          # height of the pad's underside; None: rest on the roof or ground below
    size_m: Annotated[float, Gt(0)] = 3.0
    kind: Literal["start", "target"] = "target"


@dataclass(frozen=True, kw_only=True)
class RoadSpec:
    """One explicit straight road segment at ground level."""

    start_m: tuple[float, float]
    end_m: tuple[float, float]
    width_m: Annotated[float, Gt(0)] = 8.0

    def __post_init__(self) -> None:
        if math.dist(self.start_m, self.end_m) <= 0.0:
            raise ValueError("start_m and end_m must differ")


@dataclass(frozen=True, kw_only=True)
class SceneConfig:
    """The ``scene:`` section: an optional generated city plus explicit objects."""

    generator: Literal["urban", "none"] = "none"
    urban: UrbanParams = field(default_factory=UrbanParams)
    ground_size_m: Annotated[float, Gt(0)] = 200.0        # ground edge when generator is "none"
    buildings: list[BuildingSpec] = field(default_factory=list)
    trees: list[TreeSpec] = field(default_factory=list)
    pads: list[PadSpec] = field(default_factory=list)
    roads: list[RoadSpec] = field(default_factory=list)


__all__ = ["BuildingSpec", "PadSpec", "RoadSpec", "SceneConfig", "TreeSpec", "UrbanParams"]
