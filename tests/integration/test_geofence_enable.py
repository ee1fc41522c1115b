"""Switching a drone's geofence off and on from the Python API (MAV_CMD_DO_FENCE_ENABLE's semantics),
flown in PyBullet."""

from __future__ import annotations

import numpy as np
import pytest

from unetyemu_ecs.navigation.geofence import Geofence
from unetyemu_ecs.transport.api import CommandStatus

from .test_navigation import fly_up, make_sim, result_after, run_until


def test_a_disabled_geofence_lets_the_drone_fly_out_and_enabling_it_again_holds():
    # GIVEN a drone hovering inside a 10 m fence (GF_ACTION 2: hold) that is then disabled
    sim = make_sim()
    fly_up(sim, 3.0)
    sim.set_geofence("d1", Geofence(inclusion_circles=((0.0, 0.0, 10.0),)))
    assert result_after(sim, sim.enable_geofence("d1", False)).status == CommandStatus.ACCEPTED
    # WHEN it flies to a target 20 m out
    sim.set_target("d1", 20.0, 0.0, 3.0)
    run_until(sim, lambda: np.hypot(*(sim.position_enu_m("d1")[:2] - [20.0, 0.0])) < 1.0, 20.0)
    # THEN it got there, still flying to its target, and no breach was acted on
    assert sim.nav_state("d1") == "GOTO"
    assert not any("geofence breached" in text for _, _, text in sim.events)
    # WHEN the fence is enabled again while the drone is outside it
    assert result_after(sim, sim.enable_geofence("d1", True)).status == CommandStatus.ACCEPTED
    sim.run(duration=0.5)
    # THEN the breach is acted on at once: GF_ACTION 2 holds it there
    assert sim.nav_state("d1") == "HOLD"
    assert any("geofence breached" in text for _, _, text in sim.events)
    here = sim.position_enu_m("d1").copy()
    sim.run(duration=3.0)
    assert np.linalg.norm(sim.position_enu_m("d1") - here) < 1.0


def test_enable_geofence_takes_only_true_or_false():
    sim = make_sim()
    with pytest.raises(ValueError, match="enabled must be True or False"):
        sim.enable_geofence("d1", 1)
