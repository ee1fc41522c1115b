"""Base of the sensors that cast rays into the world (LiDAR, cameras): the shared RaycastWorld of the
simulation, the moving bodies' boxes, each sensor's pose and own-hull exits, and one batched cast of
every due sensor's rays (:mod:`unetyemu_ecs.sensors.raycast`)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import esper
import numpy as np

from ..components.body import FleetSlot, RigidBody
from ..control.compiled import jit
from ..frames import R_from_quat_xyzw
from ..world import StepContext
from .base import MountedSensor, SensorSystemBase
from .buffers import ArrayPool
from .raycast import (EXIT_MARGIN_M, DirectionBins, RaycastWorld, direction_bins, exit_distance_m, import_open3d,
                      moving_body_candidates, moving_body_candidates_binned, ray_starts)


MAX_PLANS = 8


class RaycastSensorSystem(SensorSystemBase):
    """A sensor system that casts rays into the world: the shared RaycastWorld and the moving boxes."""

    def __init__(self) -> None:
        super().__init__()
        import_open3d()                     # fail when the simulation is built, not at the first cast
        self.world: RaycastWorld | None = None
        self._body_rows = np.empty(0, dtype=np.intp)
        self._body_half = np.empty((0, 3))
        self._body_radius = np.empty(0)
        self._plans: dict[tuple[int, ...], CastPlan] = {}
        self.arrays = ArrayPool()           # the rays as cast, and what subclasses fill per tick

    def gather(self, ctx: StepContext) -> None:
        super().gather(ctx)
        self._plans = {}
        if ctx.services.raycast is None:
            mesh = ctx.services.scene_mesh()
            ctx.services.raycast = RaycastWorld(mesh.vertices_m, mesh.triangles, mesh.cls, ctx.services.raycast_threads)
        self.world = ctx.services.raycast
        found = sorted((slot.row, body.half_extents_m)
                       for _, (slot, body) in esper.get_components(FleetSlot, RigidBody))
        self._body_rows = np.array([r for r, _ in found], dtype=np.intp)
        self._body_half = np.array([h for _, h in found], dtype=float).reshape(-1, 3)
        self._body_radius = np.linalg.norm(self._body_half, axis=1) + EXIT_MARGIN_M      # bounding spheres

    def own_exit_m(self, sensor: MountedSensor, dirs_sensor: np.ndarray) -> np.ndarray:
        """Where each ray (sensor frame) leaves the sensor's own vehicle box [m]."""
        half = self._body_half[np.searchsorted(self._body_rows, sensor.row)]
        dirs_body = dirs_sensor @ R_from_quat_xyzw(sensor.spec.mount_quat_xyzw()).T
        return exit_distance_m(np.asarray(sensor.spec.mount_xyz_m, dtype=float), dirs_body, half)

    def sensor_poses(self, ctx: StepContext, plan: "CastPlan") -> tuple[np.ndarray, np.ndarray]:
        """Position (N, 3) and attitude (N, 3, 3) in ENU of the frame of each sensor of ``plan``."""
        f = ctx.fleet
        R_body = f.R_enu_flu[plan.rows]
        return (f.pos_enu_m[plan.rows] + np.einsum("nij,nj->ni", R_body, plan.mount_xyz_m),
                np.einsum("nij,njk->nik", R_body, plan.R_body_sensor))

    def moving_boxes(self, ctx: StepContext) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        f = ctx.fleet
        return f.pos_enu_m[self._body_rows], f.quat_enu_flu_xyzw[self._body_rows], self._body_half

    def cast_due(self, ctx: StepContext, due: list[MountedSensor], rays: list[tuple[np.ndarray, np.ndarray]]
                 ) -> tuple[Any, np.ndarray, "CastPlan"]:
        """Cast every due sensor's rays in one batch.

        rays : per sensor, (directions (M, 3) in the sensor frame, own-hull exit distances (M,))
        Returns the hits, the rays as cast (sum M, 6) float32 (where each starts in the static scene and its
        unit direction, world frame) and the :class:`CastPlan` of ``due`` (each sensor's slice of them, ...).
        """
        plan = self._plan(due, rays)
        pos, R = self.sensor_poses(ctx, plan)
        boxes = self.moving_boxes(ctx)
        out = self.arrays.take((len(plan.dirs_sensor), 6), np.float32)     # Open3D's rows: start point, direction
        rays_to_world(plan.dirs_sensor, plan.start_static_m, plan.bounds, R, pos, out)
        if plan.bins is not None:                       # one pattern for all: binned culling
            dynamic = moving_body_candidates_binned(pos, R, out[:, 3:], plan.bins, plan.max_range_m, boxes[0],
                                                    self._body_radius, plan.own_box)
        else:
            dynamic = np.concatenate([sl.start + moving_body_candidates(pos[j], out[sl, 3:], plan.max_range_m[j],
                                                                        boxes[0], self._body_radius, int(plan.own_box[j]))
                                      for j, sl in enumerate(plan.slices)]).astype(np.intp)
        hits = self.world.cast_prepared(out, plan.start_static_m, plan.start_dynamic_m, boxes, dynamic)
        return hits, out, plan

    def _plan(self, due: list[MountedSensor], rays: list[tuple[np.ndarray, np.ndarray]]) -> "CastPlan":
        """The stacked, per-ray arrays of casting ``due`` together (:func:`per_sensor_set`)."""
        return per_sensor_set(self._plans, due, lambda: _make_plan(due, rays, self._body_rows))


@jit
def rays_to_world(dirs_sensor, start_static_m, bounds, R_world_sensor, origins_m, out):
    """Every ray of N sensors in Open3D's layout, ``out`` (M, 6) float32: where it starts in the static scene
    (``origin + start_static * R d``) and its unit direction ``R d`` in the world; sensor j's rays (sensor frame,
    ``dirs_sensor``) are rows ``bounds[j]`` to ``bounds[j + 1]``, its pose ``R_world_sensor[j]``, ``origins_m[j]``.
    Computed in float32, the precision Open3D casts in (the pose rounded to float32 once per sensor)."""
    d, rows = dirs_sensor.reshape(-1), out.reshape(-1)          # flat: no aliasing doubts, no 2-D index arithmetic
    for j in range(bounds.shape[0] - 1):
        R, o = R_world_sensor[j], origins_m[j]
        r00, r01, r02 = np.float32(R[0, 0]), np.float32(R[0, 1]), np.float32(R[0, 2])
        r10, r11, r12 = np.float32(R[1, 0]), np.float32(R[1, 1]), np.float32(R[1, 2])
        r20, r21, r22 = np.float32(R[2, 0]), np.float32(R[2, 1]), np.float32(R[2, 2])
        o0, o1, o2 = np.float32(o[0]), np.float32(o[1]), np.float32(o[2])
        for i in range(bounds[j], bounds[j + 1]):
            d0, d1, d2, start = d[3 * i], d[3 * i + 1], d[3 * i + 2], start_static_m[i]
            w0 = r00 * d0 + r01 * d1 + r02 * d2
            w1 = r10 * d0 + r11 * d1 + r12 * d2
            w2 = r20 * d0 + r21 * d1 + r22 * d2
            rows[6 * i], rows[6 * i + 1], rows[6 * i + 2] = o0 + start * w0, o1 + start * w1, o2 + start * w2
            rows[6 * i + 3], rows[6 * i + 4], rows[6 * i + 5] = w0, w1, w2


def per_sensor_set(cache: dict[tuple[int, ...], Any], due: list[MountedSensor], make: Callable[[], Any]) -> Any:
    """What ``make`` builds for the set of sensors ``due``, kept in ``cache`` for the last MAX_PLANS sets
    (sensors at different rates are due in a few recurring sets; the owner empties the cache when it gathers
    its sensors again)."""
    key = tuple(s.entity for s in due)
    found = cache.get(key)
    if found is None:
        if len(cache) >= MAX_PLANS:
            del cache[next(iter(cache))]                # the oldest
        found = cache[key] = make()
    return found


def _make_plan(due: list[MountedSensor], rays: list[tuple[np.ndarray, np.ndarray]], body_rows: np.ndarray
               ) -> "CastPlan":
    rows = np.array([s.row for s in due], dtype=np.intp)
    own = np.searchsorted(body_rows, rows)
    found = own < len(body_rows)
    found[found] = body_rows[own[found]] == rows[found]
    sizes = [len(d) for d, _ in rays]
    bounds = np.concatenate([[0], np.cumsum(sizes)])
    starts = [ray_starts(exit_m) for _, exit_m in rays]
    same = all(d is rays[0][0] or np.array_equal(d, rays[0][0]) for d, _ in rays)
    start_static = np.concatenate([a for a, _ in starts]).astype(np.float32)
    dirs_sensor = np.vstack([d for d, _ in rays]).astype(np.float32)
    return CastPlan(
        rows=rows,
        own_box=np.where(found, own, -1),
        mount_xyz_m=np.array([s.spec.mount_xyz_m for s in due], dtype=float).reshape(-1, 3),
        R_body_sensor=R_from_quat_xyzw(np.array([s.spec.mount_quat_xyzw() for s in due])).reshape(-1, 3, 3),
        dirs_sensor=dirs_sensor,
        bounds=bounds.astype(np.intp),
        start_static_m=start_static,
        start_dynamic_m=np.concatenate([b for _, b in starts]).astype(np.float32),
        slices=[slice(int(a), int(b)) for a, b in zip(bounds[:-1], bounds[1:])],
        max_range_m=np.array([getattr(s.spec, "max_range_m", np.inf) for s in due], dtype=float),
        bins=direction_bins(rays[0][0]) if same and sizes[0] > 0 else None)


@dataclass(frozen=True)
class CastPlan:
    """How a set of sensors is cast together (all of it fixed until the sensors are gathered again):

    - their fleet rows, the index of each one's own vehicle among the moving boxes (-1: none), their
      mounts (position in base_link [m], rotation base_link <- sensor);
    - their rays stacked in the sensor frames (sum M, 3) float32, and where each sensor's rays start and the
      last ends among them (``bounds``, N + 1);
    - the start distances of each ray in the static and moving-body scenes (float32), each sensor's
      slice and range, and the direction bins of their shared pattern (None when the patterns differ).
    """

    rows: np.ndarray
    own_box: np.ndarray
    mount_xyz_m: np.ndarray
    R_body_sensor: np.ndarray
    dirs_sensor: np.ndarray
    bounds: np.ndarray
    start_static_m: np.ndarray
    start_dynamic_m: np.ndarray
    slices: list[slice]
    max_range_m: np.ndarray
    bins: DirectionBins | None


__all__ = ["MAX_PLANS", "CastPlan", "RaycastSensorSystem", "per_sensor_set", "rays_to_world"]
