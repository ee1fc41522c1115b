"""Wheeled cars in PyBullet: a chassis with four sprung wheels, front steering, drive and brakes.

Each car is one multibody loaded from a generated URDF:

- ``chassis`` (base): a box, FLU, its centre at the body frame origin;
- per wheel (fl, fr, rl, rr): a prismatic ``susp_*`` joint along the chassis z axis (travel
  +/- ``suspension_travel_m``), a revolute ``steer_*`` joint about z on the front wheels (limited to
  ``max_steer``), and a continuous ``wheel_*`` joint about the wheel's axle (FLU y) carrying a
  cylinder tyre.

The suspension is a spring-damper applied as a joint force every step, ``-k x - c v - m_corner g``
(the preload makes zero deflection the static rest position), so ride, pitch under braking and
roll in turns come from the physics. Drive torque acts on the rear wheel joints; brakes are each
wheel's velocity motor with target 0 and a maximum torque equal to the brake torque (PyBullet
applies exactly up to that torque to stop the wheel, and holds a stopped car); steering is a
position servo. A parked car at rest sleeps (Bullet deactivation) until touched or driven.
Tyre/road friction is PyBullet's contact friction (Bullet multiplies the two
bodies' coefficients: ``tyre_friction x 0.9`` on the road).

A tyre's contacts reach the solver only within :data:`WHEEL_CONTACT_PROCESSING_M` of touching (Bullet's
``contactProcessingThreshold``; by default every contact within the 2 cm contact margin does). The road's
surface lies ``ROAD_TOP_Z_M`` (2 mm) above the ground plane (so that cameras and LiDAR can tell them
apart), so a tyre on a road would also hand the solver its four contacts with the plane 2 mm below,
which never push: they made a third of a driving car's physics time.
"""

from __future__ import annotations

import math
import os
import tempfile
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pybullet as p

from ..scene.primitives import ROAD_TOP_Z_M

WHEELS = ("fl", "fr", "rl", "rr")
LINK_MASS_KG = 1.0              # suspension and steering knuckles (Featherstone needs mass > 0)
STEER_SERVO_TORQUE_N_M = 1.0e4  # strong enough that the servo always reaches the commanded angle
WHEEL_CONTACT_PROCESSING_M = 0.5 * ROAD_TOP_Z_M   # [m] tyre contacts solved within this gap (< the road's height)


@dataclass(frozen=True)
class CarGeometry:
    """What the URDF needs; lengths in metres, FLU, relative to the chassis centre."""

    half_extents_m: tuple[float, float, float]
    mass_kg: float                   # whole car: chassis + wheels + knuckles
    wheelbase_m: float
    track_m: float
    wheel_radius_m: float
    wheel_width_m: float
    wheel_mass_kg: float
    wheel_z_m: float                 # wheel centre below the chassis centre at rest (negative)
    max_steer_rad: float
    suspension_travel_m: float
    rgba: tuple[float, float, float, float]

    @property
    def chassis_mass_kg(self) -> float:
        return self.mass_kg - 4 * self.wheel_mass_kg - 6 * LINK_MASS_KG


@dataclass(frozen=True)
class CarJoints:
    """Joint indices of one car body: suspension (fl, fr, rl, rr), steering (fl, fr), wheels (fl, fr, rl, rr)."""

    suspension: tuple[int, int, int, int]
    steering: tuple[int, int]
    wheels: tuple[int, int, int, int]


def _urdf(g: CarGeometry) -> str:
    hx, hy, hz = (float(h) for h in g.half_extents_m)
    m = float(g.chassis_mass_kg)
    ixx, iyy, izz = m * (hy * hy + hz * hz) / 3.0, m * (hx * hx + hz * hz) / 3.0, m * (hx * hx + hy * hy) / 3.0
    r, w, mw = float(g.wheel_radius_m), float(g.wheel_width_m), float(g.wheel_mass_kg)
    i_axle, i_diam = 0.5 * mw * r * r, mw * (3.0 * r * r + w * w) / 12.0
    knuckle = (f'<inertial><mass value="{LINK_MASS_KG}"/>'
               '<inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial>')
    rgba = " ".join(f"{c:g}" for c in g.rgba)
    out = ['<robot name="car">',
           '<material name="body"><color rgba="' + rgba + '"/></material>',
           '<material name="tyre"><color rgba="0.08 0.08 0.08 1"/></material>',
           f'<link name="chassis"><inertial><mass value="{m!r}"/>'
           f'<inertia ixx="{ixx!r}" ixy="0" ixz="0" iyy="{iyy!r}" iyz="0" izz="{izz!r}"/></inertial>'
           f'<collision><geometry><box size="{2 * hx!r} {2 * hy!r} {2 * hz!r}"/></geometry></collision>'
           f'<visual><geometry><box size="{2 * hx!r} {2 * hy!r} {2 * hz!r}"/></geometry>'
           '<material name="body"/></visual></link>']
    positions = {"fl": (g.wheelbase_m / 2, g.track_m / 2), "fr": (g.wheelbase_m / 2, -g.track_m / 2),
                 "rl": (-g.wheelbase_m / 2, g.track_m / 2), "rr": (-g.wheelbase_m / 2, -g.track_m / 2)}
    wheel_z, travel, steer = float(g.wheel_z_m), float(g.suspension_travel_m), float(g.max_steer_rad)
    for name, (x, y) in positions.items():
        x, y = float(x), float(y)
        out.append(f'<link name="susp_{name}">{knuckle}</link>')
        out.append(f'<joint name="susp_{name}" type="prismatic"><parent link="chassis"/><child link="susp_{name}"/>'
                   f'<origin xyz="{x!r} {y!r} {wheel_z!r}"/><axis xyz="0 0 1"/>'
                   f'<limit lower="{-travel!r}" upper="{travel!r}" effort="1e7" velocity="100"/>'
                   '</joint>')
        parent = f"susp_{name}"
        if name in ("fl", "fr"):
            out.append(f'<link name="steer_{name}">{knuckle}</link>')
            out.append(f'<joint name="steer_{name}" type="revolute"><parent link="{parent}"/><child link="steer_{name}"/>'
                       f'<origin xyz="0 0 0"/><axis xyz="0 0 1"/>'
                       f'<limit lower="{-steer!r}" upper="{steer!r}" effort="1e7" velocity="10"/>'
                       '</joint>')
            parent = f"steer_{name}"
        cyl = f'<origin rpy="{math.pi / 2!r} 0 0"/><geometry><cylinder radius="{r!r}" length="{w!r}"/></geometry>'
        out.append(f'<link name="wheel_{name}"><inertial><mass value="{mw!r}"/>'
                   f'<inertia ixx="{i_diam!r}" ixy="0" ixz="0" iyy="{i_axle!r}" iyz="0" izz="{i_diam!r}"/></inertial>'
                   f'<collision>{cyl}</collision><visual>{cyl}<material name="tyre"/></visual></link>')
        out.append(f'<joint name="wheel_{name}" type="continuous"><parent link="{parent}"/><child link="wheel_{name}"/>'
                   '<origin xyz="0 0 0"/><axis xyz="0 1 0"/></joint>')
    out.append("</robot>")
    return "\n".join(out)


def create_car_body(client_id: int, geometry: CarGeometry, pos_enu_m: Sequence[float],
                    quat_enu_xyzw: Sequence[float], tyre_friction: float) -> tuple[int, CarJoints]:
    """Load a car at ``pos_enu_m`` (chassis centre) and return its body id and joint indices.

    Default joint motors are switched off (PyBullet motorises every joint), damping is zero
    everywhere (losses are explicit: brakes, rolling resistance), tyres get ``tyre_friction``.
    """
    with tempfile.TemporaryDirectory(prefix="unetyemu_car_") as tmp:
        path = os.path.join(tmp, "car.urdf")
        with open(path, "w", encoding="utf-8") as fh:
            fh.write(_urdf(geometry))
        body = p.loadURDF(path, list(pos_enu_m), list(quat_enu_xyzw),
                          flags=p.URDF_USE_IMPLICIT_CYLINDER | p.URDF_USE_INERTIA_FROM_FILE,
                          physicsClientId=client_id)
    n = p.getNumJoints(body, physicsClientId=client_id)
    index = {p.getJointInfo(body, j, physicsClientId=client_id)[1].decode(): j for j in range(n)}
    for link in range(-1, n):
        p.changeDynamics(body, link, linearDamping=0.0, angularDamping=0.0, jointDamping=0.0,
                         physicsClientId=client_id)
    joints = CarJoints(tuple(index[f"susp_{w}"] for w in WHEELS), (index["steer_fl"], index["steer_fr"]),
                       tuple(index[f"wheel_{w}"] for w in WHEELS))
    for j in joints.wheels:
        p.changeDynamics(body, j, lateralFriction=float(tyre_friction), rollingFriction=0.0, spinningFriction=0.0,
                         contactProcessingThreshold=WHEEL_CONTACT_PROCESSING_M,
                         physicsClientId=client_id)
    p.setJointMotorControlArray(body, list(range(n)), p.VELOCITY_CONTROL, forces=[0.0] * n,
                                physicsClientId=client_id)
    return body, joints


def read_suspension(client_id: int, body: int, joints: CarJoints) -> list[tuple[float, float]]:
    """Deflection [m] (positive = wheel pushed up) and its rate [m/s] of each wheel (fl, fr, rl, rr)."""
    return [state[:2] for state in p.getJointStates(body, joints.suspension, physicsClientId=client_id)]


def read_wheel_rates(client_id: int, body: int, joints: CarJoints) -> np.ndarray:
    """Spin rate (4,) [rad/s] of each wheel about its axle (positive = rolling forward)."""
    return np.array([s[1] for s in p.getJointStates(body, list(joints.wheels), physicsClientId=client_id)])


class CarCommander:
    """Send one car's joint commands to PyBullet with as few calls as possible.

    Forces (suspension springs, drive torque) are per step in PyBullet and go out every step in one
    call; steering targets and brake torques are motor settings that persist, so they are sent only
    when they change. Parked cars at rest may sleep (Bullet deactivation: no cost until something
    touches them); :meth:`wake` wakes a car that is about to be driven.
    """

    def __init__(self, client_id: int, body: int, joints: CarJoints) -> None:
        self.cid, self.body, self.joints = client_id, body, joints
        self._torque_joints = list(joints.suspension) + list(joints.wheels)
        self._last_steer: tuple[float, float] | None = None
        self._last_brake: float | None = None
        self.allow_sleep(True)

    def allow_sleep(self, allowed: bool) -> None:
        if allowed:
            p.changeDynamics(self.body, -1, activationState=p.ACTIVATION_STATE_ENABLE_SLEEPING,
                             physicsClientId=self.cid)
        else:
            p.changeDynamics(self.body, -1, activationState=p.ACTIVATION_STATE_DISABLE_SLEEPING,
                             physicsClientId=self.cid)
            p.changeDynamics(self.body, -1, activationState=p.ACTIVATION_STATE_WAKE_UP, physicsClientId=self.cid)

    def apply(self, suspension_force_n: list[float], steer_left_rad: float, steer_right_rad: float,
              rear_wheel_torque_n_m: float, brake_torque_n_m: float) -> None:
        """Command the car for the next step.

        suspension_force_n : 4 forces [N] on the wheel carriers along chassis +z (fl, fr, rl, rr)
        steer_left_rad, steer_right_rad : front-left, front-right wheel angles [rad] (positive = left)
        rear_wheel_torque_n_m : drive torque [N m] on each rear wheel (positive = forward)
        brake_torque_n_m : maximum braking torque [N m] of every wheel (>= 0)
        """
        steer = (round(steer_left_rad, 6), round(steer_right_rad, 6))
        if steer != self._last_steer:
            p.setJointMotorControlArray(self.body, self.joints.steering, p.POSITION_CONTROL,
                                        targetPositions=steer, forces=[STEER_SERVO_TORQUE_N_M] * 2,
                                        physicsClientId=self.cid)
            self._last_steer = steer
        brake = round(brake_torque_n_m, 3)
        if brake != self._last_brake:
            p.setJointMotorControlArray(self.body, self.joints.wheels, p.VELOCITY_CONTROL,
                                        targetVelocities=[0.0] * 4, forces=[brake] * 4, physicsClientId=self.cid)
            self._last_brake = brake
        p.setJointMotorControlArray(self.body, self._torque_joints, p.TORQUE_CONTROL,
                                    forces=[*suspension_force_n, 0.0, 0.0, rear_wheel_torque_n_m,
                                            rear_wheel_torque_n_m], physicsClientId=self.cid)


__all__ = ["WHEELS", "CarCommander", "CarGeometry", "CarJoints", "create_car_body", "read_suspension",
           "read_wheel_rates"]
