"""Create dynamic rigid bodies in a PyBullet client."""

from __future__ import annotations

from collections.abc import Sequence

import pybullet as p


def create_box_body(client_id: int, half_extents_m: Sequence[float], mass_kg: float,
                    pos_enu_m: Sequence[float], quat_enu_xyzw: Sequence[float],
                    rgba: Sequence[float], lateral_friction: float = 0.8) -> int:
    """Create a solid box with uniform density and no artificial damping; return its body id.

    PyBullet damps linear and angular velocity by default (0.04/s); a simulator that claims
    physical behaviour must not, so both dampings are set to zero. Drag, where wanted, is an
    explicit force.
    """
    col = p.createCollisionShape(p.GEOM_BOX, halfExtents=list(half_extents_m), physicsClientId=client_id)
    vis = p.createVisualShape(p.GEOM_BOX, halfExtents=list(half_extents_m), rgbaColor=list(rgba),
                              physicsClientId=client_id)
    body = p.createMultiBody(baseMass=float(mass_kg), baseCollisionShapeIndex=col, baseVisualShapeIndex=vis,
                             basePosition=list(pos_enu_m), baseOrientation=list(quat_enu_xyzw),
                             physicsClientId=client_id)
    p.changeDynamics(body, -1, linearDamping=0.0, angularDamping=0.0, lateralFriction=lateral_friction,
                     physicsClientId=client_id)
    return body
