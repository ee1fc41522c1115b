"""Large arrays a sensor system fills at every tick, reused once nothing refers to them any more.

A LiDAR tick of 60 drones writes its rays (8 MB) and its points (7 MB) into fresh arrays. Memory that
large comes fresh from the kernel each time: every page is faulted in and zeroed before it is
written (a third of the cost of writing the points), and NumPy advises huge pages for it, which on
a machine whose huge pages are scarce made the writes of whole runs 4x slower (NumPy issue 31590).
An :class:`ArrayPool` hands back an array it made before when no one else holds it or any view of it
any more (its reference count says so: a published point cloud keeps its array, and every view of it,
alive), and otherwise makes a new one.
"""

from __future__ import annotations

import sys

import numpy as np


def _free_refs_in_take() -> int:
    """What ``sys.getrefcount`` reads for a pooled array no one else holds, looked at as :meth:`ArrayPool.take`
    looks at it (the pool's list, the loop variable, getrefcount's own argument: 3 on CPython 3.11).
    Measured rather than assumed: newer interpreters may borrow the loop variable's reference, and a count
    taken as "free" one too high would hand out an array a published message still reads."""
    arrays = [np.empty(1)]
    for array in arrays:
        return sys.getrefcount(array)
    raise AssertionError("unreachable")


_FREE_REFS = _free_refs_in_take()


class ArrayPool:
    """Arrays of a few shapes, each made once and reused whenever no one else holds it (or a view of it).

    ``keep``: how many arrays of one shape and dtype the pool holds (when all are in use, a new array is
    made and the oldest is let go)."""

    def __init__(self, keep: int = 3) -> None:
        self.keep = keep
        self._arrays: dict[tuple[tuple[int, ...], np.dtype], list[np.ndarray]] = {}

    def take(self, shape: int | tuple[int, ...], dtype: np.dtype | type | str) -> np.ndarray:
        """An array of ``shape`` and ``dtype`` that nothing else refers to, its contents undefined (np.empty)."""
        key = ((shape,) if isinstance(shape, int) else tuple(shape), np.dtype(dtype))
        arrays = self._arrays.setdefault(key, [])
        for array in arrays:
            if sys.getrefcount(array) == _FREE_REFS:
                return array
        array = np.empty(key[0], dtype=key[1])
        arrays.append(array)
        if len(arrays) > self.keep:
            del arrays[0]
        return array

    def clear(self) -> None:
        """Let every pooled array go (arrays still in use stay alive through their users)."""
        self._arrays.clear()


__all__ = ["ArrayPool"]
