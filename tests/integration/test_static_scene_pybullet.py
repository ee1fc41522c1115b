"""The static scene built in PyBullet matches the layout: ray hits, body count, geometry."""

from __future__ import annotations

import numpy as np
import pybullet as p
import pytest

from unetyemu_ecs.physics.static_scene import build_static_scene
from unetyemu_ecs.scene import ROAD_TOP_Z_M, BuildingSpec, SceneClass, SceneConfig, build_layout

SEED = 1234
RAY_TOL_M = 1e-3   # primitives are exact for ray tests; 1 mm covers float round-trips through URDF text


@pytest.fixture
def client():
    cid = p.connect(p.DIRECT)
    yield cid
    p.disconnect(cid)


@pytest.fixture
def city(client):
    cfg = SceneConfig(
        generator="urban",
        buildings=[BuildingSpec(name="probe", center_m=(0.0, 250.0), size_m=(10.0, 6.0), height_m=15.0)],
    )
    layout = build_layout(cfg, SEED)
    return layout, build_static_scene(client, layout)


def _ray(client, start, end):
    hit = p.rayTest(start, end, physicsClientId=client)[0]
    return hit[0], np.array(hit[3])


def test_vertical_ray_onto_roof_pad_hits_its_top(client, city):
    # GIVEN the city in PyBullet and its roof pad
    layout, ids = city
    x, y, z = layout.pads["roof_1"].center_enu_m
    # WHEN a ray is cast from 100 m straight down onto the pad centre
    body, pos = _ray(client, [x, y, 100.0], [x, y, -1.0])
    # THEN it hits the pad body at the pad's top
    assert ids[body] == SceneClass.PAD
    assert abs(pos[2] - z) < RAY_TOL_M


def test_vertical_ray_onto_road_hits_road_surface(client, city):
    # GIVEN a point in the middle of the first north-south street
    layout, ids = city
    road = next(o for o in layout.objects if o.cls == SceneClass.ROAD)
    x, y = road.shapes[0].center_enu_m[:2]
    # WHEN a ray is cast straight down THEN it hits the road body at the road top
    body, pos = _ray(client, [x, y, 100.0], [x, y, -1.0])
    assert ids[body] == SceneClass.ROAD
    assert abs(pos[2] - ROAD_TOP_Z_M) < RAY_TOL_M


def test_default_city_is_a_few_static_bodies(client, city):
    # GIVEN the built default city WHEN bodies are counted THEN there are few, all static
    _, ids = city
    assert p.getNumBodies(physicsClientId=client) == len(ids) <= 10
    assert all(p.getDynamicsInfo(b, -1, physicsClientId=client)[0] == 0.0 for b in ids)


def test_horizontal_ray_hits_building_face_at_known_distance(client, city):
    # GIVEN the probe building spanning x in [-5, 5] at y = 250
    # WHEN a ray at 1.5 m height travels east from x = -20
    body, pos = _ray(client, [-20.0, 250.0, 1.5], [0.0, 250.0, 1.5])
    # THEN it hits the building body 15 m away at its west face
    assert city[1][body] == SceneClass.BUILDING
    assert abs(pos[0] - (-5.0)) < RAY_TOL_M


def test_vertical_ray_onto_tree_crown_hits_crown_top(client, city):
    # GIVEN a tree WHEN a ray is cast down onto its axis THEN it hits the crown top
    layout, ids = city
    tree = next(o for o in layout.objects if o.cls == SceneClass.TREE)
    crown = tree.shapes[1]
    x, y, zc = crown.center_enu_m
    body, pos = _ray(client, [x, y, 100.0], [x, y, -1.0])
    assert ids[body] == SceneClass.TREE
    assert abs(pos[2] - (zc + crown.radius_m)) < RAY_TOL_M


def test_ground_and_road_have_high_friction(client, city):
    # GIVEN the built scene WHEN friction is read THEN ground and road use 0.9
    _, ids = city
    by_cls = {cls: body for body, cls in ids.items()}
    assert p.getDynamicsInfo(by_cls[SceneClass.GROUND], -1, physicsClientId=client)[1] == pytest.approx(0.9)
    assert p.getDynamicsInfo(by_cls[SceneClass.ROAD], -1, physicsClientId=client)[1] == pytest.approx(0.9)


def test_box_dropped_on_sidewalk_comes_to_rest_on_curb_top(client, city):
    # GIVEN a 0.4 m cube released just above a sidewalk centre
    layout, _ = city
    sidewalk = next(o for o in layout.objects if o.cls == SceneClass.SIDEWALK).shapes[0]
    x, y = sidewalk.center_enu_m[:2]
    top = sidewalk.top_z_m
    p.setGravity(0, 0, -9.81, physicsClientId=client)
    cube = p.createMultiBody(1.0, p.createCollisionShape(p.GEOM_BOX, halfExtents=[0.2] * 3, physicsClientId=client),
                             -1, [x, y, top + 0.3], physicsClientId=client)
    # WHEN simulated for 2 s
    for _ in range(480):
        p.stepSimulation(physicsClientId=client)
    # THEN it rests on the curb top (within 1 cm of Bullet's contact slop)
    z = p.getBasePositionAndOrientation(cube, physicsClientId=client)[0][2]
    assert abs(z - (top + 0.2)) < 0.01
