"""Keep concurrent runs of a sweep apart when they speak ROS 2 or MAVLink.

Runs execute on worker slots (one per ``--workers``), one run per slot at a time. A slot's runs get:

- ROS 2: their own DDS domain, ``first_domain + slot``, so one run's nodes never discover another's;
- MAVLink: their own PX4 SITL instances. A world with ``D`` drones gives slot ``s`` the instances
  ``s * D + i`` (``i``: the drone's own instance, its index among the drones unless its ``mavlink``
  component sets one), hence the ports 14540 + instance (API link), 18570 + instance (GCS link bind)
  and system id instance + 1, as ``px4 -i N`` does. Every run's GCS link still sends to 14550.
"""

from __future__ import annotations

from typing import Any

from ..config.schema import Path
from ..transport.mavlink.component import MAX_INSTANCE

MAX_ROS_DOMAIN = 101        # ROS 2's safe domain ids on Linux are 0..101 (higher ones collide with ephemeral ports)


class IsolationError(ValueError):
    """The sweep's workers cannot each get their own ROS 2 domain or MAVLink instances."""


def ros2_domain(first_domain: int, slot: int) -> int:
    """The DDS domain of the runs on worker ``slot``."""
    return first_domain + slot


def check_ros2_domains(first_domain: int, workers: int) -> None:
    if not 0 <= first_domain or first_domain + workers - 1 > MAX_ROS_DOMAIN:
        raise IsolationError(f"ROS 2 with {workers} workers needs domains {first_domain}..{first_domain + workers - 1}; "
                             f"ROS 2 domain ids go from 0 to {MAX_ROS_DOMAIN} (set ROS_DOMAIN_ID lower, or fewer "
                             "workers)")


def _drones(doc: dict[str, Any]) -> list[tuple[int, dict[str, Any]]]:
    vehicles = doc.get("vehicles") if isinstance(doc.get("vehicles"), list) else []
    return [(i, v) for i, v in enumerate(vehicles) if isinstance(v, dict) and v.get("type") == "quadrotor"]


def _own_instances(doc: dict[str, Any], forced: bool) -> list[tuple[int, int | None]]:
    """(vehicle index, instance) of each drone that has a MAVLink endpoint in slot 0; the instance is
    None for a drone ``--mavlink`` gives an endpoint (its index among the drones)."""
    out = []
    for k, (i, vehicle) in enumerate(_drones(doc)):
        components = vehicle.get("components") if isinstance(vehicle.get("components"), dict) else {}
        block = components.get("mavlink")
        if isinstance(block, dict) and isinstance(block.get("instance"), int):
            out.append((i, block["instance"]))
        elif forced:
            out.append((i, None))
    return out


def instances_per_slot(doc: dict[str, Any], forced: bool) -> int:
    """How many instance numbers one run uses (its highest instance + 1; 0 without MAVLink)."""
    drones = _drones(doc)
    own = _own_instances(doc, forced)
    return max([len(drones) if inst is None else inst + 1 for _i, inst in own], default=0)


def mavlink_overrides(doc: dict[str, Any], slot: int, forced: bool) -> tuple[tuple[Path, Any], ...]:
    """World-file overrides that move the MAVLink endpoints of a run on worker ``slot`` to its own instances."""
    stride = instances_per_slot(doc, forced)
    drone_rank = {i: k for k, (i, _v) in enumerate(_drones(doc))}
    out: list[tuple[Path, Any]] = []
    for i, instance in _own_instances(doc, forced):
        own = drone_rank[i] if instance is None else instance
        out.append((("vehicles", i, "components", "mavlink", "instance"), slot * stride + own))
    return tuple(out)


def check_mavlink_instances(doc: dict[str, Any], forced: bool, workers: int) -> None:
    stride = instances_per_slot(doc, forced)
    if stride and workers * stride - 1 > MAX_INSTANCE:
        raise IsolationError(f"MAVLink with {workers} workers of {stride} instances each needs instances up to "
                             f"{workers * stride - 1}; MAVLink system ids end at 255 (instance {MAX_INSTANCE}): "
                             "fewer workers")


__all__ = ["IsolationError", "check_mavlink_instances", "check_ros2_domains", "instances_per_slot",
           "mavlink_overrides", "ros2_domain"]
