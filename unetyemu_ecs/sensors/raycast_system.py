"""Base of the sensors that cast rays into the world (LiDAR, cameras): the shared RaycastWorld of the
simulation, the moving bodies' boxes, each sensor's pose and own-hull exits, and one batched cast of
every due sensor's rays (:mod:`unetyemu_ecs.sensors.raycast`)."""

from __future__ import annotations

from typing import Any

import esper
import numpy as np

from ..components.body import FleetSlot, RigidBody
from ..frames import R_from_quat_xyzw
from ..world import StepContext
from .base import MountedSensor, SensorSystemBase
from .raycast import EXIT_MARGIN_M, RaycastWorld, exit_distance_m, import_open3d, moving_body_candidates, ray_starts


class RaycastSensorSystem(SensorSystemBase):
    """A sensor system that casts rays into the world: the shared RaycastWorld and the moving boxes."""

    def __init__(self) -> None:
        super().__init__()
        import_open3d()                     # fail when the simulation is built, not at the first cast
        self.world: RaycastWorld | None = None
        self._body_rows = np.empty(0, dtype=np.intp)
        self._body_half = np.empty((0, 3))
        self._body_radius = np.empty(0)

    def gather(self, ctx: StepContext) -> None:
        super().gather(ctx)
        if ctx.services.raycast is None:
            mesh = ctx.services.scene_mesh()
            ctx.services.raycast = RaycastWorld(mesh.vertices_m, mesh.triangles, mesh.cls)
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

    def sensor_poses(self, ctx: StepContext, due: list[MountedSensor]) -> tuple[np.ndarray, np.ndarray]:
        """Position (N, 3) and attitude (N, 3, 3) in ENU of each sensor frame."""
        f = ctx.fleet
        rows = np.array([s.row for s in due])
        R_body = R_from_quat_xyzw(f.quat_enu_flu_xyzw[rows])
        mounts = np.array([s.spec.mount_xyz_m for s in due], dtype=float)
        R_mount = R_from_quat_xyzw(np.array([s.spec.mount_quat_xyzw() for s in due]))
        return f.pos_enu_m[rows] + np.einsum("nij,nj->ni", R_body, mounts), np.einsum("nij,njk->nik", R_body, R_mount)

    def moving_boxes(self, ctx: StepContext) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        f = ctx.fleet
        return f.pos_enu_m[self._body_rows], f.quat_enu_flu_xyzw[self._body_rows], self._body_half

    def cast_due(self, ctx: StepContext, due: list[MountedSensor], rays: list[tuple[np.ndarray, np.ndarray]]
                 ) -> tuple[Any, np.ndarray, list[slice]]:
        """Cast every due sensor's rays in one batch.

        rays : per sensor, (directions (M, 3) in the sensor frame, own-hull exit distances (M,))
        Returns the hits, the world directions (sum M, 3) and each sensor's slice of them.
        """
        pos, R = self.sensor_poses(ctx, due)
        boxes = self.moving_boxes(ctx)
        origins, dirs_w, start_s, start_d, slices, dynamic, first = [], [], [], [], [], [], 0
        for k, (dirs_s, exit_m) in enumerate(rays):
            d_w = dirs_s @ R[k].T
            origins.append(np.broadcast_to(pos[k], d_w.shape))
            dirs_w.append(d_w)
            a, b = ray_starts(exit_m)
            start_s.append(a)
            start_d.append(b)
            slices.append(slice(first, first + len(dirs_s)))
            own = int(np.searchsorted(self._body_rows, due[k].row))
            own = own if own < len(self._body_rows) and self._body_rows[own] == due[k].row else -1
            dynamic.append(first + moving_body_candidates(pos[k], d_w, getattr(due[k].spec, "max_range_m", np.inf),
                                                          boxes[0], self._body_radius, own))
            first += len(dirs_s)
        dirs_all = np.vstack(dirs_w)
        hits = self.world.cast(np.vstack(origins), dirs_all, np.concatenate(start_s), np.concatenate(start_d), boxes,
                               np.concatenate(dynamic))
        return hits, dirs_all, slices


__all__ = ["RaycastSensorSystem"]
