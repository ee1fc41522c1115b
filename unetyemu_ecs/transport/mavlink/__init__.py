"""MAVLink endpoints per drone, like PX4 SITL (docs/architecture.md §7): an API link (bind 14580+i,
to 14540+i, MAVSDK) and a GCS link (bind 18570+i, to 14550, QGroundControl / MAVProxy), system id i+1.

Entry point ``mavlink`` of group ``unetyemu_ecs.transports``: :data:`PLUGIN`.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from ...geodesy import GeodeticOrigin
from ..api import TransportError, TransportOptions, TransportPlugin
from .component import MAX_INSTANCE, MavlinkEndpoint, MavlinkSigning

COMPONENT_KEY = "mavlink"


def endpoints_of(world: Any, options: TransportOptions) -> list[tuple[str, MavlinkEndpoint]]:
    """(drone, endpoint config) of every drone with a ``mavlink`` component, and of every other drone
    when ``options.mavlink`` forces them (instance = its index among the drones, or the lowest one
    no world-file component uses when that is taken); two components with one instance are an error."""
    out: list[tuple[str, MavlinkEndpoint]] = []
    drones = [e for e in world.vehicles if e.kind == "quadrotor"]
    explicit = {e.components[COMPONENT_KEY].instance for e in drones if COMPONENT_KEY in e.components}
    used = set(explicit)
    for index, ent in enumerate(drones):
        cfg = ent.components.get(COMPONENT_KEY)
        if cfg is None and options.mavlink:
            instance = index if index not in used else min(set(range(MAX_INSTANCE + 1)) - used)
            cfg = MavlinkEndpoint(instance=instance, bind=options.mavlink_bind)
            used.add(instance)
        if cfg is not None:
            out.append((ent.name, cfg))
    seen: dict[int, str] = {}
    for name, cfg in out:
        if cfg.instance in seen:
            raise TransportError(f"mavlink: drones {seen[cfg.instance]!r} and {name!r} both use instance "
                                 f"{cfg.instance} (system id {cfg.system_id}); give each a unique instance")
        seen[cfg.instance] = name
    return out


def create(world: Any, options: TransportOptions) -> Any:
    from .transport import MavlinkTransport

    endpoints = endpoints_of(world, options)
    if not endpoints:
        return None
    o = world.spec.world.origin
    origin = GeodeticOrigin(o.lat_deg, o.lon_deg, o.alt_m)
    base_dir = Path(world.file).parent if getattr(world, "file", None) else None
    return MavlinkTransport(endpoints, origin, world.layout, 1.0 / world.spec.world.physics_hz, options.out_dir,
                            base_dir)


PLUGIN = TransportPlugin(create=create, summary="MAVLink endpoint per drone like PX4 SITL (pymavlink): "
                                                "API link 14540+i, GCS link 14550, system id i+1")

__all__ = ["COMPONENT_KEY", "MavlinkEndpoint", "MavlinkSigning", "PLUGIN", "create", "endpoints_of"]
