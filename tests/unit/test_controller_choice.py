"""Choosing a vehicle's controller per layer in the world file (``controller:``): every mistake is
refused with file:line and key path, a valid choice puts the controller's parameters on the entity
definition and, once built, in the ECS, where they select the one system that runs the law.

The registry used is the built-in parts plus a test controller registered through the API, so the
messages do not depend on which plugins happen to be installed.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated

import numpy as np
import pytest

from unetyemu_ecs import ConfigError, Simulation, load_world_text
from unetyemu_ecs.control.attitude import StabilizerGains
from unetyemu_ecs.control.position import GuidanceGains
from unetyemu_ecs.plugin_api import ControllerPlugin, Ge, Le, ThrustTorqueCommand
from unetyemu_ecs.plugins import GROUP_CONTROLLERS, GROUPS, Registry
from unetyemu_ecs.systems.flight_state import FlightMode


@dataclass(frozen=True)
class HoverOnlyParams:
    """Parameters of the test controller: one number with a range."""

    thrust_scale: Annotated[float, Ge(0.0), Le(2.0)] = 1.0


def hover_only_law(sp, state, airframe, params, memory, dt_s):
    """Test attitude law: hover thrust times ``thrust_scale``, no torque; counts its calls per vehicle."""
    n = airframe.mass_kg.shape[0]
    command = ThrustTorqueCommand(airframe.hover_thrust_frac * params.thrust_scale, np.zeros((n, 3)))
    return command, {"calls": memory["calls"] + 1.0}


HOVER_ONLY = ControllerPlugin(layer="attitude", params=HoverOnlyParams, law=hover_only_law,
                              memory={"calls": ((), 0.0)}, summary="test: hover thrust, no torque")


@pytest.fixture(scope="module")
def reg() -> Registry:
    """The built-in parts (those this project's own distribution provides) plus ``hover_only``."""
    found = Registry.discover()
    out = Registry()
    for group in GROUPS:
        for key, entry in found.entries[group].items():
            if entry.provider == "unetyemu_ecs":
                out.add(group, key, entry.spec, entry.provider)
    out.add(GROUP_CONTROLLERS, "hover_only", HOVER_ONLY)
    return out


HEAD = """\
world: {name: t, physics_hz: 240}
scene:
  generator: none
  pads:
    - {name: home, position_m: [0, 0]}
vehicles:
  - name: d1
    type: quadrotor
    preset: small
    pose: {pad: home}
"""
# line 11 is the first line after HEAD


def world(d1_extra: str, car_extra: str = "") -> str:
    """HEAD, then ``d1_extra`` (indented 4: keys of d1) from line 11, then a car with ``car_extra``."""
    return (HEAD + d1_extra + "  - name: c1\n    type: car\n    preset: medium\n"
            "    pose: {position_m: [10.0, 10.0, 1.0]}\n" + car_extra)


def issues(text: str, reg: Registry) -> list[str]:
    with pytest.raises(ConfigError) as info:
        load_world_text(text, "w.yaml", registry=reg)
    return [str(i) for i in info.value.issues]


# -- refusals ----------------------------------------------------------------------------------
def test_an_unknown_controller_name_lists_the_controllers_of_that_layer(reg):
    text = world("    controller:\n      attitude: px5_attitude\n")
    assert issues(text, reg) == ["w.yaml:12: vehicles[0].controller.attitude: unknown attitude controller "
                                 "'px5_attitude' (available: angle_rate_pd, hover_only)"]


def test_a_controller_of_another_layer_is_refused_naming_its_layer(reg):
    text = world("    controller:\n      attitude: cascade_pid\n")
    [msg] = issues(text, reg)
    assert msg.startswith("w.yaml:12: vehicles[0].controller.attitude: controller 'cascade_pid' is a position "
                          "controller, not a")
    assert msg.endswith("(attitude controllers: angle_rate_pd, hover_only)")


@pytest.mark.parametrize("block", ["attitude: null", "attitude: 3", "attitude: {params: {gain_att_p: 2.0}}"])
def test_a_layer_without_a_controller_name_is_refused_with_the_choices(reg, block):
    # a required layer cannot be switched off: a drone without an attitude controller cannot fly
    [msg] = issues(world(f"    controller:\n      {block}\n"), reg)
    assert msg.startswith("w.yaml:12: vehicles[0].controller.attitude: a quadrotor needs an attitude controller: "
                          "name one of angle_rate_pd, hover_only (got ")


def test_an_unknown_layer_key_is_refused_with_the_layers_of_the_vehicle(reg):
    text = world("    controller:\n      altitude: angle_rate_pd\n")
    assert issues(text, reg) == ["w.yaml:12: vehicles[0].controller.altitude: a quadrotor has no controller layer "
                                 "'altitude' (its layers: position, attitude, mixer)"]


def test_a_car_given_a_drone_layer_is_refused_with_its_own_layers(reg):
    text = world("", car_extra="    controller:\n      attitude: angle_rate_pd\n")
    assert issues(text, reg) == ["w.yaml:16: vehicles[1].controller.attitude: a car has no controller layer "
                                 "'attitude' (its layers: drive)"]


def test_a_parameter_out_of_range_is_named_under_controller_params(reg):
    text = world("    controller:\n      attitude:\n        name: angle_rate_pd\n        params:\n"
                 "          gain_att_p: 5000\n")
    assert issues(text, reg) == ["w.yaml:15: vehicles[0].controller.attitude.params.gain_att_p: "
                                 "must be <= 1000, got 5000.0"]


def test_a_plugin_controllers_parameter_ranges_are_checked_too(reg):
    text = world("    controller:\n      attitude: {name: hover_only, params: {thrust_scale: -0.5}}\n")
    assert issues(text, reg) == ["w.yaml:12: vehicles[0].controller.attitude.params.thrust_scale: "
                                 "must be >= 0, got -0.5"]


def test_an_unknown_parameter_lists_the_controllers_parameters(reg):
    text = world("    controller:\n      attitude: {name: hover_only, params: {thrust: 1.0}}\n")
    assert issues(text, reg) == ["w.yaml:12: vehicles[0].controller.attitude.params.thrust: unknown key 'thrust' "
                                 "(allowed: thrust_scale)"]


def test_a_misspelt_params_key_is_refused_with_the_expected_form(reg):
    text = world("    controller:\n      attitude:\n        name: angle_rate_pd\n        parms: {gain_att_p: 2.0}\n")
    assert issues(text, reg) == ["w.yaml:14: vehicles[0].controller.attitude.parms: unknown key 'parms' "
                                 "(a controller is {name: <controller>, params: {...}})"]


def test_a_controller_block_that_is_not_a_mapping_is_refused(reg):
    assert issues(world("    controller: [attitude]\n"), reg) == [
        "w.yaml:11: vehicles[0].controller: expected a mapping, got a list"]


def test_controller_params_given_as_null_are_refused(reg):
    text = world("    controller:\n      attitude: {name: angle_rate_pd, params: null}\n")
    assert issues(text, reg) == ["w.yaml:12: vehicles[0].controller.attitude.params: params: null is not a parameter "
                                 "block: give a mapping of the controller's parameters ({} keeps the defaults)"]


@pytest.mark.parametrize("key", ["motors", "guidance", "imu"])
def test_a_component_block_given_as_null_is_refused(reg, key):
    text = world(f"    components:\n      {key}: null\n")
    assert issues(text, reg) == [f"w.yaml:12: vehicles[0].components.{key}: {key}: null is not a parameter block: "
                                 "give a mapping of its parameters ({} keeps the defaults)"]


def test_every_mistake_of_a_world_is_reported_at_once(reg):
    text = world("    controller:\n      attitude: nope\n      mixer: cascade_pid\n",
                 car_extra="    controller: {drive: {name: speed_pi_steer, params: {nope: 1}}}\n")
    found = issues(text, reg)
    assert [m.split(": ")[0] + ": " + m.split(": ")[1] for m in found] == [
        "w.yaml:12: vehicles[0].controller.attitude", "w.yaml:13: vehicles[0].controller.mixer",
        "w.yaml:18: vehicles[1].controller.drive.params.nope"]


# -- registration ------------------------------------------------------------------------------
def test_two_controllers_sharing_one_params_class_are_refused_at_registration(reg):
    # the params class is the ECS component that selects a controller: shared, it could not tell them apart
    other = ControllerPlugin(layer="attitude", params=HoverOnlyParams, law=hover_only_law)
    local = Registry()
    local.add(GROUP_CONTROLLERS, "hover_only", HOVER_ONLY)
    with pytest.raises(ValueError, match="controllers 'hover_only' and 'hover_twin' share the params class "
                                         "HoverOnlyParams: each controller needs its own"):
        local.add(GROUP_CONTROLLERS, "hover_twin", other)
    assert list(local.entries[GROUP_CONTROLLERS]) == ["hover_only"]


def test_a_controller_name_registered_twice_is_refused(reg):
    local = Registry()
    local.add(GROUP_CONTROLLERS, "hover_only", HOVER_ONLY)
    with pytest.raises(ValueError, match="key 'hover_only' is provided twice"):
        local.add(GROUP_CONTROLLERS, "hover_only", HOVER_ONLY, provider="other-dist")


def test_a_controller_for_no_layer_or_with_non_dataclass_params_is_refused():
    with pytest.raises(ValueError):
        ControllerPlugin(layer="altitude", params=HoverOnlyParams, law=hover_only_law)
    with pytest.raises(TypeError, match="must be a dataclass"):
        ControllerPlugin(layer="attitude", params=dict, law=hover_only_law)
    with pytest.raises(TypeError, match="expected name -> \\(tail shape, initial value\\)"):
        ControllerPlugin(layer="attitude", params=HoverOnlyParams, law=hover_only_law, memory={"calls": 0.0})


class ForeignLe:
    """A range marker of another library (like ``annotated_types.Le``): the loader has no check for it."""

    def __init__(self, le: float) -> None:
        self.le = le


@dataclass(frozen=True)
class ForeignRangeParams:
    gain: Annotated[float, ForeignLe(10.0)] = 1.0


@dataclass(frozen=True)
class NamedParams:
    label: str = "x"


def test_a_parameter_with_a_range_the_loader_cannot_check_or_a_non_numeric_parameter_is_refused():
    with pytest.raises(TypeError, match="field 'gain' has the constraint .* which the world-file loader cannot check"):
        ControllerPlugin(layer="attitude", params=ForeignRangeParams, law=hover_only_law)
    with pytest.raises(TypeError, match="parameter 'label' must be a number or a tuple of numbers"):
        ControllerPlugin(layer="attitude", params=NamedParams, law=hover_only_law)


# -- valid choices -----------------------------------------------------------------------------
def test_a_valid_choice_puts_the_params_on_the_definition_and_unnamed_layers_keep_the_built_in(reg):
    text = world("    controller:\n      attitude: {name: angle_rate_pd, params: {gain_att_p: 2.0}}\n")
    d1 = load_world_text(text, "w.yaml", registry=reg).vehicles[0]
    assert d1.controllers["attitude"] == ("angle_rate_pd", StabilizerGains(gain_att_p=2.0))
    assert d1.controllers["position"] == ("cascade_pid", GuidanceGains())
    assert d1.controllers["mixer"][0] == "x_quad_priority"
    # a name alone takes the defaults
    plain = load_world_text(world("    controller: {attitude: hover_only}\n"), "w.yaml", registry=reg).vehicles[0]
    assert plain.controllers["attitude"] == ("hover_only", HoverOnlyParams())


def test_built_params_select_the_one_system_that_runs_each_drones_attitude_law(reg):
    # GIVEN d1 on angle_rate_pd with a changed gain and d2 on the test controller
    text = (world("    controller:\n      attitude: {name: angle_rate_pd, params: {gain_att_p: 2.0}}\n")
            + "  - name: d2\n    type: quadrotor\n    preset: small\n    pose: {position_m: [5.0, 0.0, 0.2]}\n"
            "    controller: {attitude: {name: hover_only, params: {thrust_scale: 0.5}}}\n")
    with Simulation(load_world_text(text, "w.yaml", registry=reg)) as sim:
        # THEN each carries its controller's parameters as a component, and only those
        assert sim.component("d1", StabilizerGains) == StabilizerGains(gain_att_p=2.0)
        assert sim.component("d2", HoverOnlyParams) == HoverOnlyParams(thrust_scale=0.5)
        assert StabilizerGains not in {type(c) for c in sim.components_of("d2").values()}
        # WHEN both are armed and held for 100 steps
        sim.set_target("d1", 0.0, 0.0, 2.0)
        sim.set_target("d2", 5.0, 0.0, 2.0)
        sim.step(100)
        d1, d2 = sim.row("d1"), sim.row("d2")
        systems = {s.key: list(s.rows) for s in sim.ecs.systems if getattr(s, "key", None)}
        # THEN the built-in attitude system runs for d1 only and the test one for d2 only
        assert systems["angle_rate_pd"] == [d1] and systems["hover_only"] == [d2]
        assert sorted(systems["cascade_pid"]) == sorted([d1, d2])
        # AND the test law ran once a step for d2 with its memory in the fleet arrays, never for d1
        f = sim.fleet
        assert f.flight_mode[d2] == FlightMode.AUTO
        assert f.ctl_HoverOnlyParams_calls[d2] == 100.0 and f.ctl_HoverOnlyParams_calls[d1] == 0.0
        assert f.ctl_StabilizerGains_vz_int_m_s[d2] == 0.0 and f.ctl_StabilizerGains_vz_int_m_s[d1] != 0.0
        # AND d2's command is its law's: half the hover thrust, no torque
        assert f.thrust_frac_sp[d2] == pytest.approx(0.5 * 5.0 * 9.81 / (4 * 30.0))   # small: 5 kg, 30 N motors
        assert np.all(f.torque_cmd[d2] == 0.0)


def broken_law(sp, state, airframe, params, memory, dt_s):
    """A law with a bug: it returns the wrong type."""
    return sp, {"calls": memory["calls"]}


def test_a_controller_law_that_breaks_is_named_in_the_error(reg):
    local = Registry()
    for group in GROUPS:
        for key, entry in reg.entries[group].items():
            if key != "hover_only":
                local.add(group, key, entry.spec, entry.provider)

    @dataclass(frozen=True)
    class BrokenParams:
        gain: Annotated[float, Ge(0.0), Le(1.0)] = 0.5

    local.add(GROUP_CONTROLLERS, "broken", ControllerPlugin(layer="attitude", params=BrokenParams, law=broken_law,
                                                            memory={"calls": ((), 0.0)}))
    with Simulation(load_world_text(world("    controller: {attitude: broken}\n"), "w.yaml", registry=local)) as sim:
        with pytest.raises(RuntimeError, match=r"attitude controller 'broken' failed at t = 0.0000 s: TypeError: "
                                               r"it returned a AttitudeSetpoint, not a ThrustTorqueCommand"):
            sim.step()


def law_that_writes_into_the_state(sp, state, airframe, params, memory, dt_s):
    """A law with a bug: it moves the drone by writing into the state it was given."""
    state.pos_enu_m[:, 2] += 100.0
    return ThrustTorqueCommand(np.zeros(1), np.zeros((1, 3))), {}


def test_a_controller_law_cannot_move_the_drone_by_writing_into_its_state(reg):
    local = Registry()
    for group in GROUPS:
        for key, entry in reg.entries[group].items():
            local.add(group, key, entry.spec, entry.provider)

    @dataclass(frozen=True)
    class WriterParams:
        gain: Annotated[float, Ge(0.0), Le(1.0)] = 0.5

    local.add(GROUP_CONTROLLERS, "writer", ControllerPlugin(layer="attitude", params=WriterParams,
                                                            law=law_that_writes_into_the_state, memory={}))
    with Simulation(load_world_text(world("    controller: {attitude: writer}\n"), "w.yaml", registry=local)) as sim:
        z0 = float(sim.position_enu_m("d1")[2])
        # THEN the state a law receives is read-only: the error names the controller, the fleet is untouched
        with pytest.raises(RuntimeError, match=r"attitude controller 'writer' failed at t = 0.0000 s: ValueError: "
                                               r".*read-only"):
            sim.step()
        assert float(sim.position_enu_m("d1")[2]) == z0
