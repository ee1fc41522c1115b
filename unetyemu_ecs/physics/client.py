"""One PyBullet client per simulation: connection, stepping, batched state read-back and wrenches.

PyBullet has no batched pose query, so ``read_states`` loops over bodies once per step (≈5 µs per
body, measured with PyBullet 3.2.7); everything else in the engine works on the resulting arrays.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Sequence
from operator import itemgetter
from typing import Any

import numpy as np
import pybullet as p

# fields of a PyBullet contact point: (flag, body A, body B, link A, link B, position on A, position on B, ...)
_BODIES_OF_POINT = itemgetter(1, 2)
_BODIES_AND_POINT = itemgetter(1, 2, 6)


class PhysicsError(RuntimeError):
    """PyBullet could not do what was asked (no display for the GUI, bad body...)."""


class PhysicsClient:
    """A connected PyBullet client in DIRECT (default) or GUI mode, stepping at ``dt_s``."""

    def __init__(self, dt_s: float, gravity_enu_m_s2: tuple[float, float, float], gui: bool = False) -> None:
        if gui and sys.platform.startswith("linux") and not os.environ.get("DISPLAY"):
            # PyBullet's GUI is an X11 window; without a display it prints an X error and fails (or aborts)
            raise PhysicsError("the PyBullet GUI needs a display and DISPLAY is not set: run without --gui "
                               "(headless), or under a virtual display: xvfb-run -a unetyemu run ... --gui")
        mode = p.GUI if gui else p.DIRECT
        cid = p.connect(mode)
        if cid < 0:
            raise PhysicsError("could not open the PyBullet GUI (is a display available? try without --gui)"
                               if gui else "could not start a PyBullet DIRECT client")
        self.id = cid
        self.gui = gui
        self.dt_s = float(dt_s)
        self._contact_points: Any = None                 # this step's, once queried
        p.resetSimulation(physicsClientId=cid)
        p.setPhysicsEngineParameter(fixedTimeStep=self.dt_s, numSubSteps=0, deterministicOverlappingPairs=1,
                                    physicsClientId=cid)
        p.setGravity(*gravity_enu_m_s2, physicsClientId=cid)
        if gui:
            p.configureDebugVisualizer(p.COV_ENABLE_GUI, 0, physicsClientId=cid)
            p.configureDebugVisualizer(p.COV_ENABLE_RENDERING, 0, physicsClientId=cid)

    def finish_loading(self) -> None:
        """Turn rendering back on after the scene was built (GUI only; faster loading)."""
        if self.gui:
            p.configureDebugVisualizer(p.COV_ENABLE_RENDERING, 1, physicsClientId=self.id)

    def step(self) -> None:
        """Advance the physics by one fixed step."""
        p.stepSimulation(physicsClientId=self.id)
        self._contact_points = None

    def _all_contact_points(self) -> Any:
        """PyBullet's contact points after the last step, queried once per step (they change only with a step
        or a removed body; the land detector and the impact monitor both read them)."""
        if self._contact_points is None:
            self._contact_points = p.getContactPoints(physicsClientId=self.id)
        return self._contact_points

    def read_states(self, body_ids: Sequence[int] | np.ndarray) -> np.ndarray:
        """Base pose and velocity of each body in ``body_ids``: (M, 13) rows of position [m] (3), quaternion
        xyzw (4), linear velocity [m/s] (3) and angular velocity [rad/s] (3), world frame; two PyBullet
        calls per body (the client id passed by position: PyBullet parses keywords 15-30 % slower) and one
        array for all of them, built from one flat list."""
        cid = self.id
        get_pose = p.getBasePositionAndOrientation
        get_vel = p.getBaseVelocity
        flat: list[float] = []
        extend = flat.extend
        for bid in (body_ids.tolist() if isinstance(body_ids, np.ndarray) else body_ids):
            pos, quat = get_pose(bid, cid)
            lin, ang = get_vel(bid, cid)
            extend(pos)
            extend(quat)
            extend(lin)
            extend(ang)
        return np.array(flat, dtype=float).reshape(-1, 13)

    def apply_wrenches(self, body_ids: Sequence[int] | np.ndarray, pos_enu_m: np.ndarray, force_enu_n: np.ndarray,
                       torque_enu_n_m: np.ndarray) -> None:
        """Apply a world-frame force at each body's centre of mass and a world-frame torque for one step
        (a zero force or torque is not sent: ``any`` of a row is False only when all three are zero)."""
        cid = self.id
        force = p.applyExternalForce
        torque = p.applyExternalTorque
        world = p.WORLD_FRAME
        ids = body_ids.tolist() if isinstance(body_ids, np.ndarray) else body_ids
        for bid, f, at, t in zip(ids, force_enu_n.tolist(), pos_enu_m.tolist(), torque_enu_n_m.tolist()):
            if any(f):
                force(bid, -1, f, at, world, cid)                    # positional: see read_states
            if any(t):
                torque(bid, -1, t, world, cid)

    def attach_fixed(self, parent_body: int, child_body: int, max_force_n: float = 1e5) -> int:
        """Join ``child_body`` rigidly to ``parent_body`` at their current relative pose; return the constraint id."""
        cid = self.id
        pp, qp = p.getBasePositionAndOrientation(parent_body, physicsClientId=cid)
        pc, qc = p.getBasePositionAndOrientation(child_body, physicsClientId=cid)
        inv_pos, inv_q = p.invertTransform(pp, qp)
        rel_pos, rel_q = p.multiplyTransforms(inv_pos, inv_q, pc, qc)
        constraint = p.createConstraint(parent_body, -1, child_body, -1, p.JOINT_FIXED, [0, 0, 0],
                                        parentFramePosition=rel_pos, childFramePosition=[0, 0, 0],
                                        parentFrameOrientation=rel_q, childFrameOrientation=[0, 0, 0, 1],
                                        physicsClientId=cid)
        p.changeConstraint(constraint, maxForce=max_force_n, physicsClientId=cid)
        return constraint

    def detach(self, constraint_id: int) -> None:
        """Remove a constraint made by :meth:`attach_fixed`."""
        p.removeConstraint(constraint_id, physicsClientId=self.id)

    def contact_map(self) -> dict[int, set[int]]:
        """Body id -> ids of the bodies it touched at the last step, for every body in contact (one call)."""
        out: dict[int, set[int]] = {}
        for a, b in set(map(_BODIES_OF_POINT, self._all_contact_points())):     # pairs once (up to 4 points each)
            out.setdefault(a, set()).add(b)
            out.setdefault(b, set()).add(a)
        return out

    def contacts(self) -> list[tuple[int, int, tuple[float, float, float]]]:
        """Every contact point after the last step as ``(body_a, body_b, point_on_b_enu_m)`` (one call)."""
        return list(map(_BODIES_AND_POINT, self._all_contact_points()))

    def contact_count(self, body_a: int, body_b: int | None = None) -> int:
        """Number of contact points of ``body_a`` (with ``body_b`` if given) after the last step."""
        if body_b is None:
            return len(p.getContactPoints(bodyA=body_a, physicsClientId=self.id))
        return len(p.getContactPoints(bodyA=body_a, bodyB=body_b, physicsClientId=self.id))

    def save_state(self) -> int:
        """Keep the whole physics state in memory (every body's pose and velocity, contacts); its id."""
        return p.saveState(physicsClientId=self.id)

    def restore_state(self, state_id: int) -> None:
        """Put the physics back to a state kept by :meth:`save_state` (bodies and constraints added since
        are not removed: the caller removes them first)."""
        p.restoreState(stateId=state_id, physicsClientId=self.id)
        self._contact_points = None

    def drop_contacts(self, body_ids: Any, far_z_m: float = 10_000.0) -> None:
        """Forget the contact manifolds of ``body_ids``: PyBullet keeps them across :meth:`restore_state`
        (their points and impulses warm-start the next solve), so a body put back where it touched
        something would start from forces of another time. Each body is lifted far apart and the
        contacts computed once, which drops them; the caller puts the bodies where they belong next."""
        for k, body in enumerate(np.asarray(body_ids).tolist()):
            p.resetBasePositionAndOrientation(int(body), (0.0, 50.0 * k, far_z_m), (0.0, 0.0, 0.0, 1.0),
                                              physicsClientId=self.id)
        p.performCollisionDetection(physicsClientId=self.id)
        self._contact_points = None

    def reset_body(self, body_id: int, pos_enu_m: Any, quat_xyzw: Any, vel_enu_m_s: Any = (0.0, 0.0, 0.0),
                   rate_enu_rad_s: Any = (0.0, 0.0, 0.0)) -> None:
        """Teleport a body: new base pose [m, xyzw] and velocities [m/s, rad/s] (ENU), nothing else changed."""
        p.resetBasePositionAndOrientation(body_id, list(pos_enu_m), list(quat_xyzw), physicsClientId=self.id)
        p.resetBaseVelocity(body_id, list(vel_enu_m_s), list(rate_enu_rad_s), physicsClientId=self.id)
        self._contact_points = None

    def remove_body(self, body_id: int) -> None:
        p.removeBody(body_id, physicsClientId=self.id)
        self._contact_points = None

    def close(self) -> None:
        """Disconnect; safe to call twice."""
        if self.id >= 0:
            try:
                p.disconnect(physicsClientId=self.id)
            finally:
                self.id = -1
