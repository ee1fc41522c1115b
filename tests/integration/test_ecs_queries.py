"""Systems follow the ECS: a component added, removed or replaced after spawn acts from the next step.

Each system (a ``FleetSystem``) gathers its rows and parameters again whenever the ECS structure
changes; these tests change components of live entities (inside ``sim.ecs.active()``) and check
the physics, the energy model and the sensors react.
"""

from __future__ import annotations

import dataclasses
import math

import esper
import numpy as np
import pytest

from unetyemu_ecs import Simulation, load_world_text
from unetyemu_ecs.components.aero import AeroDrag
from unetyemu_ecs.components.flight import EnergyModel
from unetyemu_ecs.sensors.imu import ImuSensor

G = 9.81
RHO = 1.225                       # sea-level air [kg/m^3], set as the world's air below
BOX_KG, BOX_AREA_M2, BOX_CD = 0.5, 0.16, 1.0

# A 0.5 kg, 40 cm box 30 m up with no drag (coefficient 0), and a second box resting on the ground that has
# aero_drag (so that the drag system is part of the world).
FALL_WORLD = f"""
world: {{name: queries, physics_hz: 240, seed: 3, air: {{density_kg_m3: 1.225}}}}
scene: {{generator: none, ground_size_m: 60}}
packages:
  - name: box
    mass_kg: {BOX_KG}
    size_m: [0.4, 0.4, 0.4]
    pose: {{position_m: [0.0, 0.0, 30.0]}}
    components: {{aero_drag: {{drag_coeff: 0.0}}}}     # a fall in vacuum (packages have a box's drag)
  - name: crate
    mass_kg: 2.0
    size_m: [0.4, 0.4, 0.4]
    pose: {{position_m: [10.0, 0.0, 0.2]}}
    components:
      aero_drag: {{drag_coeff: 1.0, area_flu_m2: [0.16, 0.16, 0.16]}}
"""


def _vz(sim: Simulation, name: str) -> float:
    return float(sim.velocity_enu_m_s(name)[2])


def test_drag_added_to_a_falling_box_after_spawn_brings_it_to_the_physical_terminal_speed_and_removing_it_restores_free_fall():
    # the speed at which drag balances weight: m g = 0.5 rho Cd A v^2
    v_terminal = math.sqrt(2.0 * BOX_KG * G / (RHO * BOX_CD * BOX_AREA_M2))      # 7.07 m/s
    with Simulation(load_world_text(FALL_WORLD)) as sim:
        # GIVEN the box falling freely for 0.25 s: it gains g t
        sim.step(60)
        assert _vz(sim, "box") == pytest.approx(-G * 0.25, rel=0.01)
        # WHEN aero_drag is added to it and it falls on for 2.5 s (3.5 time constants v_t / g)
        with sim.ecs.active():
            esper.add_component(sim.entity("box"), AeroDrag(drag_coeff=BOX_CD, area_flu_m2=(BOX_AREA_M2,) * 3))
        sim.step(600)
        # THEN it falls at the terminal speed, within 2 %, and no longer accelerates
        v1 = _vz(sim, "box")
        sim.step(24)
        v2 = _vz(sim, "box")
        assert -v1 == pytest.approx(v_terminal, rel=0.02)
        assert abs(v2 - v1) / 0.1 < 0.05 * G
        assert sim.position_enu_m("box")[2] > 5.0                    # still in the air
        # WHEN the drag is removed again
        with sim.ecs.active():
            esper.remove_component(sim.entity("box"), AeroDrag)
        sim.step(1)
        v_start = _vz(sim, "box")
        sim.step(60)
        # THEN it accelerates at g again (to 1 %)
        assert (v_start - _vz(sim, "box")) / 0.25 == pytest.approx(G, rel=0.01)


DRONES_WORLD = """
world: {name: queries, physics_hz: 240, seed: 3}
scene: {generator: none, ground_size_m: 60}
vehicles:
  - {name: d1, type: quadrotor, preset: medium, pose: {position_m: [0, 0, 0.3]}, sensors: [imu]}
  - {name: d2, type: quadrotor, preset: medium, pose: {position_m: [5, 0, 0.3]}}
"""


def test_replacing_a_drones_energy_model_changes_its_power_on_the_next_step_and_keeps_its_battery():
    with Simulation(load_world_text(DRONES_WORLD)) as sim:
        # GIVEN a disarmed drone on the ground, drawing only its avionics power p0
        sim.step(24)
        row = sim.row("d2")
        with sim.ecs.active():
            old = esper.component_for_entity(sim.entity("d2"), EnergyModel)
        assert sim.fleet.power_w[row] == pytest.approx(old.p0_w)
        energy_before_j = float(sim.fleet.energy_j[row])
        # WHEN its EnergyModel is replaced by one with 100 W more avionics power
        with sim.ecs.active():
            esper.add_component(sim.entity("d2"), dataclasses.replace(old, p0_w=old.p0_w + 100.0))
        sim.step(1)
        # THEN the very next step draws the new p0, from the battery it already had
        assert sim.fleet.power_w[row] == pytest.approx(old.p0_w + 100.0)
        assert sim.fleet.energy_j[row] == pytest.approx(energy_before_j - (old.p0_w + 100.0) * sim.dt_s)
        # AND the other drone's power is untouched
        assert sim.fleet.power_w[sim.row("d1")] == pytest.approx(old.p0_w)


def _imu_messages(sim: Simulation, vehicle: str, steps: int) -> int:
    count = 0
    for _ in range(steps):
        sim.step()
        count += sum(1 for s in sim.services.sensors.this_step if s.vehicle == vehicle and s.sensor == "imu")
    return count


def test_an_imu_added_to_a_drone_after_spawn_starts_measuring_and_stops_when_removed():
    with Simulation(load_world_text(DRONES_WORLD)) as sim:
        # GIVEN d1 with a 100 Hz IMU and d2 without one: in 0.5 s only d1 measures
        sim.step(120)
        assert _imu_messages(sim, "d1", 120) == 50
        assert _imu_messages(sim, "d2", 120) == 0
        assert ("d2", "imu") not in sim.services.sensors.latest
        # WHEN d2 gets an IMU
        with sim.ecs.active():
            esper.add_component(sim.entity("d2"), ImuSensor())
        # THEN it measures from the next step on (its first sample at once, then on the 10 ms grid),
        # stamped with its own frame
        sim.step(1)
        assert [s.vehicle for s in sim.services.sensors.this_step if s.sensor == "imu"].count("d2") == 1
        assert _imu_messages(sim, "d2", 120) == 50
        sample = sim.services.sensors.latest[("d2", "imu")]
        assert sample.msg.header.frame_id == "d2/imu_link"
        assert sample.msg.linear_acceleration.z == pytest.approx(G, abs=0.05)   # at rest: the reaction to gravity
        # WHEN the IMU is removed again
        with sim.ecs.active():
            esper.remove_component(sim.entity("d2"), ImuSensor)
        # THEN d2 stops measuring, and d1's IMU keeps its schedule throughout
        assert _imu_messages(sim, "d2", 120) == 0
        assert _imu_messages(sim, "d1", 120) == 50


def test_a_sensor_added_after_spawn_appears_in_the_static_frame_tree():
    with Simulation(load_world_text(DRONES_WORLD)) as sim:
        sim.step(2)
        # WHEN d2 gets an IMU mounted 10 cm above its base
        with sim.ecs.active():
            esper.add_component(sim.entity("d2"), ImuSensor(mount_xyz_m=(0.0, 0.0, 0.1)))
        sim.step(1)
        # THEN /tf_static is sent again, with base_link -> imu_link of d2
        static = [s for s in sim.services.sensors.this_step if s.sensor == "tf_static"]
        assert len(static) == 1
        links = {(t.header.frame_id, t.child_frame_id): t for t in static[0].msg.transforms}
        mount = links[("d2/base_link", "d2/imu_link")].transform.translation
        assert np.allclose([mount.x, mount.y, mount.z], [0.0, 0.0, 0.1])
        # AND a step with no change in the tree does not send it again
        sim.step(1)
        assert not [s for s in sim.services.sensors.this_step if s.sensor == "tf_static"]
