"""Per-car state shared by the ground-vehicle systems: drive modes, routes, fleet arrays.

Like the flight state, every array lives on the :class:`~unetyemu_ecs.fleet.FleetState` (one row per
body; only car rows are used) so each phase works on all cars in one vectorised pass.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum

import numpy as np

from ..control.car import corner_speeds_m_s
from ..fleet import FleetState


class DriveMode(IntEnum):
    """How a car is being driven."""

    PARKED = 0     # parking brake on, no drive
    ROUTE = 1      # following a route (targets and routes): pure pursuit + speed profile
    VELOCITY = 2   # forward speed and yaw rate commanded (cmd_vel)
    MANUAL = 3     # teleop: throttle, brake, steering


# the modes as plain ints, for comparisons with the fleet's arrays (an IntEnum costs NumPy a slow conversion)
DRIVE_PARKED, DRIVE_ROUTE = int(DriveMode.PARKED), int(DriveMode.ROUTE)
DRIVE_VELOCITY, DRIVE_MANUAL = int(DriveMode.VELOCITY), int(DriveMode.MANUAL)


@dataclass(frozen=True)
class CarPath:
    """A route in the form the follower needs.

    points_enu_m : (W, 3) [m], point 0 is where the car was when the route was given, z = 0
    speeds_m_s : (W,) [m/s] speed limit at each point (corner speeds; 0 at the end of an open route)
    cruise_m_s : [m/s] speed between corners
    period : number of segments of one lap of a never-ending loop (the points hold three laps and
        the follower steps back one period when its segment reaches ``wrap_from``), 0 otherwise
    lap_ends : for a loop of a set number of laps, the index of the point where each lap ends (the
        last one is the end of the route); empty otherwise
    """

    points_enu_m: np.ndarray
    speeds_m_s: np.ndarray
    cruise_m_s: float
    period: int = 0
    wrap_from: int = 0
    lap_ends: tuple[int, ...] = ()

    def laps_done(self, segment: int) -> int:
        """Laps of a set-laps loop completed by a car on ``segment`` (past every lap end before it)."""
        return sum(1 for q in self.lap_ends[:-1] if segment >= q)

    @classmethod
    def build(cls, start_enu_m: np.ndarray, waypoints_xy_m: np.ndarray, cruise_m_s: float, max_lat_accel_m_s2: float,
              loop: bool, laps: int) -> CarPath:
        """Route from ``start`` through ``waypoints`` (K, 2); a loop repeats them (``laps`` 0 = forever)."""
        wp = np.asarray(waypoints_xy_m, dtype=float).reshape(-1, 2)
        start = np.asarray(start_enu_m, dtype=float)[:2]
        if loop:
            reps = laps if laps > 0 else 3
            xy = np.vstack([start, np.tile(wp, (reps, 1))] + ([wp[:1]] if laps > 0 else []))
        else:
            xy = np.vstack([start, wp])
        keep = _not_repeated(xy)
        # lap j of a set-laps loop ends back at the first waypoint: point 1 + j*K before repeats are dropped
        new_index = np.cumsum(keep) - 1                 # a dropped point maps onto the kept one it repeats
        lap_ends = tuple(int(new_index[1 + j * len(wp)]) for j in range(1, laps + 1)) if loop and laps > 0 else ()
        xy = xy[keep]
        if len(xy) < 2:                            # asked to go where it already is
            xy = np.vstack([xy, xy])
        points = np.column_stack([xy, np.zeros(len(xy))])
        speeds = corner_speeds_m_s(points, cruise_m_s, max_lat_accel_m_s2, loop=False)
        if loop and laps == 0:
            k = len(wp)
            speeds[-1] = speeds[-1 - k]            # never stops: the far end is just another corner
            return cls(points, speeds, float(cruise_m_s), period=k, wrap_from=len(xy) - 1 - k)
        return cls(points, speeds, float(cruise_m_s), lap_ends=lap_ends)


def _not_repeated(xy: np.ndarray) -> np.ndarray:
    """Mask of the points that differ from the one before them."""
    keep = np.ones(len(xy), dtype=bool)
    keep[1:] = np.linalg.norm(np.diff(xy, axis=0), axis=1) > 1e-6
    return keep


# name -> (tail shape, dtype, fill)
CAR_ARRAYS: dict[str, tuple[tuple[int, ...], type, float]] = {
    "drive_mode": ((), np.int8, 0),
    "cmd_hold_until_s": ((), np.float64, np.inf),     # sim time a streamed teleop/cmd_vel lapses (inf: held)
    "drive_cmd": ((3,), np.float64, 0.0),            # teleop [throttle, brake, steering]
    "cmd_vel": ((2,), np.float64, 0.0),              # [forward m/s, yaw rate rad/s]
    "path_stamp": ((), np.int64, 0),
    "path_segment": ((), np.int64, 0),
    "path_laps": ((), np.int64, 0),                  # laps of a loop completed (kept when the route ends)
    "path_done": ((), np.bool_, False),
    "car_speed_sp_m_s": ((), np.float64, 0.0),
    "car_steer_sp_rad": ((), np.float64, 0.0),       # bicycle-model front angle asked by guidance
    "car_throttle": ((), np.float64, 0.0),           # applied, [-1, 1]
    "car_brake": ((), np.float64, 1.0),              # applied, [0, 1]
    "car_steer_rad": ((), np.float64, 0.0),          # applied bicycle-model angle (after limits and slew)
    "car_speed_m_s": ((), np.float64, 0.0),          # signed forward speed (FLU x)
}


def declare_car_arrays(fleet: FleetState) -> None:
    """Declare every car array on ``fleet`` (idempotent), plus the per-row path objects.

    Called once when a simulation is built (:func:`~.blackboard.declare_shared_arrays`); systems
    never declare them.
    """
    for name, (tail, dtype, fill) in CAR_ARRAYS.items():
        fleet.declare(name, tail, dtype, fill)
    fleet.declare("car_path", (), object, None)


def set_path(fleet: FleetState, row: int, path: CarPath | None) -> None:
    """Give car ``row`` a new path (None clears it) and restart following from its first segment."""
    fleet.car_path[row] = path
    fleet.path_stamp[row] += 1
    fleet.path_segment[row] = 0
    fleet.path_laps[row] = 0
    fleet.path_done[row] = False


__all__ = ["CAR_ARRAYS", "CarPath", "DriveMode", "declare_car_arrays", "set_path"]
