"""The Foxglove transport's own messages, without a server: plots-ready states, schemas, rate limiting."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from unetyemu_ecs.systems.flight_state import FlightMode, MissionState
from unetyemu_ecs.transport import foxglove as fx
from unetyemu_ecs.transport.api import Snapshot


def snapshot(**override: np.ndarray) -> Snapshot:
    """A drone (row 0) hovering at 10 m, flying east at 3 m/s, heading north, and a parked car (row 1)."""
    q_north = [0.0, 0.0, math.sin(math.pi / 4), math.cos(math.pi / 4)]          # yaw +90 deg (ENU)
    arrays = {
        "pos_enu_m": np.array([[1.0, 2.0, 10.0], [5.0, 6.0, 0.8]]),
        "vel_enu_m_s": np.array([[3.0, 0.0, -4.0], [0.0] * 3]),
        "quat_enu_flu_xyzw": np.array([q_north, [0.0, 0.0, 0.0, 1.0]]), "armed": np.array([True, False]),
        "soc_frac": np.array([0.75, np.nan]), "power_w": np.array([420.0, np.nan]),
        "pack_voltage_v": np.array([22.2, np.nan]), "pack_current_a": np.array([18.9, np.nan]),
        "energy_used_j": np.array([1000.0, np.nan]), "remaining_time_s": np.array([np.inf, np.nan]),
        "payload_kg": np.array([2.5, 0.0]), "low_battery": np.array([False, False]),
        "flight_mode": np.array([int(FlightMode.AUTO), 0]), "nav_state": np.array([4, 0]),
        "landed_state": np.array([2, 1]), "mission_state": np.array([int(MissionState.RUNNING), 0]),
        "mission_step": np.array([3, -1]),
    }
    arrays.update(override)
    return Snapshot(step=240, sim_time_s=1.0, dt_s=1 / 240, vehicles=("drone1", "car1"), kinds=("quadrotor", "car"),
                    arrays=arrays, sensors=(), events=[], events_end=0, results=[], results_end=0)


def test_a_drones_state_has_names_units_and_derived_speeds():
    state = fx.vehicle_state(snapshot(), 0)
    assert state["position_enu_m"] == {"x": 1.0, "y": 2.0, "z": 10.0} and state["altitude_m"] == 10.0
    assert state["speed_m_s"] == pytest.approx(5.0) and state["horizontal_speed_m_s"] == pytest.approx(3.0)
    assert state["vertical_speed_m_s"] == -4.0 and state["heading_deg"] == pytest.approx(90.0)
    assert (state["flight_mode"], state["nav_state"], state["landed_state"]) == ("AUTO", "MISSION", "IN_AIR")
    assert (state["mission_state"], state["mission_step"], state["soc_frac"]) == ("RUNNING", 3, 0.75)
    assert state["remaining_time_s"] is None                                  # inf: not JSON
    schema = fx.VEHICLE_STATE_SCHEMA["properties"]
    assert set(state) <= set(schema) and set(schema) == set(state)          # a drone fills every field


def test_a_car_has_no_battery_fields_and_nothing_non_finite_reaches_json():
    car = fx.vehicle_state(snapshot(), 1)
    assert car["kind"] == "car" and car["armed"] is False
    assert not {"soc_frac", "flight_mode", "mission_state"} & set(car)
    broken = fx.vehicle_state(snapshot(pos_enu_m=np.array([[np.nan, 0.0, np.inf], [0.0] * 3])), 0)
    assert broken["position_enu_m"] == {"x": None, "y": 0.0, "z": None}
    json.dumps(broken, allow_nan=False)                                       # valid JSON


def test_ros2_schemas_are_the_jazzy_definitions_with_their_dependencies():
    schema = fx.ros2msg_schema("sensor_msgs/msg/Image")
    assert (schema.name, schema.encoding) == ("sensor_msgs/msg/Image", "ros2msg")
    text = bytes(schema.data).decode()
    assert text.startswith("std_msgs/Header header") and "MSG: builtin_interfaces/Time" in text
