"""MAVLink endpoint pieces without sockets: per-datagram parsing and its counters, our signature
check, signing keys, PX4 custom modes, bytewise parameter encoding, the ``mavlink`` world-file
component's validation."""

from __future__ import annotations

import hashlib
import math
import subprocess
import sys

import pytest
from pymavlink.dialects.v20 import common as mavlink2

from unetyemu_ecs import load_world_text
from unetyemu_ecs.config.schema import ConfigError
from unetyemu_ecs.systems.flight_state import NavState
from unetyemu_ecs.transport.api import TransportError, TransportOptions
from unetyemu_ecs.transport.mavlink import endpoints_of, px4
from unetyemu_ecs.transport.mavlink.codec import (DatagramParser, RxCounters, SignatureChecker, load_key,
                                                  signing_timestamp)
from unetyemu_ecs.transport.mavlink.endpoint import decode_param, encode_param

TX = mavlink2.MAVLink(None, 255, 190)


def ping(seq: int) -> bytes:
    buf = mavlink2.MAVLink_ping_message(seq, seq, 0, 0).pack(TX)
    return buf


def parse(*datagrams: bytes) -> tuple[list[list[int]], RxCounters]:
    c = RxCounters()
    p = DatagramParser(c)
    return [[m.seq for m, _, _ in p.frames(d)] for d in datagrams], c


def test_a_stray_magic_byte_or_truncated_frame_never_swallows_the_next_datagram_or_frame():
    good = ping(1)
    out, c = parse(b"\xfd\xff", good, b"\xfd\xff" + good, b"\xfe" + good, good[:-5], good)
    assert out == [[], [1], [1], [1], [], [1]]
    assert c.truncated >= 4 and c.rx_messages == 4


def test_bad_crc_unknown_ids_and_junk_are_counted_and_the_good_frames_around_them_kept():
    bad = bytearray(ping(2))
    bad[12] ^= 0x55
    unknown = bytearray(ping(3))
    unknown[7:10] = (54321).to_bytes(3, "little")
    out, c = parse(bytes(bad) + ping(4), bytes(unknown) + ping(5), b"junk" + ping(6) + ping(7) + b"tail",
                   b"\x00" * 5000)
    assert out == [[4], [5], [6, 7], []]
    assert c.bad_crc >= 1 and c.unknown_id == 1 and c.bad_prefix == 2 and c.oversize == 1


def test_mav_ignore_crc_in_the_environment_does_not_turn_crc_checks_off():
    code = ("from pymavlink.dialects.v20 import common as m\n"
            "from unetyemu_ecs.transport.mavlink.codec import DatagramParser, RxCounters\n"
            "b = bytearray(m.MAVLink_ping_message(1, 1, 0, 0).pack(m.MAVLink(None, 1, 1))); b[-1] ^= 0xFF\n"
            "c = RxCounters(); print(len(list(DatagramParser(c).frames(bytes(b)))), c.bad_crc)\n")
    out = subprocess.run([sys.executable, "-c", code], env={"MAV_IGNORE_CRC": "1", "PATH": "/usr/bin:/bin"},
                         capture_output=True, text=True, timeout=60)
    assert out.stdout.split() == ["0", "1"], out.stderr


def signed(key: bytes, stamp: int, link_id: int = 3) -> bytes:
    mav = mavlink2.MAVLink(None, 245, 190)
    mav.signing.secret_key, mav.signing.sign_outgoing = key, True
    mav.signing.link_id, mav.signing.timestamp = link_id, stamp
    return mavlink2.MAVLink_heartbeat_message(6, 8, 0, 0, 0, 3).pack(mav)


def test_signature_check_compares_the_hmac_before_it_trusts_the_timestamp():
    key = b"\x11" * 32
    check = SignatureChecker(key)
    now = signing_timestamp()
    assert check.check(signed(key, now))
    assert not check.check(signed(key, now))                            # replay
    assert not check.check(signed(b"\x22" * 32, 2**47))                 # forged, far future: no effect ...
    assert check.check(signed(key, now + 5))                            # ... the genuine stream goes on
    assert not check.check(signed(key, now + 10**9, link_id=9))         # a new stream far from our clock


def test_signing_keys_from_hex_raw_bytes_or_a_passphrase(tmp_path, monkeypatch):
    (tmp_path / "raw.key").write_bytes(bytes(range(32)))
    assert load_key(str(tmp_path / "raw.key"), None) == bytes(range(32))
    monkeypatch.setenv("K_HEX", "ab" * 32)
    assert load_key(None, "K_HEX") == b"\xab" * 32
    monkeypatch.setenv("K_PASS", "correct horse")
    assert load_key(None, "K_PASS") == hashlib.sha256(b"correct horse").digest()
    monkeypatch.setenv("K_EMPTY", "  ")
    with pytest.raises(ValueError, match="K_EMPTY.*empty"):
        load_key(None, "K_EMPTY")


def test_px4_custom_modes_round_trip_for_every_mode_a_gcs_can_select():
    for nav in NavState:
        back = px4.nav_state_of(px4.custom_mode(nav))
        expected = {NavState.GOTO: NavState.HOLD, NavState.ORBIT: None}.get(nav, nav)
        assert back == expected, nav
    assert px4.custom_mode(NavState.OFFBOARD) == 6 << 16
    assert px4.custom_mode(NavState.MISSION) == (4 << 16) | (4 << 24)
    assert px4.nav_state_of(5 << 16) is None                             # ACRO: not flown here


def test_int32_parameters_travel_bytewise_like_px4():
    for v in (0, 2, 7, 123456):
        raw = encode_param(v, True)
        assert decode_param(mavlink2.MAVLink_param_value_message(b"X", raw, 6, 1, 0).param_value, True) == v
    assert encode_param(2.5, False) == 2.5
    assert math.isnan(encode_param(-1, True)) or encode_param(-1, True) != -1.0   # why INT32 params stay >= 0


WORLD = """world: {{name: t}}
scene: {{generator: none, ground_size_m: 100}}
vehicles:
  - {{name: d1, type: quadrotor, preset: small, pose: {{position_m: [0, 0, 0.2]}}{c1}}}
  - {{name: d2, type: quadrotor, preset: small, pose: {{position_m: [5, 0, 0.2]}}{c2}}}
"""


@pytest.mark.parametrize("block, message", [
    ("{instance: 255}", "instance: must be <= 254"),
    ("{instance: 0, bind: localhost}", "bind: must be an IPv4 address"),
    ("{instance: 0, streams: fast}", "streams: unknown value 'fast'"),
    ("{instance: 9, gcs_local_base: 65530}", "gcs_local_base + instance 9 = 65539"),
    ("{instance: 0, api_local_base: 80}", "api_local_base: must be >= 1024"),
    ("{instance: 0, signing: {required: true}}", "give exactly one of key_file and key_env"),
    ("{bind: 127.0.0.1}", "missing required key 'instance'"),
])
def test_a_bad_mavlink_block_is_reported_with_file_line_and_key_path(block, message):
    with pytest.raises(ConfigError) as err:
        load_world_text(WORLD.format(c1=f", components: {{mavlink: {block}}}", c2=""))
    assert "<string>:4: vehicles[0].components.mavlink" in str(err.value) and message in str(err.value)


def test_mavlink_forced_for_every_drone_and_duplicate_instances_refused():
    world = load_world_text(WORLD.format(c1=", components: {mavlink: {instance: 1}}", c2=""))
    eps = endpoints_of(world, TransportOptions(mavlink=True))
    # d2 would be instance 1 (its index) but d1's component has it: d2 gets the lowest free one
    assert [(name, cfg.instance, cfg.system_id, cfg.bind) for name, cfg in eps] == \
        [("d1", 1, 2, "127.0.0.1"), ("d2", 0, 1, "127.0.0.1")]
    assert endpoints_of(world, TransportOptions()) == [("d1", eps[0][1])]
    dup = load_world_text(WORLD.format(c1=", components: {mavlink: {instance: 1}}",
                                       c2=", components: {mavlink: {instance: 1}}"))
    with pytest.raises(TransportError, match="'d1' and 'd2' both use instance 1"):
        endpoints_of(dup, TransportOptions())
