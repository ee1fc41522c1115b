"""MAVLink 2 signing of an endpoint (key from an environment variable, required): unsigned and
wrongly signed commands have no effect while telemetry flows; a forged frame with a huge timestamp
does not lock out the genuine sender (pymavlink's own check would: it records the timestamp
before it compares the signature)."""

from __future__ import annotations

import pytest

from unetyemu_ecs import Simulation, load_world_text

from .mavlink_client import Client, free_ports, wait_for, world_text

KEY_HEX = "5e" * 32
ARM = 400


def test_with_signing_required_only_a_correctly_signed_arm_arms(monkeypatch):
    monkeypatch.setenv("UNETYEMU_TEST_MAVLINK_KEY", KEY_HEX)
    ports = free_ports(1)
    sim = Simulation(load_world_text(world_text(ports, 1, "{key_env: UNETYEMU_TEST_MAVLINK_KEY, required: true}")))
    plain = Client(ports["api_remote"], ports["api_local"])
    genuine = Client(ports["api_remote"] + 1, ports["api_local"], key=bytes.fromhex(KEY_HEX))
    forger = Client(ports["api_remote"] + 2, ports["api_local"], key=b"\x01" * 32)
    try:
        # GIVEN a signed endpoint whose telemetry flows (signed) while the drone sits on the ground
        hb = wait_for(sim, plain, "HEARTBEAT")
        assert hb is not None and hb.signed_frame
        assert wait_for(sim, plain, "EXTENDED_SYS_STATE", lambda m: m.landed_state == 1) is not None
        # WHEN an unsigned ARM arrives THEN it gets no ACK and the drone stays disarmed
        plain.command_long(ARM, 1.0)
        assert wait_for(sim, plain, "COMMAND_ACK", steps=240) is None
        assert sim.fleet.flight_mode[sim.row("d1")] == 0
        # WHEN a forger (wrong key) sends ARM with the genuine sender's ids and a timestamp far in the future
        forger.mav.signing.timestamp = 2**47
        forger.mav.signing.link_id = genuine.mav.signing.link_id
        forger.command_long(ARM, 1.0)
        assert wait_for(sim, forger, "COMMAND_ACK", steps=240) is None
        assert sim.fleet.flight_mode[sim.row("d1")] == 0
        # THEN the genuine, correctly signed ARM is still accepted and arms the drone
        genuine.command_long(ARM, 1.0)
        ack = wait_for(sim, genuine, "COMMAND_ACK", lambda m: m.command == ARM)
        assert ack is not None and ack.result == 0 and ack.signed_frame
        assert sim.fleet.flight_mode[sim.row("d1")] != 0
        n = sim.transport_counters()["mavlink"]["d1"]["api"]
        assert n["unsigned_rejected"] == 1 and n["bad_signature"] == 1
        # AND neither the unsigned nor the forged sender became a peer of the link
        assert n["peers"] == 1
    finally:
        for c in (plain, genuine, forger):
            c.close()
        sim.close()


@pytest.mark.parametrize("signing, message", [
    ("{key_env: UNETYEMU_TEST_NO_SUCH_VARIABLE}", "environment variable 'UNETYEMU_TEST_NO_SUCH_VARIABLE' is not set"),
    ("{key_file: /nonexistent/mavlink.key}", "cannot be read"),
])
def test_a_missing_signing_key_is_a_clear_error_at_start(signing, message):
    from unetyemu_ecs.transport.api import TransportError

    monkey_ports = free_ports(1)
    with pytest.raises(TransportError, match="mavlink endpoint of d1: .*" + message.split("'")[0]):
        Simulation(load_world_text(world_text(monkey_ports, 1, signing)))
