"""Components and sensors attached to or taken off an entity at run time act from the next step on."""

from __future__ import annotations

import math

import numpy as np
import pytest

from unetyemu_ecs import ConfigError, Simulation, load_world_text

WORLD = """
world: {name: attach, physics_hz: 240}
scene: {generator: none}
packages:
  - name: box
    mass_kg: 1.0
    size_m: [0.4, 0.4, 0.4]
    pose: {position_m: [0.0, 0.0, 300.0]}
    components: {aero_drag: {drag_coeff: 0.0}}     # a fall in vacuum (packages have a box's drag)
vehicles:
  - name: d
    type: quadrotor
    pose: {position_m: [5.0, 0.0, 0.3]}
"""
RHO, CD, AREA, G = 1.225, 1.0, 0.16, 9.81


def test_a_falling_box_given_drag_after_spawn_reaches_its_terminal_speed_and_falls_freely_once_it_is_removed():
    with Simulation(load_world_text(WORLD)) as sim:
        # GIVEN a box in free fall (its drag coefficient set to 0 in the world file)
        sim.step(240)
        assert sim.velocity_enu_m_s("box")[2] == pytest.approx(-G, rel=1e-3)
        # WHEN drag is attached
        sim.attach("box", "aero_drag", drag_coeff=CD, area_flu_m2=[AREA] * 3, air_density_kg_m3=RHO)
        sim.run(duration=12.0)
        # THEN it falls at sqrt(2 m g / (rho Cd A)), where drag balances weight
        terminal = math.sqrt(2.0 * 1.0 * G / (RHO * CD * AREA))
        assert -sim.velocity_enu_m_s("box")[2] == pytest.approx(terminal, rel=0.005)
        # WHEN the drag is taken off again THEN it accelerates at g from the next step on
        sim.detach("box", "aero_drag")
        v0 = sim.velocity_enu_m_s("box")[2]
        sim.step(24)
        assert (sim.velocity_enu_m_s("box")[2] - v0) / 0.1 == pytest.approx(-G, rel=1e-3)


def test_an_imu_attached_at_run_time_measures_from_the_next_step_and_stops_when_detached():
    with Simulation(load_world_text(WORLD)) as sim:
        sim.step(240)                                      # the drone has settled on the ground
        assert sim.sensor_keys("d") == []
        sim.attach("d", "imu", rate_hz=100.0)
        assert sim.sensor_keys("d") == ["imu"]
        sim.step(3)
        imu = sim.sensor("d", "imu")
        # an IMU at rest reads +9.81 m/s^2 up
        assert imu.linear_acceleration.z == pytest.approx(G, abs=1e-3)
        stamp = imu.header.stamp
        sim.detach("d", "imu")
        with pytest.raises(ValueError, match="has no sensor 'imu'"):
            sim.sensor("d", "imu")
        sim.step(10)
        assert not any(s.key == "imu" for s in sim.services.sensors.this_step)
        # attached again, it measures again (newer stamps)
        sim.attach("d", "imu", rate_hz=100.0)
        sim.step(3)
        again = sim.sensor("d", "imu").header.stamp
        assert (again.sec, again.nanosec) > (stamp.sec, stamp.nanosec)


def test_attaching_takes_the_presets_values_and_checks_parameters_like_a_world_file():
    with Simulation(load_world_text(WORLD)) as sim:
        drag = sim.attach("d", "aero_drag")               # the medium preset's drag areas
        assert np.allclose(drag.area_flu_m2, sim.definition_of("d").params["aero_drag"]["area_flu_m2"])
        with pytest.raises(ConfigError, match=r"aero_drag.drag_coeff: must be >= 0, got -1.0"):
            sim.attach("d", "aero_drag", drag_coeff=-1.0)
        with pytest.raises(ConfigError, match="unknown key 'sonar'"):
            sim.attach("d", "sonar")
        with pytest.raises(ConfigError, match="cannot be attached to a package"):
            sim.attach("box", "motors")
        with pytest.raises(ValueError, match="carries no 'lidar'"):
            sim.detach("d", "lidar")
