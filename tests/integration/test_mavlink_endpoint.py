"""The MAVLink endpoint with real pymavlink peers on loopback: telemetry like PX4 SITL, commands
answered by COMMAND_ACK from the simulation's own results, the PARAM protocol, and a link that
garbage neither breaks nor hijacks."""

from __future__ import annotations

import math
import socket
import time

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mavlink2

from unetyemu_ecs import Simulation, load_world_text
from unetyemu_ecs.geodesy import GeodeticOrigin, enu_to_geodetic
from unetyemu_ecs.navigation.params import PX4_PARAMS
from unetyemu_ecs.transport.api import TransportError
from unetyemu_ecs.transport.mavlink.endpoint import decode_param, encode_param

from .mavlink_client import Client, free_ports, wait_for, world_text

PX4_AUTOPILOT, QUADROTOR = 12, 2
AUTO, AUTO_LOITER = 4, 3
MAV_RESULT_ACCEPTED, MAV_RESULT_DENIED, MAV_RESULT_UNSUPPORTED = 0, 2, 3
ARM, REBOOT, DO_CHANGE_SPEED = 400, 246, 178


@pytest.fixture
def rig(tmp_path):
    """Two drones with endpoints; a client on each API link and one GCS client (like QGroundControl)."""
    ports = free_ports(2)
    sim = Simulation(load_world_text(world_text(ports)), out_dir=tmp_path / "out")
    api = [Client(ports["api_remote"] + i, ports["api_local"] + i) for i in range(2)]
    gcs = Client(ports["gcs_remote"], ports["gcs_local"], sysid=255)
    yield sim, api, gcs, ports
    for c in (*api, gcs):
        c.close()
    sim.close()


def test_every_drone_sends_a_px4_heartbeat_on_its_api_link_and_the_gcs_link_sees_both(rig):
    sim, api, gcs, _ = rig
    # GIVEN two drones on the ground, WHEN the simulation runs
    hb = [wait_for(sim, api[i], "HEARTBEAT") for i in range(2)]
    # THEN each API link carries its own drone's heartbeat: PX4 autopilot, quadrotor, AUTO.LOITER (hold), disarmed
    for i, m in enumerate(hb):
        assert m is not None
        assert (m.get_srcSystem(), m.get_srcComponent()) == (i + 1, 1)
        assert (m.autopilot, m.type) == (PX4_AUTOPILOT, QUADROTOR)
        assert ((m.custom_mode >> 16) & 0xFF, (m.custom_mode >> 24) & 0xFF) == (AUTO, AUTO_LOITER)
        assert m.base_mode & 1 and not m.base_mode & 128
    # AND the one GCS port receives the heartbeats of system 1 and system 2
    seen = set()
    for _ in range(2):
        m = wait_for(sim, gcs, "HEARTBEAT", lambda m: m.get_srcSystem() not in seen)
        assert m is not None and m.autopilot == PX4_AUTOPILOT
        seen.add(m.get_srcSystem())
    assert seen == {1, 2}


def test_global_position_int_is_the_simulated_position_in_wgs84(rig):
    sim, api, _, _ = rig
    # GIVEN a drone resting on the ground (its position does not change between steps)
    sim.step(240)
    api[1].drain()
    # WHEN its GLOBAL_POSITION_INT arrives
    m = wait_for(sim, api[1], "GLOBAL_POSITION_INT")
    assert m is not None
    # THEN lat/lon/alt are the simulation's ENU position through the world's geodetic origin
    o = sim.definition.spec.world.origin
    lat, lon, alt = enu_to_geodetic(sim.position_enu_m("d2"), GeodeticOrigin(o.lat_deg, o.lon_deg, o.alt_m))
    assert abs(m.lat - lat * 1e7) <= 2 and abs(m.lon - lon * 1e7) <= 2      # 1e-7 deg ~ 1 cm
    assert abs(m.alt - alt * 1000) <= 20
    home_z = sim.fleet.home_enu_m[sim.row("d2")][2]
    assert abs(m.relative_alt - (sim.position_enu_m("d2")[2] - home_z) * 1000) <= 20    # above home
    now_ms = sim.sim_time_s * 1000                                         # stamped in sim time: within the
    assert now_ms - 100 <= m.time_boot_ms <= now_ms                          # last chunk of steps the client waited


def test_arm_over_command_long_is_acknowledged_from_the_result_and_arms_the_drone(rig):
    sim, api, _, _ = rig
    # GIVEN the drone reports itself on the ground (EXTENDED_SYS_STATE, as MAVSDK waits for before arming)
    assert wait_for(sim, api[0], "EXTENDED_SYS_STATE", lambda m: m.landed_state == 1) is not None
    # WHEN a MAVSDK-like client sends COMPONENT_ARM_DISARM(1)
    api[0].command_long(ARM, 1.0)
    ack = wait_for(sim, api[0], "COMMAND_ACK", lambda m: m.command == ARM)
    # THEN the ACK is ACCEPTED, addressed back to the sender, and the drone is armed
    assert ack is not None and ack.result == MAV_RESULT_ACCEPTED, sim.services.results[-1:]
    assert (ack.target_system, ack.target_component) == (245, 190)
    assert sim.fleet.flight_mode[sim.row("d1")] != 0
    hb = wait_for(sim, api[0], "HEARTBEAT", lambda m: m.base_mode & 128)
    assert hb is not None
    assert sim.fleet.flight_mode[sim.row("d2")] == 0                      # the other drone is untouched


def test_unknown_mav_cmd_is_unsupported_and_nan_is_denied_with_nothing_submitted(rig):
    sim, api, _, _ = rig
    wait_for(sim, api[0], "HEARTBEAT")
    before = len(sim.services.results)
    # WHEN a command we do not implement (reboot) and commands with NaN / out-of-range values arrive
    api[0].command_long(REBOOT, 1.0)
    assert wait_for(sim, api[0], "COMMAND_ACK", lambda m: m.command == REBOOT).result == MAV_RESULT_UNSUPPORTED
    api[0].command_long(ARM, math.nan)
    assert wait_for(sim, api[0], "COMMAND_ACK", lambda m: m.command == ARM).result == MAV_RESULT_DENIED
    api[0].command_long(DO_CHANGE_SPEED, 1.0, math.nan)
    assert wait_for(sim, api[0], "COMMAND_ACK", lambda m: m.command == DO_CHANGE_SPEED).result == MAV_RESULT_DENIED
    api[0].command_long(DO_CHANGE_SPEED, 1.0, 1e9)
    assert wait_for(sim, api[0], "COMMAND_ACK", lambda m: m.command == DO_CHANGE_SPEED).result == MAV_RESULT_DENIED
    # THEN nothing reached the simulation and the drone is still disarmed
    assert len(sim.services.results) == before
    assert sim.fleet.flight_mode[sim.row("d1")] == 0


def test_param_list_set_and_read_back(rig, tmp_path):
    sim, api, gcs, _ = rig
    wait_for(sim, gcs, "HEARTBEAT")
    c = api[0]
    # WHEN the client downloads the parameter list
    c.send(mavlink2.MAVLink_param_request_list_message(1, 1))
    values = {}
    for _ in range(len(PX4_PARAMS)):
        m = wait_for(sim, c, "PARAM_VALUE")
        assert m is not None
        values[m.param_id] = m
    # THEN every parameter arrives once, with the count and its index
    assert len(values) == len(PX4_PARAMS) and {m.param_count for m in values.values()} == {len(PX4_PARAMS)}
    assert decode_param(values["MIS_TAKEOFF_ALT"].param_value, False) == pytest.approx(2.5)
    assert values["NAV_RCL_ACT"].param_type == 6 and decode_param(values["NAV_RCL_ACT"].param_value, True) == 2
    # WHEN it sets a REAL32 and an INT32 parameter (PX4 bytewise encoding) and a NaN one
    c.send(mavlink2.MAVLink_param_set_message(1, 1, b"MIS_TAKEOFF_ALT", 7.5, 9))
    echo = wait_for(sim, c, "PARAM_VALUE", lambda m: m.param_id == "MIS_TAKEOFF_ALT")
    assert echo is not None and echo.param_value == pytest.approx(7.5)
    c.send(mavlink2.MAVLink_param_set_message(1, 1, b"NAV_RCL_ACT", encode_param(3, True), 6))
    echo = wait_for(sim, c, "PARAM_VALUE", lambda m: m.param_id == "NAV_RCL_ACT")
    assert echo is not None and decode_param(echo.param_value, True) == 3
    c.send(mavlink2.MAVLink_param_set_message(1, 1, b"MPC_XY_CRUISE", math.nan, 9))
    echo = wait_for(sim, c, "PARAM_VALUE", lambda m: m.param_id == "MPC_XY_CRUISE")
    assert echo is not None and echo.param_value == pytest.approx(5.0)                  # unchanged
    # THEN a read by name gives the new value, the GCS link heard the change, and the run keeps it on disk
    c.send(mavlink2.MAVLink_param_request_read_message(1, 1, b"MIS_TAKEOFF_ALT", -1))
    back = wait_for(sim, c, "PARAM_VALUE", lambda m: m.param_id == "MIS_TAKEOFF_ALT")
    assert back is not None and back.param_value == pytest.approx(7.5)
    assert wait_for(sim, gcs, "PARAM_VALUE", lambda m: m.param_id == "MIS_TAKEOFF_ALT" and m.param_value == 7.5)
    saved = (tmp_path / "out" / "mavlink" / "d1.params").read_text()
    assert "1\t1\tMIS_TAKEOFF_ALT\t7.5\t9" in saved and "1\t1\tNAV_RCL_ACT\t3\t6" in saved


def _ping(c: Client, seq: int) -> bytes:
    return c.pack(mavlink2.MAVLink_ping_message(1000 + seq, seq, 0, 0))


def test_garbage_is_counted_and_never_disturbs_the_next_message_or_the_peer(rig):
    sim, api, _, ports = rig
    c = api[0]
    wait_for(sim, c, "HEARTBEAT")
    rng = np.random.default_rng(5)
    good = _ping(c, 1)
    bad_crc = bytearray(_ping(c, 2))
    bad_crc[-1] ^= 0xFF
    unknown = bytearray(good)
    unknown[7:10] = (54321).to_bytes(3, "little")                        # an id no dialect here knows
    garbage = [rng.bytes(64), bytes(bad_crc), good[:-4], b"\xfd", b"\xfd\xff", b"\xfe", bytes(unknown),
               b"\x00" * 300, rng.bytes(5000)]
    # GIVEN a stranger on another port sending junk and a valid message for another system
    stranger = Client(ports["api_remote"] + 7, ports["api_local"])
    try:
        for seq, junk in enumerate(garbage, start=10):
            stranger.raw(junk)
            c.raw(junk)
            # WHEN a good message follows each junk datagram (also glued behind a stray magic byte)
            c.raw(_ping(c, seq) if seq % 2 else b"\xfd\xff" + _ping(c, seq))
            # THEN it is answered
            assert wait_for(sim, c, "PING", lambda m, s=seq: m.seq == s) is not None, junk[:8]
        c.raw(_ping(c, 40) + _ping(c, 41) + _ping(c, 42))                  # several frames in one datagram
        for s in (40, 41, 42):
            assert wait_for(sim, c, "PING", lambda m, s=s: m.seq == s) is not None
        stranger.send(mavlink2.MAVLink_command_long_message(99, 1, ARM, 0, 1, 0, 0, 0, 0, 0, 0))
        sim.step(48)
        sim.flush_transports()
        stranger.poll()
        # AND the stranger never became a peer (no telemetry to it), the drone was not armed
        assert not stranger.inbox
        assert sim.fleet.flight_mode[sim.row("d1")] == 0
    finally:
        stranger.close()
    n = sim.transport_counters()["mavlink"]["d1"]["api"]
    assert n["bad_crc"] >= 2 and n["truncated"] >= 4 and n["unknown_id"] >= 2 and n["oversize"] >= 2
    assert n["bad_prefix"] >= 4 and n["not_for_us"] == 1 and n["peers"] == 1
    assert n["parser_errors"] == 0


def test_a_flood_beyond_the_receive_budget_is_dropped_by_the_kernel_and_every_datagram_is_accounted_for(rig):
    sim, api, _, _ = rig
    c = api[0]
    wait_for(sim, c, "HEARTBEAT")
    before = sim.transport_counters()["mavlink"]["d1"]["api"]["rx_datagrams"]
    # WHEN 30 000 PINGs arrive as fast as one socket can send them (the link reads 1000 datagrams/s)
    n = 30_000
    frame = _ping(c, 7)
    for _ in range(n):
        c.raw(frame)
    # THEN once the socket is drained and one more datagram arrived (the kernel stamps its drop count on
    # the next datagram it queues), what the link read plus what the kernel dropped is what was sent
    def counted() -> tuple[int, int]:
        link = sim.transport_counters()["mavlink"]["d1"]["api"]
        return link["rx_datagrams"] - before, link["rx_kernel_dropped"]

    last, deadline = (-1, -1), time.monotonic() + 60.0
    while counted() != last and time.monotonic() < deadline:
        last = counted()
        time.sleep(0.5)
    c.drain()
    c.raw(_ping(c, 99))
    assert wait_for(sim, c, "PING", lambda m: m.seq == 99) is not None        # AND the link still answers
    read, dropped = counted()
    assert read + dropped == n + 1, (read, dropped)
    assert dropped > 0 and read > 0, (read, dropped)


def test_a_port_already_in_use_is_a_clear_error_naming_the_vehicle_and_port(tmp_path):
    ports = free_ports(2)
    blocker = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    blocker.bind(("127.0.0.1", ports["gcs_local"] + 1))               # d2's GCS link
    try:
        with pytest.raises(TransportError) as err:
            Simulation(load_world_text(world_text(ports)))
        text = str(err.value)
        assert "d2" in text and f"127.0.0.1:{ports['gcs_local'] + 1}" in text and "already in use" in text
        # AND nothing was left bound: the other ports are free again
        probe = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        probe.bind(("127.0.0.1", ports["api_local"]))
        probe.close()
    finally:
        blocker.close()


def test_a_refused_command_is_acked_temporarily_rejected_and_its_reason_arrives_as_statustext(rig):
    sim, api, _, _ = rig
    c = api[0]
    assert wait_for(sim, c, "HEARTBEAT") is not None
    # WHEN a client commands a takeoff while the drone is disarmed (PX4 refuses that)
    c.command_long(22, 0.0, 0.0, 0.0, math.nan, math.nan, math.nan, math.nan)
    ack = wait_for(sim, c, "COMMAND_ACK", lambda m: m.command == 22)
    # THEN the ACK says TEMPORARILY_REJECTED, as the simulation's result did, and the refusal's text
    # from the event log arrives as a WARNING STATUSTEXT
    result = next(r for r in sim.services.results if r.kind == "takeoff")
    assert result.source == "mavlink" and result.status == 2, result            # REJECTED_STATE
    assert ack is not None and ack.result == 1
    text = wait_for(sim, c, "STATUSTEXT", lambda m: result.text[:20] in m.text)       # 50-char chunks
    assert text is not None and text.severity == 4
    assert sim.fleet.flight_mode[sim.row("d1")] == 0


def test_message_requests_intervals_ping_and_timesync_are_answered_per_link(rig):
    sim, api, gcs, _ = rig
    c = api[0]
    assert wait_for(sim, c, "HEARTBEAT") is not None
    # REQUEST_MESSAGE AUTOPILOT_VERSION (MAVSDK at connect): ACK and the version with PX4's capabilities
    c.command_long(512, 148.0)
    assert wait_for(sim, c, "COMMAND_ACK", lambda m: m.command == 512).result == MAV_RESULT_ACCEPTED
    ver = wait_for(sim, c, "AUTOPILOT_VERSION")
    assert ver is not None and ver.capabilities == 57567 and ver.flight_sw_version == 0x010F00FF and ver.uid == 1
    c.command_long(512, 242.0)                                          # HOME_POSITION on request
    assert wait_for(sim, c, "COMMAND_ACK", lambda m: m.command == 512).result == MAV_RESULT_ACCEPTED
    assert wait_for(sim, c, "HOME_POSITION") is not None
    c.command_long(512, 395.0)                                          # a message we never produce
    assert wait_for(sim, c, "COMMAND_ACK", lambda m: m.command == 512).result == MAV_RESULT_UNSUPPORTED
    # SET_MESSAGE_INTERVAL ATTITUDE off on the API link: no more ATTITUDE there, the GCS link keeps it
    c.command_long(511, 30.0, -1.0)
    assert wait_for(sim, c, "COMMAND_ACK", lambda m: m.command == 511).result == MAV_RESULT_ACCEPTED
    sim.step(24)
    sim.flush_transports()
    c.drain()
    gcs.drain()
    sim.step(240)
    sim.flush_transports()
    c.poll()
    assert c.take("ATTITUDE") is None and wait_for(sim, gcs, "ATTITUDE", lambda m: m.get_srcSystem() == 1)
    c.command_long(511, 9999.0, 1e5)                                    # not a stream of ours
    assert wait_for(sim, c, "COMMAND_ACK", lambda m: m.command == 511).result == MAV_RESULT_DENIED
    # PING and TIMESYNC requests are answered with the sender's values and sim time
    c.send(mavlink2.MAVLink_ping_message(123456, 77, 0, 0))
    pong = wait_for(sim, c, "PING", lambda m: m.seq == 77)
    assert pong is not None and pong.time_usec == 123456 and pong.target_system == 245
    c.send(mavlink2.MAVLink_timesync_message(0, 987654321))
    ts = wait_for(sim, c, "TIMESYNC", lambda m: m.ts1 == 987654321)
    assert ts is not None and 0 < ts.tc1 <= sim.sim_time_s * 1e9


def test_highres_imu_is_the_imu_sample_in_frd_gravity_minus_z_at_rest():
    ports = free_ports(1)
    sim = Simulation(load_world_text(world_text(ports, 1, vehicle_extra="sensors: [imu], ")))
    c = Client(ports["api_remote"], ports["api_local"])
    try:
        # GIVEN a drone with an IMU resting on the ground
        assert wait_for(sim, c, "EXTENDED_SYS_STATE", lambda m: m.landed_state == 1) is not None
        sim.step(120)
        sim.flush_transports()
        c.drain()
        # WHEN its HIGHRES_IMU arrives THEN the specific force points up = -z in FRD, about 1 g
        m = wait_for(sim, c, "HIGHRES_IMU")
        assert m is not None and m.zacc == pytest.approx(-9.81, abs=0.3)
        assert abs(m.xacc) < 0.3 and abs(m.yacc) < 0.3 and abs(m.zgyro) < 0.05
    finally:
        c.close()
        sim.close()


def test_a_fault_in_one_drones_telemetry_is_counted_and_the_other_drone_keeps_its_link(rig, monkeypatch):
    sim, api, _, _ = rig
    transport = sim.transports["mavlink"]
    # GIVEN drone 1's snapshot handler failing on every snapshot (a fault injected in place of a bug)
    def broken(*_args):
        raise RuntimeError("injected fault")

    monkeypatch.setattr(transport.endpoints["d1"], "on_snapshot", broken)
    # WHEN the simulation runs on
    sim.step(240)
    api[1].drain()
    # THEN drone 2 still sends telemetry, and the fault is counted for the summary, not fatal
    assert wait_for(sim, api[1], "HEARTBEAT") is not None
    counters = transport.counters()
    assert counters["handler_errors"] > 0 and "injected fault" in counters["first_handler_error"]
    assert "thread_error" not in counters
