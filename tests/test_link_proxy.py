"""The link proxy on real sockets between real pymavlink peers (UDP and TCP), and its command line.

Every wait is bounded; nothing asserts on this machine's speed (counts are compared with the proxy's
own counters, which must add up exactly)."""

from __future__ import annotations

import json
import select
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from link_support import free_port
from pymavlink import mavutil

from wire.dialect import mavlink as mav
from wire.proxy import Cut, Faults, LinkProxy

ROOT = Path(__file__).resolve().parents[1]


def conn(url: str, sysid: int) -> Any:
    c = mavutil.mavlink_connection(url, source_system=sysid, source_component=1, dialect="common")
    c.mav = mav.MAVLink(c, sysid, 1)  # the project dialect (pymavlink's lacks ESC_STATUS)
    c.mav.robust_parsing = True
    return c


def drain(c: Any, until: Callable[[list[Any]], bool], timeout: float = 5.0) -> list[Any]:
    """Messages received until ``until(msgs)`` or ``timeout`` wall seconds (0: what is there now)."""
    got: list[Any] = []
    end = time.monotonic() + timeout
    while not until(got):
        m = c.recv_match(blocking=False)
        if m is None:
            if time.monotonic() >= end:
                break
            m = c.recv_match(blocking=True, timeout=0.02)
        if m is not None and m.get_type() != "BAD_DATA":
            got.append(m)
    return got


def wait_for(pred: Callable[[], bool], timeout: float = 5.0) -> None:
    end = time.monotonic() + timeout
    while not pred():
        assert time.monotonic() < end, "timed out"
        time.sleep(0.01)


def statustexts(n: int, c: Any, tag: str = "m", rx: Any = None) -> list[Any]:
    """Send ``n`` numbered STATUSTEXTs, paced (socket buffers are finite), collecting what ``rx`` receives."""
    got: list[Any] = []
    for i in range(n):
        c.mav.statustext_send(6, f"{tag}{i}".encode())
        if i % 20 == 19:
            time.sleep(0.002)
            if rx is not None:
                got += drain(rx, lambda g: False, 0.0)
    return got


def numbers(msgs: list[Any], tag: str = "m") -> list[int]:
    return [int(m.text[len(tag):]) for m in msgs if m.get_type() == "STATUSTEXT" and m.text.startswith(tag)]


def settled(px: LinkProxy, d: str, n: int) -> Callable[[], bool]:
    """All ``n`` units sent in direction ``d`` arrived and have been delivered or dropped."""

    def done() -> bool:
        c = px.report()[d]
        out = c["tx_units"] + sum(v for k, v in c.items() if k.startswith("dropped"))
        return c["rx_units"] == n and c["in_flight"] == 0 and out == n + c["duplicated"]

    return done


def transfer(px: LinkProxy, n: int, tx: Any, rx: Any, tag: str = "m", d: str = "a->b") -> list[int]:
    """Send ``n`` numbered texts from ``tx``; the numbers ``rx`` got, once the proxy has delivered all it will."""
    before = px.report()[d]
    got = statustexts(n, tx, tag, rx)
    end = time.monotonic() + 10.0
    while not settled(px, d, before["rx_units"] + n)():
        assert time.monotonic() < end, f"the proxy did not settle: {px.report()[d]}"
        got += drain(rx, lambda g: False, 0.02)
    want = px.report()[d]["tx_units"] - before["tx_units"]
    got += drain(rx, lambda g: len(numbers(got + g, tag)) >= want, 3.0)
    return numbers(got, tag)


@pytest.fixture
def udp_pair() -> Any:
    """An 'autopilot' (udpout to the proxy's a end) and a 'ground station' (udpin on the b end's target)."""
    gcs_port = free_port()
    made: list[Any] = []

    def make(**kw: Any) -> tuple[LinkProxy, Any, Any]:
        px = LinkProxy("udpin:127.0.0.1:0", f"udpout:127.0.0.1:{gcs_port}", **kw).start()
        gcs = conn(f"udpin:127.0.0.1:{gcs_port}", 255)
        ap = conn(f"udpout:127.0.0.1:{px.a.port}", 1)
        made.extend([px, gcs, ap])
        return px, ap, gcs

    yield make
    for x in made:
        (x.stop if isinstance(x, LinkProxy) else x.close)()


def test_udp_loss_counts_add_up_and_replies_find_their_way(udp_pair: Any) -> None:
    px, ap, gcs = udp_pair(ab=Faults(loss=0.3), ba=Faults(), seed=11)
    got = transfer(px, 400, ap, gcs)
    rep = px.report()["a->b"]
    assert rep["rx_units"] == 400 and rep["tx_units"] + rep["dropped_loss"] == 400
    assert len(got) == rep["tx_units"] and got == sorted(got)
    assert 60 < rep["dropped_loss"] < 180
    # The ground station answers: its reply goes back to the autopilot's address, without faults.
    assert transfer(px, 20, gcs, ap, "r", "b->a") == list(range(20))


def test_duplicates_and_reordering_on_the_wire(udp_pair: Any) -> None:
    px, ap, gcs = udp_pair(ab=Faults(duplicate=0.2, reorder=0.2), seed=3)
    got = transfer(px, 300, ap, gcs)
    rep = px.report()["a->b"]
    assert len(got) == rep["tx_units"] == 300 + rep["duplicated"]
    assert sorted(set(got)) == list(range(300))
    swaps = sum(a > b for a, b in zip(got, got[1:], strict=False))
    assert swaps == rep["reordered"] > 20


def test_manual_cut_and_restore(udp_pair: Any) -> None:
    px, ap, gcs = udp_pair(seed=1)
    assert transfer(px, 10, ap, gcs, "a") == list(range(10))
    px.cut()
    assert px.is_cut()
    statustexts(10, ap, "b")
    statustexts(5, gcs, "c")
    wait_for(lambda: px.report()["a->b"]["rx_units"] == 20 and px.report()["b->a"]["rx_units"] == 5)
    assert drain(gcs, lambda g: False, 0.3) == [] and drain(ap, lambda g: False, 0.1) == []
    px.restore()
    assert transfer(px, 10, ap, gcs, "d") == list(range(10))
    rep = px.report()
    assert rep["a->b"]["dropped_cut"] == 10 and rep["b->a"]["dropped_cut"] == 5
    assert len(rep["cuts"]) == 1 and rep["cuts"][0]["manual"] and rep["cuts"][0]["end_s"] > rep["cuts"][0]["start_s"]


def test_scheduled_cut_counts_from_the_armed_heartbeat(udp_pair: Any) -> None:
    px, ap, gcs = udp_pair(cuts=[Cut(0.3, 0.5)], trigger="armed", seed=1)
    for _ in range(3):  # disarmed heartbeats and one from a ground station: no trigger
        ap.mav.heartbeat_send(2, 12, 0, 0, 3)
        gcs.mav.heartbeat_send(6, 8, 128, 0, 4)
    drain(gcs, lambda g: len(g) >= 3, 2.0)
    time.sleep(0.5)
    assert px.report()["triggered_at_s"] is None and not px.is_cut()
    ap.mav.heartbeat_send(2, 12, 128, 0, 4)  # armed autopilot
    wait_for(px.is_cut, 3.0)
    t = px.report()["triggered_at_s"]
    wait_for(lambda: not px.is_cut(), 3.0)
    rep = px.report()
    assert rep["cuts"][0]["start_s"] == pytest.approx(t + 0.3, abs=0.06)
    assert rep["cuts"][0]["end_s"] - rep["cuts"][0]["start_s"] == pytest.approx(0.5, abs=0.06)


def test_hostile_input_never_breaks_the_proxy() -> None:
    """Garbage and truncated frames: in frame mode what is not a whole frame is dropped and counted;
    the proxy keeps forwarding. The receiver parses every datagram on its own (as ``windseek sitl``
    does), so garbage cannot swallow the frames that follow it."""
    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rx.bind(("127.0.0.1", 0))
    rx.settimeout(0.05)
    px = LinkProxy("udpin:127.0.0.1:0", f"udpout:127.0.0.1:{rx.getsockname()[1]}", seed=2, frames=True).start()
    ap = conn(f"udpout:127.0.0.1:{px.a.port}", 1)
    raw = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        for n in (0, 1, 7, 300, 65000):
            raw.sendto(bytes([0xFD]) * min(n, 1) + bytes(range(256)) * (n // 256) + bytes(n % 256),
                       ("127.0.0.1", px.a.port))  # fmt: skip
        whole = ap.mav.statustext_encode(6, b"m99").pack(ap.mav)
        raw.sendto(b"\x00\x00" + whole[:-3], ("127.0.0.1", px.a.port))  # junk, then a truncated frame
        statustexts(5, ap)
        texts: list[str] = []
        end = time.monotonic() + 5.0
        while len([t for t in texts if t.startswith("m")]) < 5 and time.monotonic() < end:
            try:
                data = rx.recv(65536)
            except TimeoutError:
                continue
            parser = mav.MAVLink(None)
            parser.robust_parsing = True
            texts += [m.text for m in parser.parse_buffer(data) or [] if m.get_type() == "STATUSTEXT"]
        assert [t for t in texts if t.startswith("m")] == [f"m{i}" for i in range(5)]
        assert px.running and px.error is None
        garbage = px.report()["a_end"]["garbage_bytes"]
        assert garbage >= 2 + len(whole) - 3  # at least the junk and the truncated frame
    finally:
        raw.close()
        ap.close()
        px.stop()
        rx.close()


def test_tcp_both_ends_cut_the_stream_into_frames() -> None:
    server_port = free_port(socket.SOCK_STREAM)
    gcs = conn(f"tcpin:127.0.0.1:{server_port}", 255)  # the proxy's b end connects to it
    px = LinkProxy("tcpin:127.0.0.1:0", f"tcpout:127.0.0.1:{server_port}", Faults(loss=0.25), Faults(), seed=5)
    px.start()
    ap = conn(f"tcp:127.0.0.1:{px.a.port}", 1)
    try:
        wait_for(lambda: px.report()["b_end"].get("connects", 0) == 1 and px.report()["a_end"].get("connects", 0) == 1)
        got = transfer(px, 200, ap, gcs)
        rep = px.report()["a->b"]
        assert rep["rx_units"] == 200 and len(got) == rep["tx_units"] and 20 < rep["dropped_loss"] < 80
        gcs.mav.statustext_send(6, b"r0")
        assert numbers(drain(ap, lambda g: len(g) >= 1, 3.0), "r") == [0]
    finally:
        ap.close()
        px.stop()
        gcs.close()


def test_tcpout_reconnects_when_its_peer_comes_later() -> None:
    server_port = free_port(socket.SOCK_STREAM)
    px = LinkProxy("udpin:127.0.0.1:0", f"tcpout:127.0.0.1:{server_port}", seed=0).start()
    ap = conn(f"udpout:127.0.0.1:{px.a.port}", 1)
    try:
        statustexts(3, ap)
        wait_for(lambda: px.report()["a->b"]["dropped_no_peer"] == 3)
        wait_for(lambda: px.report()["b_end"].get("connect_errors", 0) >= 1)
        gcs = conn(f"tcpin:127.0.0.1:{server_port}", 255)
        wait_for(lambda: px.report()["b_end"].get("connects", 0) == 1, 5.0)
        statustexts(3, ap, "x")
        assert numbers(drain(gcs, lambda g: len(g) >= 3), "x") == [0, 1, 2]
        gcs.close()
    finally:
        ap.close()
        px.stop()


# ---------------------------------------------------------------------- the command line
def cli(*args: str) -> subprocess.Popen[str]:
    return subprocess.Popen([sys.executable, "-m", "windseek.cli", "link-proxy", *args], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, cwd=ROOT)  # fmt: skip


def line_within(p: subprocess.Popen[str], timeout: float) -> str:
    """The next stderr line of ``p``, or "" after ``timeout`` s."""
    assert p.stderr is not None
    return p.stderr.readline() if select.select([p.stderr], [], [], timeout)[0] else ""


def test_cli_forwards_with_faults_and_prints_json_on_sigterm() -> None:
    a_port, gcs_port = free_port(), free_port()
    gcs = conn(f"udpin:127.0.0.1:{gcs_port}", 255)
    p = cli(f"udpin:127.0.0.1:{a_port}", f"udpout://127.0.0.1:{gcs_port}", "--loss", "0.5/0", "--seed", "4",
            "--cut", "600:", "--drop-msg", "/HEARTBEAT", "--json", "--progress-every", "0")  # fmt: skip
    ap = None
    try:
        first = line_within(p, 30.0)
        assert first.startswith("windseek link-proxy: a udpin:127.0.0.1:") and "loss 0.5" in first, first
        ap = conn(f"udpout:127.0.0.1:{a_port}", 1)
        got = statustexts(100, ap, rx=gcs)
        p.send_signal(signal.SIGUSR1)  # a cut by hand ...
        assert line_within(p, 10.0).startswith("windseek link-proxy: cut at t = ")
        statustexts(10, ap, "x")
        time.sleep(0.3)
        p.send_signal(signal.SIGUSR2)  # ... until restored
        assert line_within(p, 10.0).startswith("windseek link-proxy: restored at t = ")
        for _ in range(2):  # filtered out on the way back
            gcs.mav.heartbeat_send(6, 8, 0, 0, 4)
        time.sleep(0.3)
        p.send_signal(signal.SIGTERM)
        out, err = p.communicate(timeout=10)
        got += drain(gcs, lambda g: False, 0.5)  # all it sent is in the socket buffer by now
    finally:
        p.kill() if p.poll() is None else None
        gcs.close()
        if ap is not None:
            ap.close()
    assert p.returncode == 0, err
    rep = json.loads(out)
    assert rep["stop_reason"] == "SIGTERM" and rep["seed"] == 4
    assert len(rep["cuts"]) == 1 and rep["cuts"][0]["manual"] and rep["cuts"][0]["end_s"] is not None
    c = rep["a->b"]
    assert c["rx_units"] == 110 and c["dropped_cut"] == 10 and c["tx_units"] + c["dropped_loss"] == 100
    assert numbers(got, "x") == [] and len(numbers(got)) == c["tx_units"]
    assert rep["b->a"]["dropped_filter"] == 2 and rep["faults"]["b->a"] == "drop message ids 0"


@pytest.mark.parametrize(("argv", "says"), [
    (["udpin:127.0.0.1:0", "udpout:127.0.0.1:9", "--loss", "1.5"], "1.5 must be in [0, 1]"),
    (["udpin:127.0.0.1:0", "udpout:127.0.0.1:9", "--dup", "0.1/0.2/0.3"], "expected one probability or two"),
    (["udpin:127.0.0.1:0", "serial:/dev/ttyS0"], "expected udpin:HOST:PORT"),
    (["udpin:127.0.0.1:0", "udpout:127.0.0.1:0"], "needs the peer's port"),
    (["udpin:127.0.0.1:0", "udpout:127.0.0.1:9", "--cut", "5"], "expected START:DURATION"),
    (["udpin:127.0.0.1:0", "udpout:127.0.0.1:9", "--burst", "0.1"], "expected ENTER:LEAVE"),
    (["udpin:127.0.0.1:0", "udpout:127.0.0.1:9", "--latency", "-3"], "must be in [0, 60000] ms"),
    (["udpin:127.0.0.1:0", "udpout:127.0.0.1:9", "--drop-msg", "HEARTBEAT,NOPE"], "'NOPE': not a MAVLink message"),
])  # fmt: skip
def test_bad_arguments_are_one_line_errors(argv: list[str], says: str, capsys: pytest.CaptureFixture[str]) -> None:
    from windseek.cli import main

    with pytest.raises(SystemExit) as e:
        main(["link-proxy", *argv])
    err = capsys.readouterr().err
    assert e.value.code == 2 and says in err and "Traceback" not in err


def test_a_port_in_use_is_a_one_line_error(capsys: pytest.CaptureFixture[str]) -> None:
    from windseek.cli import main

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        taken = s.getsockname()[1]
        assert main(["link-proxy", f"udpin:127.0.0.1:{taken}", "udpout:127.0.0.1:9"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("windseek link-proxy: error:") and "Address already in use" in err
    assert len(err.splitlines()) == 1
