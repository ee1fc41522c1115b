"""A sensor sample's message is built when first read, once, and never when nobody reads it."""

from __future__ import annotations

from unetyemu_ecs.sensors.base import SensorSample


def test_a_deferred_message_is_built_once_on_first_read_and_not_before():
    built: list[int] = []

    def build() -> dict:
        built.append(1)
        return {"data": 42}

    sample = SensorSample(1.5, "d1", "imu", "/d1/imu/data", build=build)
    assert built == []                                  # taking the measurement built nothing
    assert sample.msg == {"data": 42} and sample.msg is sample.msg
    assert built == [1]                                 # built once, on the first read
    assert (sample.time_s, sample.vehicle, sample.sensor, sample.topic, sample.ros2) == (1.5, "d1", "imu",
                                                                                           "/d1/imu/data", True)


def test_a_sample_made_with_its_message_returns_that_message():
    msg = object()
    sample = SensorSample(0.0, "d1", "gps", "/d1/gps/fix", msg, False)
    assert sample.msg is msg and sample.ros2 is False
