"""Counts over a fleet column, compiled: how a system learns in a fraction of a microsecond that it has
nothing to do (``np.count_nonzero`` of a comparison costs about 1.5 us on a few rows, mostly in calls)."""

from __future__ import annotations

from ..control.compiled import jit


@jit
def count_true(mask):
    """How many entries of the (N,) bool ``mask`` are True."""
    n = 0
    for k in range(mask.shape[0]):
        n += mask[k]
    return n


@jit
def count_not_equal(values, value):
    """How many entries of the (N,) ``values`` differ from ``value``."""
    n = 0
    for k in range(values.shape[0]):
        n += values[k] != value
    return n


@jit
def count_at_most(values, limit):
    """How many entries of the (N,) ``values`` are <= ``limit`` (NaN never is)."""
    n = 0
    for k in range(values.shape[0]):
        n += values[k] <= limit
    return n


__all__ = ["count_at_most", "count_not_equal", "count_true"]
