"""The fleet arrays the built-in systems share, declared once when a simulation is built.

Systems talk to each other only through per-row fleet arrays (:class:`~unetyemu_ecs.fleet.FleetState`);
this module is the contract of which arrays exist. Every array listed here is declared before the
first step, whether or not any entity uses it, so a system, the API or a plugin can read any of them
without probing (a row no system writes keeps the array's fill value). The tables that name,
shape and document each array are ``FLIGHT_ARRAYS`` (drones: modes, setpoints, motor thrusts, energy,
payload) and ``CAR_ARRAYS`` (cars: drive modes, paths, throttle, brake, steering); plus
``impacts`` (count of impacts per row, written by the impact monitor) on every body.

A plugin that shares state of its own declares it with ``fleet.declare`` in its system's ``gather``
(idempotent) and documents it the same way.
"""

from __future__ import annotations

import numpy as np

from ..fleet import FleetState
from .car_state import CAR_ARRAYS, declare_car_arrays
from .flight_state import FLIGHT_ARRAYS, declare_flight_arrays


def declare_shared_arrays(fleet: FleetState) -> None:
    """Declare every array of the built-in contract on ``fleet`` (idempotent)."""
    declare_flight_arrays(fleet)
    declare_car_arrays(fleet)
    fleet.declare("impacts", (), np.int64, 0)


__all__ = ["CAR_ARRAYS", "FLIGHT_ARRAYS", "declare_shared_arrays"]
