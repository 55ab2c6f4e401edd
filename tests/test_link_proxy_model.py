"""The link proxy's pure parts: the seeded fault model (``wire.proxy.faults``) and the MAVLink framing
(``wire.proxy.framing``), without sockets. Statistical checks use bounds of several standard deviations
over thousands of units, seeded, so they neither flake nor pass by luck."""

from __future__ import annotations

import math

import numpy as np
import pytest

from wire.dialect import mavlink as mav
from wire.proxy import Channel, Cut, Faults
from wire.proxy.faults import CutSchedule
from wire.proxy.framing import FrameSplitter, split_datagram

N = 20000


def units(n: int = N) -> list[bytes]:
    return [i.to_bytes(4, "big") for i in range(n)]


def run(ch: Channel, items: list[bytes], dt: float = 0.001, tail_s: float = 10.0) -> list[bytes]:
    """Offer one unit every ``dt`` seconds, collect what is due at each step and at the end."""
    out: list[bytes] = []
    for i, u in enumerate(items):
        ch.offer(i * dt, u)
        out += ch.due(i * dt)
    out += ch.due(len(items) * dt + tail_s)
    for u in out:
        ch.sent(u)
    return out


def ids(out: list[bytes]) -> list[int]:
    return [int.from_bytes(u, "big") for u in out]


def chan(seed: int = 1, **kw: object) -> Channel:
    return Channel(Faults(**kw), np.random.default_rng(seed))  # type: ignore[arg-type]


def test_no_faults_delivers_everything_at_once_in_order() -> None:
    ch = chan()
    for i, u in enumerate(units(100)):
        ch.offer(float(i), u)
        assert ch.due(float(i)) == [u]
    assert ch.counters["delayed"] == 0 and ch.in_flight == 0


def test_loss_rate_and_determinism() -> None:
    out = run(chan(seed=7, loss=0.3), units())
    lost = N - len(out)
    assert abs(lost - 0.3 * N) < 5 * math.sqrt(N * 0.3 * 0.7)
    assert ids(out) == sorted(ids(out))  # loss alone never reorders
    assert run(chan(seed=7, loss=0.3), units()) == out  # same seed, same units: the same losses
    assert run(chan(seed=8, loss=0.3), units()) != out
    c = chan(seed=7, loss=0.3)
    run(c, units())
    assert c.counters["dropped_loss"] == lost and c.counters["tx_units"] == len(out)


def test_faults_do_not_depend_on_timing() -> None:
    """The i-th unit meets the same fate however fast the units come (five draws per unit, always)."""
    a = run(chan(seed=3, loss=0.2, duplicate=0.1), units(5000), dt=0.001)
    b = run(chan(seed=3, loss=0.2, duplicate=0.1), units(5000), dt=0.37)
    assert a == b


def test_burst_losses_come_in_runs() -> None:
    # Gilbert-Elliott: enter 0.02, leave 0.25: bad 7.4 % of the time, runs of 1/0.25 = 4 on average.
    ch = chan(seed=2, burst=(0.02, 0.25))
    got = set(ids(run(ch, units())))
    lost = [i not in got for i in range(N)]
    runs = [len(r) for r in "".join("x" if x else "." for x in lost).split(".") if r]
    assert 3.0 < np.mean(runs) < 5.0, np.mean(runs)
    frac = sum(lost) / N
    assert abs(frac - 0.02 / 0.27) < 0.025, frac
    indep = chan(seed=2, loss=frac)
    got_i = set(ids(run(indep, units())))
    runs_i = [len(r) for r in "".join("x" if i not in got_i else "." for i in range(N)).split(".") if r]
    assert np.mean(runs_i) < 1.2  # the same loss rate without bursts: mostly single losses


def test_duplicates_follow_their_original() -> None:
    ch = chan(seed=4, duplicate=0.25)
    out = ids(run(ch, units()))
    assert len(out) == N + ch.counters["duplicated"]
    assert abs(ch.counters["duplicated"] - 0.25 * N) < 5 * math.sqrt(N * 0.25 * 0.75)
    assert out == sorted(out)  # a copy comes right after its original
    assert len(set(out)) == N


def test_reordering_swaps_neighbours_only() -> None:
    ch = chan(seed=5, reorder=0.1)
    out = ids(run(ch, units()))
    assert sorted(out) == list(range(N))  # nothing lost, nothing duplicated
    swaps = [i for i in range(len(out) - 1) if out[i] > out[i + 1]]
    assert len(swaps) == ch.counters["reordered"] > 0.07 * N
    for i in swaps:  # each held unit goes right after the next one: an adjacent swap
        assert out[i] == out[i + 1] + 1


def test_a_held_unit_goes_alone_after_max_hold() -> None:
    ch = chan(seed=0, reorder=1.0, max_hold_s=0.2)
    ch.offer(0.0, b"x")
    assert ch.due(0.1) == [] and ch.next_time() == pytest.approx(0.2)
    assert ch.due(0.2) == [b"x"] and ch.counters["reordered"] == 0


def _delays(ch: Channel, n: int, dt: float) -> np.ndarray:
    t_out: dict[int, float] = {}
    for i, u in enumerate(units(n)):
        t = i * dt
        ch.offer(t, u)
        for v in ch.due(t):
            t_out[int.from_bytes(v, "big")] = t
        while ch.next_time() < (i + 1) * dt:  # deliver at the exact release time, like the proxy's thread
            t_rel = ch.next_time()
            for v in ch.due(t_rel):
                t_out[int.from_bytes(v, "big")] = t_rel
    assert list(t_out) == sorted(t_out)  # jitter never reorders
    return np.array([t_out[i] - i * dt for i in list(t_out)[: n - 100]])


def test_latency_and_jitter_delay_without_reordering() -> None:
    # Sparse units (0.1 s apart, more than the jitter's span): the delay is latency + U(-jitter, +jitter).
    d = _delays(chan(seed=6, latency_s=0.05, jitter_s=0.03), 2000, 0.1)
    assert d.min() >= 0.02 - 1e-9 and d.max() <= 0.08 + 1e-9
    assert abs(float(np.mean(d)) - 0.05) < 0.002 and float(np.std(d)) == pytest.approx(0.03 / math.sqrt(3), rel=0.1)
    # Dense units (2 ms apart): order is kept, so a unit waits for the one ahead: the delays bunch
    # towards latency + jitter, never beyond it.
    ch = chan(seed=6, latency_s=0.05, jitter_s=0.03)
    d = _delays(ch, 3000, 0.002)
    assert d.min() >= 0.02 - 1e-9 and d.max() <= 0.08 + 1e-9 and float(np.median(d)) > 0.05
    assert ch.counters["delayed"] == 3000


def test_bandwidth_limits_throughput_and_counts_queue_drops() -> None:
    # 1000 B/s, 100-byte units offered at 20 per second (2000 B/s): half must go.
    ch = chan(bandwidth_bps=1000.0, queue_bytes=500)
    delivered = []
    for i in range(400):
        t = i * 0.05
        ch.offer(t, bytes(100))
        delivered += [t] * len(ch.due(t))
    assert ch.counters["dropped_queue"] + len(delivered) + ch.in_flight == 400
    assert 0.45 < ch.counters["dropped_queue"] / 400 < 0.55
    rate = 100 * len(delivered) / 20.0
    assert rate == pytest.approx(1000.0, rel=0.06)  # the link's rate, not the offered one


def test_bounds_on_what_is_in_flight() -> None:
    ch = Channel(Faults(latency_s=10.0), np.random.default_rng(0), max_units=50, max_bytes=1 << 20)
    for _ in range(80):
        ch.offer(0.0, bytes(10))
    assert ch.in_flight == 50 and ch.counters["dropped_overflow"] == 30


def test_a_cut_drops_what_arrives_and_what_is_in_flight() -> None:
    ch = chan(latency_s=1.0, reorder=1.0)
    for i in range(10):
        ch.offer(0.1 * i, bytes(5))
    assert ch.in_flight == 10
    assert ch.drop_all() == 10 and ch.counters["dropped_cut"] == 10
    ch.offer(1.0, bytes(5), cut=True)
    assert ch.counters["dropped_cut"] == 11 and ch.due(100.0) == []


def test_filtered_messages_never_get_through() -> None:
    fs = frames()  # heartbeat (v2), statustext, local position, heartbeat (v1), heartbeat (signed)
    ch = chan(drop_ids=frozenset({mav.MAVLINK_MSG_ID_HEARTBEAT}))
    for i, f in enumerate(fs):
        ch.offer(float(i), f)
    ch.offer(9.0, fs[1] + fs[0])  # a datagram holding a heartbeat goes whole
    assert ch.due(10.0) == [fs[1], fs[2]] and ch.counters["dropped_filter"] == 4


def test_cut_schedule() -> None:
    s = CutSchedule([Cut(5.0, 2.0), Cut.parse("10:")])
    assert not s.active(6.0)  # not triggered yet: scheduled cuts wait for the trigger
    s.trigger(1.0)
    assert [s.active(t) for t in (5.9, 6.0, 7.9, 8.0, 10.9, 11.0, 1e6)] == [False, True, True, False, False, True, True]
    assert s.next_change(0.0) == 6.0 and s.next_change(8.5) == 11.0 and s.next_change(12.0) == math.inf
    s.manual = True
    assert s.active(9.0)
    assert Cut.parse("2.5:1").duration_s == 1.0 and math.isinf(Cut.parse("3:").duration_s)
    for bad in ("5", "x:1", "-1:2", "3:0", "3:-1", "nan:1", "1:nan"):
        with pytest.raises(ValueError, match="START:DURATION"):
            Cut.parse(bad)


@pytest.mark.parametrize("kw", [{"drop_ids": frozenset({-1})},
                                {"loss": 1.5}, {"duplicate": -0.1}, {"reorder": math.nan}, {"latency_s": -1.0},
                                {"bandwidth_bps": 0.0}, {"burst": (0.5, 2.0)}, {"queue_bytes": -1}])  # fmt: skip
def test_bad_faults_are_refused(kw: dict) -> None:
    with pytest.raises(ValueError):
        Faults(**kw).validate()


# ---------------------------------------------------------------------- framing
def frames() -> list[bytes]:
    m = mav.MAVLink(None, 1, 1)
    out = [mav.MAVLink_heartbeat_message(2, 12, 128, 0, 4, 3).pack(m),
           mav.MAVLink_statustext_message(6, b"hello".ljust(50, b"\0")).pack(m),
           mav.MAVLink_local_position_ned_message(1000, 1.0, 2.0, -3.0, 0.1, 0.2, 0.3).pack(m)]  # fmt: skip
    m1 = mav.MAVLink(None, 1, 1)
    m1.WIRE_PROTOCOL_VERSION = "1.0"
    out.append(mav.MAVLink_heartbeat_message(2, 12, 0, 0, 4, 3).pack(m1, force_mavlink1=True))
    signed = mav.MAVLink(None, 1, 1)
    signed.signing.secret_key = bytes(range(32))
    signed.signing.sign_outgoing = True
    out.append(mav.MAVLink_heartbeat_message(2, 12, 0, 0, 4, 3).pack(signed))
    return out


def test_frames_are_cut_out_of_a_stream_in_any_chunks() -> None:
    fs = frames()
    assert fs[3][0] == 0xFE and fs[4][0] == 0xFD and len(fs[4]) == len(fs[0]) + 13 - (len(fs[0]) - len(fs[4]) + 13)
    stream = b"\x00\x01junk" + b"".join(fs) + b"\x02"
    for chunk in (1, 3, 7, 64, len(stream)):
        sp = FrameSplitter()
        got: list[bytes] = []
        for i in range(0, len(stream), chunk):
            got += sp.feed(stream[i : i + chunk])
        assert got == fs, chunk
        assert sp.garbage == 6 + 1  # the junk before, the stray byte after
    parser = mav.MAVLink(None)
    assert [parser.parse_buffer(f)[0].get_type() for f in got] == ["HEARTBEAT", "STATUSTEXT",
                                                                   "LOCAL_POSITION_NED", "HEARTBEAT", "HEARTBEAT"]


def test_a_datagram_is_split_and_a_truncated_tail_counted() -> None:
    fs = frames()
    data = b"".join(fs[:3]) + fs[3][:5]
    got, bad = split_datagram(data)
    assert got == fs[:3] and bad == 5
    rng = np.random.default_rng(0)
    for _ in range(200):  # hostile bytes: never an exception, never more out than in
        junk = rng.integers(0, 256, int(rng.integers(0, 600))).astype(np.uint8).tobytes()
        out, bad = split_datagram(junk)
        assert sum(map(len, out)) + bad == len(junk)
