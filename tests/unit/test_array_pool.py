"""The sensors' array pool: an array comes back only when no one holds it or a view of it any more."""

from __future__ import annotations

import numpy as np

from unetyemu_ecs.sensors.buffers import ArrayPool


def test_an_array_let_go_is_handed_out_again():
    pool = ArrayPool()
    first = pool.take((1000, 6), np.float32)
    first_id = id(first)
    del first
    again = pool.take((1000, 6), np.float32)
    assert id(again) == first_id and again.shape == (1000, 6) and again.dtype == np.float32


def test_an_array_or_a_view_of_it_still_held_is_never_handed_out():
    pool = ArrayPool()
    held = pool.take(500, np.float64)
    other = pool.take(500, np.float64)
    assert other is not held
    view = other[10:20].view(np.uint8)               # e.g. a published message's bytes of a slice
    del other
    third = pool.take(500, np.float64)
    assert third is not held and not np.shares_memory(third, view)
    del view
    assert pool.take(500, np.float64) is not held     # the second array is free again, the first never was


def test_shapes_and_dtypes_are_pooled_apart():
    pool = ArrayPool()
    a = pool.take(64, np.float32)
    del a
    assert pool.take(64, np.int32).dtype == np.int32
    assert pool.take((8, 8), np.float32).shape == (8, 8)
    points = np.dtype([("x", "<f4"), ("ring", "<u4")])
    assert pool.take(64, points).dtype == points and pool.take(64, np.dtype("V8")).dtype == np.dtype("V8")


def test_the_pool_keeps_at_most_keep_arrays_of_a_kind_when_all_are_in_use():
    pool = ArrayPool(keep=2)
    held = [pool.take(100, np.float32) for _ in range(5)]
    assert len({id(a) for a in held}) == 5              # all in use: five different arrays
    assert len(pool._arrays[((100,), np.dtype(np.float32))]) == 2
    kept = [id(a) for a in pool._arrays[((100,), np.dtype(np.float32))]]
    del held
    assert id(pool.take(100, np.float32)) == kept[0]                  # free again: reused, oldest first
    assert id(pool.take(100, np.float32)) == kept[0]
