"""Turn one world-file entity (package, car or drone) into a PyBullet body and an esper entity.

Units and frames (REP 103): positions are ENU [m] in the PyBullet world (x East, y North, z up,
gravity along -z); ``EntityDefinition.pos_enu_m`` is the centre of the body (a box's centre, a car's
chassis centre). ``yaw_rad`` turns the body about ENU z, 0 = facing East, counter-clockwise
positive; the body frame is FLU with its origin at that centre, and the base orientation handed to
PyBullet is the quaternion of body FLU in ENU, xyzw. Masses are [kg] (a car's ``mass_kg`` is the
whole car: chassis, wheels and knuckles), half extents [m] along FLU x, y, z, colours RGBA in
[0, 1]. A car's wheel centres sit ``wheel_radius_m - ground_clearance_m - half_z`` [m] from the
chassis centre along body z (negative: below it), so the chassis' underside clears the ground by
``ground_clearance_m`` when the tyres touch it.

:func:`spawn_entity` needs the simulation's esper world active (``with ecs.active():``): it creates
the entity there and gives it its fleet row.
"""

from __future__ import annotations

import math

import esper
import numpy as np

from ..components.body import Appearance, FleetSlot, Identity, RigidBody
from ..components.car import CarBody, CarDynamics
from ..components.mission import MissionRuntime
from ..config.world_file import EntityDefinition
from ..fleet import FleetState
from ..frames import quat_xyzw_from_euler_rpy
from ..physics.bodies import create_box_body
from ..physics.car_body import CarGeometry, create_car_body
from ..physics.client import PhysicsClient

PACKAGE_RGBA = (0.80, 0.60, 0.30, 1.0)   # cardboard brown


def spawn_entity(physics: PhysicsClient, fleet: FleetState, ent: EntityDefinition) -> int:
    """Create ``ent``'s PyBullet body, its fleet row and its esper entity with every component; return
    the esper entity id.

    Components: Identity, FleetSlot, RigidBody, Appearance, CarBody (cars), then the world file's
    components as given (``mission`` becomes a MissionRuntime around its MissionSpec).
    """
    quat_enu_flu_xyzw = np.asarray(quat_xyzw_from_euler_rpy(0.0, 0.0, ent.yaw_rad)).ravel()
    mass_kg = float(ent.params["mass_kg"])
    car_joints = None
    rgba = tuple(float(c) for c in (PACKAGE_RGBA if ent.kind == "package" else ent.params["rgba"]))
    if ent.kind == "package":
        half_m = np.asarray(ent.params["size_m"], dtype=float) / 2.0
        body = create_box_body(physics.id, half_m, mass_kg, ent.pos_enu_m, quat_enu_flu_xyzw, rgba)
    elif ent.kind == "car":
        half_m = np.asarray(ent.params["body_half_extents_m"], dtype=float)
        dyn: CarDynamics = ent.components["car_dynamics"]
        clearance_m = float(ent.params["ground_clearance_m"])
        geometry = CarGeometry(
            half_extents_m=tuple(half_m), mass_kg=mass_kg, wheelbase_m=dyn.wheelbase_m, track_m=dyn.track_m,
            wheel_radius_m=dyn.wheel_radius_m, wheel_width_m=dyn.wheel_width_m, wheel_mass_kg=dyn.wheel_mass_kg,
            wheel_z_m=dyn.wheel_radius_m - clearance_m - half_m[2], max_steer_rad=math.radians(dyn.max_steer_deg),
            suspension_travel_m=dyn.suspension_travel_m, rgba=rgba)
        body, car_joints = create_car_body(physics.id, geometry, ent.pos_enu_m, quat_enu_flu_xyzw, dyn.tyre_friction)
    else:
        half_m = np.asarray(ent.params["body_half_extents_m"], dtype=float)
        body = create_box_body(physics.id, half_m, mass_kg, ent.pos_enu_m, quat_enu_flu_xyzw, rgba)
    eid = esper.create_entity()
    row = fleet.allocate(eid, body)
    esper.add_component(eid, Identity(name=ent.name, kind=ent.kind, preset=ent.preset, index=ent.index))
    esper.add_component(eid, FleetSlot(row=row))
    esper.add_component(eid, RigidBody(body_id=body, mass_kg=mass_kg, half_extents_m=half_m))
    esper.add_component(eid, Appearance(rgba=rgba))
    if car_joints is not None:
        esper.add_component(eid, CarBody(joints=car_joints))
    for key, comp in ent.components.items():
        if key == "mission":
            esper.add_component(eid, MissionRuntime(spec=comp))
        else:
            esper.add_component(eid, comp)
    for _name, params in ent.controllers.values():    # the parameters of each layer's controller select it
        esper.add_component(eid, params)
    return eid


__all__ = ["PACKAGE_RGBA", "spawn_entity"]
