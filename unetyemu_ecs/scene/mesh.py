"""Triangulate a scene layout into one triangle mesh with per-triangle object ids and classes.

The mesh is what ray casters (Open3D LiDAR, depth and RGB cameras) consume. Boxes become 12
triangles, upright cylinders 12-sided prisms with caps, spheres once-subdivided icospheres; every
triangle is wound counter-clockwise seen from outside, so its right-hand normal points outwards.
Each shape type is triangulated in one vectorised pass. Coordinates are world ENU [m].
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass

import numpy as np

from .primitives import Box, Cylinder, SceneLayout, Sphere

CYLINDER_SIDES = 12

# Unit cube corners (bit 0: x, bit 1: y, bit 2: z; 0 -> -1, 1 -> +1) and its outward CCW triangles.
_CUBE_CORNERS = np.array([[(k & 1) * 2 - 1, (k >> 1 & 1) * 2 - 1, (k >> 2 & 1) * 2 - 1] for k in range(8)], dtype=np.float64)
_CUBE_TRIANGLES = np.array(
    [
        [0, 2, 3], [0, 3, 1],   # -z
        [4, 5, 7], [4, 7, 6],   # +z
        [0, 1, 5], [0, 5, 4],   # -y
        [2, 6, 7], [2, 7, 3],   # +y
        [0, 4, 6], [0, 6, 2],   # -x
        [1, 3, 7], [1, 7, 5],   # +x
    ],
    dtype=np.int64,
)


def _icosphere(subdivisions: int) -> tuple[np.ndarray, np.ndarray]:
    """Return unit icosphere vertices (V, 3) and outward CCW triangles (T, 3)."""
    t = (1.0 + 5.0**0.5) / 2.0
    v = [[-1, t, 0], [1, t, 0], [-1, -t, 0], [1, -t, 0], [0, -1, t], [0, 1, t],
         [0, -1, -t], [0, 1, -t], [t, 0, -1], [t, 0, 1], [-t, 0, -1], [-t, 0, 1]]
    f = [[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9], [5, 11, 4],
         [11, 10, 2], [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8],
         [3, 8, 9], [4, 9, 5], [2, 4, 11], [6, 2, 10], [8, 6, 7], [9, 8, 1]]
    verts = [np.array(x, dtype=np.float64) / np.linalg.norm(x) for x in v]
    faces = f
    for _ in range(subdivisions):
        mid: dict[tuple[int, int], int] = {}

        def midpoint(a: int, b: int) -> int:
            key = (min(a, b), max(a, b))
            if key not in mid:
                m = verts[a] + verts[b]
                verts.append(m / np.linalg.norm(m))
                mid[key] = len(verts) - 1
            return mid[key]

        new = []
        for a, b, c in faces:
            ab, bc, ca = midpoint(a, b), midpoint(b, c), midpoint(c, a)
            new += [[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]
        faces = new
    return np.array(verts), np.array(faces, dtype=np.int64)


_SPHERE_VERTS, _SPHERE_TRIS = _icosphere(1)


def _cylinder_template(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Return unit cylinder vertices (2n + 2, 3) (radius 1, z in [-1, 1]) and outward CCW triangles."""
    a = 2.0 * np.pi * np.arange(n) / n
    ring = np.stack([np.cos(a), np.sin(a)], axis=1)
    verts = np.concatenate([
        np.column_stack([ring, -np.ones(n)]),       # 0..n-1 bottom ring
        np.column_stack([ring, np.ones(n)]),        # n..2n-1 top ring
        [[0.0, 0.0, -1.0], [0.0, 0.0, 1.0]],        # 2n bottom centre, 2n+1 top centre
    ])
    k = np.arange(n)
    k1 = (k + 1) % n
    side = np.concatenate([np.stack([k, k1, n + k1], 1), np.stack([k, n + k1, n + k], 1)])
    bottom = np.stack([np.full(n, 2 * n), k1, k], 1)
    top = np.stack([np.full(n, 2 * n + 1), n + k, n + k1], 1)
    return verts, np.concatenate([side, bottom, top])


_CYL_VERTS, _CYL_TRIS = _cylinder_template(CYLINDER_SIDES)
for _a in (_CUBE_CORNERS, _CUBE_TRIANGLES, _SPHERE_VERTS, _SPHERE_TRIS, _CYL_VERTS, _CYL_TRIS):
    _a.flags.writeable = False


@dataclass(frozen=True)
class SceneMesh:
    """One triangle mesh of the whole static scene.

    Attributes
    ----------
    vertices_m : (V, 3) float64 [m], ENU
    triangles : (T, 3) int32, vertex indices, counter-clockwise seen from outside
    object_id : (T,) int32, :class:`SceneObject` id of each triangle
    cls : (T,) uint8, :class:`SceneClass` of each triangle
    """

    vertices_m: np.ndarray
    triangles: np.ndarray
    object_id: np.ndarray
    cls: np.ndarray

    def digest(self) -> str:
        """Return the sha256 hex digest over the four arrays' bytes (fixed dtypes, C order)."""
        h = hashlib.sha256()
        for a, dt in ((self.vertices_m, np.float64), (self.triangles, np.int32),
                      (self.object_id, np.int32), (self.cls, np.uint8)):
            h.update(np.ascontiguousarray(a, dtype=dt).tobytes())
        return h.hexdigest()


def _instances(template_v: np.ndarray, template_t: np.ndarray, scale: np.ndarray, yaw: np.ndarray,
               center: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Return vertices (N*Vt, 3) and local triangles (N*Tt, 3) of N scaled, yawed, shifted templates."""
    n = center.shape[0]
    local = template_v[None, :, :] * scale[:, None, :]                  # (N, Vt, 3)
    c, s = np.cos(yaw)[:, None], np.sin(yaw)[:, None]
    x = c * local[..., 0] - s * local[..., 1]
    y = s * local[..., 0] + c * local[..., 1]
    verts = np.stack([x, y, local[..., 2]], axis=-1) + center[:, None, :]
    tris = template_t[None, :, :] + (np.arange(n) * template_v.shape[0])[:, None, None]
    return verts.reshape(-1, 3), tris.reshape(-1, 3)


def triangulate(layout: SceneLayout) -> SceneMesh:
    """Return the triangle mesh of every shape in ``layout`` (boxes, then cylinders, then spheres)."""
    rows: dict[type, list] = {Box: [], Cylinder: [], Sphere: []}
    for obj in layout.objects:
        for s in obj.shapes:
            rows[type(s)].append((s, obj.object_id, int(obj.cls)))

    parts_v, parts_t, parts_id, parts_cls = [], [], [], []
    offset = 0

    def add(verts: np.ndarray, tris: np.ndarray, n_tri_per: int, meta: list) -> None:
        nonlocal offset
        ids = np.array([m[1] for m in meta], dtype=np.int32)
        cl = np.array([m[2] for m in meta], dtype=np.uint8)
        parts_v.append(verts)
        parts_t.append(tris + offset)
        parts_id.append(np.repeat(ids, n_tri_per))
        parts_cls.append(np.repeat(cl, n_tri_per))
        offset += verts.shape[0]

    if rows[Box]:
        m = rows[Box]
        center = np.array([r[0].center_enu_m for r in m], dtype=np.float64)
        half = np.array([r[0].half_extents_m for r in m], dtype=np.float64)
        yaw = np.array([r[0].yaw_rad for r in m], dtype=np.float64)
        add(*_instances(_CUBE_CORNERS, _CUBE_TRIANGLES, half, yaw, center), len(_CUBE_TRIANGLES), m)
    if rows[Cylinder]:
        m = rows[Cylinder]
        center = np.array([r[0].center_enu_m for r in m], dtype=np.float64)
        scale = np.array([[r[0].radius_m, r[0].radius_m, r[0].half_height_m] for r in m], dtype=np.float64)
        add(*_instances(_CYL_VERTS, _CYL_TRIS, scale, np.zeros(len(m)), center), len(_CYL_TRIS), m)
    if rows[Sphere]:
        m = rows[Sphere]
        center = np.array([r[0].center_enu_m for r in m], dtype=np.float64)
        scale = np.repeat(np.array([r[0].radius_m for r in m], dtype=np.float64)[:, None], 3, axis=1)
        add(*_instances(_SPHERE_VERTS, _SPHERE_TRIS, scale, np.zeros(len(m)), center), len(_SPHERE_TRIS), m)

    if not parts_v:
        return SceneMesh(np.zeros((0, 3)), np.zeros((0, 3), np.int32), np.zeros(0, np.int32), np.zeros(0, np.uint8))
    return SceneMesh(
        np.concatenate(parts_v),
        np.concatenate(parts_t).astype(np.int32),
        np.concatenate(parts_id),
        np.concatenate(parts_cls),
    )


__all__ = ["CYLINDER_SIDES", "SceneMesh", "triangulate"]
