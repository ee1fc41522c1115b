"""Static scene geometry as plain frozen data: shapes, objects, pads, parking spots and the layout.

Everything is in the world ENU frame (x east, y north, z up), in metres and radians, with the ground
surface at z = 0. A :class:`SceneLayout` is produced once (by the urban generator and/or explicit
world-file objects) and consumed by the physics builder and the mesh triangulator.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import IntEnum

import numpy as np

PAD_THICKNESS_M = 0.1          # pads are boxes this thick; > 2 x Bullet's 0.04 m margin keeps them solid
ROAD_TOP_Z_M = 0.002           # road surface: just above the ground so cameras and LiDAR can tell them apart
ROAD_THICKNESS_M = 0.1
GROUND_THICKNESS_M = 0.1


class SceneClass(IntEnum):
    """Semantic class of a scene object (stored per triangle as uint8)."""

    GROUND = 0
    ROAD = 1
    SIDEWALK = 2
    BUILDING = 3
    TREE = 4
    PAD = 5


@dataclass(frozen=True)
class Box:
    """Box yawed about the world z axis.

    Attributes
    ----------
    center_enu_m : (3,) float64 [m], ENU
    half_extents_m : (3,) float64 [m], along the box's own x, y, z axes
    yaw_rad : float [rad], rotation of the box axes about +z, counter-clockwise from east
    """

    center_enu_m: np.ndarray
    half_extents_m: np.ndarray
    yaw_rad: float = 0.0

    @property
    def top_z_m(self) -> float:
        """Return the height of the top face [m]."""
        return float(self.center_enu_m[2] + self.half_extents_m[2])


@dataclass(frozen=True)
class Cylinder:
    """Upright cylinder (axis along world z).

    Attributes
    ----------
    center_enu_m : (3,) float64 [m], ENU, centre of the axis
    radius_m, half_height_m : float [m]
    """

    center_enu_m: np.ndarray
    radius_m: float
    half_height_m: float

    @property
    def top_z_m(self) -> float:
        """Return the height of the top cap [m]."""
        return float(self.center_enu_m[2] + self.half_height_m)


@dataclass(frozen=True)
class Sphere:
    """Sphere.

    Attributes
    ----------
    center_enu_m : (3,) float64 [m], ENU
    radius_m : float [m]
    """

    center_enu_m: np.ndarray
    radius_m: float


Shape = Box | Cylinder | Sphere


@dataclass(frozen=True)
class SceneObject:
    """One named static object made of one or more shapes; ``object_id`` is its index in the layout."""

    object_id: int
    name: str
    cls: SceneClass
    shapes: tuple[Shape, ...]


@dataclass(frozen=True)
class Pad:
    """A landing pad.

    Attributes
    ----------
    name : str
    kind : str, 'start' or 'target'
    center_enu_m : (3,) float64 [m], ENU, centre of the pad's TOP surface
    size_m : float [m], edge of the square pad
    object_id : int, id of the pad's :class:`SceneObject`
    on_roof : bool, True when the pad rests on a building roof
    """

    name: str
    kind: str
    center_enu_m: np.ndarray
    size_m: float
    object_id: int
    on_roof: bool


@dataclass(frozen=True)
class ParkingSpot:
    """A parking spot on the road next to a curb.

    Attributes
    ----------
    name : str
    center_enu_m : (3,) float64 [m], ENU, on the road surface
    yaw_rad : float [rad], heading along the street (right-hand traffic), counter-clockwise from east
    """

    name: str
    center_enu_m: np.ndarray
    yaw_rad: float


@dataclass(frozen=True)
class SceneLayout:
    """All static objects of a world plus its pads and parking spots.

    Attributes
    ----------
    objects : tuple of SceneObject, ``objects[i].object_id == i``; object 0 is the ground
    pads : dict name -> Pad
    parking : dict name -> ParkingSpot
    extent_min_m, extent_max_m : (2,) float64 [m], ENU x/y bounds of the built area
    """

    objects: tuple[SceneObject, ...]
    pads: dict[str, Pad]
    parking: dict[str, ParkingSpot]
    extent_min_m: np.ndarray
    extent_max_m: np.ndarray
    # Footprint tables for surface_height_m, derived once from ``objects``.
    _footprints: tuple[np.ndarray, ...] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        for i, obj in enumerate(self.objects):
            if obj.object_id != i:
                raise ValueError(f"objects[{i}] has object_id {obj.object_id}; ids must equal positions")
        box_rows, cyl_rows, sph_rows = [], [], []
        for obj in self.objects:
            for s in obj.shapes:
                if isinstance(s, Box):
                    box_rows.append((*s.center_enu_m, *s.half_extents_m, s.yaw_rad, obj.object_id))
                elif isinstance(s, Cylinder):
                    cyl_rows.append((*s.center_enu_m, s.radius_m, s.half_height_m, obj.object_id))
                else:
                    sph_rows.append((*s.center_enu_m, s.radius_m, obj.object_id))
        boxes = np.array(box_rows, dtype=np.float64).reshape(-1, 8)
        cyls = np.array(cyl_rows, dtype=np.float64).reshape(-1, 6)
        spheres = np.array(sph_rows, dtype=np.float64).reshape(-1, 5)
        for a in (boxes, cyls, spheres):
            a.flags.writeable = False
        object.__setattr__(self, "_footprints", (boxes, cyls, spheres))

    def support_at(self, x_m: float, y_m: float) -> tuple[float, int]:
        """Return the top height [m] and object id of the highest box/cylinder covering (x, y).

        Spheres (tree crowns) are not supports. Returns ``(0.0, 0)`` (the ground) when nothing covers
        the point. Points exactly on a footprint's edge count as covered.
        """
        boxes, cyls, _ = self._footprints
        best_z, best_id = 0.0, 0
        if boxes.shape[0]:
            dx, dy = x_m - boxes[:, 0], y_m - boxes[:, 1]
            c, s = np.cos(boxes[:, 6]), np.sin(boxes[:, 6])
            lx, ly = c * dx + s * dy, -s * dx + c * dy         # point in each box's frame
            eps = 1e-9
            inside = (np.abs(lx) <= boxes[:, 3] + eps) & (np.abs(ly) <= boxes[:, 4] + eps)
            top = np.where(inside, boxes[:, 2] + boxes[:, 5], -np.inf)
            k = int(np.argmax(top))
            if top[k] > best_z:
                best_z, best_id = float(top[k]), int(boxes[k, 7])
        if cyls.shape[0]:
            inside = np.hypot(x_m - cyls[:, 0], y_m - cyls[:, 1]) <= cyls[:, 3]
            top = np.where(inside, cyls[:, 2] + cyls[:, 4], -np.inf)
            k = int(np.argmax(top))
            if top[k] > best_z:
                best_z, best_id = float(top[k]), int(cyls[k, 5])
        return best_z, best_id

    def contains_xy(self, x_m: float, y_m: float) -> bool:
        """Whether ENU (x, y) [m] lies within the world's extent (on its ground)."""
        lo, hi = self.extent_min_m, self.extent_max_m
        return bool(lo[0] <= x_m <= hi[0] and lo[1] <= y_m <= hi[1])

    def extent_text(self) -> str:
        """The extent for messages: ``x in [lo, hi] m, y in [lo, hi] m``."""
        lo, hi = self.extent_min_m, self.extent_max_m
        return f"x in [{lo[0]:g}, {hi[0]:g}] m, y in [{lo[1]:g}, {hi[1]:g}] m"

    def surface_height_m(self, x_m: float, y_m: float) -> float:
        """Return the top z [m] of the highest box/cylinder footprint covering (x, y); 0.0 for ground."""
        return self.support_at(x_m, y_m)[0]

    def objects_overlapping_box(self, center_enu_m: np.ndarray, half_extents_m: np.ndarray, yaw_rad: float,
                                skip_ground: bool = False) -> list[int]:
        """Return the ids of the objects whose shapes intersect a box yawed about z (touching is not
        intersecting), in id order; ``skip_ground`` leaves out object 0."""
        c = np.asarray(center_enu_m, dtype=np.float64)
        h = np.asarray(half_extents_m, dtype=np.float64)
        boxes, cyls, spheres = self._footprints
        hit: set[int] = set()
        if boxes.shape[0]:
            z_ok = np.abs(boxes[:, 2] - c[2]) < boxes[:, 5] + h[2]
            xy_ok = _rects_overlap(c[:2], h[:2], yaw_rad, boxes[:, :2], boxes[:, 3:5], boxes[:, 6])
            hit.update(boxes[z_ok & xy_ok, 7].astype(int).tolist())
        if cyls.shape[0]:
            z_ok = np.abs(cyls[:, 2] - c[2]) < cyls[:, 4] + h[2]
            d = _rect_point_distance(c[:2], h[:2], yaw_rad, cyls[:, :2])
            hit.update(cyls[z_ok & (d < cyls[:, 3]), 5].astype(int).tolist())
        if spheres.shape[0]:
            co, si = np.cos(yaw_rad), np.sin(yaw_rad)
            d = spheres[:, :3] - c
            local = np.stack([co * d[:, 0] + si * d[:, 1], -si * d[:, 0] + co * d[:, 1], d[:, 2]], axis=1)
            dist = np.linalg.norm(np.maximum(np.abs(local) - h, 0.0), axis=1)
            hit.update(spheres[dist < spheres[:, 3], 4].astype(int).tolist())
        if skip_ground:
            hit.discard(0)
        return sorted(hit)

    def nearest_object(self, point_enu_m: np.ndarray, cls: SceneClass | None = None) -> tuple[SceneObject, float]:
        """Return the object (of class ``cls`` if given) whose surface is nearest to a point, and that distance [m].

        Used to name what a vehicle touched (a contact point lies on the surface, distance ~0).
        The ground plane (object 0) counts as the plane z = 0. Not for the hot path: O(shapes).
        """
        q = np.asarray(point_enu_m, dtype=np.float64)
        boxes, cyls, spheres = self._footprints
        dists, ids = [np.array([abs(q[2])])], [np.array([0])]
        if boxes.shape[0]:
            d = q - boxes[:, :3]
            c, s = np.cos(boxes[:, 6]), np.sin(boxes[:, 6])
            local = np.stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1], d[:, 2]], axis=1)
            outside = np.abs(local) - boxes[:, 3:6]
            dist = np.linalg.norm(np.maximum(outside, 0.0), axis=1) + np.minimum(outside.max(axis=1), 0.0)
            dists.append(np.abs(dist))
            ids.append(boxes[:, 7].astype(int))
        if cyls.shape[0]:
            radial = np.hypot(q[0] - cyls[:, 0], q[1] - cyls[:, 1]) - cyls[:, 3]
            axial = np.abs(q[2] - cyls[:, 2]) - cyls[:, 4]
            out = np.stack([radial, axial], axis=1)
            dist = np.linalg.norm(np.maximum(out, 0.0), axis=1) + np.minimum(out.max(axis=1), 0.0)
            dists.append(np.abs(dist))
            ids.append(cyls[:, 5].astype(int))
        if spheres.shape[0]:
            dists.append(np.abs(np.linalg.norm(q - spheres[:, :3], axis=1) - spheres[:, 3]))
            ids.append(spheres[:, 4].astype(int))
        dist_all, id_all = np.concatenate(dists), np.concatenate(ids)
        if cls is not None:
            keep = np.array([self.objects[i].cls == cls for i in id_all])
            if not keep.any():
                raise ValueError(f"the scene has no {cls.name.lower()} objects")
            dist_all, id_all = dist_all[keep], id_all[keep]
        k = int(np.argmin(dist_all))
        return self.objects[int(id_all[k])], float(dist_all[k])


def _rects_overlap(c: np.ndarray, h: np.ndarray, yaw: float, oc: np.ndarray, oh: np.ndarray,
                   oyaw: np.ndarray) -> np.ndarray:
    """Separating-axis test of one yawed rectangle (centre (2,), half (2,)) against many (R, 2) -> (R,) bool."""
    u = np.array([np.cos(yaw), np.sin(yaw)])
    v = np.array([-u[1], u[0]])
    ou = np.stack([np.cos(oyaw), np.sin(oyaw)], axis=1)
    ov = np.stack([-ou[:, 1], ou[:, 0]], axis=1)
    d = oc - c
    overlap = np.ones(oc.shape[0], dtype=bool)
    for axis in (u[None, :].repeat(oc.shape[0], 0), v[None, :].repeat(oc.shape[0], 0), ou, ov):
        r1 = h[0] * np.abs(axis @ u) + h[1] * np.abs(axis @ v)
        r2 = oh[:, 0] * np.abs(np.sum(axis * ou, axis=1)) + oh[:, 1] * np.abs(np.sum(axis * ov, axis=1))
        overlap &= np.abs(np.sum(axis * d, axis=1)) < r1 + r2
    return overlap


def _rect_point_distance(c: np.ndarray, h: np.ndarray, yaw: float, pts: np.ndarray) -> np.ndarray:
    """Distance (P,) [m] from points (P, 2) to a yawed rectangle (0 inside)."""
    co, si = np.cos(yaw), np.sin(yaw)
    d = pts - c
    local = np.stack([co * d[:, 0] + si * d[:, 1], -si * d[:, 0] + co * d[:, 1]], axis=1)
    return np.linalg.norm(np.maximum(np.abs(local) - h, 0.0), axis=1)


def box_overlaps_box(c1: np.ndarray, h1: np.ndarray, yaw1: float, c2: np.ndarray, h2: np.ndarray, yaw2: float) -> bool:
    """Whether two boxes yawed about z (centres (3,), half extents (3,) [m]) intersect; touching does not."""
    if abs(float(c1[2]) - float(c2[2])) >= float(h1[2]) + float(h2[2]):
        return False
    return bool(_rects_overlap(np.asarray(c1[:2], float), np.asarray(h1[:2], float), yaw1,
                               np.asarray(c2[:2], float)[None, :], np.asarray(h2[:2], float)[None, :],
                               np.array([yaw2]))[0])


__all__ = [
    "GROUND_THICKNESS_M",
    "PAD_THICKNESS_M",
    "ROAD_THICKNESS_M",
    "ROAD_TOP_Z_M",
    "Box",
    "Cylinder",
    "Pad",
    "ParkingSpot",
    "SceneClass",
    "SceneLayout",
    "SceneObject",
    "Shape",
    "Sphere",
    "box_overlaps_box",
]
