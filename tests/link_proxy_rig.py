"""The rig of the link proxy's end-to-end tests: ``windseek sitl`` (a subprocess) streaming to the proxy
(``windseek link-proxy`` in its own process, or :class:`~wire.proxy.LinkProxy` in this one) and to a
listener that never sends a HEARTBEAT; the MAVSDK runner connects behind the proxy.
"""

from __future__ import annotations

import json
import math
import select
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from link_support import free_port

from mission.runners.inprocess import SUCCESS_RADIUS_M
from mission.runners.mavsdk_runner import MissionConfig, MissionResult
from sitl.scenario import load_scenario
from wire import param_codec
from wire.dialect import mavlink as mav
from wire.proxy import Faults, LinkProxy
from wire.proxy.framing import split_datagram
from wire.px4_modes import name as px4_mode_name

ROOT = Path(__file__).resolve().parents[1]
SCENARIO = "open-field-low"


#: HEARTBEAT, PARAM_VALUE, LOCAL_POSITION_NED, STATUSTEXT: what the listener decodes.
WANTED = {0, 22, 32, 253}


class Listener(threading.Thread):
    """A UDP peer of the SITL that never sends a HEARTBEAT: the vehicle's true state, outside the proxy."""

    def __init__(self) -> None:
        super().__init__(daemon=True)
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.port = self.sock.getsockname()[1]
        self.t = 0.0  # vehicle time, s
        self.mode, self.armed, self.pos = "", False, np.zeros(3)
        self.modes: list[tuple[float, str, bool]] = []  # (t, mode, armed) at every change
        self.texts: list[tuple[float, str]] = []
        self.params: dict[str, float] = {}
        self.stop = threading.Event()

    def run(self) -> None:
        parser = mav.MAVLink(None)
        parser.robust_parsing = True
        while not self.stop.is_set():
            if not select.select([self.sock], [], [], 0.1)[0]:
                continue
            # Decode only the frames it needs (by the id in the header): the SITL streams ~1000 messages a
            # second of vehicle time, and this thread shares the GIL with the runner under test.
            frames, _ = split_datagram(self.sock.recv(65536))
            for f in frames:
                if f[0] == 0xFD and int.from_bytes(f[7:10], "little") in WANTED:
                    for m in parser.parse_buffer(f) or []:
                        self._on(m)

    def _on(self, m: Any) -> None:
        mtype = m.get_type()
        if mtype == "LOCAL_POSITION_NED":
            self.t, self.pos = m.time_boot_ms * 1e-3, np.array([m.x, m.y, m.z])
        elif mtype == "HEARTBEAT" and (m.get_srcSystem(), m.get_srcComponent()) == (1, 1):
            mode, armed = px4_mode_name(m.custom_mode), bool(m.base_mode & 128)
            if (mode, armed) != (self.mode, self.armed):
                self.modes.append((self.t, mode, armed))
            self.mode, self.armed = mode, armed
        elif mtype == "STATUSTEXT" and m.get_srcSystem() == 1:
            self.texts.append((self.t, m.text))
        elif mtype == "PARAM_VALUE":
            self.params[m.param_id] = param_codec.decode(m.param_value, m.param_type)

    def set_param(self, sitl_port: int, name: str, value: float, param_type: int = param_codec.REAL32) -> None:
        """PARAM_SET straight to the SITL (not a HEARTBEAT: the listener still does not count as a link);
        ``param_type`` as the parameter's PX4 type (INT32 values travel bytewise)."""
        enc = mav.MAVLink(None, 250, 1)
        field = param_codec.encode(value, param_type)
        frame = enc.param_set_encode(1, 1, name.encode(), field, param_type).pack(enc)
        end = time.monotonic() + 10.0
        while self.params.get(name) != pytest.approx(value):
            assert time.monotonic() < end, f"the SITL did not take {name} = {value}"
            self.sock.sendto(frame, ("127.0.0.1", sitl_port))
            time.sleep(0.2)

    def wait(self, pred: Callable[[], bool], timeout: float, what: str) -> None:
        end = time.monotonic() + timeout
        while not pred():
            assert time.monotonic() < end, f"timed out after {timeout} s waiting for {what}"
            time.sleep(0.02)

    def after(self, t: float) -> list[tuple[float, str, bool]]:
        return [x for x in self.modes if x[0] >= t]


def proxy_args(f: Faults) -> list[str]:
    """``windseek link-proxy`` options for ``f`` (both directions)."""
    return ["--loss", str(f.loss), "--dup", str(f.duplicate), "--reorder", str(f.reorder),
            "--latency", str(f.latency_s * 1e3), "--jitter", str(f.jitter_s * 1e3)]  # fmt: skip


class ProxyProcess:
    """``windseek link-proxy`` in its own process (as a user runs it: no GIL shared with the runner under
    test); SIGUSR1 cuts the link, SIGUSR2 restores it, SIGTERM ends it and its JSON report is read."""

    def __init__(self, faults: Faults, seed: int, a_port: int, b_port: int) -> None:
        self.a_port = a_port
        cmd = [sys.executable, "-m", "windseek.cli", "link-proxy", f"udpin:127.0.0.1:{a_port}",
               f"udpout:127.0.0.1:{b_port}", "--seed", str(seed), "--json", "--progress-every", "0",
               *proxy_args(faults)]  # fmt: skip
        self.proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT)
        self.said: list[str] = []
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()
        self._wait_for("windseek link-proxy: a ", 30.0)
        self.report: dict[str, Any] = {}

    def _read(self) -> None:
        assert self.proc.stderr is not None
        for line in self.proc.stderr:
            self.said.append(line.rstrip())

    def _wait_for(self, prefix: str, timeout: float) -> None:
        end = time.monotonic() + timeout
        while not any(x.startswith(prefix) for x in self.said):
            assert self.proc.poll() is None, f"link-proxy exited: {self.said}"
            assert time.monotonic() < end, f"link-proxy did not say {prefix!r}: {self.said}"
            time.sleep(0.01)

    def cut(self) -> None:
        self.proc.send_signal(signal.SIGUSR1)
        self._wait_for("windseek link-proxy: cut", 5.0)

    def restore(self) -> None:
        self.proc.send_signal(signal.SIGUSR2)
        self._wait_for("windseek link-proxy: restored", 5.0)

    def close(self) -> dict[str, Any]:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
            out, _ = self.proc.communicate(timeout=15)
            self.report = json.loads(out)
        return self.report


class Rig:
    """The SITL subprocess (at ``speed``), the proxy in front of the runner's port, the listener."""

    def __init__(self, faults: Faults, speed: float, seed: int = 1, tlog: Path | None = None,
                 thread: bool = False) -> None:  # fmt: skip
        self.speed = speed
        self.mport = free_port()
        self.listener = Listener()
        self.listener.start()
        self.thread: LinkProxy | None = None  # the proxy in this process (frame units, faults changed live), or:
        if thread:
            self.thread = LinkProxy("udpin:127.0.0.1:0", f"udpout:127.0.0.1:{self.mport}", faults, seed=seed,
                                    frames=True).start()  # fmt: skip
        self.proxy = ProxyProcess(faults, seed, free_port(), self.mport) if not thread else None
        a_port = self.thread.a.port if self.thread is not None else self.pxp.a_port
        self.port = free_port()
        cmd = [sys.executable, "-m", "windseek.cli", "sitl", SCENARIO, "--speed", str(speed), "--true-wind-hz", "0",
               "--udp-bind", f"127.0.0.1:{self.port}", "--udp", f"127.0.0.1:{a_port}",
               f"127.0.0.1:{self.listener.port}"]  # fmt: skip
        if tlog is not None:
            cmd += ["--tlog", str(tlog)]
        self.proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT)
        assert self.proc.stdout is not None
        line = self.proc.stdout.readline()
        assert line.startswith("windseek sitl:"), f"SITL did not start: {line!r}"
        self.lines: list[str] = []
        self.t_cut = self.t_back = math.nan  # vehicle times of a cut and of the restore

    @property
    def pxp(self) -> ProxyProcess:
        assert self.proxy is not None
        return self.proxy

    def config(self, **kw: Any) -> MissionConfig:
        return MissionConfig(connect=f"udpin://127.0.0.1:{self.mport}", strategy="surge-cast", speed_hint=self.speed,
                             say=self.lines.append, seed=1, **kw)  # fmt: skip

    def close_sitl(self) -> None:
        """Stop the SITL (it closes its links and its tlog)."""
        if self.proc.poll() is not None:
            return
        self.proc.terminate()
        try:
            _, self.err = self.proc.communicate(timeout=15)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            _, self.err = self.proc.communicate(timeout=5)

    def close(self) -> None:
        self.close_sitl()
        err = getattr(self, "err", "")
        try:
            rep = self.proxy.close() if self.proxy is not None else {}
            if self.thread is not None:
                rep = self.thread.report()
                self.thread.stop()
        finally:
            if self.proxy is not None and self.proxy.proc.poll() is None:
                self.proxy.proc.kill()
            self.listener.stop.set()
            self.listener.join(2)
            self.listener.sock.close()
        print("\n".join(self.lines))  # shown when a test fails
        print(rep, self.proxy.said[-5:] if self.proxy is not None else "")
        print(err[-1500:])


def make_rigs() -> Iterator[Callable[..., Rig]]:
    """The body of a ``rigs`` fixture: a factory of rigs, all closed at the end."""
    made: list[Rig] = []

    def make(*a: Any, **kw: Any) -> Rig:
        made.append(Rig(*a, **kw))
        return made[-1]

    yield make
    for r in made:
        r.close()


def true_source() -> np.ndarray:
    plume = load_scenario(SCENARIO).plume
    assert plume is not None
    return np.asarray(plume.plume.sources[0].position_ned, dtype=float)


def assert_found_and_landed(res: MissionResult) -> None:
    assert res.cause == "declared" and res.declared_ned is not None, res.reasons
    err = float(np.hypot(*(np.asarray(res.declared_ned[0:2]) - true_source()[0:2])))
    assert err <= SUCCESS_RADIUS_M, f"declared {res.declared_ned}: {err:.1f} m from the source"
    assert res.landed and res.disarmed and not res.link_lost


def assert_faulted_both_ways(rep: dict[str, Any], key: str, lo: float, hi: float) -> None:
    for d in ("a->b", "b->a"):
        c = rep[d]
        frac = c[key] / max(c["rx_units"], 1)
        assert c["rx_units"] > 100 and lo < frac < hi, (d, c)
