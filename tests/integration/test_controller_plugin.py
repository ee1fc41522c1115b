"""A controller plugin (plugins/px4_attitude) installed with pip replaces the attitude layer of the
drones that choose it, in the full simulator (esper + PyBullet): a mixed fleet flies its deliveries
with the built-in layer not running for the replaced drone, and the plugin's step responses in
PyBullet are those its README gives from a rigid-body model.

The plugin is installed with ``pip install --target`` into a private directory that comes first on
the PYTHONPATH of a subprocess (the test environment need not have it); each subprocess checks that
the entry point it runs was loaded from that directory and prints its measurements as JSON.
"""

from __future__ import annotations

import json
import math
import textwrap
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from ..conftest import REPO_ROOT, WORLDS, pip_install_plugin, run_python_with_site

PLUGIN_DIR = REPO_ROOT / "plugins" / "px4_attitude"

# Run first in every subprocess: the px4_attitude entry point, found and loaded from the --target copy.
PREAMBLE = """
import json, sys
import numpy as np
from unetyemu_ecs import Simulation, load_world_text
from unetyemu_ecs.plugins import Registry
REG = Registry.discover()
ENTRY = REG.entries["unetyemu_ecs.controllers"].get("px4_attitude")
assert ENTRY is not None, f"px4_attitude not found: {REG.failures}"
RESULT = {"provider": ENTRY.provider, "law_file": sys.modules[ENTRY.spec.law.__module__].__file__,
          "layer": str(ENTRY.spec.layer)}
"""


@pytest.fixture(scope="module")
def plugin_site(tmp_path_factory) -> Path:
    """pip-install the px4_attitude plugin into a private directory (no dependencies, no network)."""
    return pip_install_plugin(PLUGIN_DIR, tmp_path_factory.mktemp("px4_site"))


def run_with_plugin(site: Path, code: str, timeout_s: float = 600.0) -> dict[str, Any]:
    """Run ``PREAMBLE + code`` with the plugin's site first on the path; ``code`` fills the dict
    ``RESULT``, printed as JSON at the end. Checks that the plugin came from ``site``."""
    script = textwrap.dedent(PREAMBLE) + textwrap.dedent(code) + "\nprint(json.dumps(RESULT))\n"
    res = run_python_with_site(site, script, timeout_s)
    assert res.returncode == 0, res.stderr[-4000:]
    out = json.loads(res.stdout.strip().splitlines()[-1])
    assert out["provider"] == "unetyemu-px4-attitude" and out["layer"] == "attitude", out
    assert Path(out["law_file"]).resolve().is_relative_to(site.resolve()), out["law_file"]
    return out


# -- a mixed fleet: drone a flies px4_attitude, drone b the built-in angle_rate_pd ----------------
MIXED_WORLD = """
world: {name: mixed_fleet, physics_hz: 240, seed: 5}
scene:
  generator: none
  ground_size_m: 200
  pads:
    - {name: home_a, position_m: [0, 0], kind: start}
    - {name: home_b, position_m: [0, 10], kind: start}
    - {name: drop_a, position_m: [30, 0]}
    - {name: drop_b, position_m: [30, 10], z_m: 4.0}      # a raised pad: its top 4.1 m up
packages:
  - {name: parcel_a, mass_kg: 2.0, size_m: [0.4, 0.4, 0.3], pose: {pad: home_a, offset_m: [1.0, 0.0]}}
  - {name: parcel_b, mass_kg: 2.0, size_m: [0.4, 0.4, 0.3], pose: {pad: home_b, offset_m: [1.0, 0.0]}}
vehicles:
  - name: a
    type: quadrotor
    preset: medium
    pose: {pad: home_a, offset_m: [-0.6, 0.0]}
    controller: {attitude: px4_attitude}
    components:
      mission:
        name: deliver_a
        cruise_speed: 6.0
        steps:
          - {type: pickup, package: parcel_a}
          - {type: takeoff, altitude_m: 8.0}
          - {type: cruise, waypoints: [{x: 30.0, y: 0.0, z: 8.0}], pad: drop_a}
          - {type: land, pad: drop_a}
          - {type: deliver}
  - name: b
    type: quadrotor
    preset: medium
    pose: {pad: home_b, offset_m: [-0.6, 0.0]}
    components:
      mission:
        name: deliver_b
        cruise_speed: 6.0
        steps:
          - {type: pickup, package: parcel_b}
          - {type: takeoff, altitude_m: 8.0}
          - {type: cruise, waypoints: [{x: 30.0, y: 10.0, z: 8.0}], pad: drop_b}
          - {type: land, pad: drop_b}
          - {type: deliver}
"""

MIXED_RUN = f"""
from unetyemu_px4_attitude import MEMORY
world = load_world_text({MIXED_WORLD!r}, "mixed_fleet.yaml", registry=REG)
RESULT["controllers"] = {{e.name: {{k: v[0] for k, v in e.controllers.items()}} for e in world.entities
                         if e.kind == "quadrotor"}}
with Simulation(world) as sim:
    f = sim.fleet
    a, b = sim.row("a"), sim.row("b")
    sim.step()
    builtin_int = "ctl_StabilizerGains_vz_int_m_s"
    px4_arrays = {{name: "ctl_Px4AttitudeParams_" + name for name in MEMORY}}
    max_a_builtin = max_b_builtin = max_a_px4_vz = 0.0
    b_px4_untouched = True
    payload_seen = {{"a": 0.0, "b": 0.0}}
    while sim.sim_time_s < 60.0:
        sim.step()
        max_a_builtin = max(max_a_builtin, abs(float(getattr(f, builtin_int)[a])))
        max_b_builtin = max(max_b_builtin, abs(float(getattr(f, builtin_int)[b])))
        max_a_px4_vz = max(max_a_px4_vz, abs(float(getattr(f, px4_arrays["vz_int_m_s2"])[a])))
        for name, arr in px4_arrays.items():
            tail, initial = MEMORY[name]
            b_px4_untouched &= bool(np.array_equal(getattr(f, arr)[b], np.full(tail, initial), equal_nan=True))
        for n, r in (("a", a), ("b", b)):
            payload_seen[n] = max(payload_seen[n], float(f.payload_kg[r]))
        states = [sim.mission_status(n)["state"] for n in ("a", "b")]
        if "running" not in states:
            break
    systems = {{s.key: [int(r) for r in s.rows] for s in sim.ecs.systems if getattr(s, "key", None)}}
    RESULT.update(
        rows={{"a": a, "b": b}}, systems=systems, t_end_s=sim.sim_time_s,
        status={{n: sim.mission_status(n) for n in ("a", "b")}},
        parcel={{n: sim.position_enu_m("parcel_" + n).tolist() for n in ("a", "b")}},
        pad={{n: [*sim.layout.pads["drop_" + n].center_enu_m.tolist(), sim.layout.pads["drop_" + n].size_m]
             for n in ("a", "b")}},
        max_a_builtin=max_a_builtin, max_b_builtin=max_b_builtin, max_a_px4_vz=max_a_px4_vz,
        b_px4_untouched=b_px4_untouched, payload_seen=payload_seen,
        events=[list(e) for e in sim.events])
"""


@pytest.fixture(scope="module")
def mixed_fleet(plugin_site) -> dict[str, Any]:
    return run_with_plugin(plugin_site, MIXED_RUN)


def test_each_drone_of_the_mixed_fleet_gets_the_attitude_controller_it_chose(mixed_fleet):
    # GIVEN drone a with `controller: {attitude: px4_attitude}` and drone b with no controller block
    # THEN a's attitude layer is the plugin and every other layer of both drones is the built-in one
    assert mixed_fleet["controllers"] == {
        "a": {"position": "cascade_pid", "attitude": "px4_attitude", "mixer": "x_quad_priority"},
        "b": {"position": "cascade_pid", "attitude": "angle_rate_pd", "mixer": "x_quad_priority"}}


def test_both_drones_of_the_mixed_fleet_complete_their_deliveries_onto_their_pads(mixed_fleet):
    # WHEN both fly pickup, takeoff, a 30 m cruise, landing on a pad (one raised 4 m) and delivery
    r = mixed_fleet
    # THEN both missions complete well within a minute of sim time
    for n in ("a", "b"):
        assert r["status"][n]["state"] == "completed", (n, r["status"][n], r["events"])
        assert r["payload_seen"][n] == 2.0, n                    # it did carry its 2 kg parcel
    assert r["t_end_s"] < 60.0
    # AND each parcel rests on its own pad: within the pad's square, its bottom on the pad's top
    for n in ("a", "b"):
        x, y, z, size = r["pad"][n]
        parcel = np.array(r["parcel"][n])
        assert np.all(np.abs(parcel[:2] - [x, y]) < size / 2), (n, parcel)
        assert parcel[2] == pytest.approx(z + 0.15, abs=0.05), (n, parcel)


def test_the_built_in_attitude_controller_does_not_run_for_the_drone_that_replaced_it(mixed_fleet):
    r = mixed_fleet
    a, b = r["rows"]["a"], r["rows"]["b"]
    # THEN the built-in layer's system has only b in its rows, the plugin's only a; both share the rest
    assert r["systems"]["angle_rate_pd"] == [b]
    assert r["systems"]["px4_attitude"] == [a]
    assert sorted(r["systems"]["cascade_pid"]) == sorted([a, b]) == sorted(r["systems"]["x_quad_priority"])
    # AND the built-in vertical-speed integrator of a stayed exactly 0 through the whole flight, while
    # b's took up its 2 kg parcel (the built-in assumes the unloaded hover thrust)
    assert r["max_a_builtin"] == 0.0
    assert r["max_b_builtin"] > 0.1
    # AND the plugin's memory of b never left its initial values, while a's vertical integrator worked
    assert r["b_px4_untouched"] is True
    assert r["max_a_px4_vz"] > 1.0        # 2 kg on 8 kg: about 2.5 m/s^2 of extra lift to find


# -- the plugin's step responses in PyBullet -----------------------------------------------------
STEP_RUN = """
import math
from unetyemu_ecs.components.flight import GuidanceLimits
from unetyemu_ecs.frames import euler_rpy_from_quat_xyzw
WORLD = '''
world: {name: steps, physics_hz: 240, seed: 7}
scene: {generator: none, ground_size_m: 300, pads: [{name: home, position_m: [0, 0]}]}
vehicles:
  - {name: d1, type: quadrotor, preset: medium, pose: {position_m: [0.0, 0.0, 0.3]},
     controller: {attitude: px4_attitude}}
'''
with Simulation(load_world_text(WORLD, "steps.yaml", registry=REG)) as sim:
    lim = sim.component("d1", GuidanceLimits)
    row = sim.row("d1")

    def record(seconds):
        t0, t, roll, vz = sim.sim_time_s, [], [], []
        for _ in range(round(seconds / sim.dt_s)):
            sim.step()
            r, _, _ = euler_rpy_from_quat_xyzw(sim.fleet.quat_enu_flu_xyzw[row][None])
            t.append(sim.sim_time_s - t0)
            roll.append(float(r[0]))
            vz.append(float(sim.fleet.vel_enu_m_s[row, 2]))
        return {"t": t, "roll": roll, "vz": vz}

    sim.set_target("d1", 0.0, 0.0, 10.0)          # hover at 10 m
    sim.run(duration=10.0)
    sim.teleop("d1", 0.0, 0.0, 0.0, 0.0)            # sticks centred: level, holding height
    RESULT["before_roll"] = record(1.0)
    sim.teleop("d1", 0.0, 0.0, 0.2, 0.0)            # roll stick 0.2
    RESULT["roll_step"] = record(1.5)
    sim.teleop("d1", 0.0, 0.0, 0.0, 0.0)
    sim.run(duration=3.0)
    RESULT["before_climb"] = record(0.5)
    sim.teleop("d1", 1.0 / lim.lim_climb_m_s, 0.0, 0.0, 0.0)      # throttle stick for 1 m/s up
    RESULT["climb_step"] = record(3.0)
    RESULT["max_tilt_rad"] = math.radians(lim.max_tilt_deg)
"""


@pytest.fixture(scope="module")
def step_responses(plugin_site) -> dict[str, Any]:
    return run_with_plugin(plugin_site, STEP_RUN)


def _step_figures(t: np.ndarray, y: np.ndarray, target: float) -> dict[str, float]:
    """Rise (10-90 %), overshoot (fraction of the step) and settling time (last exit from a 5 % band)."""
    rise = t[np.argmax(y >= 0.9 * target)] - t[np.argmax(y >= 0.1 * target)]
    outside = np.flatnonzero(np.abs(y - target) > 0.05 * abs(target))
    settle = t[outside[-1] + 1] if outside.size else t[0]
    return {"rise_s": float(rise), "overshoot": float((y.max() - target) / target), "settle_s": float(settle)}


def test_a_roll_stick_step_is_followed_within_5_percent_by_half_a_second_without_overshoot(step_responses):
    # GIVEN a medium drone with px4_attitude hovering level at 10 m in MANUAL with the sticks centred
    r = step_responses
    assert np.max(np.abs(r["before_roll"]["roll"])) < math.radians(0.2)
    # WHEN the roll stick steps to 0.2: a roll setpoint of 0.2 * max_tilt (9 deg on the medium preset)
    target = 0.2 * r["max_tilt_rad"]
    t, roll = np.array(r["roll_step"]["t"]), np.array(r["roll_step"]["roll"])
    fig = _step_figures(t, roll, target)
    # THEN roll is within 5 % of the setpoint from 0.5 s on, and overshoots by less than 15 %
    assert np.all(np.abs(roll[t >= 0.5] - target) <= 0.05 * target), fig
    assert fig["overshoot"] < 0.15, fig
    # AND it is the README's (pure-numpy model) response: rise 0.23 s, no overshoot, settled by 0.32 s
    assert fig["rise_s"] == pytest.approx(0.23, abs=0.03), fig
    assert fig["settle_s"] == pytest.approx(0.32, abs=0.05), fig


def test_a_throttle_stick_step_reaches_the_commanded_climb_rate(step_responses):
    # GIVEN the same drone hovering level again
    r = step_responses
    assert np.max(np.abs(r["before_climb"]["vz"])) < 0.05
    # WHEN the throttle stick asks for 1 m/s up
    t, vz = np.array(r["climb_step"]["t"]), np.array(r["climb_step"]["vz"])
    fig = _step_figures(t, vz, 1.0)
    # THEN it climbs at 1 m/s within 5 % from 1 s on, overshooting by less than 15 %
    assert np.all(np.abs(vz[t >= 1.0] - 1.0) <= 0.05), fig
    assert fig["overshoot"] < 0.15, fig
    # AND as the README's model says: rise 0.38 s, settled within 5 % by about 0.5 s
    assert fig["rise_s"] == pytest.approx(0.38, abs=0.05), fig
    assert fig["settle_s"] == pytest.approx(0.48, abs=0.1), fig


# -- the paper's scenario flown with the plugin ---------------------------------------------------
URBAN_RUN = f"""
import dataclasses
import yaml
from unetyemu_ecs.sensors.base import SensorSpec
data = yaml.safe_load(open({str(WORLDS / "urban_delivery.yaml")!r}))
for v in data["vehicles"]:
    if v["type"] == "quadrotor":
        v["controller"] = {{"attitude": "px4_attitude"}}
world = load_world_text(yaml.safe_dump(data, sort_keys=False), "urban_delivery_px4.yaml", registry=REG)
# sensors only read the state: without them the flights are the same, at a third of the cost
world = dataclasses.replace(world, entities=tuple(
    dataclasses.replace(e, components={{k: c for k, c in e.components.items() if not isinstance(c, SensorSpec)}})
    for e in world.entities))
RESULT["attitude"] = {{e.name: e.controllers["attitude"][0] for e in world.entities if e.kind == "quadrotor"}}
with Simulation(world) as sim:
    while sim.sim_time_s < 200.0:
        sim.step(24)
        if all(sim.mission_status(n)["state"] != "running" for n in ("drone1", "drone2")):
            break
    RESULT.update(
        t_end_s=sim.sim_time_s, status={{n: sim.mission_status(n) for n in ("drone1", "drone2")}},
        package=sim.position_enu_m("package1").tolist(), drone1=sim.position_enu_m("drone1").tolist(),
        drone3_z=float(sim.position_enu_m("drone3")[2]),
        roof=[*sim.layout.pads["roof_1"].center_enu_m.tolist(), sim.layout.pads["roof_1"].size_m],
        home=sim.layout.pads["start_1"].center_enu_m.tolist(),
        impacts=[list(e) for e in sim.events if e[1].startswith("drone") and e[2].startswith("impact")],
        events=[list(e) for e in sim.events if e[1].startswith("drone")])
"""


@pytest.mark.slow
def test_the_urban_delivery_scenario_with_every_drone_on_px4_attitude_completes(plugin_site):
    # GIVEN worlds/urban_delivery.yaml with the attitude layer of all three drones set to px4_attitude
    # WHEN it runs until both mission drones are done
    r = run_with_plugin(plugin_site, URBAN_RUN, timeout_s=1200.0)
    assert set(r["attitude"].values()) == {"px4_attitude"} and len(r["attitude"]) == 3
    # THEN the rooftop delivery and the target sequence complete, without touching anything
    for n in ("drone1", "drone2"):
        assert r["status"][n]["state"] == "completed", (n, r["status"][n], r["events"])
    assert r["impacts"] == []
    # AND the package rests on the rooftop pad, drone1 is back home and the teleop drone still hovers
    x, y, z, size = r["roof"]
    package = np.array(r["package"])
    assert np.all(np.abs(package[:2] - [x, y]) < size / 2) and package[2] == pytest.approx(z + 0.15, abs=0.05)
    assert np.linalg.norm(np.array(r["drone1"][:2]) - r["home"][:2]) < 1.5
    assert r["drone3_z"] > 5.0
