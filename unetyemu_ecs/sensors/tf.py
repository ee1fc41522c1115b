"""The frame tree as ``tf2_msgs/TFMessage`` (REP-105, docs/architecture.md §3).

``map -> <vehicle>/odom -> <vehicle>/base_link -> <vehicle>/<sensor link> [-> optical frame]``:

- ``/tf_static`` (once, at the first step): ``map -> <v>/odom`` (identity: the simulator's odometry is
  ground truth, it does not drift), ``<v>/base_link -> <v>/<link>`` for every sensor's mount, and
  ``<link> -> <optical frame>`` for cameras (z forward, x right, y down);
- ``/tf`` (every ``1 / TF_HZ`` s of sim time): ``<v>/odom -> <v>/base_link`` of every vehicle, in one
  message.

The messages go to the sensor outputs under vehicle ``""`` and keys ``tf`` / ``tf_static``
(:meth:`unetyemu_ecs.app.Simulation.transforms`).
"""

from __future__ import annotations

from typing import Any

import esper
import numpy as np

from ..components.body import FleetSlot, Identity
from ..frames import quat_xyzw_from_R
from ..phases import Phase
from ..world import StepContext
from .base import SensorSample, SensorSpec
from .camera import R_LINK_OPTICAL
from .messages import header, msg_type, quaternion, vector3

TF_HZ = 50.0


def _transform(time_s: float, parent: str, child: str, xyz: np.ndarray, q_xyzw: np.ndarray) -> Any:
    T, Transform = msg_type("geometry_msgs/msg/TransformStamped"), msg_type("geometry_msgs/msg/Transform")
    return T(header=header(time_s, parent), child_frame_id=child,
             transform=Transform(translation=vector3(xyz), rotation=quaternion(q_xyzw)))


class TransformSystem(esper.Processor):
    """Publishes /tf_static once and /tf at TF_HZ for every vehicle. Phase: OUTPUTS. Always present."""

    phase = Phase.OUTPUTS
    order = 10

    def __init__(self) -> None:
        self._static_sent = False
        self._next_s = 0.0
        self._seen_version = -1
        self._vehicles: list[tuple[int, str]] = []

    def process(self, ctx: StepContext) -> None:
        f = ctx.fleet
        if f.version != self._seen_version:
            self._vehicles = sorted((slot.row, ident.name) for _, (slot, ident)
                                    in esper.get_components(FleetSlot, Identity) if ident.kind != "package")
            self._seen_version = f.version
            self._static_sent = False                    # new vehicles: send the static tree again
        if not self._vehicles:
            return
        time_s = ctx.sim_time_s + ctx.dt_s
        TFMessage = msg_type("tf2_msgs/msg/TFMessage")
        if not self._static_sent:
            ctx.services.sensors.put(SensorSample(time_s, "", "tf_static", "/tf_static",
                                                  TFMessage(transforms=self._static_tree(time_s))))
            self._static_sent = True
        if time_s + 1e-9 >= self._next_s:
            self._next_s += (np.floor((time_s + 1e-9 - self._next_s) * TF_HZ) + 1) / TF_HZ
            tfs = [_transform(time_s, f"{name}/odom", f"{name}/base_link", f.pos_enu_m[row], f.quat_enu_flu_xyzw[row])
                   for row, name in self._vehicles]
            ctx.services.sensors.put(SensorSample(time_s, "", "tf", "/tf", TFMessage(transforms=tfs)))

    def _static_tree(self, time_s: float) -> list[Any]:
        out = []
        q_identity = np.array([0.0, 0.0, 0.0, 1.0])
        q_optical = np.asarray(quat_xyzw_from_R(R_LINK_OPTICAL)).reshape(4)
        by_name = {ident.name: ent for ent, ident in esper.get_component(Identity)}
        for _, name in self._vehicles:
            out.append(_transform(time_s, "map", f"{name}/odom", np.zeros(3), q_identity))
            for comp in esper.components_for_entity(by_name[name]):
                if not isinstance(comp, SensorSpec) or not comp.LINK:
                    continue
                frame = comp.frame_name(name)                  # what its messages are stamped with
                link = f"{name}/{comp.LINK}" if comp.OPTICAL else frame
                out.append(_transform(time_s, f"{name}/base_link", link, np.asarray(comp.mount_xyz_m, float),
                                      comp.mount_quat_xyzw()))
                if comp.OPTICAL:
                    out.append(_transform(time_s, link, frame, np.zeros(3), q_optical))
        return out


__all__ = ["TF_HZ", "TransformSystem"]
