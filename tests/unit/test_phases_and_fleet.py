"""Phase ordering rules and fleet row bookkeeping (no esper, no PyBullet)."""

from __future__ import annotations

import numpy as np
import pytest

from unetyemu_ecs.fleet import FleetState, row_selector
from unetyemu_ecs.phases import Phase, phase_named, priority


def test_earlier_phases_get_higher_esper_priority_because_esper_runs_highest_first():
    # GIVEN every phase at its first and last order
    prios = [(priority(ph, 0), priority(ph, 99)) for ph in Phase]
    # THEN priorities strictly decrease along the phase order, orders included
    flat = [p for pair in prios for p in pair]
    assert flat == sorted(flat, reverse=True)
    assert len(set(flat)) == len(flat)


def test_phase_order_matches_the_design():
    assert [p.name for p in sorted(Phase)] == [
        "COMMANDS", "MISSION", "GUIDANCE", "STABILIZE", "ACTUATE", "PHYSICS", "STATE", "PAYLOAD_ENERGY",
        "SENSORS", "OUTPUTS"]


def test_unknown_phase_name_fails_loudly():
    with pytest.raises(ValueError, match="unknown phase 'physic'"):
        phase_named("physic")
    assert phase_named("Physics") is Phase.PHYSICS


def test_order_outside_a_phase_is_rejected():
    with pytest.raises(ValueError):
        priority(Phase.ACTUATE, 100)


def test_fleet_reuses_a_freed_row_and_bumps_its_version():
    # GIVEN three bodies
    fleet = FleetState(capacity=2)
    rows = [fleet.allocate(entity=e, body_id=10 + e) for e in (1, 2, 3)]
    assert rows == [0, 1, 2] and fleet.capacity >= 3
    v = fleet.version
    # WHEN the middle one is freed and a new one allocated
    fleet.free(2)
    assert fleet.version > v
    np.testing.assert_array_equal(fleet.rows, [0, 2])
    row = fleet.allocate(entity=4, body_id=14)
    # THEN the freed row is reused, reset, and the new entity maps to it
    assert row == 1 and fleet.row_of(4) == 1 and fleet.body_id[1] == 14
    np.testing.assert_array_equal(fleet.quat_enu_flu_xyzw[1], [0, 0, 0, 1])
    np.testing.assert_array_equal(fleet.R_enu_flu[1], np.eye(3))
    assert len(fleet) == 3


def test_growing_the_fleet_keeps_existing_state():
    fleet = FleetState(capacity=1)
    fleet.allocate(entity=1, body_id=5)
    fleet.pos_enu_m[0] = (1.0, 2.0, 3.0)
    fleet.allocate(entity=2, body_id=6)
    np.testing.assert_array_equal(fleet.pos_enu_m[0], (1.0, 2.0, 3.0))


def test_allocating_an_entity_twice_is_an_error():
    fleet = FleetState()
    fleet.allocate(entity=1, body_id=5)
    with pytest.raises(ValueError):
        fleet.allocate(entity=1, body_id=6)


def test_contiguous_rows_are_selected_by_a_slice_and_others_by_their_indices():
    assert row_selector(np.array([3, 4, 5])) == slice(3, 6)
    gappy = row_selector(np.array([0, 2, 3]))
    np.testing.assert_array_equal(gappy, [0, 2, 3])
    values = np.arange(10.0)
    for rows in ([3, 4, 5], [0, 2, 3], [7]):
        np.testing.assert_array_equal(values[row_selector(np.array(rows))], values[rows])
    assert row_selector(np.empty(0, dtype=np.intp)).size == 0


def test_the_fleet_selects_its_active_rows_with_a_slice_until_a_gap_opens():
    fleet = FleetState(capacity=4)
    for e in (1, 2, 3):
        fleet.allocate(entity=e, body_id=e)
    assert fleet.active == slice(0, 3)
    fleet.free(2)
    np.testing.assert_array_equal(fleet.active, [0, 2])
    fleet.allocate(entity=4, body_id=4)
    assert fleet.active == slice(0, 3)
