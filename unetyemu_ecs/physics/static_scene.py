"""Build the static scene in PyBullet as a ground plane plus one fixed compound body per scene class.

Why not ``createCollisionShapeArray``: in pybullet 3.2.7 it keeps only the first 16 child shapes
(``MAX_COMPOUND_COLLISION_SHAPES``) and silently drops the rest, and chaining 16-shape chunks as
fixed links of one multibody costs as much per step as separate bodies (measured with 800 boxes and
20 dynamic boxes: 12.0 ms per simulated second with no buildings, 55.6 ms with 800 separate static
bodies, 53.0 ms with 50 chunk links on one multibody, 16.7 ms with 50 chunk bodies, 14.0 ms with
one URDF link holding 800 collision boxes). So each class is written as a one-link URDF whose link
holds every collision and visual primitive of that class (PyBullet merges them into one
``btCompoundShape`` with no child limit) and loaded as a fixed base. Primitive boxes, cylinders and
spheres are exact for ray tests (unlike triangle meshes, no internal-edge bumps for wheels).

Coordinates are world ENU [m]; the ground plane is z = 0.
"""

from __future__ import annotations

import os
import tempfile

import pybullet as p

from unetyemu_ecs.scene.colors import SCENE_RGBA
from unetyemu_ecs.scene.primitives import Box, Cylinder, SceneClass, SceneLayout

GROUND_FRICTION = 0.9          # dry asphalt/concrete against rubber
RGBA = SCENE_RGBA                # the scene classes' colours (shared with the cameras and the web view)
_HIGH_FRICTION = (SceneClass.ROAD, SceneClass.SIDEWALK)


def _f(x: float) -> str:
    """Format a float so that it parses back to the same double."""
    return repr(float(x))


def _urdf(name: str, cls: SceneClass, shapes: list) -> str:
    """Return a one-link URDF holding every shape as a collision and a coloured visual element."""
    lines = [f'<robot name="{name}">', '<link name="base">',
             '<inertial><mass value="0"/><inertia ixx="0" ixy="0" ixz="0" iyy="0" iyz="0" izz="0"/></inertial>']
    for s in shapes:
        c = s.center_enu_m
        if isinstance(s, Box):
            yaw = s.yaw_rad
            geom = f'<box size="{_f(2 * s.half_extents_m[0])} {_f(2 * s.half_extents_m[1])} {_f(2 * s.half_extents_m[2])}"/>'
            mat = "body"
        elif isinstance(s, Cylinder):
            yaw = 0.0
            geom = f'<cylinder radius="{_f(s.radius_m)}" length="{_f(2 * s.half_height_m)}"/>'
            mat = "trunk" if cls == SceneClass.TREE else "body"
        else:
            yaw = 0.0
            geom = f'<sphere radius="{_f(s.radius_m)}"/>'
            mat = "crown" if cls == SceneClass.TREE else "body"
        origin = f'<origin xyz="{_f(c[0])} {_f(c[1])} {_f(c[2])}" rpy="0 0 {_f(yaw)}"/>'
        # One element per line: pybullet's XML reader rejects very long lines.
        lines.append(f"<collision>{origin}<geometry>{geom}</geometry></collision>")
        lines.append(f'<visual>{origin}<geometry>{geom}</geometry><material name="{mat}"/></visual>')
    lines.append("</link>")
    body = RGBA.get(cls, (0.7, 0.7, 0.7, 1.0))
    for mat, rgba in (("body", body), ("trunk", RGBA["trunk"]), ("crown", RGBA["crown"])):
        lines.append(f'<material name="{mat}"><color rgba="{" ".join(_f(v) for v in rgba)}"/></material>')
    lines.append("</robot>")
    return "\n".join(lines)


def build_static_scene(client_id: int, layout: SceneLayout) -> dict[int, SceneClass]:
    """Create the layout's static geometry in a PyBullet client.

    Parameters
    ----------
    client_id : int, PyBullet physics client id
    layout : SceneLayout, world ENU [m]

    Returns
    -------
    dict of int -> SceneClass
        Body id -> the class it holds: the ground plane first, then one fixed body per non-empty
        scene class other than GROUND, in :class:`SceneClass` order (ROAD, SIDEWALK, BUILDING,
        TREE, PAD).
    """
    ground = layout.objects[0].shapes[0]
    plane = p.createCollisionShape(p.GEOM_PLANE, physicsClientId=client_id)
    plane_vis = -1
    if isinstance(ground, Box):
        plane_vis = p.createVisualShape(
            p.GEOM_BOX, halfExtents=[float(ground.half_extents_m[0]), float(ground.half_extents_m[1]), 0.001],
            visualFramePosition=[float(ground.center_enu_m[0]), float(ground.center_enu_m[1]), -0.001],
            rgbaColor=RGBA["ground"], physicsClientId=client_id,
        )
    ground_id = p.createMultiBody(0.0, plane, plane_vis, [0.0, 0.0, 0.0], physicsClientId=client_id)
    p.changeDynamics(ground_id, -1, lateralFriction=GROUND_FRICTION, physicsClientId=client_id)
    ids = {ground_id: SceneClass.GROUND}

    by_cls: dict[SceneClass, list] = {}
    for obj in layout.objects[1:]:
        by_cls.setdefault(obj.cls, []).extend(obj.shapes)
    with tempfile.TemporaryDirectory(prefix="unetyemu_scene_") as tmp:
        for cls in sorted(by_cls):
            if cls == SceneClass.GROUND or not by_cls[cls]:
                continue
            path = os.path.join(tmp, f"{cls.name.lower()}.urdf")
            with open(path, "w", encoding="utf-8") as fh:
                fh.write(_urdf(cls.name.lower(), cls, by_cls[cls]))
            body = p.loadURDF(path, [0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0], useFixedBase=True, flags=p.URDF_USE_IMPLICIT_CYLINDER,
                              physicsClientId=client_id)
            if cls in _HIGH_FRICTION:
                p.changeDynamics(body, -1, lateralFriction=GROUND_FRICTION, physicsClientId=client_id)
            ids[body] = cls
    return ids


__all__ = ["GROUND_FRICTION", "RGBA", "build_static_scene"]
