"""The ray-cast sensors' compiled post-processing gives what the numpy formulas gave: the hits of a static and a
moving-body cast merged into distances, normals, classes and boxes (bit for bit), the LiDAR's point clouds
(points and rings bit for bit, intensities to float32 rounding) and the rays culled for the moving-body cast (the
same rays).

The reference code below is the code as it was before those changes, copied verbatim (as functions of the
objects the methods belonged to)."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from unetyemu_ecs.frames import quat_normalize_xyzw
from unetyemu_ecs.sensors.lidar import POINT_DTYPE, _write_points
from unetyemu_ecs.sensors.raycast import (EXIT_MARGIN_M, MOVING_BODY, RayHits, RaycastWorld, box_triangles,
                                          direction_bins, moving_body_candidates, moving_body_candidates_binned)


# -- the code before the change (references) -------------------------------------------------------------------------
def cast_prepared_ref(self, rays, start_static_m, start_dynamic_m, boxes, dynamic_rays=None):
    o3d = self._o3d
    m = len(rays)
    start_static = np.asarray(start_static_m, dtype=np.float32)
    hit = self.static.cast_rays(o3d.core.Tensor.from_numpy(rays), nthreads=self.threads)
    t = hit["t_hit"].numpy() + start_static
    normal = hit["primitive_normals"].numpy()
    cls = self._cls_of_prim[np.minimum(hit["primitive_ids"].numpy(), len(self._tri_cls))]   # NO_HIT: invalid id
    box = np.full(m, -1, dtype=np.int32)
    idx = np.arange(m) if dynamic_rays is None else np.asarray(dynamic_rays, dtype=np.intp)
    if boxes is not None and len(boxes[0]) and idx.size:
        verts, tris = box_triangles(*boxes)
        dyn = o3d.t.geometry.RaycastingScene()
        dyn.add_triangles(o3d.core.Tensor(verts.astype(np.float32)), o3d.core.Tensor(tris.astype(np.uint32)))
        start = np.asarray(start_dynamic_m, dtype=np.float32)[idx]
        sub = rays[idx]
        sub[:, :3] += (start - start_static[idx])[:, None] * sub[:, 3:]
        dhit = dyn.cast_rays(o3d.core.Tensor.from_numpy(sub), nthreads=self.threads)
        td = dhit["t_hit"].numpy() + start
        nearer = td < t[idx]
        k = idx[nearer]
        t[k] = td[nearer]
        normal[k] = dhit["primitive_normals"].numpy()[nearer]
        cls[k] = MOVING_BODY
        box[k] = dhit["primitive_ids"].numpy().astype(np.int32)[nearer] // 12
    return RayHits(t, normal, cls, box)


def lidar_cloud_ref(hits, dirs_sensor, cast, rings, min_m, max_m, reflectivity, slices):
    t = hits.t
    kept = (t <= max_m) & (t >= min_m)                      # a miss (inf) is never kept
    # every sensor's points in one array, in sensor order (each cloud is a slice of it), written by
    # columns from the kept rays (np.compress of contiguous rows: the cheapest selection)
    cloud = np.empty(int(np.count_nonzero(kept)), dtype=POINT_DTYPE)
    columns = cloud.view(np.float32).reshape(-1, 5)           # x, y, z, intensity, (ring + padding)
    np.multiply(np.compress(kept, dirs_sensor, axis=0), np.compress(kept, t)[:, None], out=columns[:, :3])
    cos_incidence = np.einsum("ij,ij->i", np.compress(kept, hits.normal, axis=0),
                              np.compress(kept, cast, axis=0)[:, 3:])
    np.multiply(reflectivity[np.compress(kept, hits.cls)], np.abs(cos_incidence), out=columns[:, 3])
    cloud.view(np.uint32).reshape(-1, 5)[:, 4] = np.compress(kept, rings)   # ring, then 2 bytes of padding
    ends = np.cumsum([np.count_nonzero(kept[sl]) for sl in slices]).tolist()
    return cloud, ends


def moving_body_candidates_binned_ref(origins_m, R_world_sensor, dirs_world, bins, max_range_m, centers_m, radii_m,
                                      exclude):
    n = len(origins_m)
    k_rays = len(dirs_world) // max(n, 1)
    v = centers_m[None, :, :] - origins_m[:, None, :]                          # (N, B, 3)
    dist = np.sqrt(np.einsum("nbi,nbi->nb", v, v))
    near = dist - radii_m[None, :] <= np.asarray(max_range_m, dtype=float)[:, None]
    own = np.asarray(exclude, dtype=np.intp)
    mine = own >= 0
    near[np.flatnonzero(mine), own[mine]] = False
    sensor, body = np.nonzero(near)
    if sensor.size == 0:
        return np.empty(0, dtype=np.intp)
    d, r = dist[sensor, body], radii_m[body]
    inside = d <= r                                                            # every ray of that sensor
    whole = np.unique(sensor[inside])
    out = [(whole[:, None] * k_rays + np.arange(k_rays)[None, :]).reshape(-1)] if whole.size else []
    keep = ~inside & ~np.isin(sensor, whole)
    sensor, body, d, r = sensor[keep], body[keep], d[keep], r[keep]
    if sensor.size:
        vp = v[sensor, body]                                                   # (P, 3) world
        u = np.einsum("pji,pj->pi", R_world_sensor[sensor], vp) / d[:, None]   # unit, sensor frame
        reach = np.arcsin(r / d)
        cos_bin = np.clip(u @ bins.axis.T, -1.0, 1.0)                         # (P, bins)
        pair, cell = np.nonzero(np.arccos(cos_bin) <= reach[:, None] + bins.half_angle_rad[None, :])
        if pair.size:
            sizes = np.diff(bins.starts)[cell]
            first = np.repeat(bins.starts[cell] - np.concatenate([[0], np.cumsum(sizes)[:-1]]), sizes)
            ray = bins.order[first + np.arange(sizes.sum())] + np.repeat(sensor[pair] * k_rays, sizes)
            p = np.repeat(pair, sizes)
            along = np.einsum("mi,mi->m", dirs_world[ray], vp[p])
            hit = along >= np.sqrt(d[p] ** 2 - r[p] ** 2)
            out.append(ray[hit])
    if not out:
        return np.empty(0, dtype=np.intp)
    return np.unique(np.concatenate(out)).astype(np.intp)


# -- a small city: ground, a few buildings of other classes, drone-sized moving boxes -------------------------------
def _scene(rng, near: np.ndarray) -> tuple[RaycastWorld, tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """The city, and moving boxes scattered around, one of them 2 m from each point of ``near``."""
    verts = [np.array([[-300.0, -300.0, 0.0], [300.0, -300.0, 0.0], [300.0, 300.0, 0.0], [-300.0, 300.0, 0.0]])]
    tris, cls = [np.array([[0, 1, 2], [0, 2, 3]])], [np.array([1, 1])]
    for k in range(12):
        v, t = box_triangles(np.array([[rng.uniform(-80, 80), rng.uniform(-80, 80), 10.0]]),
                             np.array([[0.0, 0.0, 0.0, 1.0]]), np.array([[5.0, 5.0, 10.0]]))
        tris.append(t + sum(len(x) for x in verts))
        verts.append(v)
        cls.append(np.full(12, 2 + k % 4))
    n_boxes = 30
    centers = np.column_stack([rng.uniform(-40, 40, n_boxes), rng.uniform(-40, 40, n_boxes), rng.uniform(1, 25, n_boxes)])
    centers[:len(near)] = near + [2.0, 0.0, 0.0]
    boxes = (centers, quat_normalize_xyzw(rng.normal(size=(n_boxes, 4))), np.tile([0.3, 0.3, 0.1], (n_boxes, 1)))
    return RaycastWorld(np.vstack(verts), np.vstack(tris), np.concatenate(cls)), boxes


def _rays(rng, n_sensors: int, per_sensor: int):
    origins = np.repeat(rng.uniform([-30, -30, 2], [30, 30, 30], (n_sensors, 3)), per_sensor, axis=0)
    dirs = rng.normal(size=(n_sensors * per_sensor, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    start_static = rng.choice([0.0, 0.05, 0.3], len(dirs))
    start_dynamic = np.where(start_static > 0, start_static + 2 * EXIT_MARGIN_M, 0.0)
    rays = np.empty((len(dirs), 6), dtype=np.float32)
    rays[:, :3] = origins + start_static[:, None] * dirs
    rays[:, 3:] = dirs
    return origins, rays, start_static.astype(np.float32), start_dynamic.astype(np.float32)


@pytest.mark.parametrize("n_sensors, per_sensor, culled", [(1, 500, False), (4, 3000, True), (6, 2000, False)])
def test_merged_static_and_moving_body_hits_are_bit_for_bit_what_they_were(rng, n_sensors, per_sensor, culled):
    origins, rays, start_static, start_dynamic = _rays(rng, n_sensors, per_sensor)
    world, boxes = _scene(rng, origins[::per_sensor])
    dynamic = None
    if culled:
        radii = np.linalg.norm(boxes[2], axis=1) + EXIT_MARGIN_M
        dynamic = np.concatenate([k * per_sensor + moving_body_candidates(origins[k * per_sensor],
                                                                          rays[k * per_sensor:(k + 1) * per_sensor, 3:],
                                                                          np.inf, boxes[0], radii)
                                  for k in range(n_sensors)])
    got = world.cast_prepared(rays.copy(), start_static, start_dynamic, boxes, dynamic)
    want = cast_prepared_ref(world, rays.copy(), start_static, start_dynamic, boxes, dynamic)
    for name in ("t", "normal", "cls", "box"):
        assert getattr(got, name).dtype == getattr(want, name).dtype, name
        assert_array_equal(getattr(got, name), getattr(want, name), err_msg=name)
    # the scene was seen: sky, the ground, buildings and moving bodies
    assert np.isinf(got.t).any() and (got.cls == 1).any() and (got.cls == MOVING_BODY).any() and (got.cls > 1).any()


@pytest.mark.parametrize("n_sensors, per_sensor", [(1, 800), (5, 1200)])
def test_lidar_point_clouds_are_what_they_were(rng, n_sensors, per_sensor):
    origins, rays, start_static, start_dynamic = _rays(rng, n_sensors, per_sensor)
    world, boxes = _scene(rng, origins[::per_sensor])
    hits = world.cast_prepared(rays, start_static, start_dynamic, boxes)
    m = len(rays)
    dirs_sensor = rng.normal(size=(m, 3)).astype(np.float32)
    rings = rng.integers(0, 16, m).astype("<u4")
    min_m, max_m = rng.uniform(0.0, 2.0, n_sensors).astype(np.float32), rng.uniform(20.0, 120.0, n_sensors).astype(np.float32)
    reflectivity = rng.uniform(0.0, 1.0, 256).astype(np.float32)
    slices = [slice(k * per_sensor, (k + 1) * per_sensor) for k in range(n_sensors)]
    want, want_ends = lidar_cloud_ref(hits, dirs_sensor, rays, rings, np.repeat(min_m, per_sensor),
                                      np.repeat(max_m, per_sensor), reflectivity, slices)
    counts = np.empty(n_sensors, dtype=np.intp)
    room = np.empty(m, dtype=POINT_DTYPE)
    _write_points(hits.t, dirs_sensor, hits.normal, rays, hits.cls, rings, np.arange(n_sensors + 1) * per_sensor,
                  min_m, max_m, reflectivity, room.view(np.float32).reshape(-1, 5), room.view(np.uint32).reshape(-1, 5),
                  counts)
    got = room[:int(counts.sum())]
    assert np.cumsum(counts).tolist() == want_ends
    for name in ("x", "y", "z", "ring"):
        assert_array_equal(got[name], want[name], err_msg=name)
    assert_allclose(got["intensity"], want["intensity"], rtol=2e-7, atol=1e-7)
    assert 0 < len(got) < m                                     # some rays out of range, some kept


def rays_to_world_ref(plan_basis, R, pos, n, out):
    """The one matrix product per batch as it was: rows ``[d, start d, 1]`` times ``[[0, R^T], [R^T, 0], [p, 0]]``."""
    to_world = np.zeros((n, 7, 6), dtype=np.float32)
    R_t = R.transpose(0, 2, 1)
    to_world[:, 0:3, 3:6] = R_t
    to_world[:, 3:6, 0:3] = R_t
    to_world[:, 6, 0:3] = pos
    k = len(out) // n
    np.matmul(plan_basis.reshape(n, k, 7), to_world, out=out.reshape(n, k, 6))


@pytest.mark.parametrize("n_sensors, per_sensor", [(1, 100), (7, 5760)])
def test_rays_in_the_world_are_the_matrix_product_to_float32_precision(rng, n_sensors, per_sensor):
    from unetyemu_ecs.frames import R_from_quat_xyzw
    from unetyemu_ecs.sensors.raycast_system import rays_to_world
    dirs = rng.normal(size=(n_sensors * per_sensor, 3))
    dirs = (dirs / np.linalg.norm(dirs, axis=1, keepdims=True)).astype(np.float32)
    start = rng.choice([0.0, 0.05, 0.4], len(dirs)).astype(np.float32)
    R = R_from_quat_xyzw(quat_normalize_xyzw(rng.normal(size=(n_sensors, 4))))
    pos = rng.uniform(-150.0, 150.0, (n_sensors, 3))
    got, want = np.empty((len(dirs), 6), np.float32), np.empty((len(dirs), 6), np.float32)
    rays_to_world(dirs, start, np.arange(n_sensors + 1) * per_sensor, R, pos, got)
    basis = np.hstack([dirs, start[:, None] * dirs, np.ones((len(dirs), 1), dtype=np.float32)])
    rays_to_world_ref(basis, R, pos, n_sensors, want)
    assert_allclose(got[:, 3:], want[:, 3:], rtol=0, atol=1e-6)              # unit directions
    assert_allclose(got[:, :3], want[:, :3], rtol=0, atol=3e-5)              # start points within 150 m
    # and they are the rotated rays from the sensors' origins to float32 arithmetic (a few ulps of a unit vector;
    # positions within 150 m to their float32 rounding plus that)
    exact = np.einsum("nij,nkj->nki", R, dirs.astype(float).reshape(n_sensors, per_sensor, 3)).reshape(-1, 3)
    assert_allclose(got[:, 3:], exact, rtol=0, atol=2.5e-7)
    assert_allclose(got[:, :3], np.repeat(pos, per_sensor, axis=0) + start[:, None] * exact, rtol=0, atol=2e-5)


@pytest.mark.parametrize("seed", range(6))
def test_rays_culled_for_the_moving_body_cast_are_the_rays_they_were(seed):
    # 40 LiDARs (360 x 16) among 150 drone-sized bodies: each rides one (its own, excluded), some have a body right
    # beside them, two sit inside another body's sphere, ranges differ, a few bodies lie beyond every range
    from unetyemu_ecs.frames import R_from_quat_xyzw
    from unetyemu_ecs.sensors.lidar import LidarSensor, ray_directions_sensor
    rng = np.random.default_rng(seed)
    pattern, _ = ray_directions_sensor(LidarSensor())
    n, n_bodies = 40, 150
    origins = np.column_stack([rng.uniform(-60, 60, n), rng.uniform(-60, 60, n), rng.uniform(2, 30, n)])
    R = R_from_quat_xyzw(quat_normalize_xyzw(rng.normal(size=(n, 4))))
    centers = np.vstack([origins, np.column_stack([rng.uniform(-200, 200, n_bodies - n),
                                                  rng.uniform(-200, 200, n_bodies - n), rng.uniform(1, 40, n_bodies - n)])])
    centers[n:n + 2] = origins[[7, 21]] + rng.uniform(-0.1, 0.1, (2, 3))          # sensors 7 and 21 inside a sphere
    centers[n + 2:n + 10] = origins[:8] + rng.uniform(-3.0, 3.0, (8, 3))          # bodies right beside sensors 0..7
    radii = rng.uniform(0.3, 2.5, n_bodies) + EXIT_MARGIN_M
    max_range = rng.uniform(20.0, 120.0, n)
    own = np.where(rng.uniform(size=n) < 0.9, np.arange(n), -1)                  # most sensors ride a body
    dirs_world = np.concatenate([pattern @ R[k].T for k in range(n)]).astype(np.float32)
    bins = direction_bins(pattern)
    args = (origins, R, dirs_world, bins, max_range, centers, radii, own)
    got = moving_body_candidates_binned(*args)
    want = moving_body_candidates_binned_ref(*args)
    assert got.dtype == want.dtype
    assert_array_equal(got, want)
    k = len(pattern)
    assert 2 * k <= len(got) < 0.5 * len(dirs_world)                 # two sensors keep every ray, most are culled
    # the rays in Open3D's layout (a strided view of the cast rows) give the same rays
    rows = np.zeros((len(dirs_world), 6), dtype=np.float32)
    rows[:, 3:] = dirs_world
    assert_array_equal(moving_body_candidates_binned(origins, R, rows[:, 3:], bins, max_range, centers, radii, own), want)
