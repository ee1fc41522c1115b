"""MAVLink mission items -> MissionSpec / Geofence / rally points (transport/mavlink/items.py).

Items are built as real pymavlink messages, packed and parsed again, so the values are what a
ground station's bytes decode to (float32 params, int32 lat/lon * 1e7).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mav

from unetyemu_ecs.geodesy import GeodeticOrigin, enu_to_geodetic
from unetyemu_ecs.mission import spec as mission_spec
from unetyemu_ecs.transport.mavlink import items as it
from unetyemu_ecs.transport.mavlink.items import ItemError, MissionItem

ORIGIN = GeodeticOrigin(47.397742, 8.545594, 488.0)    # PX4 SITL's default home (Zurich)
NAN = float("nan")
_TX = mav.MAVLink(None, srcSystem=255, srcComponent=190)
_RX = mav.MAVLink(None)


def wire(msg):
    """``msg`` as a peer receives it: packed to bytes and parsed."""
    out = _RX.parse_buffer(msg.pack(_TX))
    assert out and len(out) == 1, out
    return out[0]


def latlon(e: float, n: float) -> tuple[int, int]:
    lat, lon, _ = enu_to_geodetic(np.array([e, n, 0.0]), ORIGIN)
    return int(round(float(lat) * 1e7)), int(round(float(lon) * 1e7))


def item(seq, command, *, e=None, n=None, z=0.0, frame=mav.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
         p1=0.0, p2=0.0, p3=0.0, p4=NAN, mission_type=0, x=None, y=None) -> MissionItem:
    if e is not None:
        x, y = latlon(e, n)
    msg = mav.MAVLink_mission_item_int_message(1, 1, seq, frame, command, 0, 1, p1, p2, p3, p4,
                                               x or 0, y or 0, z, mission_type)
    return MissionItem.from_msg(wire(msg))


def wp(seq, e, n, z, **kw):
    return item(seq, mav.MAV_CMD_NAV_WAYPOINT, e=e, n=n, z=z, **kw)


def speed(seq, v, kind=1.0):
    return item(seq, mav.MAV_CMD_DO_CHANGE_SPEED, frame=mav.MAV_FRAME_MISSION, p1=kind, p2=v, p3=-1.0)


def rtl(seq):
    return item(seq, mav.MAV_CMD_NAV_RETURN_TO_LAUNCH, frame=mav.MAV_FRAME_MISSION)


HAS_RETURN = "return" in mission_spec.STEP_TYPES


def test_mavsdk_style_mission_becomes_one_cruise_with_speeds_then_return():
    # GIVEN what MAVSDK's mission plugin uploads for 4 fly-through waypoints with speeds, RTL after:
    # NAV_WAYPOINT then DO_CHANGE_SPEED after each, NAV_RETURN_TO_LAUNCH at the end
    pts = [(0.0, 20.0, 10.0, 4.0), (20.0, 20.0, 12.0, 6.0), (20.0, 0.0, 12.0, 8.0), (0.0, 0.0, 10.0, 10.0)]
    items = []
    for e, n, z, v in pts:
        items.append(wp(len(items), e, n, z, p2=1.0, p4=NAN))
        items.append(speed(len(items), v))
    items.append(rtl(len(items)))
    if not HAS_RETURN:
        with pytest.raises(ItemError) as exc:
            it.build_mission(items, ORIGIN, home_z_m=2.0)
        assert exc.value.result == mav.MAV_MISSION_UNSUPPORTED and exc.value.seq == 8
        return
    # WHEN it is mapped with home 2 m above the ground plane
    plan = it.build_mission(items, ORIGIN, home_z_m=2.0, params={"MPC_XY_CRUISE": 7.0})
    spec = plan.spec
    # THEN one cruise step holds the 4 waypoints (relative altitudes on top of home), each flown at the
    # speed set after the waypoint before it (the first at the mission default), then a return step
    assert [s.type for s in spec.steps] == ["cruise", "return"]
    wps = spec.steps[0].waypoints
    assert len(wps) == 4
    for w, (e, n, z, _) in zip(wps, pts):
        assert w.x == pytest.approx(e, abs=0.02) and w.y == pytest.approx(n, abs=0.02)
        assert w.z == pytest.approx(z + 2.0)
        assert w.yaw_deg is None
    assert [w.cruise_speed for w in wps] == [None, 4.0, 6.0, 8.0]
    assert spec.cruise_speed == 7.0
    # and the step table: items 0..7 are the cruise step (waypoints 0, 2, 4, 6), item 8 the return
    assert [(s.first, s.last) for s in plan.steps] == [(0, 7), (8, 8)]
    assert [seq for seq, _ in plan.steps[0].nav] == [0, 2, 4, 6]
    assert plan.step_of_seq(5) == 0 and plan.step_of_seq(8) == 1 and plan.step_of_seq(9) is None


def test_takeoff_hold_yaw_land_delay_and_gripper_mapping():
    # GIVEN takeoff to 15 m, a waypoint held 3 s with yaw 90 deg NED (east), a grab there,
    # a waypoint, a release, a 4 s delay, a camera item, and a landing where it is
    items = [
        item(0, mav.MAV_CMD_NAV_TAKEOFF, z=15.0),
        wp(1, 30.0, 40.0, 15.0, p1=3.0, p4=90.0),
        item(2, mav.MAV_CMD_DO_GRIPPER, frame=mav.MAV_FRAME_MISSION, p1=1.0, p2=1.0),
        wp(3, -50.0, 10.0, 20.0),
        item(4, mav.MAV_CMD_DO_GRIPPER, frame=mav.MAV_FRAME_MISSION, p1=1.0, p2=0.0),
        item(5, mav.MAV_CMD_NAV_DELAY, frame=mav.MAV_FRAME_MISSION, p1=4.0, p2=-1.0, p3=-1.0, p4=-1.0),
        item(6, mav.MAV_CMD_IMAGE_START_CAPTURE, frame=mav.MAV_FRAME_MISSION),
        item(7, mav.MAV_CMD_NAV_LAND, z=0.0),
    ]
    plan = it.build_mission(items, ORIGIN, home_z_m=0.0)
    steps = plan.spec.steps
    assert [s.type for s in steps] == ["takeoff", "cruise", "pickup", "cruise", "deliver", "idle", "land"]
    assert steps[0].altitude_m == pytest.approx(15.0) and not steps[0].waypoints
    assert steps[1].wait_after == pytest.approx(3.0)
    assert steps[1].waypoints[0].yaw_deg == pytest.approx(0.0, abs=1e-9)     # NED 90 (east) = ENU 0
    # the gripper acts at the NAV item before it
    assert (steps[2].waypoints[0].x, steps[2].waypoints[0].y) == (steps[1].waypoints[0].x, steps[1].waypoints[0].y)
    assert steps[4].waypoints[0].x == pytest.approx(-50.0, abs=0.02)
    assert steps[5].duration_s == pytest.approx(4.0)
    assert not steps[6].waypoints                                            # lat/lon 0: land where it is
    # the camera item (6) belongs to the idle step before it
    assert plan.steps[5].first == 5 and plan.steps[5].last == 6


def test_amsl_frame_uses_the_origin_altitude():
    plan = it.build_mission([wp(0, 10.0, 0.0, ORIGIN.alt_m + 25.0, frame=mav.MAV_FRAME_GLOBAL_INT)], ORIGIN,
                            home_z_m=5.0)
    assert plan.spec.steps[0].waypoints[0].z == pytest.approx(25.0)


def test_mission_item_float_message_is_accepted_like_int():
    lat, lon, _ = enu_to_geodetic(np.array([10.0, 20.0, 0.0]), ORIGIN)
    msg = wire(mav.MAVLink_mission_item_message(1, 1, 0, mav.MAV_FRAME_GLOBAL_RELATIVE_ALT, 16, 0, 1,
                                                0, 0, 0, NAN, float(lat), float(lon), 10.0, 0))
    m = MissionItem.from_msg(msg)
    assert not m.int_xy
    wpt = it.build_mission([m], ORIGIN).spec.steps[0].waypoints[0]
    assert wpt.x == pytest.approx(10.0, abs=1.0) and wpt.y == pytest.approx(20.0, abs=1.0)   # float32 lat/lon
    # converting to the INT message scales lat/lon by 1e7
    x, y = m.xy(as_int=True)
    assert x == round(m.x * 1e7) and y == round(m.y * 1e7)


@pytest.mark.parametrize("bad, result, seq", [
    (lambda: wp(1, 0.0, 0.0, 10.0, frame=mav.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT), mav.MAV_MISSION_UNSUPPORTED_FRAME, 1),
    (lambda: wp(1, 0.0, 0.0, 10.0, frame=mav.MAV_FRAME_LOCAL_NED), mav.MAV_MISSION_UNSUPPORTED_FRAME, 1),
    (lambda: item(1, mav.MAV_CMD_DO_JUMP, frame=mav.MAV_FRAME_MISSION, p1=0, p2=3), mav.MAV_MISSION_UNSUPPORTED, 1),
    (lambda: wp(1, 0.0, 0.0, 10.0, p1=-1.0), mav.MAV_MISSION_INVALID_PARAM1, 1),
    (lambda: wp(1, 0.0, 0.0, 10.0, p4=400.0), mav.MAV_MISSION_INVALID_PARAM4, 1),
    (lambda: wp(1, 0.0, 25_000.0, 10.0), mav.MAV_MISSION_INVALID_PARAM5_X, 1),      # 25 km north
    (lambda: wp(1, -25_000.0, 0.0, 10.0), mav.MAV_MISSION_INVALID_PARAM6_Y, 1),     # 25 km west
    (lambda: wp(1, 0.0, 0.0, 20_000.0), mav.MAV_MISSION_INVALID_PARAM7, 1),
    (lambda: wp(1, 0.0, 0.0, NAN), mav.MAV_MISSION_INVALID_PARAM7, 1),
    (lambda: item(1, 16, x=0, y=0, z=10.0), mav.MAV_MISSION_INVALID_PARAM5_X, 1),   # waypoint without lat/lon
    (lambda: item(1, 16, x=95 * 10**7, y=0, z=10.0), mav.MAV_MISSION_INVALID_PARAM5_X, 1),
    (lambda: speed(1, 45.0), mav.MAV_MISSION_INVALID_PARAM2, 1),                    # above the 30 m/s cap
    (lambda: speed(1, 2.0, kind=7.0), mav.MAV_MISSION_INVALID_PARAM1, 1),
    (lambda: item(1, mav.MAV_CMD_DO_GRIPPER, frame=2, p2=0.5), mav.MAV_MISSION_INVALID_PARAM2, 1),
    (lambda: item(1, mav.MAV_CMD_NAV_DELAY, frame=2, p1=-1.0), mav.MAV_MISSION_INVALID_PARAM1, 1),
    (lambda: item(1, mav.MAV_CMD_NAV_TAKEOFF, z=-3.0), mav.MAV_MISSION_INVALID_PARAM7, 1),
    (lambda: wp(2, 0.0, 0.0, 10.0), mav.MAV_MISSION_INVALID_SEQUENCE, 2),
])
def test_bad_items_are_refused_with_the_mavlink_result_and_the_item(bad, result, seq):
    items = [wp(0, 5.0, 5.0, 10.0), bad()]
    with pytest.raises(ItemError) as exc:
        it.build_mission(items, ORIGIN)
    assert exc.value.result == result
    assert exc.value.seq == seq
    assert exc.value.text                      # a reason for people (sent as STATUSTEXT)


def test_a_mission_of_only_do_items_has_no_spec():
    plan = it.build_mission([speed(0, 3.0)], ORIGIN)
    assert plan.spec is None and plan.count == 1 and plan.step_of_seq(0) is None


def fence_vertex(seq, cmd, count, e, n):
    return item(seq, cmd, e=e, n=n, z=0.0, frame=mav.MAV_FRAME_GLOBAL_INT, p1=count, mission_type=1)


def test_fence_items_build_a_geofence():
    # GIVEN a 200 m square inclusion polygon, an exclusion circle of 20 m in it, an exclusion triangle
    inc = mav.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION
    exc = mav.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_EXCLUSION
    square = [(-100.0, -100.0), (100.0, -100.0), (100.0, 100.0), (-100.0, 100.0)]
    items = [fence_vertex(i, inc, 4, e, n) for i, (e, n) in enumerate(square)]
    items.append(item(4, mav.MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION, e=50.0, n=50.0, frame=5, p1=20.0, mission_type=1))
    items += [fence_vertex(5 + i, exc, 3, e, n) for i, (e, n) in enumerate([(-90, -90), (-60, -90), (-90, -60)])]
    fence = it.build_geofence(items, ORIGIN)
    # THEN containment follows the zones, in ENU
    pts = np.array([[0.0, 0.0], [150.0, 0.0], [50.0, 60.0], [-85.0, -85.0], [-50.0, -50.0]])
    assert fence.contains(pts).tolist() == [True, False, False, False, True]
    assert fence.inclusion_polygons[0][1] == pytest.approx([100.0, -100.0], abs=0.02)


def test_fence_circle_inclusion_and_bad_fences():
    circle = item(0, mav.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION, e=0.0, n=0.0, frame=5, p1=30.0, mission_type=1)
    fence = it.build_geofence([circle], ORIGIN)
    assert fence.contains((0.0, 29.0, 5.0)) and not fence.contains((0.0, 31.0, 5.0))
    inc = mav.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION
    # a polygon announcing 4 vertices with only 3 following
    short = [fence_vertex(i, inc, 4, e, n) for i, (e, n) in enumerate([(0, 0), (10, 0), (10, 10)])]
    with pytest.raises(ItemError) as e1:
        it.build_geofence(short, ORIGIN)
    assert e1.value.result == mav.MAV_MISSION_INVALID_PARAM1
    # a two-vertex polygon
    with pytest.raises(ItemError) as e2:
        it.build_geofence([fence_vertex(i, inc, 2, e, n) for i, (e, n) in enumerate([(0, 0), (10, 0)])], ORIGIN)
    assert e2.value.result == mav.MAV_MISSION_INVALID_PARAM1
    # a zero radius, a waypoint in a fence list
    with pytest.raises(ItemError) as e3:
        it.build_geofence([item(0, mav.MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION, e=0.0, n=0.0, frame=5, p1=0.0)], ORIGIN)
    assert e3.value.result == mav.MAV_MISSION_INVALID_PARAM1
    with pytest.raises(ItemError) as e4:
        it.build_geofence([wp(0, 0.0, 0.0, 5.0)], ORIGIN)
    assert e4.value.result == mav.MAV_MISSION_UNSUPPORTED
    assert it.build_geofence([], ORIGIN) is None


def test_rally_points_in_enu():
    pts = it.build_rally([item(0, mav.MAV_CMD_NAV_RALLY_POINT, e=120.0, n=-40.0, z=15.0, mission_type=2),
                          item(1, mav.MAV_CMD_NAV_RALLY_POINT, e=0.0, n=80.0, frame=5, z=ORIGIN.alt_m + 3.0,
                               mission_type=2)], ORIGIN, home_z_m=1.0)
    assert np.allclose(pts, [(120.0, -40.0, 16.0), (0.0, 80.0, 3.0)], atol=0.02)
    with pytest.raises(ItemError) as exc:
        it.build_rally([wp(0, 0.0, 0.0, 5.0)], ORIGIN)
    assert exc.value.result == mav.MAV_MISSION_UNSUPPORTED


def test_too_many_items_is_no_space():
    many = [speed(i, 3.0) for i in range(it.MAX_ITEMS + 1)]
    with pytest.raises(ItemError) as exc:
        it.build_mission(many, ORIGIN)
    assert exc.value.result == mav.MAV_MISSION_NO_SPACE
    assert math.isfinite(exc.value.seq)
