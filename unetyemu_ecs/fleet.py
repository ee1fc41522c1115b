"""Structure-of-arrays hot state of every dynamic body (vehicles and packages).

One row per body. Rows are allocated when an entity is spawned and freed when it is removed; freed
rows are reused. ``version`` increases whenever the set of rows changes, so that systems re-gather
their row indices only then, never per step.
"""

from __future__ import annotations

import numpy as np


class FleetState:
    """Per-body arrays, indexed by row; shapes are ``(capacity, ...)``.

    Attributes
    ----------
    pos_enu_m : (C, 3) float64 [m], ENU, centre of mass of the base
    quat_enu_flu_xyzw : (C, 4) float64, attitude of body FLU in world ENU, xyzw
    R_enu_flu : (C, 3, 3) float64, the same attitude as a rotation matrix (body FLU -> world ENU),
        written with the quaternion by the state read-back so that no system converts it again
    vel_enu_m_s : (C, 3) float64 [m/s], ENU
    rate_enu_rad_s : (C, 3) float64 [rad/s], angular velocity in world ENU
    rate_flu_rad_s : (C, 3) float64 [rad/s], angular velocity in body FLU
    acc_enu_m_s2 : (C, 3) float64 [m/s^2], ENU, finite difference of velocity over the last step
    wind_enu_m_s : (C, 3) float64 [m/s], ENU, air velocity at the body (written in ACTUATE)
    force_cmd_enu_n : (C, 3) float64 [N], ENU, external force at the centre of mass for the next
        physics step; accumulated in ACTUATE, applied and cleared in PHYSICS
    torque_cmd_enu_n_m : (C, 3) float64 [N m], ENU, external torque, same life cycle
    odometer_m : (C,) float64 [m], path length travelled since spawn
    body_id : (C,) int64, PyBullet body id (-1 for a free row)
    entity : (C,) int64, esper entity id (-1 for a free row)
    """

    _BUILTIN_VEC3 = ("pos_enu_m", "vel_enu_m_s", "rate_enu_rad_s", "rate_flu_rad_s", "acc_enu_m_s2",
             "wind_enu_m_s", "force_cmd_enu_n", "torque_cmd_enu_n_m")

    def __init__(self, capacity: int = 8) -> None:
        self.capacity = 0
        self.version = 0
        self.pos_enu_m = np.zeros((0, 3))
        self.quat_enu_flu_xyzw = np.zeros((0, 4))
        self.R_enu_flu = np.zeros((0, 3, 3))
        self.vel_enu_m_s = np.zeros((0, 3))
        self.rate_enu_rad_s = np.zeros((0, 3))
        self.rate_flu_rad_s = np.zeros((0, 3))
        self.acc_enu_m_s2 = np.zeros((0, 3))
        self.wind_enu_m_s = np.zeros((0, 3))
        self.force_cmd_enu_n = np.zeros((0, 3))
        self.torque_cmd_enu_n_m = np.zeros((0, 3))
        self.odometer_m = np.zeros(0)
        self.body_id = np.zeros(0, dtype=np.int64)
        self.entity = np.zeros(0, dtype=np.int64)
        self._row_of_entity: dict[int, int] = {}
        self._active_rows = np.zeros(0, dtype=np.intp)
        self.active: slice | np.ndarray = self._active_rows    # row_selector of the active rows
        # name -> (tail shape, dtype, fill) of arrays declared by systems (see declare())
        self._declared: dict[str, tuple[tuple[int, ...], np.dtype, float]] = {}
        for name in self._BUILTIN_VEC3:
            self._declared[name] = ((3,), np.dtype(np.float64), 0.0)
        self._grow(max(1, capacity))

    def declare(self, name: str, tail_shape: tuple[int, ...] = (), dtype: type = np.float64,
                fill: float = 0.0) -> np.ndarray:
        """Add a per-row array ``name`` of shape ``(capacity, *tail_shape)`` (or return the existing one).

        Declared arrays grow with the fleet and are reset to ``fill`` when a row is allocated. Systems
        that own domain state (motor thrusts, setpoints, battery energy) declare it here so that
        every per-row array lives in one place. Re-fetch the array after ``version`` changes: growth
        reallocates it.
        """
        spec = (tuple(tail_shape), np.dtype(dtype), fill)
        if name in self._declared:
            if self._declared[name][:2] != spec[:2]:
                raise ValueError(f"fleet array {name!r} already declared as {self._declared[name][:2]}")
            return getattr(self, name)
        if hasattr(self, name):
            raise ValueError(f"{name!r} is a FleetState attribute, not a declarable array")
        self._declared[name] = spec
        setattr(self, name, np.full((self.capacity, *spec[0]), fill, dtype=spec[1]))
        return getattr(self, name)

    # -- allocation ---------------------------------------------------------------------------
    def _grow(self, new_capacity: int) -> None:
        old = self.capacity
        for name, (tail, dtype, fill) in self._declared.items():
            arr = np.full((new_capacity, *tail), fill, dtype=dtype)
            arr[:old] = getattr(self, name)
            setattr(self, name, arr)
        quat = np.zeros((new_capacity, 4))
        quat[:, 3] = 1.0
        quat[:old] = self.quat_enu_flu_xyzw
        self.quat_enu_flu_xyzw = quat
        rot = np.zeros((new_capacity, 3, 3))
        rot[:] = np.eye(3)
        rot[:old] = self.R_enu_flu
        self.R_enu_flu = rot
        odo = np.zeros(new_capacity)
        odo[:old] = self.odometer_m
        self.odometer_m = odo
        for name in ("body_id", "entity"):
            arr = np.full(new_capacity, -1, dtype=np.int64)
            arr[:old] = getattr(self, name)
            setattr(self, name, arr)
        self.capacity = new_capacity

    def allocate(self, entity: int, body_id: int) -> int:
        """Give ``entity`` (with PyBullet body ``body_id``) a row and return it."""
        if entity in self._row_of_entity:
            raise ValueError(f"entity {entity} already has fleet row {self._row_of_entity[entity]}")
        free = np.flatnonzero(self.entity[: self.capacity] < 0)
        if free.size == 0:
            row = self.capacity
            self._grow(2 * self.capacity)
        else:
            row = int(free[0])
        self.entity[row] = entity
        self.body_id[row] = body_id
        for name, (_, _, fill) in self._declared.items():
            getattr(self, name)[row] = fill
        self.quat_enu_flu_xyzw[row] = (0.0, 0.0, 0.0, 1.0)
        self.R_enu_flu[row] = np.eye(3)
        self.odometer_m[row] = 0.0
        self._row_of_entity[entity] = row
        self._bump()
        return row

    def free(self, entity: int) -> None:
        """Release the row of ``entity``."""
        row = self._row_of_entity.pop(entity)
        self.entity[row] = -1
        self.body_id[row] = -1
        self._bump()

    def _bump(self) -> None:
        self.version += 1
        self._active_rows = np.flatnonzero(self.entity >= 0).astype(np.intp)
        self.active = row_selector(self._active_rows)

    # -- queries -------------------------------------------------------------------------------
    @property
    def rows(self) -> np.ndarray:
        """Active rows in ascending order, (M,) intp."""
        return self._active_rows

    def row_of(self, entity: int) -> int:
        """Row of ``entity``; ``KeyError`` if it has none."""
        return self._row_of_entity[entity]

    def __len__(self) -> int:
        return int(self._active_rows.size)


def row_selector(rows: np.ndarray) -> slice | np.ndarray:
    """The cheapest index that selects ``rows`` (ascending, unique) of a fleet array.

    A contiguous run of rows (the usual case: a fleet of drones spawned together) becomes a slice,
    whose reads are views and whose writes skip numpy's fancy-index machinery (10x cheaper for a
    handful of rows); anything else stays the index array. Reads through a slice are *views*: copy
    before the array is written if the old values are still needed.
    """
    rows = np.asarray(rows, dtype=np.intp)
    if rows.size and int(rows[-1]) - int(rows[0]) + 1 == rows.size:
        return slice(int(rows[0]), int(rows[-1]) + 1)
    return rows
