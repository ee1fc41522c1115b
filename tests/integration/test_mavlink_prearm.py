"""Pre-arm health and the geofence switch over MAVLink, with a real pymavlink peer on loopback:
SYS_STATUS's PREARM bit and MAV_CMD_RUN_PREARM_CHECKS report the simulation's own arming checks
(the ``arm_block`` the navigator writes from the check the Arm command applies); MAV_CMD_DO_FENCE_ENABLE
switches the drone's geofence enforcement."""

from __future__ import annotations

import esper
import pytest

from unetyemu_ecs import Simulation, load_world_text
from unetyemu_ecs.navigation.geofence import Geofence
from unetyemu_ecs.navigation.state import NavRuntime
from unetyemu_ecs.transport.api import CommandStatus

from .mavlink_client import Client, free_ports, wait_for, world_text

PREARM = 0x10000000
ARM, DO_FENCE_ENABLE, RUN_PREARM_CHECKS = 400, 207, 401
ACCEPTED, DENIED = 0, 2
CRITICAL, INFO = 2, 6
FORCE_ARM = 21196


@pytest.fixture
def rig(tmp_path):
    """One drone with an endpoint and a client on its API link."""
    ports = free_ports(1)
    sim = Simulation(load_world_text(world_text(ports, n_drones=1)), out_dir=tmp_path / "out")
    c = Client(ports["api_remote"], ports["api_local"])
    yield sim, c
    c.close()
    sim.close()


def _drain_battery(sim: Simulation, frac: float) -> None:
    """Leave ``frac`` of the charge d1 holds now (the energy model goes on from there)."""
    sim.fleet.soc_frac[sim.row("d1")] *= frac


def _settle(sim: Simulation) -> None:
    """Step until d1 rests on the ground (dropped from its spawn height it is in the air at first)."""
    for _ in range(100):
        if sim.landed_state("d1") == "ON_GROUND":
            return
        sim.step(24)
    raise AssertionError("d1 did not come to rest on the ground")


def _sys_status(sim: Simulation, c: Client, cond=lambda m: True):
    sim.step(24)            # past the state change: the next SYS_STATUS is built from a newer snapshot
    c.drain()
    return wait_for(sim, c, "SYS_STATUS", cond)


def test_prearm_health_follows_the_arming_checks_and_is_set_while_armed(rig):
    sim, c = rig
    # GIVEN a drone resting on the ground with a full battery
    _settle(sim)
    m = _sys_status(sim, c)
    # THEN SYS_STATUS reports the PREARM check present, enabled and healthy
    assert m is not None
    assert m.onboard_control_sensors_present & PREARM and m.onboard_control_sensors_enabled & PREARM
    assert m.onboard_control_sensors_health & PREARM
    assert sim.fleet.arm_block[sim.row("d1")] == 0
    # WHEN a geofence is set that the drone stands outside of (battery still full)
    sim.set_geofence("d1", Geofence(inclusion_circles=((100.0, 0.0, 10.0),)))
    m = _sys_status(sim, c)
    # THEN PREARM is unhealthy (arming would be refused: outside_fence) ...
    assert m is not None and not m.onboard_control_sensors_health & PREARM
    # ... AND healthy again once the fence is disabled (MAV_CMD_DO_FENCE_ENABLE 0)
    c.command_long(DO_FENCE_ENABLE, 0.0)
    assert wait_for(sim, c, "COMMAND_ACK", lambda m: m.command == DO_FENCE_ENABLE).result == ACCEPTED
    m = _sys_status(sim, c)
    assert m is not None and m.onboard_control_sensors_health & PREARM
    # WHEN its battery is drained to 5 % (below the 10 % low-battery level)
    _drain_battery(sim, 0.05)
    m = _sys_status(sim, c)
    # THEN PREARM is unhealthy, for the reason the Arm command gives
    assert m is not None and not m.onboard_control_sensors_health & PREARM
    command_id = sim.arm("d1")
    sim.step()
    res = sim.command_result(command_id)
    assert (res.status, res.reason) == (CommandStatus.REJECTED_STATE, "low_battery")
    # WHEN it is force-armed anyway (PX4's 21196)
    c.command_long(ARM, 1.0, FORCE_ARM)
    assert wait_for(sim, c, "COMMAND_ACK", lambda m: m.command == ARM).result == ACCEPTED
    # THEN an armed drone reports PREARM healthy, as PX4 does
    m = _sys_status(sim, c)
    assert m is not None and sim.is_armed("d1") and m.onboard_control_sensors_health & PREARM


def test_run_prearm_checks_is_accepted_and_reports_the_arming_verdict_as_statustext(rig):
    sim, c = rig
    assert wait_for(sim, c, "HEARTBEAT") is not None
    _settle(sim)
    sim.step(24)
    # WHEN a GCS asks a healthy drone on the ground to run its pre-arm checks
    c.drain()
    c.command_long(RUN_PREARM_CHECKS)
    # THEN the command is ACCEPTED and an INFO STATUSTEXT says they passed
    assert wait_for(sim, c, "COMMAND_ACK", lambda m: m.command == RUN_PREARM_CHECKS).result == ACCEPTED
    text = wait_for(sim, c, "STATUSTEXT", lambda m: "Preflight" in m.text)
    assert text is not None and text.text == "Preflight checks passed" and text.severity == INFO
    # WHEN the battery is drained below its low-battery level and the checks run again
    _drain_battery(sim, 0.05)
    sim.step(24)
    c.drain()
    c.command_long(RUN_PREARM_CHECKS)
    # THEN still ACCEPTED, and a CRITICAL STATUSTEXT names why arming would be refused
    assert wait_for(sim, c, "COMMAND_ACK", lambda m: m.command == RUN_PREARM_CHECKS).result == ACCEPTED
    text = wait_for(sim, c, "STATUSTEXT", lambda m: "Preflight" in m.text)
    assert text is not None and text.text == "Preflight Fail: low battery" and text.severity == CRITICAL


def test_do_fence_enable_switches_the_drones_fence_and_refuses_disabling_the_floor_only(rig):
    sim, c = rig
    assert wait_for(sim, c, "HEARTBEAT") is not None
    sim.step()

    def fence_enabled() -> bool:
        with sim.ecs.active():
            return esper.component_for_entity(sim.entity("d1"), NavRuntime).fence_enabled

    assert fence_enabled()
    # WHEN a client disables the geofence (param1 0)
    c.command_long(DO_FENCE_ENABLE, 0.0)
    # THEN the ACK is ACCEPTED, from the simulation's result, and the fence is off
    assert wait_for(sim, c, "COMMAND_ACK", lambda m: m.command == DO_FENCE_ENABLE).result == ACCEPTED
    result = next(r for r in reversed(sim.services.results) if r.kind == "fence_enable")
    assert result.source == "mavlink" and result.status == CommandStatus.ACCEPTED
    assert not fence_enabled()
    # WHEN it asks to disable the floor only (param1 2), which is not supported: DENIED, nothing changes
    c.command_long(DO_FENCE_ENABLE, 2.0)
    assert wait_for(sim, c, "COMMAND_ACK", lambda m: m.command == DO_FENCE_ENABLE).result == DENIED
    assert not fence_enabled()
    # WHEN it enables the fence again (param1 1): ACCEPTED and on
    c.command_long(DO_FENCE_ENABLE, 1.0)
    assert wait_for(sim, c, "COMMAND_ACK", lambda m: m.command == DO_FENCE_ENABLE).result == ACCEPTED
    assert fence_enabled()
