"""Energy, battery, air and wind models in the full flight stack, checked against their formulas.

- climb: the extra power of a steady climb is momentum theory's, ``T (V_c + v_i - v_h)``;
- forward flight: the power-vs-speed curve has the bucket shape with its minimum where a trim
  calculation with Glauert's inflow puts it;
- battery: the pack's voltage sags under the hover current by ``I (R0 + R1)``;
- air: the default world is ISA at its origin's altitude;
- wind: a drone holds position in 8 m/s of mean wind, tilted as its drag predicts, and spends more.
"""

from __future__ import annotations

import numpy as np
import pytest

from unetyemu_ecs import Simulation, load_world_text
from unetyemu_ecs.components.aero import AeroDrag
from unetyemu_ecs.components.flight import EnergyModel
from unetyemu_ecs.control.atmosphere import isa_density_kg_m3
from unetyemu_ecs.control.battery_ecm import cell_ocv_v
from unetyemu_ecs.control.rotor_power import climb_to_hover_power_ratio, profile_hover_power_w, rotor_shaft_power_w

from .test_flight import drone, hover

G = 9.81
MASS_KG = 8.0           # the medium preset


def big_world(drones: str, extra: str = "") -> str:
    return f"""
world:
  name: models
  physics_hz: 240
  seed: 3
{extra}
scene:
  generator: none
  ground_size_m: 1500
vehicles:
{drones}
"""


def mean_power_w(sim: Simulation, name: str, seconds: float) -> tuple[float, np.ndarray]:
    """Mean electrical power and the positions over ``seconds``."""
    row = sim.row(name)
    power, pos = [], []
    for _ in range(int(round(seconds / sim.dt_s))):
        sim.step()
        power.append(sim.fleet.power_w[row])
        pos.append(sim.fleet.pos_enu_m[row].copy())
    return float(np.mean(power)), np.array(pos)


def test_the_default_world_breathes_isa_air_at_its_650_m_origin_and_a_world_file_can_set_it():
    with Simulation(load_world_text(big_world(drone("d1")))) as sim:
        assert sim.services.air_density_kg_m3 == pytest.approx(1.150, abs=0.001)       # ISA at 650 m
        assert sim.services.air_density_kg_m3 == pytest.approx(float(isa_density_kg_m3(650.0)))
    hot = "  air: {temperature_c: 35.0}\n"          # a hot day: ISA pressure, thinner air
    with Simulation(load_world_text(big_world(drone("d1"), hot))) as sim:
        assert sim.services.air_density_kg_m3 == pytest.approx(1.150 * (288.15 - 0.0065 * 650) / 308.15, rel=2e-3)
    sea = "  air: {density_kg_m3: 1.225}\n"
    with Simulation(load_world_text(big_world(drone("d1"), sea))) as sim:
        assert sim.services.air_density_kg_m3 == 1.225


def test_a_steady_climb_costs_what_momentum_theory_says_and_the_paper_model_misses_most_of_it():
    climb_m_s, seconds = 3.0, 6.0
    extra_w = {}
    for model in ("momentum", "hover_actuator_disk"):
        comps = f"      energy: {{model: {model}}}\n"
        with Simulation(load_world_text(big_world(drone("d1", components=comps)))) as sim:
            hover(sim, "d1", 10.0, 12.0)
            hover_w, _ = mean_power_w(sim, "d1", 3.0)
            sim.set_target("d1", 0.0, 0.0, 200.0, speed=climb_m_s)
            sim.run(duration=4.0)                                  # reach the steady climb
            climb_w, pos = mean_power_w(sim, "d1", seconds)
            rate = (pos[-1, 2] - pos[0, 2]) / seconds
            assert rate == pytest.approx(climb_m_s, rel=0.03)
            extra_w[model] = climb_w - hover_w
            energy, drag = sim.component("d1", EnergyModel), sim.component("d1", AeroDrag)
            rho = sim.services.air_density_kg_m3
    area = np.pi * energy.rotor_radius_m ** 2

    def rotors_w(thrust_n: float, climb: float) -> float:
        """Four rotors sharing ``thrust_n`` in an axial climb: P_c = P_h (V_c/(2 v_h) + sqrt((V_c/(2 v_h))^2 + 1))."""
        v_h = np.sqrt(thrust_n / 4 / (2 * rho * area))
        return thrust_n * v_h * float(climb_to_hover_power_ratio(climb, v_h)) / energy.efficiency

    # momentum theory in the climb, with the thrust that also carries the body's drag (0.5 rho C_d A_top V^2)
    climb_thrust_n = MASS_KG * G + 0.5 * rho * drag.drag_coeff * drag.area_flu_m2[2] * climb_m_s ** 2
    expected_w = rotors_w(climb_thrust_n, climb_m_s) - rotors_w(MASS_KG * G, 0.0)
    assert extra_w["momentum"] == pytest.approx(expected_w, rel=0.05)
    # that is between half and all of the potential-energy rate over eta: the induced power falls in a climb
    potential_w = MASS_KG * G * climb_m_s / energy.efficiency
    assert 0.5 * potential_w < extra_w["momentum"] < potential_w
    # the paper's eq. 4 sees only the thrust (a few % more in the climb): a fraction of it
    assert extra_w["hover_actuator_disk"] < 0.25 * extra_w["momentum"]


def trim(speed_m_s: float, rho: float, drag: AeroDrag, energy: EnergyModel) -> tuple[float, float]:
    """Level flight of the medium drone at airspeed ``speed_m_s`` by a trim calculation: the pitch [rad]
    and thrust that balance weight and the body's drag (per body axis, as the simulator's drag law),
    then each rotor's power with its inflow (axial V sin(pitch), in-plane V cos(pitch)), plus P0.
    Returns ``(power_w, pitch_rad)``."""
    ax, _, az = drag.area_flu_m2
    q = 0.5 * rho * drag.drag_coeff
    pitch = thrust = 0.0
    for _ in range(100):                       # fixed point on the pitch angle
        vx, vz = speed_m_s * np.cos(pitch), speed_m_s * np.sin(pitch)
        fx, fz = -q * speed_m_s * ax * vx, -q * speed_m_s * az * vz       # body-axis drag
        # world x: T sin(p) + fx cos(p) + fz sin(p) = 0;  world z: T cos(p) - fx sin(p) + fz cos(p) = m g
        thrust = (MASS_KG * G + fx * np.sin(pitch) - fz * np.cos(pitch)) / np.cos(pitch)
        pitch = np.arctan2(-(fx * np.cos(pitch) + fz * np.sin(pitch)), thrust)
    area = np.pi * energy.rotor_radius_m ** 2
    profile = profile_hover_power_w(energy.rotor_solidity, energy.blade_drag_coeff, rho, area, energy.tip_speed_m_s)
    per_rotor = rotor_shaft_power_w(np.array([thrust / 4]), np.array([speed_m_s * np.sin(pitch)]),
                                    np.array([speed_m_s * np.cos(pitch)]), rho, area, profile, energy.tip_speed_m_s)
    return float(4 * per_rotor[0] / energy.efficiency + energy.p0_w), float(pitch)


def test_power_against_airspeed_has_the_bucket_shape_with_its_minimum_where_momentum_theory_puts_it():
    speeds = [0.0, 7.0, 14.0, 21.0, 28.0]
    measured = []
    with Simulation(load_world_text(big_world(drone("d1", pose="{position_m: [-700.0, 0.0, 0.3]}")))) as sim:
        rho = sim.services.air_density_kg_m3
        drag, energy = sim.component("d1", AeroDrag), sim.component("d1", EnergyModel)
        hover(sim, "d1", 20.0, 10.0)
        for v in speeds:
            if v > 0.0:
                sim.set_target("d1", 700.0, 0.0, 20.0, speed=v)
                sim.run(duration=max(4.0, v / 2.0))              # accelerate (and settle) at this speed
            p, pos = mean_power_w(sim, "d1", 3.0)
            assert np.linalg.norm(pos[-1, :2] - pos[0, :2]) / 3.0 == pytest.approx(v, abs=0.3)
            measured.append(p)
    predicted = [trim(v, rho, drag, energy)[0] for v in speeds]
    assert np.allclose(measured, predicted, rtol=0.04), (measured, predicted)
    # the bucket: power falls from hover, reaches its minimum at an intermediate speed, then rises
    k = int(np.argmin(measured))
    assert 0 < k < len(speeds) - 1
    assert int(np.argmin(predicted)) == k
    assert measured[0] > measured[k] and measured[-1] > measured[k]


def test_the_lipo_pack_sags_under_the_hover_current_by_its_resistances():
    with Simulation(load_world_text(big_world(drone("d1")))) as sim:
        row = sim.row("d1")
        energy = sim.component("d1", EnergyModel)
        sim.run(duration=0.5)
        v_ground = sim.fleet.pack_voltage_v[row]                      # P0 only
        hover(sim, "d1", 10.0, 15.0)
        sim.run(duration=5 * energy.rc_tau_s)                       # the RC pair settles
        f = sim.fleet
        current, soc = f.pack_current_a[row], f.soc_frac[row]
        ocv = energy.cells_series * float(cell_ocv_v(soc))
        r0, r1 = energy.cells_series * energy.cell_r0_ohm, energy.cells_series * energy.cell_r1_ohm
        assert f.pack_voltage_v[row] == pytest.approx(ocv - current * (r0 + r1), abs=0.02)
        assert f.pack_voltage_v[row] * current == pytest.approx(f.power_w[row], rel=1e-3)
        assert f.pack_voltage_v[row] < v_ground - 0.2


@pytest.mark.parametrize("model", ["momentum", "hover_actuator_disk"])
def test_a_drone_holds_position_in_8_m_s_of_wind_tilted_as_its_drag_predicts(model):
    comps = f"      energy: {{model: {model}}}\n"
    power = {}
    for wind in ("", "  wind: {speed_m_s: 8.0, toward_deg: 90.0}\n"):         # blowing toward north
        with Simulation(load_world_text(big_world(drone("d1", components=comps), wind))) as sim:
            hover(sim, "d1", 15.0, 20.0)
            power[bool(wind)], pos = mean_power_w(sim, "d1", 10.0)
            R = sim.fleet.R_enu_flu[sim.row("d1")].copy()
            drag, energy = sim.component("d1", AeroDrag), sim.component("d1", EnergyModel)
            rho = sim.services.air_density_kg_m3
        assert np.max(np.linalg.norm(pos[:, :2], axis=1)) < 0.5           # it holds its position
    # holding still in 8 m/s of wind is flying at 8 m/s airspeed: the thrust axis leans into the wind
    # (toward south) by the trim angle that balances drag and weight
    trim_w, trim_pitch = trim(8.0, rho, drag, energy)
    assert np.degrees(np.arctan2(-R[1, 2], R[2, 2])) == pytest.approx(np.degrees(trim_pitch), abs=0.3)
    if model == "momentum":
        # and it draws the trim's power: less than in still air for this rotor (translational lift: the
        # wind through the disks lowers the induced power more than the drag adds)
        assert power[True] == pytest.approx(trim_w, rel=0.04)
        assert power[True] < power[False]
    else:
        # the paper's eq. 4 sees only the larger thrust that balances the drag: more power than in still air
        assert power[True] > power[False]


def test_the_wind_pushes_a_falling_package_as_its_box_drag_predicts_and_reaches_cars():
    extra = "  air: {density_kg_m3: 1.2}\n  wind: {speed_m_s: 10.0, toward_deg: 0.0}\n"
    world = big_world("""  - name: car1
    type: car
    preset: medium
    pose: {position_m: [20.0, 20.0, 1.0]}
""", extra).replace("vehicles:", """packages:
  - name: box
    mass_kg: 2.0
    size_m: [0.4, 0.4, 0.4]
    pose: {position_m: [0.0, 0.0, 60.0]}
vehicles:""")
    with Simulation(load_world_text(world)) as sim:
        drag = sim.component("box", AeroDrag)
        assert drag.drag_coeff == pytest.approx(1.05) and np.allclose(drag.area_flu_m2, 0.16)
        assert sim.component("car1", AeroDrag).area_flu_m2[0] > 0.0            # cars have drag too
        sim.run(duration=2.0)
        box_v = sim.velocity_enu_m_s("box")
        assert np.allclose(sim.fleet.wind_enu_m_s[sim.row("car1")], [10.0, 0.0, 0.0])
    # reference: m dv/dt = m g - 0.5 rho C_d A |v - w| (v - w), the box falling face-on (it does not turn)
    v, w, k = np.zeros(3), np.array([10.0, 0.0, 0.0]), 0.5 * 1.2 * 1.05 * 0.16 / 2.0
    for _ in range(20_000):
        rel = v - w
        v = v + 1e-4 * (np.array([0.0, 0.0, -G]) - k * np.linalg.norm(rel) * rel)
    assert box_v == pytest.approx(v, abs=0.05)


def test_dryden_turbulence_is_seeded_per_body_and_shakes_a_hovering_drone():
    def run(seed: int, w20: float) -> tuple[np.ndarray, np.ndarray]:
        extra = f"  wind: {{speed_m_s: 5.0, turbulence_w20_m_s: {w20}}}\n"
        world = big_world(drone("d1") + drone("d2", pose="{position_m: [10.0, 0.0, 0.3]}"), extra)
        with Simulation(load_world_text(world, seed=seed)) as sim:
            hover(sim, "d1", 15.0, 1.0)
            hover(sim, "d2", 15.0, 9.0)
            wind, pos = [], []
            for _ in range(int(10.0 / sim.dt_s)):
                sim.step()
                wind.append(sim.fleet.wind_enu_m_s[[sim.row("d1"), sim.row("d2")]].copy())
                pos.append(sim.position_enu_m("d1"))
        return np.array(wind), np.array(pos)

    wind_a, pos_a = run(1, 15.4)            # MIL-F-8785C moderate turbulence
    wind_b, _ = run(1, 15.4)
    wind_c, _ = run(2, 15.4)
    _, pos_calm = run(1, 0.0)
    assert np.array_equal(wind_a, wind_b)                                 # the same seed: the same gusts
    assert not np.allclose(wind_a, wind_c)                                # another seed: other gusts
    assert not np.allclose(wind_a[:, 0], wind_a[:, 1])                    # each body its own turbulence
    assert np.all(np.abs(wind_a[:, :, :2].mean(axis=(0, 1)) - [5.0, 0.0]) < 3.0)
    assert np.std(wind_a[:, 0, 2]) > 0.1                                  # vertical gusts too
    spread = lambda p: np.std(p[:, :2], axis=0).sum()                     # noqa: E731
    assert spread(pos_a) > 2.0 * spread(pos_calm)                         # the drone is shaken


def test_a_gust_blows_as_the_1_minus_cosine_shape_over_its_time():
    extra = "  wind: {gusts: [{start_s: 1.0, peak_m_s: 6.0, rise_time_s: 2.0, toward_deg: 90.0}]}\n"
    with Simulation(load_world_text(big_world(drone("d1"), extra))) as sim:
        row = sim.row("d1")
        seen = {}
        for _ in range(int(6.0 / sim.dt_s)):
            t = sim.sim_time_s
            sim.step()
            seen[round(t, 4)] = sim.fleet.wind_enu_m_s[row].copy()
    for t, speed in ((0.5, 0.0), (2.0, 3.0), (3.0, 6.0), (4.0, 3.0), (5.5, 0.0)):
        assert seen[t] == pytest.approx([0.0, speed, 0.0], abs=1e-9)


def test_with_a_rated_voltage_the_motors_maximum_thrust_follows_the_pack_as_voltage_squared():
    ratios = {}
    for soc in (1.0, 0.15):
        comps = f"      motors: {{rated_voltage_v: 22.2}}\n      energy: {{initial_soc_frac: {soc}}}\n"
        with Simulation(load_world_text(big_world(drone("d1", components=comps)))) as sim:
            hover(sim, "d1", 10.0, 8.0)
            f, row = sim.fleet, sim.row("d1")
            volts = f.pack_voltage_v[row]
            sim.step()
            # the motors' command per unit of mixer output is F_max (V / V_rated)^2, V from the step before
            f_max_n = f.motor_thrust_cmd_n[row] / f.motor_frac_cmd[row]
            assert f_max_n == pytest.approx(np.full(4, 55.0 * (volts / 22.2) ** 2), rel=1e-9)
            assert abs(sim.position_enu_m("d1")[2] - 10.0) < 0.1           # it still hovers
            ratios[soc] = f_max_n[0] / 55.0
    assert ratios[1.0] > 1.15 and ratios[0.15] < ratios[1.0] - 0.1        # a full pack lifts more than a low one
