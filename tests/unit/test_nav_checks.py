"""Range checks of the navigation commands (command_checks, the single validator of every transport)."""

from __future__ import annotations

import math

import pytest

from unetyemu_ecs import command_checks as cc
from unetyemu_ecs.systems.flight_state import NavState


def test_nav_mode_accepts_names_and_numbers_and_refuses_the_rest():
    assert cc.check_nav_mode("d", "rtl") == NavState.RTL
    assert cc.check_nav_mode("d", int(NavState.HOLD)) == NavState.HOLD
    for bad in ("CRUISE", 99, True, 1.0, None):
        with pytest.raises(ValueError, match="mode must be one of"):
            cc.check_nav_mode("d", bad)


def test_takeoff_altitude_and_heading_ranges():
    assert cc.check_takeoff("d") == (None, None)
    alt, yaw = cc.check_takeoff("d", 5, 90)
    assert alt == 5.0 and yaw == pytest.approx(math.pi / 2)
    for bad in (float("nan"), 0.0, -1.0, 1e6, True, "5"):
        with pytest.raises(ValueError, match="alt_m"):
            cc.check_takeoff("d", bad)
    with pytest.raises(ValueError, match="yaw_deg"):
        cc.check_takeoff("d", 5, 400)


def test_param_names_and_ranges_come_from_the_px4_table():
    assert cc.check_param("d", "MIS_TAKEOFF_ALT", 7.5) == ("MIS_TAKEOFF_ALT", 7.5)
    with pytest.raises(ValueError, match="unknown flight parameter"):
        cc.check_param("d", "NOT_A_PARAM", 1)
    with pytest.raises(ValueError, match=r"MPC_XY_CRUISE must be in \[3, 20\]"):
        cc.check_param("d", "MPC_XY_CRUISE", 50)
    with pytest.raises(ValueError, match="whole number"):
        cc.check_param("d", "GF_ACTION", 1.5)
    with pytest.raises(ValueError, match="finite"):
        cc.check_param("d", "RTL_RETURN_ALT", float("nan"))


def test_change_speed_kinds_and_caps():
    assert cc.check_change_speed("d", "climb", 2) == ("climb", 2.0)
    with pytest.raises(ValueError, match="which must be one of"):
        cc.check_change_speed("d", "sideways", 2)
    with pytest.raises(ValueError, match="descent speed must be in"):
        cc.check_change_speed("d", "descent", 9)
    with pytest.raises(ValueError):
        cc.check_change_speed("d", "ground", 0)


def test_mission_step_and_flags():
    assert cc.check_mission_step("d", 3) == 3
    for bad in (-1, 1.0, True, 10**9):
        with pytest.raises(ValueError, match="mission step"):
            cc.check_mission_step("d", bad)
    with pytest.raises(ValueError, match="force must be True or False"):
        cc.check_flag("force", 1)
