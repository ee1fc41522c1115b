"""Behaviour of the procedural city, the layout builder and the scene mesh (no PyBullet)."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose

from unetyemu_ecs import load_world_text
from unetyemu_ecs.scene import (
    PAD_THICKNESS_M,
    Box,
    BuildingSpec,
    PadSpec,
    SceneClass,
    SceneConfig,
    UrbanParams,
    build_layout,
    generate_urban,
    triangulate,
)
from unetyemu_ecs.scene.urban import PAD_CLEARANCE_M

SEED = 1234


@pytest.fixture(scope="module")
def city():
    return build_layout(SceneConfig(generator="urban"), SEED)


def _boxes_of(layout, cls):
    return [(o, s) for o in layout.objects if o.cls == cls for s in o.shapes if isinstance(s, Box)]


def _rect(box):
    c, h = box.center_enu_m, box.half_extents_m
    return np.array([c[0] - h[0], c[1] - h[1], c[0] + h[0], c[1] + h[1]])


def _overlap_area(a, b):
    return max(0.0, min(a[2], b[2]) - max(a[0], b[0])) * max(0.0, min(a[3], b[3]) - max(a[1], b[1]))


def _distance_to_rect(x, y, r):
    return float(np.hypot(max(r[0] - x, x - r[2], 0.0), max(r[1] - y, y - r[3], 0.0)))


def test_same_seed_gives_identical_mesh_digest():
    # GIVEN the default city config WHEN built twice with one seed THEN the meshes are identical
    cfg = SceneConfig(generator="urban")
    assert triangulate(build_layout(cfg, 7)).digest() == triangulate(build_layout(cfg, 7)).digest()


def test_different_seed_gives_different_mesh_digest():
    # GIVEN the default city config WHEN built with two seeds THEN the meshes differ
    cfg = SceneConfig(generator="urban")
    assert triangulate(build_layout(cfg, 7)).digest() != triangulate(build_layout(cfg, 8)).digest()


def test_no_building_overlaps_a_street_or_another_building(city):
    # GIVEN the default city
    buildings = [_rect(s) for _, s in _boxes_of(city, SceneClass.BUILDING)]
    roads = [_rect(s) for _, s in _boxes_of(city, SceneClass.ROAD)]
    assert len(buildings) > 20 and len(roads) > 0
    # WHEN footprints are intersected THEN no building touches a road or another building
    for i, b in enumerate(buildings):
        assert all(_overlap_area(b, r) == 0.0 for r in roads)
        assert all(_overlap_area(b, o) == 0.0 for o in buildings[i + 1:])


def test_buildings_keep_the_configured_gap_to_each_other(city):
    # GIVEN the default city WHEN neighbouring footprints are compared THEN they are >= building_gap_m apart
    gap = UrbanParams().building_gap_m
    rects = np.array([_rect(s) for _, s in _boxes_of(city, SceneClass.BUILDING)])
    for i, a in enumerate(rects):
        for b in rects[i + 1:]:
            dx = max(b[0] - a[2], a[0] - b[2])
            dy = max(b[1] - a[3], a[1] - b[3])
            assert max(dx, dy) >= gap - 1e-9


def test_every_building_height_is_within_the_configured_range():
    # GIVEN a narrow height range WHEN a city is generated THEN every building stands on the ground within it
    params = UrbanParams(building_height_m=(12.0, 18.0))
    layout = generate_urban(params, np.random.default_rng(SEED))
    for _, s in _boxes_of(layout, SceneClass.BUILDING):
        assert s.center_enu_m[2] - s.half_extents_m[2] == pytest.approx(0.0, abs=1e-12)
        assert 12.0 <= 2.0 * s.half_extents_m[2] <= 18.0


def test_pads_exist_with_configured_counts_and_names():
    # GIVEN 3 start, 5 target and 2 roof pads WHEN generated THEN exactly those named pads exist
    params = UrbanParams(start_pads=3, target_pads=5, roof_pads=2)
    layout = generate_urban(params, np.random.default_rng(SEED))
    expected = {"start_1", "start_2", "start_3", "target_1", "target_2", "target_3", "target_4", "target_5",
                "roof_1", "roof_2"}
    assert set(layout.pads) == expected
    assert all(layout.pads[f"start_{k}"].kind == "start" for k in (1, 2, 3))
    assert all(layout.pads[n].kind == "target" and layout.pads[n].on_roof for n in ("roof_1", "roof_2"))
    assert not any(layout.pads[f"target_{k}"].on_roof for k in range(1, 6))


def test_roof_pad_top_is_roof_height_plus_pad_thickness(city):
    # GIVEN a roof pad WHEN the building under its centre is found THEN the pad top = roof + thickness
    pad = city.pads["roof_1"]
    x, y, z = pad.center_enu_m
    under = [s for _, s in _boxes_of(city, SceneClass.BUILDING) if _distance_to_rect(x, y, _rect(s)) == 0.0]
    assert len(under) == 1
    assert z == pytest.approx(under[0].top_z_m + PAD_THICKNESS_M, abs=1e-9)
    assert under[0].top_z_m <= UrbanParams().roof_pad_max_height_m


def test_ground_pads_have_two_metres_free_of_buildings_and_trees(city):
    # GIVEN the ground pads WHEN distances from each pad's square to buildings and tree trunks/crowns are
    # measured THEN every one is at least the 2 m clearance
    buildings = [_rect(s) for _, s in _boxes_of(city, SceneClass.BUILDING)]
    trees = [(o.shapes[1].center_enu_m, o.shapes[1].radius_m) for o in city.objects if o.cls == SceneClass.TREE]
    ground = [p for p in city.pads.values() if not p.on_roof]
    assert len(ground) == 8
    for pad in ground:
        h = 0.5 * pad.size_m
        sq = np.array([pad.center_enu_m[0] - h, pad.center_enu_m[1] - h, pad.center_enu_m[0] + h, pad.center_enu_m[1] + h])
        for b in buildings:
            gap = np.hypot(max(b[0] - sq[2], sq[0] - b[2], 0.0), max(b[1] - sq[3], sq[1] - b[3], 0.0))
            assert gap >= PAD_CLEARANCE_M
        for c, r in trees:
            assert _distance_to_rect(c[0], c[1], sq) - r >= PAD_CLEARANCE_M


def test_parking_spots_have_two_metres_free_of_buildings_and_trunks_and_lie_on_road(city):
    # GIVEN the parking spots WHEN compared with buildings, trunks and roads THEN each is >= 2 m clear and on a road
    assert list(city.parking) == [f"parking_{k}" for k in range(1, UrbanParams().parking_spots + 1)]
    buildings = [_rect(s) for _, s in _boxes_of(city, SceneClass.BUILDING)]
    trunks = [o.shapes[0] for o in city.objects if o.cls == SceneClass.TREE]
    roads = [_rect(s) for _, s in _boxes_of(city, SceneClass.ROAD)]
    for spot in city.parking.values():
        x, y, z = spot.center_enu_m
        assert all(_distance_to_rect(x, y, b) >= PAD_CLEARANCE_M for b in buildings)
        assert all(np.hypot(x - t.center_enu_m[0], y - t.center_enu_m[1]) - t.radius_m >= PAD_CLEARANCE_M for t in trunks)
        assert any(_distance_to_rect(x, y, r) == 0.0 for r in roads)
        assert z == pytest.approx(city.surface_height_m(x, y))


def test_explicit_building_appears_in_mesh_with_its_id_class_and_bounds():
    # GIVEN an explicit 10 x 6 x 15 m building at (30, -20) in an empty world
    cfg = SceneConfig(buildings=[BuildingSpec(name="tower", center_m=(30.0, -20.0), size_m=(10.0, 6.0), height_m=15.0)])
    layout = build_layout(cfg, SEED)
    # WHEN triangulated
    mesh = triangulate(layout)
    (oid,) = [o.object_id for o in layout.objects if o.name == "tower"]
    sel = mesh.object_id == oid
    # THEN its 12 triangles are class BUILDING and span exactly the spec
    assert sel.sum() == 12
    assert np.all(mesh.cls[sel] == SceneClass.BUILDING)
    v = mesh.vertices_m[np.unique(mesh.triangles[sel])]
    assert_allclose(v.min(axis=0), [25.0, -23.0, 0.0], atol=1e-12)
    assert_allclose(v.max(axis=0), [35.0, -17.0, 15.0], atol=1e-12)


def test_pad_without_z_rests_on_the_roof_below_it():
    # GIVEN an explicit building and a pad over it with z_m None
    cfg = SceneConfig(
        buildings=[BuildingSpec(name="tower", center_m=(30.0, -20.0), size_m=(10.0, 6.0), height_m=15.0)],
        pads=[PadSpec(name="helipad", position_m=(30.0, -20.0))],
    )
    # WHEN the layout is built THEN the pad top is the roof plus the pad thickness, flagged on_roof
    pad = build_layout(cfg, SEED).pads["helipad"]
    assert_allclose(pad.center_enu_m, [30.0, -20.0, 15.0 + PAD_THICKNESS_M], atol=1e-12)
    assert pad.on_roof


def test_duplicate_pad_name_is_rejected_naming_the_item():
    # GIVEN a city (which has start_1) and an explicit pad also named start_1
    cfg = SceneConfig(generator="urban", pads=[PadSpec(name="extra", position_m=(0.0, 0.0), z_m=50.0),
                                               PadSpec(name="start_1", position_m=(1.0, 1.0), z_m=60.0)])
    # WHEN built THEN a ValueError names the item and the name
    with pytest.raises(ValueError, match=r"scene\.pads\[1\]: duplicate pad name 'start_1'"):
        build_layout(cfg, SEED)


def test_pad_straddling_a_roof_edge_is_rejected():
    # GIVEN a pad whose footprint hangs over a building edge WHEN built THEN a ValueError names it
    cfg = SceneConfig(buildings=[BuildingSpec(center_m=(0.0, 0.0), size_m=(10.0, 10.0), height_m=10.0)],
                      pads=[PadSpec(name="edge", position_m=(5.0, 0.0))])
    with pytest.raises(ValueError, match=r"scene\.pads\[0\].*straddles"):
        build_layout(cfg, SEED)


def test_every_box_triangle_faces_outwards(city):
    # GIVEN the mesh of the default city plus a yawed building
    cfg = SceneConfig(generator="urban", buildings=[BuildingSpec(center_m=(0.0, 300.0), size_m=(8.0, 4.0), height_m=9.0, yaw_deg=30.0)])
    layout = build_layout(cfg, SEED)
    mesh = triangulate(layout)
    boxes = [(o.object_id, s) for o in layout.objects for s in o.shapes if isinstance(s, Box)]
    # WHEN each box triangle's normal is compared with the direction from the box centre
    # (boxes come first in the mesh, 12 triangles each, in object order)
    tri = mesh.vertices_m[mesh.triangles[: 12 * len(boxes)]]
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    centres = np.repeat(np.array([s.center_enu_m for _, s in boxes]), 12, axis=0)
    # THEN every normal points away from its box's centre
    assert np.all(np.einsum("ij,ij->i", normal, tri.mean(axis=1) - centres) > 0.0)
    assert np.array_equal(mesh.object_id[: 12 * len(boxes)], np.repeat([i for i, _ in boxes], 12))


def test_scene_config_loads_from_yaml_mapping_through_the_schema():
    # GIVEN a parsed YAML scene section
    from unetyemu_ecs.config.schema import SourceMap, parse
    data = {"generator": "urban", "urban": {"blocks_x": 2, "blocks_y": 3, "building_height_m": [10, 20]},
            "buildings": [{"center_m": [1, 2], "size_m": [3, 4], "height_m": 5}],
            "pads": [{"name": "p", "position_m": [0, 0], "kind": "start"}]}
    # WHEN converted THEN the dataclasses carry the values
    cfg = parse(data, SceneConfig, SourceMap("w.yaml"))
    assert cfg.urban.blocks_y == 3 and cfg.urban.building_height_m == (10.0, 20.0)
    assert cfg.buildings[0].size_m == (3.0, 4.0) and cfg.pads[0].kind == "start"


def test_depot_block_outside_grid_is_rejected():
    # GIVEN a depot block outside a 2 x 2 grid WHEN the params are built THEN a ValueError says so
    with pytest.raises(ValueError, match="depot_block"):
        UrbanParams(blocks_x=2, blocks_y=2, depot_block=(2, 0))


def test_nearest_object_names_the_building_a_point_on_its_face_belongs_to(city):
    # GIVEN every building in the city and a point 1 cm outside the middle of its east face
    for obj, box in _boxes_of(city, SceneClass.BUILDING)[:40]:
        c, h, yaw = box.center_enu_m, box.half_extents_m, box.yaw_rad
        east_face = c + np.array([np.cos(yaw), np.sin(yaw), 0.0]) * (h[0] + 0.01)
        # WHEN the nearest building is looked up THEN it is that building, 1 cm away
        found, dist = city.nearest_object(east_face, SceneClass.BUILDING)
        assert found.object_id == obj.object_id
        assert dist == pytest.approx(0.01, abs=1e-9)


def test_nearest_object_measures_to_tree_crowns_and_the_ground(city):
    tree = next(o for o in city.objects if o.cls == SceneClass.TREE)
    crown = tree.shapes[1]
    above = crown.center_enu_m + np.array([0.0, 0.0, crown.radius_m + 0.5])
    found, dist = city.nearest_object(above, SceneClass.TREE)
    assert found.object_id == tree.object_id and dist == pytest.approx(0.5)
    found, dist = city.nearest_object(np.array([0.0, 0.0, 0.3]), SceneClass.GROUND)
    assert found.object_id == 0 and dist == pytest.approx(0.3)



@pytest.mark.parametrize("seed", [5, 6, 9, 19])
def test_a_truck_fits_every_parking_spot_under_the_trees(seed):
    # GIVEN the default city with these seeds (each once grew a low crown over a parking spot)
    trucks = "".join(f"  - {{name: t{k}, type: car, preset: truck, pose: {{parking: parking_{k}}}}}\n"
                     for k in range(1, 9))
    # WHEN a truck is parked on every spot THEN the world loads: no body starts inside a tree crown
    world = load_world_text(f"world: {{seed: {seed}}}\nscene: {{generator: urban}}\nvehicles:\n{trucks}")
    assert len(world.vehicles) == 8
