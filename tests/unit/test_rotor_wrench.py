"""Four rotor forces at their hubs are, for the rigid body, one force at the centre of mass and one
torque: the formula against the cross products, and PyBullet's response to both against each other."""

from __future__ import annotations

import numpy as np
import pybullet as p
import pytest

from unetyemu_ecs.control.mixer import SPIN_REACTION_SIGN, motor_positions_flu_m
from unetyemu_ecs.control.rotor_wrench import rotor_torque_matrix_flu, rotor_wrench_enu
from unetyemu_ecs.frames import R_from_quat_xyzw, quat_normalize_xyzw


def test_the_resultant_is_the_sum_of_the_hub_forces_and_their_moments_plus_the_reaction_torques(rng):
    n = 6
    thrust = rng.uniform(0.0, 30.0, (n, 4))
    q = quat_normalize_xyzw(rng.normal(size=(n, 4)))
    R = R_from_quat_xyzw(q)
    hubs = motor_positions_flu_m(rng.uniform(0.1, 0.5, n))
    kappa = rng.uniform(0.005, 0.03, n)
    force, torque = rotor_wrench_enu(thrust, R, rotor_torque_matrix_flu(hubs, kappa))
    for k in range(n):
        z = R[k, :, 2]
        f_i = thrust[k, :, None] * z                                        # each motor's force, ENU
        r_i = hubs[k] @ R[k].T                                              # each hub from the CoM, ENU
        expected_torque = np.cross(r_i, f_i).sum(axis=0) + kappa[k] * (thrust[k] @ SPIN_REACTION_SIGN) * z
        assert force[k] == pytest.approx(f_i.sum(axis=0), abs=1e-12)
        assert torque[k] == pytest.approx(expected_torque, abs=1e-12)


def _box(cid: int, pos, quat) -> int:
    shape = p.createCollisionShape(p.GEOM_BOX, halfExtents=[0.25, 0.25, 0.08], physicsClientId=cid)
    return p.createMultiBody(8.0, shape, basePosition=pos, baseOrientation=quat, physicsClientId=cid)


def test_pybullet_moves_a_body_the_same_under_four_hub_forces_and_under_their_resultant(rng):
    # GIVEN two identical drone bodies in the same tilted, spinning state, far apart, no gravity
    cid = p.connect(p.DIRECT)
    try:
        p.setGravity(0, 0, 0, physicsClientId=cid)
        p.setTimeStep(1 / 240, physicsClientId=cid)
        q0 = quat_normalize_xyzw([0.1, -0.2, 0.3, 0.9])
        hub_body, wrench_body = _box(cid, [0, 0, 5], q0), _box(cid, [10, 0, 5], q0)
        for b in (hub_body, wrench_body):
            p.resetBaseVelocity(b, [0.5, -0.2, 0.1], [0.3, 0.1, -0.4], physicsClientId=cid)
        hubs = motor_positions_flu_m([0.354])
        matrix = rotor_torque_matrix_flu(hubs, [0.016])
        for _ in range(120):                            # half a second of uneven, changing thrusts (FL strongest)
            thrust = rng.uniform(5.0, 20.0, (1, 4)) + [[10.0, 0.0, 0.0, 0.0]]
            # WHEN one gets each motor's force at its hub plus the reaction torque, the other the resultant
            pos, quat = p.getBasePositionAndOrientation(hub_body, physicsClientId=cid)
            R = R_from_quat_xyzw(np.array([quat]))
            z = R[0, :, 2]
            for i in range(4):
                hub_enu = np.array(pos) + R[0] @ hubs[0, i]
                p.applyExternalForce(hub_body, -1, (thrust[0, i] * z).tolist(), hub_enu.tolist(), p.WORLD_FRAME,
                                     physicsClientId=cid)
            reaction = 0.016 * float(thrust[0] @ SPIN_REACTION_SIGN) * z
            p.applyExternalTorque(hub_body, -1, reaction.tolist(), p.WORLD_FRAME, physicsClientId=cid)
            pos_w, quat_w = p.getBasePositionAndOrientation(wrench_body, physicsClientId=cid)
            force, torque = rotor_wrench_enu(thrust, R_from_quat_xyzw(np.array([quat_w])), matrix)
            p.applyExternalForce(wrench_body, -1, force[0].tolist(), list(pos_w), p.WORLD_FRAME, physicsClientId=cid)
            p.applyExternalTorque(wrench_body, -1, torque[0].tolist(), p.WORLD_FRAME, physicsClientId=cid)
            p.stepSimulation(physicsClientId=cid)
        # THEN both moved and turned the same (to rounding): same velocity, rates and attitude
        (pa, qa), (pb, qb) = (p.getBasePositionAndOrientation(b, physicsClientId=cid)
                              for b in (hub_body, wrench_body))
        va, wa = p.getBaseVelocity(hub_body, physicsClientId=cid)
        vb, wb = p.getBaseVelocity(wrench_body, physicsClientId=cid)
        assert np.linalg.norm(va) > 1.0 and np.linalg.norm(wa) > 1.0          # the thrusts did act
        assert va == pytest.approx(vb, abs=1e-9) and wa == pytest.approx(wb, abs=1e-9)
        assert np.subtract(pa, [0, 0, 0]) == pytest.approx(np.subtract(pb, [10, 0, 0]), abs=1e-9)
        assert abs(abs(float(np.dot(qa, qb))) - 1.0) < 1e-12
    finally:
        p.disconnect(cid)
