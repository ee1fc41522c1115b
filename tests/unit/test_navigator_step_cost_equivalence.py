"""The navigator's, land detector's and flight-command system's cheaper per-step forms give bit for bit what the
plain forms gave: the arming verdict without np.select, the fence test written
out for the whole fleet, the land detector that tests only drones touching something or carrying a package, the
navigator that walks only drones with something to do, and the command system that does nothing when nothing is
pending. The plain forms are kept below as they were written, and a fleet flown through take-off, landing,
auto-disarm, RTL, missions, sticks, streams, a geofence and a package with them must match every fleet array,
every navigator state and every event, step by step."""

from __future__ import annotations

import math
import types
from types import SimpleNamespace

import esper
import numpy as np
import pytest
from numpy.testing import assert_array_equal

from unetyemu_ecs import Simulation, load_world_text
from unetyemu_ecs.components.body import FleetSlot, RigidBody
from unetyemu_ecs.components.flight import GuidanceLimits, TeleopScript
from unetyemu_ecs.navigation.geofence import Geofence
from unetyemu_ecs.navigation.params import FlightParams
from unetyemu_ecs.navigation.state import NavRuntime
from unetyemu_ecs.systems import flight_commands
from unetyemu_ecs.systems.commands import serve_commands
from unetyemu_ecs.systems.flight_commands import FlightCommandSystem, _cancel_mission
from unetyemu_ecs.systems.flight_state import (FLIGHT_ARRAYS, LANDED_ON_GROUND, LANDED_UNDEFINED, MODE_DISARMED,
                                               NAV_MANUAL, NAV_OFFBOARD, NAV_POSCTL, ArmBlock, FlightMode, LandedState,
                                               NavState)
from unetyemu_ecs.systems.navigator import (_NOTHING, LAND_TRIGGER_S, LandDetectorSystem, NavigatorSystem, _arm_codes,
                                            _RowLimits, _set_mode, arm_blocks, enforce_fence,
                                            ensure_all_drones, fence_active, fence_breach, fences_active,
                                            fly_manual, fly_offboard, manual_fresh, manual_lost, offboard_fresh,
                                            offboard_lost)

RNG = np.random.default_rng(11)


# -- the plain forms, as they were written ------------------------------------------------------
def old_arm_blocks(f, rows, fence_why, limits):
    low_frac, max_payload = limits
    has_battery = np.isfinite(low_frac[rows])
    low = has_battery & (f.low_battery[rows] | (f.soc_frac[rows] < low_frac[rows]))
    motors_off = ~f.motors_enabled[rows]
    overweight = motors_off & (f.payload_kg[rows] > max_payload[rows])
    outside = np.array([bool(w) for w in fence_why], dtype=bool)
    landed = f.landed_state[rows]
    in_air = (landed != LANDED_ON_GROUND) & (landed != LANDED_UNDEFINED)
    codes = np.select([low, overweight, motors_off, outside, in_air],
                      [int(ArmBlock.LOW_BATTERY), int(ArmBlock.OVERWEIGHT), int(ArmBlock.MOTORS_DISABLED),
                       int(ArmBlock.OUTSIDE_FENCE), int(ArmBlock.IN_AIR)], default=int(ArmBlock.NONE))
    return codes.astype(np.int8)


def old_land_detector_update(self, ctx):
    f = ctx.fleet
    t = ctx.sim_time_s + ctx.dt_s
    contact = ctx.physics.contact_map()
    rows = self.rows
    vel = f.vel_enu_m_s[rows]
    speed_z = np.abs(vel[:, 2]).tolist()
    speed_xy = np.hypot(vel[:, 0], vel[:, 1]).tolist()
    rate = np.linalg.norm(f.rate_flu_rad_s[rows], axis=1).tolist()
    packages = f.payload_entity[rows].tolist()
    landed = f.landed_state[rows].tolist()
    states = list(landed)
    modes, nav_states = f.flight_mode[rows].tolist(), f.nav_state[rows].tolist()
    for k, (ent, body, nav, params) in enumerate(zip(self.entities.tolist(), *self.components)):
        touching = contact.get(body.body_id, _NOTHING)
        if packages[k] >= 0:
            carried = esper.component_for_entity(packages[k], RigidBody).body_id
            touching = (touching | contact.get(carried, _NOTHING)) - {body.body_id, carried}
        still = (bool(touching) and speed_z[k] < params["LNDMC_Z_VEL_MAX"]
                 and speed_xy[k] < params["LNDMC_XY_VEL_MAX"]
                 and rate[k] < math.radians(params["LNDMC_ROT_MAX"]))
        prev = landed[k]
        if still:
            if math.isnan(nav.contact_since_s):
                nav.contact_since_s = t
            on_ground = (prev in (LANDED_UNDEFINED, LANDED_ON_GROUND)
                         or t - nav.contact_since_s >= LAND_TRIGGER_S - 1e-9)
        else:
            nav.contact_since_s = math.nan
            on_ground = False
        if on_ground:
            if prev != LANDED_ON_GROUND:
                nav.ground_since_s = t
                states[k] = LANDED_ON_GROUND
            continue
        nav.ground_since_s = math.nan
        if modes[k] != MODE_DISARMED:
            nav.took_off = True
        states[k] = int(self._airborne_state(ent, nav_states[k], nav))
    f.landed_state[rows] = states


def old_navigator_update(self, ctx):
    f = ctx.fleet
    t = ctx.sim_time_s
    rows = self.rows
    drones = list(zip(self.entities.tolist(), *self.components))
    unset = rows[~f.home_set[rows]]
    if unset.size:
        f.home_enu_m[unset] = f.pos_enu_m[unset]
        f.home_set[unset] = True
    fenced = [old_fence_active(nav, params) for _, nav, params in drones]
    why = [fence_breach(f, row, nav, params) if on else ""
           for on, row, (_, nav, params) in zip(fenced, rows.tolist(), drones)]
    f.arm_block[rows] = old_arm_blocks(f, rows, why, self._limits)
    modes, nav_states = f.flight_mode[rows].tolist(), f.nav_state[rows].tolist()
    grounded = (f.landed_state[rows] == LANDED_ON_GROUND).tolist()
    for k, (row, (ent, nav, params)) in enumerate(zip(rows.tolist(), drones)):
        if modes[k] == MODE_DISARMED:
            if nav.mode:
                _set_mode(nav, "", "", t, None)
            nav.took_off, nav.armed_s = False, math.nan
            continue
        if nav.mode:
            self._advance(ctx, ent, row, nav, params)
        elif nav_states[k] == NAV_OFFBOARD and nav.offboard is not None:
            if offboard_fresh(nav, params, t):
                fly_offboard(ctx, ent, row, nav, params, new=False)
            else:
                offboard_lost(ctx, ent, row, nav, params)
        elif nav_states[k] in (NAV_POSCTL, NAV_MANUAL) and nav.manual is not None:
            if manual_fresh(nav, params, t):
                fly_manual(ctx, row, nav, params)
            else:
                manual_lost(ctx, ent, row, nav, params)
        on_ground = grounded[k]
        if not on_ground and int(f.flight_mode[row]) != MODE_DISARMED:
            if fenced[k]:
                enforce_fence(ctx, ent, row, nav, params)
            else:
                nav.fence_ok = True
        if on_ground:
            self._auto_disarm(ctx, ent, row, nav, params)


def old_flight_commands_process(self, ctx):
    f = ctx.fleet
    ensure_all_drones()
    serve_commands(ctx, GuidanceLimits, self._take, self._hold_after_lapse)
    for ent, (slot, script) in esper.get_components(FleetSlot, TeleopScript):
        k = self._script_next.get(ent, 0)
        frames = script.keyframes
        applied = False
        while k < len(frames) and frames[k].t_s <= ctx.sim_time_s + 1e-9:
            f.stick[slot.row] = frames[k].stick
            k += 1
            applied = True
        if applied:
            f.flight_mode[slot.row] = FlightMode.MANUAL
            f.nav_state[slot.row] = NavState.MANUAL
            _cancel_mission(ctx, ent, "teleop")
        self._script_next[ent] = k


# -- the arming verdict -------------------------------------------------------------------------
def random_fleet(n: int) -> tuple[SimpleNamespace, tuple[np.ndarray, np.ndarray]]:
    f = SimpleNamespace(
        landed_state=RNG.choice([-128, -1, 0, 1, 2, 3, 4, 5, 127], n).astype(np.int8),
        motors_enabled=RNG.random(n) < 0.7,
        payload_kg=RNG.choice([0.0, 0.5, 2.0, 50.0, np.nan, np.inf], n),
        low_battery=RNG.random(n) < 0.2,
        soc_frac=RNG.choice([0.0, 0.05, 0.1, 0.2, 0.8, 1.0, np.nan], n))
    limits = (RNG.choice([-np.inf, 0.1, 0.2, np.nan, np.inf], n), RNG.choice([np.inf, 1.0, 2.0, np.nan, -np.inf], n))
    return f, limits


def plain(f: SimpleNamespace, limits: tuple[np.ndarray, np.ndarray]) -> None:
    """The usual fleet: every drone has a battery, none a bay, motors on, batteries fine."""
    f.motors_enabled[:] = True
    f.low_battery[:] = False
    f.soc_frac[:] = 0.8
    limits[0][:] = 0.1
    limits[1][:] = np.inf


@pytest.mark.parametrize("usual", [False, True])
def test_arming_verdicts_are_the_first_failing_check_in_order_as_np_select_gave(usual):
    for n in (1, 2, 3, 7, 40, 300):
        f, limits = random_fleet(n)
        if usual:
            plain(f, limits)
        for rows in (np.arange(n), RNG.permutation(n)[: max(1, n // 2)], RNG.integers(0, n, n)):
            for why in ([""] * rows.size, [RNG.choice(["", "outside the fence zones"]) for _ in rows]):
                expected = old_arm_blocks(f, rows, why, limits)
                got = arm_blocks(f, rows, why, limits)
                assert got.dtype == np.int8
                assert_array_equal(got, expected)
                lim = _RowLimits(limits[0][rows], limits[1][rows])
                outside = [bool(w) for w in why]
                outside_or_none = outside if any(outside) else None
                assert_array_equal(_arm_codes(f, rows, lim, None if outside_or_none is None
                                              else np.array(outside, dtype=bool)), expected)
        # through a slice, as a system whose rows are contiguous reads them
        lim = _RowLimits(limits[0][1:], limits[1][1:])
        expected = old_arm_blocks(f, np.arange(1, n), [""] * (n - 1), limits)
        assert_array_equal(_arm_codes(f, slice(1, n), lim, None), expected)


def test_arming_verdicts_of_states_stored_wider_than_the_fleets_int8_are_the_same():
    f, limits = random_fleet(50)
    expected = old_arm_blocks(f, np.arange(50), [""] * 50, limits)
    f.landed_state = f.landed_state.astype(np.int64)
    assert_array_equal(arm_blocks(f, np.arange(50), [""] * 50, limits), expected)


def test_the_fleet_stores_landed_and_nav_states_as_int8_and_the_navigator_reads_nav_states_as_uint8():
    assert FLIGHT_ARRAYS["landed_state"][:2] == ((), np.int8)
    assert FLIGHT_ARRAYS["nav_state"][:2] == ((), np.int8)


def old_fence_active(nav, params):
    return nav.fence_enabled and ((nav.fence is not None and not nav.fence.empty)
                                  or params["GF_MAX_HOR_DIST"] > 0.0 or params["GF_MAX_VER_DIST"] > 0.0)


def test_the_fleet_fence_test_is_the_old_fence_test_of_each_drone():
    navs, params_of = [], []
    for enabled in (True, False):
        for fence in (None, Geofence(), Geofence(inclusion_circles=((0.0, 0.0, 10.0),))):
            for hor in (0.0, 5.0):
                for ver in (0.0, 3.0):
                    params = FlightParams()
                    params.set("GF_MAX_HOR_DIST", hor)
                    params.set("GF_MAX_VER_DIST", ver)
                    navs.append(NavRuntime(fence=fence, fence_enabled=enabled))
                    params_of.append(params)
    expected = [old_fence_active(nav, params) for nav, params in zip(navs, params_of)]
    assert fences_active(navs, params_of) == expected
    assert [fence_active(nav, params) for nav, params in zip(navs, params_of)] == expected
    assert any(expected) and not all(expected)


# -- a fleet flown through every branch, old and new side by side --------------------------------
N_DRONES = 12
MISSION = '[{"type": "takeoff", "altitude_m": 2}, {"type": "land"}]'


def fleet_world() -> str:
    drones = "".join(f"  - {{name: d{i}, type: quadrotor, preset: medium, pose: {{position_m: [{4.0 * i}, 0.0, "
                     f"{1.0 if i == 7 else 0.3}]}}}}\n" for i in range(N_DRONES))
    return f"""
world: {{name: nav_equivalence, physics_hz: 240, seed: 11}}
scene:
  generator: none
  ground_size_m: 300
  pads:
    - {{name: home, position_m: [0, 0]}}
packages:
  - {{name: parcel, mass_kg: 0.5, size_m: [0.4, 0.4, 0.3], pose: {{pad: home, offset_m: [28.0, 0.0]}}}}
  - {{name: crate, mass_kg: 1.0, size_m: [0.4, 0.4, 0.3], pose: {{pad: home, offset_m: [50.0, 6.0]}}}}
vehicles:
{drones}"""


def commands(sim: Simulation, step: int) -> list[int]:
    """What each drone is told at this step: d0 takes off and lands, d1 arms and never takes off, d2 takes off
    and returns home, d3 breaches its fence, d4 teleop lapses, d5 flies a mission, d6 a cmd_vel stream, d7 lifts
    the parcel it rests on and lands with it, d8 sticks that stop, d9 an offboard stream that stops (and then
    carries, as far as the land detector knows, a crate resting on the ground), d10 a low battery and d11 an
    overweight package keep them from arming."""
    ids: list[int] = []
    if step == 24:
        for i in range(N_DRONES):
            ids.append(sim.set_param(f"d{i}", "COM_DISARM_LAND", 0.5))
        ids += [sim.set_param("d1", "COM_DISARM_PRFLT", 1.0), sim.set_param("d3", "GF_MAX_HOR_DIST", 4.0),
                sim.set_param("d2", "RTL_RETURN_ALT", 3.0), sim.set_param("d2", "RTL_DESCEND_ALT", 2.0),
                sim.set_param("d8", "NAV_RCL_ACT", 3), sim.set_param("d8", "COM_FAIL_ACT_T", 1.0)]
        f = sim.fleet
        f.soc_frac[sim.row("d10")], f.low_battery[sim.row("d10")] = 0.05, True
        f.motors_enabled[sim.row("d11")], f.payload_kg[sim.row("d11")] = False, 50.0
    if step == 150:
        ids.append(sim.gripper("d7", True))
    if step == 240:
        ids += [sim.arm(f"d{i}") for i in range(10)]
    if step == 250:
        ids += [sim.takeoff("d0", 3.0), sim.takeoff("d2", 3.0), sim.takeoff("d3", 2.0), sim.takeoff("d7", 2.0),
                sim.load_mission("d5", MISSION), sim.teleop("d4", 0.3, 0.0, 0.0, 0.0, hold_s=0.5),
                sim.cmd_vel("d6", 0.0, 0.0, up_m_s=1.0), sim.manual_control("d8", 0.0, 0.0, 0.5, 0.0),
                sim.offboard_setpoint("d9", pos=(36.0, 0.0, 2.0))]
    if step == 260:
        ids += [sim.set_nav_mode("d8", "POSCTL"), sim.set_nav_mode("d9", "OFFBOARD")]
    if 250 < step < 500 and step % 24 == 0:
        ids += [sim.manual_control("d8", 0.0, 0.0, 0.8, 0.0), sim.offboard_setpoint("d9", pos=(36.0, 0.0, 2.0))]
    if step == 700:
        ids += [sim.set_target("d3", 20.0, 0.0, 2.0), sim.land("d0"), sim.return_to_launch("d2"), sim.land("d7")]
    if step == 1000:    # d9, hovering, is told it carries the crate lying on the ground far away: only that touches
        sim.fleet.payload_entity[sim.row("d9")] = sim.entity("crate")
    if step == 1200:
        sim.fleet.payload_kg[sim.row("d11")] = 0.0       # motors still off, no longer overweight
    return ids


def shuttle(sim: Simulation, step: int) -> list[int]:
    """Every drone rests, climbs to 4 m and flies 10 m east, as a fleet under position control does; d5 is
    terminated on the way, falls, is armed again (forced) while falling and recovers."""
    if step == 120:
        return [sim.set_target(f"d{i}", 4.0 * i, 0.0, 4.0) for i in range(N_DRONES)]
    if step == 600:
        return [sim.set_target(f"d{i}", 4.0 * i + 10.0, 0.0, 4.0) for i in range(N_DRONES)]
    if step == 650:
        return [sim.terminate("d5")]
    if step == 700:
        return [sim.arm("d5", force=True)]
    return []


def system_of(sim: Simulation, cls: type):
    return next(s for s in sim.ecs.systems if type(s) is cls)


def as_before(sim: Simulation) -> Simulation:
    """The plain forms in place of the new ones, on this simulation's systems only."""
    for cls, name, plain_form in ((LandDetectorSystem, "update", old_land_detector_update),
                                  (NavigatorSystem, "update", old_navigator_update),
                                  (FlightCommandSystem, "process", old_flight_commands_process)):
        system = system_of(sim, cls)
        setattr(system, name, types.MethodType(plain_form, system))
    return sim


def without_the_body_map(sim: Simulation) -> Simulation:
    """The land detector looks for contacts drone by drone (what it does when two drones would share a body id)."""
    detector = system_of(sim, LandDetectorSystem)
    gather = detector.gather

    def gather_without_the_body_map(ctx):
        gather(ctx)
        detector._k_of_body = None

    detector.gather = gather_without_the_body_map
    return sim


def fleet_bytes(sim: Simulation) -> dict[str, bytes]:
    f = sim.fleet
    out = {}
    for name in sorted(f._declared) + ["quat_enu_flu_xyzw", "R_enu_flu", "odometer_m", "body_id", "entity"]:
        arr = getattr(f, name)
        if arr.dtype.kind in "fiub":
            out[name] = arr.tobytes()
    out["route"] = repr([None if r is None else (r.points_enu_m.tobytes(), r.speeds_m_s.tobytes(),
                                                 repr(r.yaw_sp_rad)) for r in f.route])
    return out


def nav_states(sim: Simulation) -> str:
    with sim.ecs.active():
        return repr([(ent, nav.mode, nav.phase, nav.phase_started_s, nav.took_off, nav.armed_s, nav.contact_since_s,
                      nav.ground_since_s, nav.fence_ok, nav.fence_enabled,
                      None if nav.goal_enu_m is None else np.asarray(nav.goal_enu_m).tobytes())
                     for ent, nav in sorted(esper.get_component(NavRuntime))])


def fly_side_by_side(script, steps: int) -> tuple[list, dict[str, set]]:
    """Fly the fleet with the plain forms, the list forms and the array forms in step; every fleet array and every
    navigator state must match after every step, the events and command results at the end. Returns the events
    and what the plain run went through (landed states, arming verdicts, flight modes; d7 on the ground with
    the parcel while armed)."""
    world = load_world_text(fleet_world())
    sims = [as_before(Simulation(world, ros2="off")), without_the_body_map(Simulation(world, ros2="off")),
            Simulation(world, ros2="off")]
    seen: dict[str, set] = {"landed": set(), "blocks": set(), "modes": set(), "carried_on_ground": set()}
    ids: list[list[int]] = [[] for _ in sims]
    try:
        for step in range(steps):
            for sim, sent in zip(sims, ids):
                sent += script(sim, step)
                sim.step()
            ref, ref_nav = fleet_bytes(sims[0]), nav_states(sims[0])
            for sim, form in zip(sims[1:], ("contacts drone by drone", "contacts by body map")):
                got = fleet_bytes(sim)
                differ = [name for name in ref if got[name] != ref[name]]
                assert not differ, f"step {step}, {form}: {differ} differ from the plain forms"
                assert nav_states(sim) == ref_nav, f"step {step}, {form}: navigator state differs"
            f, row7 = sims[0].fleet, sims[0].row("d7")
            seen["landed"].update(f.landed_state[:N_DRONES].tolist())
            seen["blocks"].update(f.arm_block[:N_DRONES].tolist())
            seen["modes"].add(tuple(f.flight_mode[:N_DRONES] != MODE_DISARMED))
            if f.payload_entity[row7] >= 0 and f.landed_state[row7] == LANDED_ON_GROUND:
                seen["carried_on_ground"].add(bool(f.flight_mode[row7] != MODE_DISARMED))
        events = sims[0].events
        for sim, sent in zip(sims[1:], ids[1:]):
            assert sim.events == events
            assert sent == ids[0]
            assert [sim.command_result(i) for i in sent] == [sims[0].command_result(i) for i in ids[0]]
    finally:
        for sim in sims:
            sim.close()
    return events, seen


def test_a_fleet_through_every_navigator_branch_flies_bit_for_bit_as_before():
    events, seen = fly_side_by_side(commands, 1900)
    # the flight went through every branch the new forms take
    assert seen["landed"] == {int(s) for s in LandedState if s != LandedState.UNDEFINED}
    assert seen["blocks"] == {int(b) for b in ArmBlock}
    assert True in seen["carried_on_ground"]
    texts = [f"{name}: {text}" for _, name, text in events]
    for expected in ("d7: picked up parcel", "d0: takeoff to z = 3.0 m", "d4: teleop timed out",
                     "d1: disarmed: armed 1 s without taking off (COM_DISARM_PRFLT)", "d5: mission step 1 (land) done",
                     "d8: failsafe: manual control lost", "d8: failsafe: manual control still lost: land",
                     "d9: failsafe: offboard setpoints lost", "d2: returning to", "d3: geofence breached",
                     "d7: landed", "d7: disarmed: landed 0.5 s ago", "d0: disarmed: landed 0.5 s ago",
                     "d2: disarmed: landed 0.5 s ago", "d8: disarmed: landed 0.5 s ago",
                     "d9: disarmed: landed 0.5 s ago"):
        assert any(text.startswith(expected) for text in texts), expected


def test_a_shuttling_fleet_with_one_drone_falling_flies_bit_for_bit_as_before():
    events, seen = fly_side_by_side(shuttle, 1200)
    # all on the ground, then all flying and armed (nothing for the navigator to do drone by drone), then one
    # disarmed and falling through the air, armed again in the air (took_off set anew by the land detector)
    assert {LANDED_ON_GROUND, int(LandedState.IN_AIR)} <= seen["landed"]
    assert (True,) * N_DRONES in seen["modes"]
    assert tuple(i != 5 for i in range(N_DRONES)) in seen["modes"]
    d5 = [text for _, name, text in events if name == "d5"]
    terminated = next(k for k, text in enumerate(d5) if text.startswith("disarmed: flight termination"))
    assert not any(text.startswith("impact") for text in d5[terminated:])      # caught before the ground


# -- the command system when there is nothing to do ----------------------------------------------
def test_the_command_system_serves_only_pending_or_lapsing_commands_and_equips_drones_added_later(monkeypatch):
    world = load_world_text(fleet_world())
    sim = Simulation(world, ros2="off")
    served = []
    monkeypatch.setattr(flight_commands, "serve_commands", lambda *a, **k: served.append(a[0].step)
                        or serve_commands(*a, **k))
    try:
        sim.run(duration=0.5)
        assert served == []                         # nothing was sent: nothing was served
        sim.teleop("d4", 0.3, 0.0, 0.0, 0.0, hold_s=0.1)
        sim.step()
        assert served == [sim.step_count - 1]       # the command
        sim.run(duration=0.2)
        assert len(served) == 2 and sim.nav_state("d4") == "HOLD"   # and its lapse, a step after hold_s
        # a drone that lost its navigator state gets a new one on the next step, as ensure_all_drones gives
        ent = sim.entity("d3")
        with sim.ecs.active():
            esper.remove_component(ent, NavRuntime)
        sim.step()
        with sim.ecs.active():
            assert isinstance(esper.try_component(ent, NavRuntime), NavRuntime)
            assert esper.has_component(ent, FlightParams)
        assert len(served) == 2
    finally:
        sim.close()
