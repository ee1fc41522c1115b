"""MAVLink messages -> the simulation's commands (ENU, radians), through a real endpoint and a real
Inbox (no sockets: the endpoint's links are not opened, so its answers go nowhere)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mavlink2

from unetyemu_ecs import load_world_text
from unetyemu_ecs.geodesy import GeodeticOrigin, enu_to_geodetic
from unetyemu_ecs.systems.flight_state import NavState
from unetyemu_ecs.transport import bus
from unetyemu_ecs.transport.api import Snapshot
from unetyemu_ecs.transport.mavlink.component import MavlinkEndpoint
from unetyemu_ecs.transport.mavlink.endpoint import DroneEndpoint

ORIGIN = GeodeticOrigin(47.397742, 8.545594, 488.0)
LAYOUT = load_world_text("world: {name: t}\nscene: {generator: none, ground_size_m: 400}\n").layout   # +-200 m
TX = mavlink2.MAVLink(None, 245, 190)
RX = mavlink2.MAVLink(None)


def wire(msg):
    return RX.parse_buffer(msg.pack(TX))[0]


def snapshot(pos=(10.0, 20.0, 5.0)) -> Snapshot:
    arrays = {"pos_enu_m": np.array([pos]), "home_enu_m": np.array([[10.0, 20.0, 0.0]]),
              "home_set": np.array([True]), "quat_enu_flu_xyzw": np.array([[0.0, 0.0, 0.0, 1.0]])}
    return Snapshot(1, 1.0, 1 / 240, ("d1",), ("quadrotor",), arrays, (), [], 0, [], 0)


@pytest.fixture
def ep():
    inbox = bus.Inbox()
    e = DroneEndpoint("d1", MavlinkEndpoint(instance=0), ORIGIN, LAYOUT, inbox.submit, 1 / 240, None, None)
    e.on_snapshot(snapshot((10.0, 20.0, 0.1)), 0)          # local origin: where the drone started
    e.on_snapshot(snapshot(), 0)
    e.inbox = inbox
    return e


def submitted(ep) -> list:
    return ep.inbox.drain()


def handle(ep, msg) -> None:
    ep.handle(wire(msg), ep.links[0], ("127.0.0.1", 1), 0.0)


def test_offboard_position_velocity_and_body_velocity_setpoints_in_enu(ep):
    # local NED position 5 m north, 3 m east, 2 m up of the start; yaw 90 deg NED = east = 0 ENU
    handle(ep, mavlink2.MAVLink_set_position_target_local_ned_message(0, 1, 1, 1, 0b1001_1111_1000,
                                                                      5, 3, -2, 0, 0, 0, 0, 0, 0, math.pi / 2, 0))
    (sp,) = submitted(ep)
    assert isinstance(sp, bus.OffboardSetpoint) and sp.source == "mavlink"
    assert sp.pos_enu_m == pytest.approx((13.0, 25.0, 2.1))
    assert sp.yaw_rad == pytest.approx(0.0, abs=1e-6) and sp.vel_enu_m_s is None      # float32 on the wire
    # NED velocity 1 north, 2 east, 0.5 down; yaw rate 0.3 rad/s clockwise (NED) = -0.3 CCW
    handle(ep, mavlink2.MAVLink_set_position_target_local_ned_message(0, 1, 1, 1, 0b0000_0101_1100_0111,
                                                                      0, 0, 0, 1, 2, 0.5, 0, 0, 0, 0, 0.3))
    (sp,) = submitted(ep)
    assert sp.vel_enu_m_s == pytest.approx((2.0, 1.0, -0.5)) and sp.yaw_rate_rad_s == pytest.approx(-0.3)
    # MAVSDK's body velocity (MAV_FRAME_BODY_NED: forward, right, down) -> FLU
    handle(ep, mavlink2.MAVLink_set_position_target_local_ned_message(0, 1, 1, 8, 0b0000_0101_1100_0111,
                                                                      0, 0, 0, 1, 2, -0.5, 0, 0, 0, 0, 0))
    (sp,) = submitted(ep)
    assert sp.vel_flu_m_s == pytest.approx((1.0, -2.0, 0.5)) and sp.vel_enu_m_s is None


def test_set_attitude_target_becomes_an_enu_attitude_setpoint_with_its_thrust(ep):
    from unetyemu_ecs.frames import quat_xyzw_from_euler_rpy, quat_xyzw_to_wxyz

    # FRD in NED: roll 5 deg right side down, pitch 10 deg nose UP, heading 90 deg (east); thrust 0.7
    q = [float(x) for x in quat_xyzw_to_wxyz(quat_xyzw_from_euler_rpy(*np.radians([5.0, 10.0, 90.0])))]
    handle(ep, mavlink2.MAVLink_set_attitude_target_message(0, 1, 1, 7, q, 0, 0, 0, 0.7))
    (sp,) = submitted(ep)
    # -> FLU in ENU: right side down is still +roll, nose up is -pitch, east is heading 0
    assert sp.attitude_rp_rad == pytest.approx(np.radians([5.0, -10.0]), abs=1e-6)
    assert sp.yaw_rad == pytest.approx(0.0, abs=1e-6) and sp.thrust_frac == pytest.approx(0.7)
    assert sp.pos_enu_m is None and sp.vel_enu_m_s is None and sp.vel_flu_m_s is None
    # rates only (attitude ignored), thrust ignored, a thrust vector (THRUST_BODY_SET), thrust above 1 and a
    # zero quaternion: refused, nothing submitted
    for mask, quat, thrust in ((128, q, 0.5), (7 | 64, q, 0.5), (7 | 32, q, 0.5), (7, q, 1.2),
                               (7, [0.0, 0.0, 0.0, 0.0], 0.5)):
        handle(ep, mavlink2.MAVLink_set_attitude_target_message(0, 1, 1, mask, quat, 0, 0, 0, thrust))
    assert submitted(ep) == [] and ep.setpoints_rejected == 5


def test_nan_setpoints_and_out_of_range_sticks_are_dropped(ep):
    handle(ep, mavlink2.MAVLink_set_position_target_local_ned_message(0, 1, 1, 1, 0b1001_1111_1000,
                                                                      math.nan, 3, -2, 0, 0, 0, 0, 0, 0, 0, 0))
    handle(ep, mavlink2.MAVLink_manual_control_message(1, 0, 0, 1500, 0, 0))
    assert submitted(ep) == [] and ep.unhandled_messages == 2
    # a position outside the world (1 km north) goes through the project's offboard check: refused
    handle(ep, mavlink2.MAVLink_set_position_target_local_ned_message(0, 1, 1, 1, 0b1001_1111_1000,
                                                                      1000, 0, -2, 0, 0, 0, 0, 0, 0, 0, 0))
    assert submitted(ep) == [] and ep.setpoints_rejected == 1
    # position with velocity feed-forward (MAVSDK set_position_velocity_ned): the position is flown
    handle(ep, mavlink2.MAVLink_set_position_target_local_ned_message(0, 1, 1, 1, 0b1001_1100_0000,
                                                                      5, 3, -2, 1, 1, 0, 0, 0, 0, 0, 0))
    (sp,) = submitted(ep)
    assert sp.pos_enu_m == pytest.approx((13.0, 25.0, 2.1)) and sp.vel_enu_m_s is None
    handle(ep, mavlink2.MAVLink_manual_control_message(1, 500, -250, 500, 1000, 0))
    (mc,) = submitted(ep)
    assert (mc.pitch, mc.roll, mc.throttle, mc.yaw) == (0.5, -0.25, 0.5, 1.0)


def test_commands_map_to_enu_and_px4_modes(ep):
    lat, lon, alt = (float(v) for v in enu_to_geodetic([40.0, -30.0, 12.0], ORIGIN))
    handle(ep, mavlink2.MAVLink_command_long_message(1, 1, 192, 0, -1, 1, 0, 180, lat, lon, alt))
    handle(ep, mavlink2.MAVLink_command_long_message(1, 1, 22, 0, 0, 0, 0, math.nan, math.nan, math.nan, 498.0))
    handle(ep, mavlink2.MAVLink_command_long_message(1, 1, 176, 0, 1, 6, 0, 0, 0, 0, 0))
    handle(ep, mavlink2.MAVLink_command_int_message(1, 1, 6, 34, 0, 0, 25, 3, 0, math.nan,
                                                    int(lat * 1e7), int(lon * 1e7), 12.0))
    goto, takeoff, mode, orbit = submitted(ep)
    # COMMAND_LONG carries lat/lon as float32 (~0.3 m at this latitude): why MAVSDK uses COMMAND_INT
    assert isinstance(goto, bus.SetTarget) and goto.pos_enu_m == pytest.approx((40.0, -30.0, 12.0), abs=0.5)
    assert goto.yaw_rad == pytest.approx(-math.pi / 2) and goto.speed_m_s is None    # 180 deg NED = south
    assert isinstance(takeoff, bus.Takeoff) and takeoff.alt_enu_m == pytest.approx(10.0)
    assert isinstance(mode, bus.SetNavMode) and mode.nav_state == NavState.OFFBOARD
    # COMMAND_INT, frame GLOBAL_RELATIVE_ALT_INT: 12 m above home (z 0) -> 12 m
    assert isinstance(orbit, bus.Orbit) and orbit.radius_m == 25 and orbit.speed_m_s == 3
    assert orbit.center_enu_m == pytest.approx((40.0, -30.0, 12.0), abs=0.02)


def test_values_outside_the_world_or_not_numbers_are_denied_and_nothing_submitted(ep):
    for p in ([1, 1, 0, 0, 95.0, 0, 500], [-1, 1, 0, math.inf, math.nan, math.nan, math.nan],
              [-1, 1, 0, 0, math.nan, math.nan, 1e9]):
        handle(ep, mavlink2.MAVLink_command_long_message(1, 1, 192, 0, *p))
    handle(ep, mavlink2.MAVLink_command_long_message(1, 1, 176, 0, 1, 5, 0, 0, 0, 0, 0))        # ACRO
    handle(ep, mavlink2.MAVLink_command_int_message(1, 1, 1, 192, 0, 0, -1, 1, 0, 0, 0, 0, 10))  # LOCAL_NED frame
    assert submitted(ep) == [] and ep.commands["denied"] == 5


def test_mission_item_numbers_need_an_uploaded_mission_holding_them(ep):
    # GIVEN no uploaded mission: WHEN a GCS sets the current item / starts from item 3 THEN DENIED
    handle(ep, mavlink2.MAVLink_command_long_message(1, 1, 224, 0, 3, 0, 0, 0, 0, 0, 0))
    handle(ep, mavlink2.MAVLink_command_long_message(1, 1, 300, 0, 3, 0, 0, 0, 0, 0, 0))
    assert submitted(ep) == [] and ep.commands["denied"] == 2
    # a plain MISSION_START goes to the simulation, which answers whether there is a mission to run
    handle(ep, mavlink2.MAVLink_command_long_message(1, 1, 300, 0, 0, 0, 0, 0, 0, 0, 0))
    (start,) = submitted(ep)
    assert isinstance(start, bus.StartMission) and start.first_step == 0
