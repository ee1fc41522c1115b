"""Discovery of the dds backend under ROS 2's discovery variables, in a loopback-only network namespace
with a veth pair standing for the LAN (tests/ros2_peer/netns_discovery.py)."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from unetyemu_ecs.transport.ros2.dds_backend import (LOOPBACK_CONFIG, Ros2Error, dds_config,
                                                     discovery_range_from_env, static_peers_from_env)


DRIVER = Path(__file__).resolve().parent.parent / "ros2_peer" / "netns_discovery.py"
LARGE_MESSAGE_SETTINGS = ("<MaxMessageSize>65000B</MaxMessageSize>", "<FragmentSize>62000B</FragmentSize>",
                          "<MaxInitTransmit>150000</MaxInitTransmit>", "<MaxRexmit>150kB</MaxRexmit>",
                          '<HeartbeatInterval min="5ms" minsched="10ms">20ms</HeartbeatInterval>')
RANGES = ["", "SUBNET", "LOCALHOST", "OFF", "SYSTEM_DEFAULT"]


def _can_unshare() -> bool:
    try:
        return subprocess.run(["unshare", "-n", "true"], capture_output=True, timeout=10).returncode == 0
    except (OSError, subprocess.TimeoutExpired):
        return False


def _in_namespace(discovery_range: str | None, seconds: float = 6.0, *extra: str) -> dict:
    env = {k: v for k, v in os.environ.items() if not k.startswith(("CYCLONEDDS_", "ROS_"))}
    if discovery_range is not None:
        env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = discovery_range
    done = subprocess.run(["unshare", "-n", sys.executable, str(DRIVER), str(seconds), *extra], cwd=DRIVER.parent,
                          env=env, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout.strip().splitlines()[-1])


needs_netns = pytest.mark.skipif(not _can_unshare(), reason="needs `unshare -n` (root or user namespaces)")


@pytest.mark.parametrize("discovery_range", RANGES)
def test_every_discovery_range_keeps_the_large_message_settings(discovery_range):
    config = dds_config(discovery_range, ["192.0.2.7"], host_interfaces=["eth9"])
    assert all(s in config for s in LARGE_MESSAGE_SETTINGS)


@needs_netns
def test_cyclonedds_accepts_the_configuration_of_every_discovery_range():
    # in a loopback-only namespace: a domain with the host's interfaces would join multicast groups there
    code = ("import sys; from cyclonedds.domain import Domain; "
            "from unetyemu_ecs.transport.ros2.dds_backend import dds_config; "
            f"[Domain(201 + k, dds_config(r, ['127.0.0.1'])) for k, r in enumerate({RANGES!r})]; print('ok')")
    env = {k: v for k, v in os.environ.items() if not k.startswith(("CYCLONEDDS_", "ROS_"))}
    done = subprocess.run(["unshare", "-n", "sh", "-c", f"ip link set lo up; exec {sys.executable} -c \"$0\"", code],
                          env={**env, "PYTHONPATH": str(Path(__file__).resolve().parents[2])}, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0 and done.stdout.strip() == "ok", done.stderr


def test_the_default_sends_multicast_with_ttl_0_on_the_default_interface_and_loopback():
    config = dds_config("", [], host_interfaces=["eth0"])
    assert "<MulticastTimeToLive>0</MulticastTimeToLive>" in config
    assert '<NetworkInterface autodetermine="true"/>' in config and 'name="lo"' in config
    assert "<AllowMulticast>false</AllowMulticast>" not in config
    # without another interface up, loopback alone
    assert "autodetermine" not in dds_config("", [], host_interfaces=[])


def test_subnet_opens_to_the_lan_localhost_confines_to_loopback_off_discovers_nothing():
    subnet, localhost, off = (dds_config(r, [], host_interfaces=["eth0"]) for r in ("SUBNET", "LOCALHOST", "OFF"))
    assert "MulticastTimeToLive" not in subnet and "autodetermine" in subnet
    assert localhost == LOOPBACK_CONFIG and '<NetworkInterface name="lo"/>' in localhost
    assert "<AllowMulticast>false</AllowMulticast>" in localhost and '<Peer address="127.0.0.1"/>' in localhost
    assert "<ParticipantIndex>none</ParticipantIndex>" in off and "Peer " not in off


def test_static_peers_are_added_in_every_range(monkeypatch):
    monkeypatch.setenv("ROS_STATIC_PEERS", "192.0.2.7; robot.local;")
    assert static_peers_from_env() == ["192.0.2.7", "robot.local"]
    for discovery_range in RANGES:
        config = dds_config(discovery_range, static_peers_from_env(), host_interfaces=["eth0"])
        assert re.search(r'<Peer address="192.0.2.7"/>\s*<Peer address="robot.local"/>', config), discovery_range


@pytest.mark.parametrize("name, value", [("ROS_AUTOMATIC_DISCOVERY_RANGE", "LAN"),
                                         ("ROS_STATIC_PEERS", "a<b"), ("ROS_STATIC_PEERS", 'x" y')])
def test_a_bad_discovery_variable_is_a_clear_error(monkeypatch, name, value):
    monkeypatch.setenv(name, value)
    with pytest.raises(Ros2Error, match=name):
        discovery_range_from_env() if name.endswith("RANGE") else static_peers_from_env()


@needs_netns
def test_a_default_configured_peer_discovers_the_simulator_and_no_packet_of_it_reaches_the_lan():
    # GIVEN no discovery variable set, a peer with cyclonedds' defaults (as rmw_cyclonedds_cpp under
    # ROS 2's default range) on a host with a LAN interface
    got = _in_namespace(None)
    # THEN the peer finds the node and receives its topics
    assert got["received"]["clock_samples"] > 10 and got["received"]["nodes"] == ["unetyemu_sim"]
    # AND on the LAN side of the interface: the peer's own discovery (TTL 32: the capture works),
    # nothing at all from the simulator
    assert got["on_the_lan"][got["peer"]] == [32]
    assert got["sim"] not in got["on_the_lan"]


@needs_netns
def test_ros_automatic_discovery_range_subnet_opens_the_simulator_to_the_lan():
    got = _in_namespace("SUBNET")
    assert got["received"]["clock_samples"] > 10
    assert got["on_the_lan"][got["sim"]] == [32]


@needs_netns
@pytest.mark.parametrize("discovery_range", ["LOCALHOST", "OFF"])
def test_localhost_and_off_keep_the_simulator_away_from_multicast_discovery(discovery_range):
    got = _in_namespace(discovery_range)
    assert got["received"]["clock_samples"] == 0
    assert got["sim"] not in got["on_the_lan"]


@needs_netns
def test_a_fast_dds_peer_with_fast_dds_defaults_discovers_the_simulator_with_no_setting():
    # GIVEN the Fast DDS C++ peer (what rmw_fastrtps_cpp is built on) with Fast DDS' own defaults
    sys.path.insert(0, str(DRIVER.parent.parent / "fastdds_peer"))
    from peer_build import PeerBuildError, build_peer
    try:
        exe = build_peer()
    except PeerBuildError as exc:
        pytest.fail(str(exc))
    got = _in_namespace(None, 6.0, str(exe))
    # THEN it receives the IMU and the clock, and still nothing of the simulator's is on the LAN
    assert got["fastdds"]["imu"]["count"] > 10 and got["fastdds"]["imu"]["frame_id"] == "d1/imu_link"
    assert got["fastdds"]["clock"]["count"] > 10
    assert got["sim"] not in got["on_the_lan"]
