"""World files are validated on load: every problem reported with file, line and key path."""

from __future__ import annotations

import pytest

from unetyemu_ecs import ConfigError, load_world, load_world_text
from unetyemu_ecs.plugins import Registry
from unetyemu_ecs.sensors.imu import ImuSensor

from ..conftest import WORLDS

GOOD = """\
world:
  name: t
  physics_hz: 240
scene:
  generator: none
  pads:
    - {name: home, position_m: [0, 0]}
packages:
  - name: p1
    mass_kg: 1.0
    pose: {pad: home, offset_m: [1, 0]}
vehicles:
  - name: d1
    type: quadrotor
    preset: small
    pose: {pad: home}
"""


def _issues(text: str) -> list[str]:
    with pytest.raises(ConfigError) as info:
        load_world_text(text, "w.yaml", registry=Registry.discover())
    return [str(i) for i in info.value.issues]


def test_shipped_worlds_are_valid():
    for path in sorted(WORLDS.glob("*.yaml")):
        world = load_world(path)
        assert world.name


def test_a_good_world_resolves_poses_on_pads():
    world = load_world_text(GOOD, registry=Registry.discover())
    d1 = world.vehicles[0]
    # the small drone's box (0.08 m half height) rests on the pad top
    pad = world.layout.pads["home"]
    assert d1.pos_enu_m[2] == pytest.approx(pad.center_enu_m[2] + 0.08, abs=0.01)
    assert world.packages[0].pos_enu_m[0] == pytest.approx(pad.center_enu_m[0] + 1.0)


def test_negative_mass_is_reported_with_line_and_key_path():
    bad = GOOD.replace("mass_kg: 1.0", "mass_kg: -1.0")
    assert _issues(bad) == ["w.yaml:10: packages[0].mass_kg: must be > 0, got -1.0"]


def test_zero_physics_rate_is_reported():
    assert _issues(GOOD.replace("physics_hz: 240", "physics_hz: 0")) == [
        "w.yaml:3: world.physics_hz: must be >= 50, got 0.0"]


def test_unknown_key_lists_the_allowed_ones():
    (msg,) = _issues(GOOD.replace("  physics_hz: 240", "  physics_hz: 240\n  gravty: 1"))
    assert msg.startswith("w.yaml:4: world.gravty: unknown key 'gravty' (allowed: ")
    assert "gravity_m_s2" in msg


def test_wrong_type_is_reported():
    (msg,) = _issues(GOOD.replace("physics_hz: 240", "physics_hz: fast"))
    assert msg == "w.yaml:3: world.physics_hz: expected a number, got string 'fast'"


def test_duplicate_vehicle_names_are_reported_at_the_second_one():
    text = GOOD + "  - name: d1\n    type: car\n    pose: {position_m: [20, 0, 1]}\n"
    (msg,) = _issues(text)
    assert msg == "w.yaml:17: vehicles[1].name: duplicate name 'd1' (already used by vehicles[0] on line 13)"


def test_unknown_preset_and_bad_rate_are_reported_together():
    text = GOOD.replace("preset: small", "preset: huge").replace("physics_hz: 240", "physics_hz: -1")
    assert _issues(text) == [
        "w.yaml:3: world.physics_hz: must be >= 50, got -1.0",
        "w.yaml:15: vehicles[0].preset: unknown quadrotor preset 'huge' (expected one of: large, medium, small)"]


def test_unknown_pad_is_reported_with_the_pads_that_exist():
    (msg,) = _issues(GOOD.replace("pose: {pad: home, offset", "pose: {pad: nowhere, offset"))
    assert msg == "w.yaml:11: packages[0].pose.pad: unknown pad 'nowhere' (pads in this scene: home)"


def test_duplicate_yaml_keys_are_errors_not_silently_overwritten():
    (msg,) = _issues(GOOD.replace("  physics_hz: 240", "  physics_hz: 240\n  physics_hz: 100"))
    assert msg == "w.yaml:4: world.physics_hz: duplicate key 'physics_hz' (first on line 3)"


def test_yaml_syntax_error_names_the_line():
    (msg,) = _issues(GOOD.replace("  name: t", "  name: [t"))
    assert msg.startswith("w.yaml:") and "YAML syntax error" in msg


def test_pose_needs_exactly_one_placement():
    (msg,) = _issues(GOOD.replace("pose: {pad: home}", "pose: {pad: home, position_m: [0, 0, 1]}"))
    assert msg.startswith("w.yaml:16: vehicles[0].pose: a pose needs exactly one of position_m, pad, parking")


def test_unknown_component_lists_the_available_ones():
    text = GOOD + "    components: {warp_drive: {}}\n"
    (msg,) = _issues(text)
    assert msg.startswith("w.yaml:17: vehicles[0].components.warp_drive: unknown key 'warp_drive' (available: aero_drag, ")


def test_component_parameters_are_validated_against_the_component_dataclass():
    text = GOOD + "    components:\n      aero_drag: {drag_coeff: -2, area_flu_m2: [0.1, 0.1]}\n"
    issues = _issues_with_builtin(text)
    assert "w.yaml:18: vehicles[0].components.aero_drag.drag_coeff: must be >= 0, got -2.0" in issues
    assert "w.yaml:18: vehicles[0].components.aero_drag.area_flu_m2: expected list of 3 numbers, got 2 element(s)" in issues


def _issues_with_builtin(text: str) -> list[str]:
    with pytest.raises(ConfigError) as info:
        load_world_text(text, "w.yaml", registry=Registry.discover())
    return [str(i) for i in info.value.issues]


def test_every_problem_of_a_file_is_reported_at_once():
    text = GOOD.replace("physics_hz: 240", "physics_hz: -5").replace("mass_kg: 1.0", "mass_kg: zero")
    assert len(_issues(text)) == 2


def test_missing_file_is_a_config_error():
    with pytest.raises(ConfigError, match="file not found"):
        load_world("/nonexistent/world.yaml")


def test_sensors_all_attaches_every_installed_sensor_that_fits_and_components_keep_their_parameters():
    text = """
world: {name: s}
scene: {generator: none}
vehicles:
  - {name: d1, type: quadrotor, pose: {position_m: [0, 0, 1]}, sensors: all, components: {imu: {rate_hz: 400}}}
  - {name: c1, type: car, pose: {position_m: [10, 0, 1]}, sensors: [gps, lidar]}
"""
    world = load_world_text(text)
    d1, c1 = world.entities
    assert {"imu", "gps", "battery", "odometry", "lidar", "camera", "depth_camera"} <= set(d1.components)
    assert d1.components["imu"] == ImuSensor(rate_hz=400.0)
    assert {"gps", "lidar"} <= set(c1.components) and "battery" not in c1.components


def test_an_unknown_sensor_name_is_reported_at_its_place():
    text = """
world: {name: s}
scene: {generator: none}
vehicles:
  - {name: c1, type: car, pose: {position_m: [10, 0, 1]}, sensors: [gps, sonar]}
"""
    with pytest.raises(ConfigError) as err:
        load_world_text(text)
    assert "vehicles[0].sensors[1]" in str(err.value) and "unknown sensor 'sonar'" in str(err.value)


def test_a_sensor_topic_that_is_not_an_absolute_ros2_name_is_reported_and_ros2_switches_are_booleans():
    text = GOOD + "    ros2: sometimes\n"
    assert any("vehicles[0].ros2: expected true or false" in e for e in _issues(text))
    text = GOOD + "    components: {lidar: {topic: d1/points}, imu: {topic: /d1/imu data}, camera: {ros2: 2}}\n"
    errors = "\n".join(_issues(text))
    assert "vehicles[0].components.lidar.topic: 'd1/points' is not an absolute ROS 2 topic name" in errors
    assert "vehicles[0].components.imu.topic: '/d1/imu data' is not an absolute ROS 2 topic name" in errors
    assert "vehicles[0].components.camera.ros2: expected true or false" in errors
    world = load_world_text(GOOD + "    ros2: false\n    components: {imu: {topic: /d1/imu_fast}}\n")
    (drone,) = world.vehicles
    assert drone.ros2 is False and drone.components["imu"].ros2 is False       # the vehicle takes its sensors along
    assert drone.components["imu"].topic == "/d1/imu_fast"


def test_bad_air_and_wind_are_reported_with_their_lines():
    text = GOOD.replace("  physics_hz: 240\n", """  physics_hz: 240
  air: {temperature_c: 150, density_kg_m3: 0}
  wind: {speed_m_s: 80, turbulence_w20_m_s: -1, gusts: [{start_s: 1, peak_m_s: 3, rise_time_s: 0}]}
""")
    issues = _issues(text)
    assert "w.yaml:4: world.air.temperature_c: must be <= 60, got 150.0" in issues
    assert "w.yaml:4: world.air.density_kg_m3: must be >= 0.01, got 0.0" in issues
    assert "w.yaml:5: world.wind.speed_m_s: must be <= 50, got 80.0" in issues
    assert "w.yaml:5: world.wind.turbulence_w20_m_s: must be >= 0, got -1.0" in issues
    assert "w.yaml:5: world.wind.gusts[0].rise_time_s: must be > 0, got 0.0" in issues


def test_unknown_energy_models_and_an_impossible_pack_are_reported_naming_the_choices():
    issues = _issues(GOOD + "    components:\n      energy: {model: blade_element, battery: nicd, cells_series: 0}\n")
    assert any(i.startswith("w.yaml:18: vehicles[0].components.energy.model: ") and "hover_actuator_disk" in i
               for i in issues), issues
    assert any(i.startswith("w.yaml:18: vehicles[0].components.energy.battery: ") and "lipo" in i for i in issues)
    assert "w.yaml:18: vehicles[0].components.energy.cells_series: must be >= 1, got 0" in issues
