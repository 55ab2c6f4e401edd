"""The live estimator in a worker thread (``estimator.worker.EstimatorWorker``) for asyncio programs.

A bounded queue with a counted drop policy (the oldest IMU sample first), a producer faster than
the filter (the estimate still converges on the data that got through), a bounded stop while the
producer still floods, and an exception in the core that is counted without ending the thread.
Real MAVLink messages (``estimator_stream``). No assertion on the machine's speed.
"""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest
from estimator_stream import Flight, autopilot_messages, over_the_wire, record

from estimator.live import LiveConfig, LiveCore
from estimator.worker import EstimatorWorker
from vehicle.vehicle_file import load_vehicle


@pytest.fixture(scope="module")
def flight() -> Flight:
    return record(30.0)


@pytest.fixture(scope="module")
def stream(flight: Flight) -> list:
    return over_the_wire([(1, 1, autopilot_messages(flight))])


def _core() -> LiveCore:
    return LiveCore(LiveConfig(vehicle=load_vehicle()))


def test_a_filling_queue_thins_imu_samples_and_a_full_one_drops_the_oldest(stream: list) -> None:
    msgs = stream[:400]
    w = EstimatorWorker(_core(), max_queue=100)
    for m in msgs:
        w.submit(m)
    c = w.counts
    assert w.queued() == 100 and c["high_water"] == 100 and c["received"] == 400
    assert c["decimated_imu"] > 0 and c["dropped_imu"] > 0 and c["dropped_other"] > 0
    assert 100 + c["decimated_imu"] + c["dropped_imu"] + c["dropped_other"] == 400
    kept = []
    while batch := w._take():  # the worker thread's view
        kept += batch
    idx = [next(i for i, x in enumerate(msgs) if x is m) for m in kept]
    assert idx == sorted(idx), "arrival order kept"
    # The newest stretch: every non-IMU message from the first kept one on is there ...
    tail = msgs[idx[0]:]
    assert [id(m) for m in kept if m.get_type() != "HIL_SENSOR"] == [
        id(m) for m in tail if m.get_type() != "HIL_SENSOR"]  # fmt: skip
    # ... with the IMU samples thinned to every 8th once the queue was 90 % full.
    imu_idx = [next(i for i, x in enumerate([m for m in msgs if m.get_type() == "HIL_SENSOR"]) if x is m)
               for m in kept if m.get_type() == "HIL_SENSOR"]  # fmt: skip
    assert len(imu_idx) > 3 and np.all(np.diff(imu_idx)[-3:] == 8)


def test_producer_faster_than_the_filter(flight: Flight, stream: list) -> None:
    """30 s of flight (about 11,000 messages) submitted as fast as the producer can: the queue stays
    within its bound, every message is either processed or counted as dropped, and the estimate the
    worker publishes converges on what got through."""
    w = EstimatorWorker(_core(), max_queue=2000)
    w.start()
    try:
        for m in stream:
            w.submit(m)
        end = time.monotonic() + 120.0
        while w.queued() and time.monotonic() < end:
            time.sleep(0.05)
        assert w.queued() == 0
        time.sleep(0.3)  # the last batch's snapshot
        snap = w.snapshot()
    finally:
        assert w.stop(5.0)
    c = w.counts
    assert c["high_water"] <= 2000 and c["errors"] == 0
    lost = c["decimated_imu"] + c["dropped_imu"] + c["dropped_other"]
    assert c["processed"] + lost == c["received"] == len(stream)
    # The producer (a deque append per message) outruns the filter (a UKF step per IMU sample)
    # whatever the machine: IMU samples were thinned or dropped.
    assert c["decimated_imu"] + c["dropped_imu"] > 0
    assert snap.ready and snap.counters["decimated_imu"] == c["decimated_imu"]
    assert snap.inputs_line is not None and snap.inputs_line.startswith("inputs: IMU HIL_SENSOR")
    assert snap.t == pytest.approx(flight.imu[-1][0], abs=0.05)  # thinned to every 8th sample at most
    truth = flight.wind_between(snap.t - 0.2, snap.t)
    assert np.linalg.norm(snap.wind_ned[:2] - truth[:2]) < 1.0
    assert np.all(np.linalg.eigvalsh(snap.cov_ned) > 0)


def test_stop_is_bounded_while_the_producer_floods(stream: list) -> None:
    w = EstimatorWorker(_core(), max_queue=500)
    w.start()
    go = threading.Event()
    done = threading.Event()

    def produce() -> None:
        go.set()
        while not done.is_set():
            for m in stream[:3000]:
                w.submit(m)
                if done.is_set():
                    return

    t = threading.Thread(target=produce, daemon=True)
    t.start()
    go.wait(5.0)
    time.sleep(0.5)
    assert w.stop(2.0), "the worker thread did not end within 2 s"
    done.set()
    t.join(5.0)
    assert w.counts["after_stop"] >= 0 and w.queued() <= 500
    n = w.counts["after_stop"]
    w.submit(stream[0])
    assert w.counts["after_stop"] == n + 1


class _Broken:
    """A message object without its fields (a buggy adapter): the core raises on it."""

    def get_type(self) -> str:
        return "HIL_SENSOR"

    def get_srcSystem(self) -> int:  # noqa: N802 - the pymavlink name
        return 1

    def get_srcComponent(self) -> int:  # noqa: N802 - the pymavlink name
        return 1


def test_an_exception_in_the_core_is_counted_and_the_worker_goes_on(stream: list) -> None:
    w = EstimatorWorker(_core(), max_queue=20000)  # room for all: nothing thinned
    for m in stream[:1500]:
        w.submit(m)
    w.submit(_Broken())
    for m in stream[1500:3000]:
        w.submit(m)
    w.start()
    try:
        end = time.monotonic() + 60.0
        while w.counts["processed"] < 3001 and time.monotonic() < end:
            time.sleep(0.05)
    finally:
        assert w.stop(5.0)
    assert w.counts["errors"] == 1 and w.counts["processed"] == 3001
    assert any("estimator error" in n for n in w.take_notes())
    assert w.core.est.accepted["imu"] > 1500  # all after the 1 s input-selection window
