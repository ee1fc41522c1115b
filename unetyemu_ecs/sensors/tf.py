"""The frame tree as ``tf2_msgs/TFMessage`` (REP-105, docs/architecture.md §3).

``map -> <vehicle>/odom -> <vehicle>/base_link -> <vehicle>/<sensor link> [-> optical frame]``:

- ``/tf_static`` (once, at the first step): ``map -> <v>/odom`` (identity: the simulator's odometry is
  ground truth, it does not drift), ``<v>/base_link -> <v>/<link>`` for every sensor's mount, and
  ``<link> -> <optical frame>`` for cameras (z forward, x right, y down);
- ``/tf`` (every ``1 / TF_HZ`` s of sim time): ``<v>/odom -> <v>/base_link`` of every vehicle, in one
  message. The loop only copies the poses; the message is built when it is first read (by a
  transport, on its own thread, or by ``Simulation.transforms``), so nobody listening costs nothing.

The static tree follows the world: a vehicle spawned or removed, or a sensor added to or removed
from a vehicle after spawn, sends ``/tf_static`` again on the next step.

The messages go to the sensor outputs under vehicle ``""`` and keys ``tf`` / ``tf_static``
(:meth:`unetyemu_ecs.app.Simulation.transforms`).
"""

from __future__ import annotations

from functools import partial
from typing import Any

import esper
import numpy as np

from ..components.body import Identity
from ..frames import quat_xyzw_from_R
from ..phases import Phase
from ..systems.fleet_system import FleetSystem
from ..world import StepContext
from .base import SensorSample, SensorSpec
from .camera import R_LINK_OPTICAL
from .messages import msg_type, stamp

TF_HZ = 50.0


def tf_message(time_s: float, frames: tuple[tuple[str, str], ...], xyz: np.ndarray, q_xyzw: np.ndarray) -> Any:
    """A TFMessage of ``parent -> child`` (``frames``) transforms with translations (N, 3) [m] and rotations
    (N, 4) xyzw, all stamped ``time_s`` (the transforms share one stamp object: messages are read-only)."""
    T, Transform, Header = (msg_type("geometry_msgs/msg/TransformStamped"), msg_type("geometry_msgs/msg/Transform"),
                            msg_type("std_msgs/msg/Header"))
    Vector3, Quaternion = msg_type("geometry_msgs/msg/Vector3"), msg_type("geometry_msgs/msg/Quaternion")
    t = stamp(time_s)
    return msg_type("tf2_msgs/msg/TFMessage")(transforms=[
        T(header=Header(stamp=t, frame_id=parent), child_frame_id=child,
          transform=Transform(translation=Vector3(x=x, y=y, z=z), rotation=Quaternion(x=qx, y=qy, z=qz, w=qw)))
        for (parent, child), (x, y, z), (qx, qy, qz, qw)
        in zip(frames, np.asarray(xyz, dtype=float).tolist(), np.asarray(q_xyzw, dtype=float).tolist())])


class TransformSystem(FleetSystem):
    """Publishes /tf_static (at the first step, and again whenever the tree changes) and /tf at TF_HZ
    for every vehicle. Phase: OUTPUTS. Always present."""

    phase = Phase.OUTPUTS
    order = 10
    requires = (Identity,)

    def __init__(self) -> None:
        super().__init__()
        self._static_sent = False
        self._next_s = 0.0
        self._vehicle_rows = np.empty(0, dtype=np.intp)
        self._frames: tuple[tuple[str, str], ...] = ()        # (odom, base_link) of each vehicle
        self._static: list[tuple[str, str, tuple[float, ...], tuple[float, ...]]] = []  # parent, child, xyz, q_xyzw

    def gather(self, ctx: StepContext) -> None:
        vehicles = [(row, int(ent), ident.name) for row, ent, ident in zip(self.rows.tolist(), self.entities,
                                                                          self.components[0])
                    if ident.kind != "package"]
        self._vehicle_rows = np.array([row for row, _, _ in vehicles], dtype=np.intp)
        self._frames = tuple((f"{name}/odom", f"{name}/base_link") for _, _, name in vehicles)
        static = self._static_tree(vehicles)
        if static != self._static:                     # new vehicles or sensors: send the static tree again
            self._static = static
            self._static_sent = False

    def update(self, ctx: StepContext) -> None:
        if not self._vehicle_rows.size:
            return
        f = ctx.fleet
        time_s = ctx.sim_time_s + ctx.dt_s
        if not self._static_sent:
            frames = tuple((parent, child) for parent, child, _, _ in self._static)
            xyz = np.array([t[2] for t in self._static]).reshape(-1, 3)
            q_xyzw = np.array([t[3] for t in self._static]).reshape(-1, 4)
            ctx.services.sensors.put(SensorSample(time_s, "", "tf_static", "/tf_static",
                                                  tf_message(time_s, frames, xyz, q_xyzw)))
            self._static_sent = True
        if time_s + 1e-9 >= self._next_s:
            self._next_s += (np.floor((time_s + 1e-9 - self._next_s) * TF_HZ) + 1) / TF_HZ
            rows = self._vehicle_rows
            poses = (f.pos_enu_m.take(rows, axis=0), f.quat_enu_flu_xyzw.take(rows, axis=0))   # copies
            ctx.services.sensors.put(SensorSample(time_s, "", "tf", "/tf",
                                                  build=partial(tf_message, time_s, self._frames, *poses)))

    @staticmethod
    def _static_tree(vehicles: list[tuple[int, int, str]]) -> list[tuple[str, str, tuple[float, ...], tuple[float, ...]]]:
        """(parent, child, xyz, q_xyzw) of every static transform of ``vehicles`` (row, entity, name)."""
        out = []
        zero, q_identity = (0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0)
        q_optical = tuple(float(v) for v in np.asarray(quat_xyzw_from_R(R_LINK_OPTICAL)).reshape(4))
        for _, ent, name in vehicles:
            out.append(("map", f"{name}/odom", zero, q_identity))
            for comp in esper.components_for_entity(ent):
                if not isinstance(comp, SensorSpec) or not comp.LINK:
                    continue
                frame = comp.frame_name(name)                  # what its messages are stamped with
                link = f"{name}/{comp.LINK}" if comp.OPTICAL else frame
                out.append((f"{name}/base_link", link, tuple(float(v) for v in comp.mount_xyz_m),
                            tuple(float(v) for v in comp.mount_quat_xyzw())))
                if comp.OPTICAL:
                    out.append((link, frame, zero, q_optical))
        return out


__all__ = ["TF_HZ", "TransformSystem", "tf_message"]
