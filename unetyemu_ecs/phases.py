"""The fixed order of work inside one physics step (docs/architecture.md §2); the only ordering authority.

esper runs processors with the *highest* priority first, so a system in phase ``P`` with order
``k`` is registered with priority ``-(100 * P + k)``: earlier phases, and lower orders within a
phase, run first.
"""

from __future__ import annotations

from enum import IntEnum


class Phase(IntEnum):
    """Phases of one physics step, in the order they run."""

    COMMANDS = 1        # drain inbound queues (ROS 2, MAVLink, teleop) into command components
    MISSION = 2         # mission state machines produce routes and targets
    GUIDANCE = 3        # pure pursuit and cascaded position -> velocity -> acceleration -> tilt
    STABILIZE = 4       # altitude, attitude and yaw loops -> normalised thrust and torques
    ACTUATE = 5         # motor mixing, wheel torque, brakes, steering, external forces
    PHYSICS = 6         # one PyBullet step
    STATE = 7           # read poses and velocities back into the fleet arrays
    PAYLOAD_ENERGY = 8  # attach/detach constraints, per-motor power, batteries
    SENSORS = 9         # each sensor at its own rate on the sim clock (read-only)
    OUTPUTS = 10        # publishers, telemetry, CSV logs (read-only)


ORDERS_PER_PHASE = 100


def priority(phase: Phase, order: int = 0) -> int:
    """Return the esper priority for a system of ``phase`` at position ``order`` within it."""
    if not isinstance(phase, Phase):
        raise ValueError(f"unknown phase {phase!r}; expected one of {[p.name for p in Phase]}")
    if not 0 <= order < ORDERS_PER_PHASE:
        raise ValueError(f"order within a phase must be in [0, {ORDERS_PER_PHASE}), got {order}")
    return -(ORDERS_PER_PHASE * int(phase) + order)


def phase_named(name: str) -> Phase:
    """Return the phase called ``name`` (case-insensitive); unknown names fail loudly."""
    try:
        return Phase[name.strip().upper()]
    except KeyError:
        raise ValueError(f"unknown phase {name!r}; expected one of "
                         f"{', '.join(p.name.lower() for p in Phase)}") from None
