"""The engine: phase order, isolation of simulations, the sim clock against free fall."""

from __future__ import annotations

import math

import esper
import numpy as np
import pytest

from unetyemu_ecs import Phase, Simulation, load_world_text
from unetyemu_ecs.components.body import Identity, RigidBody

DROP_WORLD = """
world: {name: drop, physics_hz: 240, seed: 0}
scene: {generator: none, ground_size_m: 50}
packages:
  - name: box
    mass_kg: 2.0
    size_m: [0.4, 0.4, 0.4]
    pose: {position_m: [0.0, 0.0, 10.2]}
    components: {aero_drag: {drag_coeff: 0.0}}     # a fall in vacuum (packages have a box's drag)
"""


class _Recorder(esper.Processor):
    """Appends (step, phase name) to a shared journal every step."""

    def __init__(self, journal: list, phase: Phase, order: int = 0) -> None:
        self.journal = journal
        self.phase = phase
        self.order = order

    def process(self, ctx) -> None:
        self.journal.append((ctx.step, self.phase.name, self.order))


def _recorder_class(name: str) -> type:
    # esper keys processors by type: one class per recorder
    return type(name, (_Recorder,), {})


def test_systems_run_in_phase_order_every_step_whatever_order_they_were_added_in():
    # GIVEN recorders in every phase, added in reverse order, two of them sharing a phase
    journal: list = []
    with Simulation(load_world_text(DROP_WORLD)) as sim:
        specs = [(ph, 0) for ph in reversed(Phase)] + [(Phase.ACTUATE, 60)]
        for i, (ph, order) in enumerate(specs):
            sim.ecs.add_system(_recorder_class(f"Rec{i}")(journal, ph, order))
        # WHEN two steps run
        sim.step(2)
    # THEN each step saw every phase once, in the design's order, with order 60 after order 0
    for step in (0, 1):
        seen = [(name, order) for s, name, order in journal if s == step]
        expected = [(ph.name, 0) for ph in Phase]
        expected.insert(expected.index(("ACTUATE", 0)) + 1, ("ACTUATE", 60))
        assert seen == expected


def test_a_system_without_a_phase_is_refused():
    class NoPhase(esper.Processor):
        def process(self, ctx) -> None:
            pass

    with Simulation(load_world_text(DROP_WORLD)) as sim, pytest.raises(ValueError, match="phase"):
        sim.ecs.add_system(NoPhase())


def test_two_simulations_in_one_process_do_not_see_each_others_entities():
    # GIVEN two simulations of different worlds alive at the same time
    other = DROP_WORLD.replace("name: box", "name: crate").replace("[0.0, 0.0, 10.2]", "[5.0, 0.0, 3.0]")
    with Simulation(load_world_text(DROP_WORLD)) as a, Simulation(load_world_text(other)) as b:
        # WHEN both step, interleaved
        for _ in range(10):
            a.step()
            b.step()
        # THEN each esper world holds only its own entity
        with a.ecs.active():
            names_a = [ident.name for _, ident in esper.get_component(Identity)]
        with b.ecs.active():
            names_b = [ident.name for _, ident in esper.get_component(Identity)]
        assert names_a == ["box"] and names_b == ["crate"]
        # AND each physics client holds only its own body: the boxes fell from their own heights
        assert a.position_enu_m("box")[2] > 9.0 and b.position_enu_m("crate")[2] < 3.0
        assert a.ecs.name != b.ecs.name
    # AND closing them leaves esper's default world active and their worlds gone
    assert esper.current_world == "default"
    assert a.ecs.name not in esper.list_worlds() and b.ecs.name not in esper.list_worlds()


def test_sim_clock_counts_exact_physics_steps():
    with Simulation(load_world_text(DROP_WORLD)) as sim:
        stats = sim.run(until=0.5)
        assert sim.step_count == 120 and stats.steps == 120
        assert sim.sim_time_s == pytest.approx(0.5, abs=1e-12)
        sim.run(duration=0.25)
        assert sim.step_count == 180


def test_body_dropped_from_10_m_lands_when_free_fall_predicts():
    # GIVEN a box whose bottom is 10 m above the ground, at rest, no drag
    with Simulation(load_world_text(DROP_WORLD)) as sim:
        g = 9.81
        expected_s = math.sqrt(2 * 10.0 / g)
        body = sim.component("box", RigidBody).body_id
        row = sim.row("box")
        # WHEN stepping until its bottom reaches the ground
        landed_s = None
        while sim.sim_time_s < 2 * expected_s:
            v_before = sim.fleet.vel_enu_m_s[row, 2]
            sim.step()
            if sim.fleet.pos_enu_m[row, 2] - 0.2 <= 0.0:
                landed_s = sim.sim_time_s
                break
        # THEN it gets there at sqrt(2h/g) within one physics step
        assert landed_s is not None
        assert abs(landed_s - expected_s) <= sim.dt_s
        # AND the speed just before impact is g*t (no hidden damping)
        assert v_before == pytest.approx(-g * (landed_s - sim.dt_s), rel=1e-9)
        # AND PyBullet reports the contact on the next step (contacts are found before integration)
        sim.step()
        assert sim.physics.contact_count(body) > 0


def test_state_phase_reads_velocity_and_acceleration_of_a_falling_body():
    with Simulation(load_world_text(DROP_WORLD)) as sim:
        sim.step(24)
        row = sim.row("box")
        np.testing.assert_allclose(sim.fleet.acc_enu_m_s2[row], [0, 0, -9.81], atol=1e-9)
        np.testing.assert_allclose(sim.fleet.vel_enu_m_s[row], [0, 0, -9.81 * 0.1], atol=1e-9)
        assert sim.fleet.odometer_m[row] == pytest.approx(-sim.position_enu_m("box")[2] + 10.2, rel=1e-9)


def test_same_seed_gives_bit_identical_trajectories():
    def final_state() -> bytes:
        text = DROP_WORLD.replace("[0.0, 0.0, 10.2]", "[0.0, 0.0, 1.0]")
        with Simulation(load_world_text(text)) as sim:
            sim.run(until=2.0)
            return sim.fleet.pos_enu_m[sim.fleet.rows].tobytes() + sim.fleet.quat_enu_flu_xyzw[sim.fleet.rows].tobytes()

    assert final_state() == final_state()


def test_run_and_step_both_hand_publishers_only_this_steps_sensor_messages():
    from unetyemu_ecs import Simulation, load_world_text
    text = """
world: {name: t, physics_hz: 240, seed: 1}
scene: {generator: none}
vehicles:
  - {name: d1, type: quadrotor, pose: {position_m: [0, 0, 0.1]}, components: {imu: {rate_hz: 240}}}
"""
    with Simulation(load_world_text(text)) as sim:
        sim.run(duration=1.0)
        assert len([s for s in sim.services.sensors.this_step if s.sensor == "imu"]) == 1
        sim.step(10)
        assert len([s for s in sim.services.sensors.this_step if s.sensor == "imu"]) == 1
