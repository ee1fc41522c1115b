"""Recording: a rosbag2 with MCAP storage of every topic, read back by an independent reader (rosbags)."""

from __future__ import annotations

import pytest
import yaml

from unetyemu_ecs import Simulation, load_world
from unetyemu_ecs.cli import main as cli_main
from unetyemu_ecs.sensors.messages import typestore
from unetyemu_ecs.transport.api import TransportError

from ..conftest import WORLDS


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """Three seconds of the delivery scenario with all its sensors, recorded."""
    bag = tmp_path_factory.mktemp("rec") / "delivery"
    with Simulation(load_world(WORLDS / "urban_delivery.yaml"), record=bag) as sim:
        sim.run(duration=3.0)
        assert sim.flush_transports(30.0)
        counters = sim.transport_counters()["record"]
        steps = sim.step_count
    return bag, counters, steps


def read_back(bag) -> dict[str, list[tuple[int, object]]]:
    """Every message of every connection, deserialised with the Jazzy definitions: topic -> [(log time, msg)]."""
    from rosbags.highlevel import AnyReader

    out: dict[str, list[tuple[int, object]]] = {}
    with AnyReader([bag], default_typestore=typestore()) as reader:
        assert reader.duration > 0
        for conn, timestamp, raw in reader.messages():
            out.setdefault(conn.topic, []).append((timestamp, reader.deserialize(raw, conn.msgtype)))
    return out


def test_the_bag_is_a_rosbag2_with_mcap_storage_and_every_message_decodes(recorded):
    bag, counters, _ = recorded
    assert (bag / "metadata.yaml").is_file() and (bag / "delivery.mcap").is_file()
    assert (bag / "delivery.mcap").read_bytes()[:8] == b"\x89MCAP0\r\n"          # the MCAP magic
    messages = read_back(bag)
    assert counters["snapshots_dropped"] == 0 and counters["publish_errors"] == 0
    # what was published is what is in the bag, topic by topic
    assert sum(len(v) for v in messages.values()) == counters["published"]
    for topic in ("/clock", "/tf", "/tf_static", "/drone1/lidar/points", "/drone1/imu/data", "/drone2/depth/image_raw",
                  "/drone3/camera/image_raw", "/drone1/battery", "/drone1/mission/status"):
        assert topic in messages, sorted(messages)


def test_the_official_mcap_reader_decodes_every_message_from_the_schemas_in_the_file(recorded):
    """The reference MCAP library (what rosbag2's MCAP storage and Foxglove are built on) reads the file, and
    its ROS 2 decoder (its own CDR reader, from the ``ros2msg`` schema text the file carries, not rosbags')
    decodes every message; the file says it is a rosbag2 and offers each topic's QoS as the live node did."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    bag, counters, _ = recorded
    with open(bag / "delivery.mcap", "rb") as fh:
        reader = make_reader(fh, decoder_factories=[DecoderFactory()])
        assert reader.get_header().profile == "ros2"
        summary = reader.get_summary()
        assert {m.name for m in reader.iter_metadata()} == {"rosbag2"}
        assert all(s.encoding == "ros2msg" for s in summary.schemas.values())
        qos = {c.topic: yaml.safe_load(c.metadata["offered_qos_profiles"])[0] for c in summary.channels.values()}
        decoded = {}
        for _schema, channel, _message, _msg in reader.iter_decoded_messages():
            decoded[channel.topic] = decoded.get(channel.topic, 0) + 1
    assert sum(decoded.values()) == summary.statistics.message_count == counters["published"]
    cloud = next(iter(read_back(bag)["/drone1/lidar/points"]))[1]
    assert cloud.width * cloud.point_step == len(cloud.data)
    # latched as the live node offers them (transient local, their depth); the rest volatile, keep last 10
    assert qos["/tf_static"]["durability"] == 1 and qos["/tf_static"]["depth"] == 1
    assert qos["/drone1/mission/status"]["durability"] == 1
    assert qos["/drone1/imu/data"]["durability"] == 2 and qos["/drone1/imu/data"]["depth"] == 10
    assert all(q["reliability"] == 1 for q in qos.values())


def test_counts_follow_the_sensor_rates_and_stamps_are_sim_time(recorded):
    bag, _, steps = recorded
    messages = read_back(bag)
    clock = messages["/clock"]
    assert len(clock) == steps + 1                                   # the built world, then every step
    times = [t for t, _ in clock]
    assert times == sorted(times) and len(set(times)) == len(times)
    for t, msg in clock:                                             # the log time is the sim time
        assert msg.clock.sec * 10**9 + msg.clock.nanosec == t
    assert len(messages["/drone1/imu/data"]) == pytest.approx(3.0 * 100.0, abs=2)      # 100 Hz for 3 s
    assert len(messages["/drone1/lidar/points"]) == pytest.approx(3.0 * 10.0, abs=1)
    for topic, items in messages.items():
        stamps = [t for t, _ in items]
        assert stamps == sorted(stamps), topic
        header = getattr(items[-1][1], "header", None)
        if header is not None:                                       # sensors: header stamp = log time
            assert header.stamp.sec * 10**9 + header.stamp.nanosec == items[-1][0], topic


def test_recording_into_an_existing_directory_is_refused_and_nothing_starts(tmp_path):
    (tmp_path / "bag").mkdir()
    with pytest.raises(TransportError, match="exists already"):
        Simulation(load_world(WORLDS / "empty.yaml"), record=tmp_path / "bag")
    with pytest.raises(ValueError, match="record must be the path"):
        Simulation(load_world(WORLDS / "empty.yaml"), record=3)


def test_the_cli_records_next_to_the_runs_logs(tmp_path):
    out = tmp_path / "run"
    assert cli_main(["run", str(WORLDS / "empty.yaml"), "--duration", "0.5", "--out", str(out), "--quiet",
                     "--record"]) == 0
    assert (out / "recording" / "recording.mcap").is_file() and (out / "summary.json").is_file()
    assert len(read_back(out / "recording")["/clock"]) == 121


def test_a_chosen_set_of_topics_is_recorded_and_nothing_else(tmp_path):
    bag = tmp_path / "chosen"
    with Simulation(load_world(WORLDS / "urban_delivery.yaml"), record=bag,
                    record_topics=["/drone1/*", "/clock", "/nothing/here"]) as sim:
        sim.run(duration=0.5)
        assert sim.flush_transports(30.0)
        counters = sim.transport_counters()["record"]
    messages = read_back(bag)
    assert "/clock" in messages and "/drone1/imu/data" in messages and "/drone1/mission/status" in messages
    assert all(t == "/clock" or t.startswith("/drone1/") for t in messages), sorted(messages)
    assert counters["patterns_matching_nothing"] == ["/nothing/here"]
    assert sum(len(v) for v in messages.values()) == counters["published"]


def test_bad_topic_choices_are_refused_with_what_is_wrong(tmp_path):
    world = load_world(WORLDS / "empty.yaml")
    with pytest.raises(ValueError, match="not a topic pattern"):
        Simulation(world, record=tmp_path / "a", record_topics=["drone1 imu"])
    with pytest.raises(ValueError, match="list of topic patterns"):
        Simulation(world, record=tmp_path / "b", record_topics="/tf")
    with pytest.raises(ValueError, match="without record"):
        Simulation(world, record_topics=["/tf"])
    assert cli_main(["run", str(WORLDS / "empty.yaml"), "--duration", "0.1", "--out", str(tmp_path / "run"),
                     "--quiet", "--record-topics", "/tf"]) == 2
    assert not (tmp_path / "run").exists()


def test_the_recorder_runs_in_a_worker_process_whose_death_never_stops_the_simulation(tmp_path):
    import os
    import signal

    with Simulation(load_world(WORLDS / "empty.yaml"), record=tmp_path / "bag") as sim:
        worker = sim.transports["record"]
        pid = sim.transport_counters()["record"]["worker"]["pid"]
        assert pid != os.getpid()
        sim.run(duration=0.5)
        assert sim.flush_transports(30.0)
        os.kill(pid, signal.SIGKILL)                 # the worker dies mid-run
        sim.run(duration=0.5)                        # the simulation goes on
        sim.flush_transports(5.0)
        counters = sim.transport_counters()["record"]
        assert sim.step_count == 240
    assert counters["worker"]["error"]               # and the summary says what happened
    assert counters["published"] >= 121              # what was written before stays counted
    assert worker.counters()["worker"]["pid"] is None
