"""PAYLOAD_ENERGY phase: join packages to drones with a fixed constraint, and release them.

A pickup does nothing but join the two rigid bodies: the drone's controllers then feel the extra
mass, the shifted centre of mass and the larger inertia through the physics (the paper's §2.1.1).
A package heavier than the drone's ``max_payload_kg`` disables its motors while attached.

What a drone carries is public through the fleet array ``payload_entity`` (the esper entity of the
package, -1 when none) and ``payload_kg``; the mission reads those, never this system's state.
"""

from __future__ import annotations

from dataclasses import dataclass

import esper
import numpy as np

from ..components.body import FleetSlot, Identity, RigidBody
from ..components.flight import PayloadBay
from ..phases import Phase
from ..world import StepContext
from .fleet_system import FleetSystem
from .flight_state import REQUEST_NONE, PayloadRequest, PayloadResult
from .row_counts import count_not_equal


@dataclass(frozen=True)
class Carried:
    """A package joined to a drone."""

    package: str
    package_entity: int
    constraint_id: int
    mass_kg: float


class PayloadSystem(FleetSystem):
    """Serve attach/release requests of drones with a :class:`PayloadBay`.

    Phase: PAYLOAD_ENERGY (order 10); event-driven: does nothing on steps without requests.
    Reads: fleet.payload_request, payload_package, poses. Writes: fleet.payload_result, payload_kg,
    payload_entity, motors_enabled; PyBullet constraints.
    """

    phase = Phase.PAYLOAD_ENERGY
    order = 10
    requires = (PayloadBay,)

    def __init__(self) -> None:
        super().__init__()
        self._carried: dict[int, Carried] = {}          # drone entity -> what it carries (and its constraint)

    def update(self, ctx: StepContext) -> None:
        f = ctx.fleet
        if not count_not_equal(f.payload_request[self.sel], REQUEST_NONE):
            return
        r = self.rows
        bays = self.components[0]
        pending = np.flatnonzero(f.payload_request[r] != REQUEST_NONE)
        for k in pending.tolist():
            row = int(r[k])
            request = int(f.payload_request[row])
            f.payload_request[row] = PayloadRequest.NONE
            if request == PayloadRequest.ATTACH:
                f.payload_result[row] = self._attach(ctx, row, bays[k], f.payload_package[row])
            else:
                f.payload_result[row] = self._release(ctx, row)

    def _attach(self, ctx: StepContext, row: int, bay: PayloadBay, wanted: str | None) -> int:
        f = ctx.fleet
        drone = int(f.entity[row])
        ident = esper.component_for_entity(drone, Identity)
        if drone in self._carried:
            return int(PayloadResult.ATTACHED)
        body = esper.component_for_entity(drone, RigidBody)
        bottom_z = f.pos_enu_m[row, 2] - body.half_extents_m[2]
        taken = {c.package_entity for c in self._carried.values()}
        best: tuple[float, int, str, RigidBody] | None = None
        for ent, (pid, slot, pbody) in esper.get_components(Identity, FleetSlot, RigidBody):
            if pid.kind != "package" or ent in taken or (wanted is not None and pid.name != wanted):
                continue
            delta = f.pos_enu_m[slot.row] - f.pos_enu_m[row]
            horiz = float(np.hypot(delta[0], delta[1]))
            gap = float(bottom_z - (f.pos_enu_m[slot.row, 2] + pbody.half_extents_m[2]))
            if horiz <= bay.reach_horizontal_m and -0.05 <= gap <= bay.reach_vertical_m:
                if best is None or horiz < best[0]:
                    best = (horiz, ent, pid.name, pbody)
        if best is None:
            ctx.services.note(ctx.sim_time_s, ident.name, "pickup: no package within reach")
            return int(PayloadResult.NOTHING_IN_REACH)
        _, pkg_ent, pkg_name, pbody = best
        constraint = ctx.physics.attach_fixed(body.body_id, pbody.body_id)
        self._carried[drone] = Carried(pkg_name, pkg_ent, constraint, pbody.mass_kg)
        f.payload_kg[row] = pbody.mass_kg
        f.payload_entity[row] = pkg_ent
        if pbody.mass_kg > bay.max_payload_kg:
            f.motors_enabled[row] = False
            ctx.services.note(ctx.sim_time_s, ident.name,
                              f"pickup {pkg_name}: {pbody.mass_kg:g} kg exceeds max payload "
                              f"{bay.max_payload_kg:g} kg; motors disabled")
            return int(PayloadResult.OVERWEIGHT)
        ctx.services.note(ctx.sim_time_s, ident.name, f"picked up {pkg_name} ({pbody.mass_kg:g} kg)")
        return int(PayloadResult.ATTACHED)

    def release(self, ctx: StepContext, row: int) -> int:
        """Let go at once of what drone ``row`` carries (an environment's reset; missions ask through
        ``payload_request``); a PayloadResult."""
        return self._release(ctx, row)

    def _release(self, ctx: StepContext, row: int) -> int:
        f = ctx.fleet
        drone = int(f.entity[row])
        carried = self._carried.pop(drone, None)
        if carried is None:
            return int(PayloadResult.RELEASED)
        ctx.physics.detach(carried.constraint_id)
        f.payload_kg[row] = 0.0
        f.payload_entity[row] = -1
        f.motors_enabled[row] = bool(f.soc_frac[row] > 0.0)   # unless the battery is empty
        ident = esper.component_for_entity(drone, Identity)
        ctx.services.note(ctx.sim_time_s, ident.name, f"released {carried.package}")
        return int(PayloadResult.RELEASED)
