"""What a selective transport in a worker process gets of each step, decided in the simulation's process.

A ProcessTransport whose worker said what it wants (:class:`Wants`) queues, on the simulation thread,
only the samples of the wanted topics, each topic's first sample, every sample of the kept (latched)
topics, the arrays at their rate while wanted, and no step that carries nothing of that. These tests
drive ``offer`` directly (no worker is started) and look at what was queued to be sent.
"""

from __future__ import annotations

import numpy as np
import pytest

from unetyemu_ecs.sensors.base import SensorSample
from unetyemu_ecs.transport.api import Snapshot
from unetyemu_ecs.transport.snapshot import ticks_in_step
from unetyemu_ecs.transport.worker import ProcessTransport, Wants

DT_S = 1.0 / 240.0
EVENTS: list = []
RESULTS: list = []


def step(k: int, topics: tuple[str, ...] = (), events_end: int = 0, status: dict | None = None) -> Snapshot:
    t = k * DT_S
    return Snapshot(step=k, sim_time_s=t, dt_s=DT_S, vehicles=("d1",), kinds=("quadrotor",),
                    arrays={"pos_enu_m": np.zeros((1, 3))},
                    sensors=tuple(SensorSample(t, "d1", topic.rsplit("/", 1)[-1], topic, msg=k) for topic in topics),
                    events=EVENTS, events_end=events_end, results=RESULTS, results_end=0,
                    mission_status=status or {})


def transport(wants: Wants, arrays_hz: float = 20.0) -> ProcessTransport:
    t = ProcessTransport("test", "nowhere:none", world=None, options=None, arrays=("pos_enu_m",),
                         keep=lambda topic: topic == "/tf_static", arrays_hz=arrays_hz)
    t._wants = wants                       # as the worker's "wants" reply sets it
    return t


def queued(t: ProcessTransport) -> list[Snapshot]:
    return [snap for _, snap in t._queue.get_all(0.0)]


def test_only_wanted_topics_cross_after_each_topics_first_sample_and_latched_ones_always():
    t = transport(Wants(topics=frozenset({"/d1/imu"})))
    for k in range(1, 4):
        t.offer(step(k, ("/d1/imu", "/d1/camera", "/tf_static")))
    got = [[s.topic for s in snap.sensors] for snap in queued(t)]
    assert got == [["/d1/imu", "/d1/camera", "/tf_static"],        # the camera's first: it gets advertised
                   ["/d1/imu", "/tf_static"], ["/d1/imu", "/tf_static"]]
    assert t.samples_held_back == 2 and t.snapshots_held_back == 0


def test_a_step_with_nothing_wanted_stays_behind_unless_it_has_news():
    t = transport(Wants())
    t.offer(step(1, ("/d1/camera",)))                        # first sample of the topic: crosses
    t.offer(step(2, ("/d1/camera",)))                        # nothing wanted: stays
    t.offer(step(3))                                         # nothing at all: stays
    EVENTS.append((3 * DT_S, "d1", "took off"))
    t.offer(step(4, events_end=len(EVENTS)))                 # a new event: crosses
    t.offer(step(5, events_end=len(EVENTS)))                 # the same event: stays
    t.offer(step(6, status={"d1": {"state": "running"}}))    # a mission status change: crosses
    assert [snap.step for snap in queued(t)] == [1, 4, 6]
    assert t.snapshots_held_back == 3 and t.counters()["snapshots_offered"] == 6
    EVENTS.clear()


def test_every_snapshot_crosses_while_the_clock_is_wanted_and_the_arrays_only_at_their_rate():
    t = transport(Wants(every_snapshot=True, arrays=True), arrays_hz=20.0)     # 20 Hz: every 12th step
    for k in range(0, 49):
        t.offer(step(k))
    snaps = queued(t)
    assert len(snaps) == 49 and all(not snap.sensors for snap in snaps)
    assert [snap.step for snap in snaps if snap.arrays] == [0, 12, 24, 36, 48]
    t._wants = Wants(every_snapshot=True)                     # /vehicles and the states unsubscribed
    t.offer(step(60))
    assert [dict(snap.arrays) for snap in queued(t)] == [{}]


@pytest.mark.parametrize("hz, dt_s, steps", [(20.0, 1 / 240, 241), (10.0, 1 / 240, 241), (7.0, 0.003, 1000)])
def test_a_clock_ticks_once_a_period_in_the_step_that_holds_the_tick(hz, dt_s, steps):
    ticks = [k for k in range(steps) if ticks_in_step(k * dt_s, dt_s, hz)]
    period_steps = 1.0 / (hz * dt_s)
    assert ticks[0] == 0                                      # the first tick is at t = 0
    assert len(ticks) == int((steps - 1) * dt_s * hz + 1e-9) + 1
    for n, k in enumerate(ticks):                             # tick n at n / hz lies in step k: ((k-1) dt, k dt]
        assert (k - 1) * dt_s < n / hz + 1e-9 <= k * dt_s + 1e-9
    assert np.allclose(np.diff(ticks).mean(), period_steps, rtol=0.02)
