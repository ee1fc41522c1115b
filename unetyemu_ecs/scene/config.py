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

from unetyemu_ecs.config.limits import MAX_SCENE_OBJECTS, MAX_XY_M, XY, Deg, Name, ZM
from unetyemu_ecs.config.schema import Each, Ge, Gt, Le, Lt, MaxLen, Ordered

# Ranges (reasons): the tallest building is 828 m, the tallest tree 116 m; city blocks are 50-250 m
# (Manhattan 80 x 274 m); the widest avenues are ~100 m; a landing pad is 1-30 m across.
MAX_BLOCKS = 16                  # per axis: a 16 x 16 city is ~8 500 objects (config.limits.MAX_SCENE_OBJECTS)
Height = Annotated[float, Gt(0), Le(1_000.0)]            # buildings [m]
TreeHeight = Annotated[float, Gt(0), Le(150.0)]          # [m]
Crown = Annotated[float, Gt(0), Le(30.0)]                # crown radius [m]
HeightRange = Annotated[tuple[Height, Height], Ordered()]
TreeHeightRange = Annotated[tuple[TreeHeight, TreeHeight], Ordered()]
CrownRange = Annotated[tuple[Crown, Crown], Ordered()]
# lots below 5 m hold no building (a lot needs 2 m plus the gaps) and would only multiply the loop
LotRange = Annotated[tuple[Annotated[float, Ge(5.0), Le(500.0)], Annotated[float, Ge(5.0), Le(500.0)]], Ordered()]
PadSize = Annotated[float, Ge(0.5), Le(50.0)]            # a pad narrower than 0.5 m holds no drone [m]
PadCount = Annotated[int, Ge(0), Le(100)]                # pads of one kind (each needs its plaza cell)
BlockIndex = Annotated[int, Ge(0), Lt(MAX_BLOCKS)]


@dataclass(frozen=True, kw_only=True)
class UrbanParams:
    """Parameters of the procedural street-grid city (``scene.urban``).

    The city is ``blocks_x`` x ``blocks_y`` square blocks separated by streets, with streets on the
    outer border too, centred on the world origin. Each block has a raised sidewalk ring; its inside
    is split into lots holding one building each, except the depot block (an open plaza with the
    start pads) and the target block (an open plaza with the ground target pads).
    """

    blocks_x: Annotated[int, Ge(1), Le(MAX_BLOCKS)] = 4
    blocks_y: Annotated[int, Ge(1), Le(MAX_BLOCKS)] = 4
    block_size_m: Annotated[float, Gt(0), Le(500.0)] = 60.0   # edge of a square block, sidewalk included
    street_width_m: Annotated[float, Ge(4), Le(100.0)] = 12.0  # kerb to kerb: one lane to a wide avenue
    sidewalk_width_m: Annotated[float, Gt(0), Le(20.0)] = 3.0
    curb_height_m: Annotated[float, Gt(0), Le(0.5)] = 0.15
    building_height_m: HeightRange = (8.0, 60.0)
    lot_size_m: LotRange = (14.0, 26.0)                   # edge length range of the lots a block splits into
    building_fill_frac: Annotated[tuple[float, float], Each(Gt(0)), Each(Le(1)), Ordered()] = (0.7, 1.0)
    building_gap_m: Annotated[float, Ge(0), Le(50.0)] = 3.0   # minimum gap between neighbouring buildings
    empty_lot_frac: Annotated[float, Ge(0), Le(1)] = 0.1   # chance that a lot stays empty
    # along the sidewalk centreline; closer than 2 m the crowns merge and the tree count explodes
    tree_spacing_m: Annotated[float, Ge(2.0), Le(500.0)] = 10.0
    tree_height_m: TreeHeightRange = (5.0, 9.0)
    crown_radius_m: CrownRange = (1.2, 2.2)
    start_pads: PadCount = 4
    target_pads: PadCount = 4
    roof_pads: PadCount = 2
    roof_pad_max_height_m: Height = 25.0                   # roof pads prefer buildings at most this tall
    parking_spots: Annotated[int, Ge(0), Le(1_000)] = 8
    pad_size_m: PadSize = 3.0                              # edge of a square pad
    depot_block: tuple[BlockIndex, BlockIndex] = (0, 0)
    target_block: tuple[BlockIndex, BlockIndex] | None = None  # None: the opposite corner

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
        n = self.max_objects()
        if n > MAX_SCENE_OBJECTS:
            raise ValueError(
                f"this city could hold up to {n} objects (limit {MAX_SCENE_OBJECTS}): use fewer or smaller "
                "blocks, a larger lot_size_m or tree_spacing_m"
            )

    def max_objects(self) -> int:
        """Upper bound on the objects :func:`~unetyemu_ecs.scene.urban.generate_urban` makes, known before
        generating: per block a sidewalk, one building per lot (lots are at least ``lot_size_m[0]``,
        the last one may be smaller) and four rows of trees; plus roads, pads and the ground."""
        inner = self.block_size_m - 2.0 * self.sidewalk_width_m
        lots = (math.floor(inner / self.lot_size_m[0]) + 1) ** 2
        trees = 4 * (max(math.floor((self.block_size_m - 6.0) / self.tree_spacing_m), 0) + 1)
        roads = self.blocks_x + self.blocks_y + 2
        pads = self.start_pads + self.target_pads + self.roof_pads
        return self.blocks_x * self.blocks_y * (1 + lots + trees) + roads + pads + 1


@dataclass(frozen=True, kw_only=True)
class BuildingSpec:
    """One explicit building: a box standing on the ground (``scene.buildings[i]``)."""

    name: Name | None = None                              # None: building_<k>
    center_m: XY                                          # footprint centre, ENU x/y
    # footprint edge lengths before yaw (x, y): up to 2 km (the largest buildings are ~1 km long)
    size_m: tuple[Annotated[float, Gt(0), Le(2_000.0)], Annotated[float, Gt(0), Le(2_000.0)]]
    height_m: Height
    yaw_deg: Deg = 0.0                                    # counter-clockwise from east


@dataclass(frozen=True, kw_only=True)
class TreeSpec:
    """One explicit tree: trunk cylinder plus crown sphere, standing on the ground."""

    position_m: XY
    height_m: TreeHeight = 6.0                            # top of the crown
    crown_radius_m: Crown = 2.0

    def __post_init__(self) -> None:
        if self.height_m <= 2.0 * self.crown_radius_m:
            raise ValueError(
                f"height_m {self.height_m:g} must exceed twice crown_radius_m {self.crown_radius_m:g}"
            )


@dataclass(frozen=True, kw_only=True)
class PadSpec:
    """One explicit landing pad (``scene.pads[i]``)."""

    name: Name
    position_m: XY                                        # pad centre, ENU x/y
    z_m: ZM | None = None             # height of the pad's underside; None: rest on the roof or ground below
    size_m: PadSize = 3.0
    kind: Literal["start", "target"] = "target"


@dataclass(frozen=True, kw_only=True)
class RoadSpec:
    """One explicit straight road segment at ground level."""

    start_m: XY
    end_m: XY
    width_m: Annotated[float, Gt(0), Le(100.0)] = 8.0

    def __post_init__(self) -> None:
        if math.dist(self.start_m, self.end_m) <= 0.0:
            raise ValueError("start_m and end_m must differ")


@dataclass(frozen=True, kw_only=True)
class SceneConfig:
    """The ``scene:`` section: an optional generated city plus explicit objects.

    The explicit lists are capped so that, with the city, the scene stays within
    ``config.limits.MAX_SCENE_OBJECTS`` objects (checked before anything is generated).
    """

    generator: Literal["urban", "none"] = "none"
    urban: UrbanParams = field(default_factory=UrbanParams)
    # seeds the generated city; none: the world's seed. A fixed city seed keeps the streets and pads
    # while world.seed (or a sweep's --seeds) varies the wind and the sensor noise
    seed: Annotated[int, Ge(0), Le(2**63 - 1)] | None = None
    # ground edge when generator is "none": 1 m to the whole 40 km world (config.limits.MAX_XY_M)
    ground_size_m: Annotated[float, Ge(1.0), Le(2.0 * MAX_XY_M)] = 200.0
    buildings: Annotated[list[BuildingSpec], MaxLen(MAX_SCENE_OBJECTS)] = field(default_factory=list)
    trees: Annotated[list[TreeSpec], MaxLen(MAX_SCENE_OBJECTS)] = field(default_factory=list)
    pads: Annotated[list[PadSpec], MaxLen(1_000)] = field(default_factory=list)
    roads: Annotated[list[RoadSpec], MaxLen(MAX_SCENE_OBJECTS)] = field(default_factory=list)

    def __post_init__(self) -> None:
        generated = self.urban.max_objects() if self.generator == "urban" else 1
        n = generated + len(self.buildings) + len(self.trees) + len(self.pads) + len(self.roads)
        if n > MAX_SCENE_OBJECTS:
            raise ValueError(f"the scene could hold up to {n} objects (limit {MAX_SCENE_OBJECTS}): fewer "
                             "explicit objects or a smaller city")


__all__ = ["BuildingSpec", "PadSpec", "RoadSpec", "SceneConfig", "TreeSpec", "UrbanParams"]
