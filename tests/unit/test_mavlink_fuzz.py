"""Fuzzing the endpoint without sockets: valid frames (good CRC) of every message it consumes with
random field values (NaN, inf, extremes, random ids and commands), and random mutations of them,
through a real endpoint and Inbox. Nothing raises inside a handler (``parser_errors`` stays 0),
every datagram is counted, and what reaches the Inbox is only what the checks let through."""

from __future__ import annotations

import math
import random

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mavlink2

from unetyemu_ecs import load_world_text
from unetyemu_ecs.geodesy import GeodeticOrigin
from unetyemu_ecs.transport import bus
from unetyemu_ecs.transport.api import Snapshot
from unetyemu_ecs.transport.mavlink.component import MavlinkEndpoint
from unetyemu_ecs.transport.mavlink.endpoint import DroneEndpoint

ORIGIN = GeodeticOrigin(47.397742, 8.545594, 488.0)
LAYOUT = load_world_text("world: {name: t}\nscene: {generator: none, ground_size_m: 400}\n").layout   # +-200 m
CONSUMED = (mavlink2.MAVLink_command_long_message, mavlink2.MAVLink_command_int_message,
            mavlink2.MAVLink_param_set_message, mavlink2.MAVLink_param_request_read_message,
            mavlink2.MAVLink_param_request_list_message, mavlink2.MAVLink_set_mode_message,
            mavlink2.MAVLink_set_position_target_local_ned_message,
            mavlink2.MAVLink_set_position_target_global_int_message, mavlink2.MAVLink_set_attitude_target_message,
            mavlink2.MAVLink_manual_control_message,
            mavlink2.MAVLink_follow_target_message, mavlink2.MAVLink_ping_message, mavlink2.MAVLink_timesync_message,
            mavlink2.MAVLink_heartbeat_message, mavlink2.MAVLink_mission_count_message,
            mavlink2.MAVLink_mission_item_int_message, mavlink2.MAVLink_mission_request_list_message,
            mavlink2.MAVLink_mission_request_int_message, mavlink2.MAVLink_mission_ack_message,
            mavlink2.MAVLink_mission_clear_all_message, mavlink2.MAVLink_mission_set_current_message)
INT_RANGES = {"uint8_t": (0, 255), "int8_t": (-128, 127), "uint16_t": (0, 65535), "int16_t": (-32768, 32767),
              "uint32_t": (0, 2**32 - 1), "int32_t": (-2**31, 2**31 - 1), "uint64_t": (0, 2**64 - 1),
              "int64_t": (-2**63, 2**63 - 1)}
COMMANDS = (16, 17, 20, 21, 22, 34, 176, 178, 179, 185, 192, 193, 211, 224, 300, 400, 510, 511, 512, 520, 246)


def value(rng: random.Random, name: str, ftype: str, length: int):
    if length and ftype == "char":
        return bytes(rng.randrange(256) for _ in range(rng.randrange(length + 1)))
    if length:
        return [value(rng, name, ftype, 0) for _ in range(length)]
    if ftype in ("float", "double"):
        return rng.choice([math.nan, math.inf, -math.inf, 0.0, 1.0, -1.0, 1e30, rng.uniform(-1e4, 1e4),
                           rng.uniform(-200, 200), 21196.0, 6.0])
    if name in ("target_system",):
        return rng.choice([0, 1, 1, 1, rng.randrange(256)])
    if name == "command":
        return rng.choice(COMMANDS + (rng.randrange(65536),))
    lo, hi = INT_RANGES[ftype]
    return rng.choice([lo, hi, 0, 1, rng.randint(lo, hi)])


def random_message(rng: random.Random):
    cls = rng.choice(CONSUMED)
    lengths = dict(zip(cls.ordered_fieldnames, cls.array_lengths))
    args = [value(rng, n, t, lengths[n]) for n, t in zip(cls.fieldnames, cls.fieldtypes)]
    return cls(*args)


@pytest.mark.filterwarnings("error::RuntimeWarning")          # no NaN/inf arithmetic on the way either
def test_ten_thousand_random_and_mutated_datagrams_never_break_a_handler():
    rng = random.Random(13)
    inbox = bus.Inbox()
    ep = DroneEndpoint("d1", MavlinkEndpoint(instance=0), ORIGIN, LAYOUT, inbox.submit, 1 / 240, None, None)
    arrays = {"pos_enu_m": np.array([[1.0, 2.0, 3.0]]), "quat_enu_flu_xyzw": np.array([[0.0, 0.0, 0.0, 1.0]])}
    ep.on_snapshot(Snapshot(1, 1.0, 1 / 240, ("d1",), ("quadrotor",), arrays, (), [], 0, [], 0), 0)
    tx = mavlink2.MAVLink(None, 245, 190)
    link = ep.links[0]
    n = 10_000
    for k in range(n):
        msg = random_message(rng)
        try:
            data = bytearray(msg.pack(tx))
        except Exception:                          # a value pymavlink itself cannot pack: send junk instead
            data = bytearray(rng.randbytes(rng.randrange(1, 300)))
        if k % 3 == 1:                             # mutate: flip bytes, cut, glue, prefix junk
            for _ in range(rng.randrange(1, 4)):
                data[rng.randrange(len(data))] = rng.randrange(256)
        elif k % 3 == 2:
            data = rng.choice([data[:rng.randrange(len(data))], b"\xfd" + data, data + data,
                               rng.randbytes(3) + data])
        ep.on_datagram(link, bytes(data), ("127.0.0.1", 40000 + k % 7), float(k))
        ep.tick(float(k))
    c = link.rx
    assert c.rx_datagrams == n and c.parser_errors == 0
    assert c.rx_messages > n // 2 and c.bad_crc + c.truncated + c.bad_prefix > n // 4
    for cmd in inbox.drain():                      # whatever got through is a well-formed command
        for field in ("pos_enu_m", "vel_enu_m_s", "vel_flu_m_s", "center_enu_m"):
            v = getattr(cmd, field, None)
            assert v is None or all(math.isfinite(x) for x in v), cmd
        for field in ("yaw_rad", "yaw_rate_rad_s", "speed_m_s", "alt_enu_m", "value", "radius_m"):
            v = getattr(cmd, field, None)
            assert v is None or math.isfinite(v), cmd
