"""End-to-end through the link proxy: ``windseek sitl`` <-> :class:`~wire.proxy.LinkProxy` <-> the MAVSDK runner.

The SITL streams to the proxy's ``a`` end (and to a listener that never sends, so it never keeps the
data link alive); the proxy forwards to the runner's ``udpin`` port with seeded faults.

1. (Mission uploads through the proxy: ``tests/test_link_proxy_mission.py``.)
2. A full search (``surge-cast``, live UKF wind, ``open-field-low``) at 30 % loss each way, and with
   duplicates and reordering: arm, take-off, search, declaration within 5 m, landing, disarm.
3. Cuts during the search, measured in vehicle seconds by the listener (the failsafes count vehicle
   time): 5 s (the vehicle holds on the offboard loss; the runner waits for a fresh heartbeat and lands
   it), 15 s (the data-link failsafe lands the vehicle; the runner reports it landed and disarmed and
   sends it nothing), permanent (the runner gives up after its grace time; the vehicle lands by itself).

The SITL runs faster than real time (``--speed``). MAVSDK's heartbeats, which keep the autopilot's
data link alive, are paced by the wall clock (1 Hz), so at speed K the data-link timeout
(``COM_DL_LOSS_T``, 10 s of vehicle time) would see only 10 / K of them. Under loss the tests that
are not about the data-link failsafe set it to 10 K s, the same 10 heartbeats as in a real flight.
"""

from __future__ import annotations

import asyncio
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
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from link_support import free_port
from pymavlink import mavutil

from mission.runners.inprocess import SUCCESS_RADIUS_M
from mission.runners.mavsdk_runner import MissionConfig, MissionResult, run_mission
from mission.safety import SafetyLimits
from sitl.scenario import load_scenario
from wire.dialect import mavlink as mav
from wire.proxy import Faults, LinkProxy
from wire.proxy.framing import split_datagram
from wire.px4_modes import name as px4_mode_name

pytestmark = pytest.mark.e2e
pytest.importorskip("mavsdk")

ROOT = Path(__file__).resolve().parents[1]
SCENARIO = "open-field-low"
LOSS = Faults(loss=0.3)
DUP_REORDER = Faults(duplicate=0.2, reorder=0.2, latency_s=0.005, jitter_s=0.005)


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
            self.params[m.param_id] = m.param_value

    def set_param(self, sitl_port: int, name: str, value: float) -> None:
        """PARAM_SET straight to the SITL (not a HEARTBEAT: the listener still does not count as a link)."""
        enc = mav.MAVLink(None, 250, 1)
        frame = enc.param_set_encode(1, 1, name.encode(), value, mav.MAV_PARAM_TYPE_REAL32).pack(enc)
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
        a_port = self.thread.a.port if self.thread is not None else self.proxy.a_port
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


@pytest.fixture
def rigs() -> Iterator[Callable[..., Rig]]:
    made: list[Rig] = []

    def make(*a: Any, **kw: Any) -> Rig:
        made.append(Rig(*a, **kw))
        return made[-1]

    yield make
    for r in made:
        r.close()


def true_source() -> np.ndarray:
    return np.asarray(load_scenario(SCENARIO).plume.plume.sources[0].position_ned, dtype=float)


def assert_found_and_landed(res: MissionResult) -> None:
    assert res.cause == "declared", res.reasons
    err = float(np.hypot(*(np.asarray(res.declared_ned[0:2]) - true_source()[0:2])))
    assert err <= SUCCESS_RADIUS_M, f"declared {res.declared_ned}: {err:.1f} m from the source"
    assert res.landed and res.disarmed and not res.link_lost


def assert_faulted_both_ways(rep: dict[str, Any], key: str, lo: float, hi: float) -> None:
    for d in ("a->b", "b->a"):
        c = rep[d]
        frac = c[key] / max(c["rx_units"], 1)
        assert c["rx_units"] > 100 and lo < frac < hi, (d, c)


# ---------------------------------------------------------------------- searches on a bad link
LOSS_SPEED = 2.0  # the offboard-loss timeout (1 s of vehicle time) is 0.5 s of wall time: room for hiccups


@pytest.mark.asyncio
async def test_search_completes_at_30_percent_loss_each_way(rigs: Callable[..., Rig]) -> None:
    rig = rigs(LOSS, LOSS_SPEED, seed=2)
    rig.listener.set_param(rig.port, "COM_DL_LOSS_T", 10.0 * LOSS_SPEED)  # 10 MAVSDK heartbeats (see above)
    res = await asyncio.wait_for(run_mission(rig.config()), 200.0)
    print(res.to_dict())
    assert_found_and_landed(res)
    rig.close_sitl()
    assert_faulted_both_ways(rig.pxp.close(), "dropped_loss", 0.25, 0.35)
    lis = rig.listener
    lis.wait(lambda: not lis.armed, 5.0, "the listener sees the disarm")
    assert lis.pos[2] > -0.2 and not any("Data link lost" in t for _, t in lis.texts)
    assert [m for _, m, _ in lis.modes].count("OFFBOARD") == 1  # never dropped out of the search


@pytest.mark.asyncio
async def test_search_completes_with_duplicates_and_reordering(rigs: Callable[..., Rig]) -> None:
    rig = rigs(DUP_REORDER, 3.0, seed=3)
    res = await asyncio.wait_for(run_mission(rig.config()), 200.0)
    print(res.to_dict())
    assert_found_and_landed(res)
    rig.close_sitl()
    rep = rig.pxp.close()
    assert_faulted_both_ways(rep, "duplicated", 0.15, 0.25)
    assert_faulted_both_ways(rep, "reordered", 0.1, 0.25)
    lis = rig.listener
    lis.wait(lambda: not lis.armed, 5.0, "the listener sees the disarm")
    assert [m for _, m, _ in lis.modes].count("OFFBOARD") == 1


# ---------------------------------------------------------------------- cuts
#: Slower than the searches: the offboard-loss timeout (1 s of vehicle time) must stay well above the
#: runner's scheduling hiccups on a loaded machine, or the vehicle holds before the cut.
CUT_SPEED = 2.0
CUT_LIMITS = replace(SafetyLimits(), link_timeout_s=1.5)  # wall seconds without telemetry = a loss
#: What the runner may say to the autopilot: mode changes, arming, take-off, landing, setpoints.
COMMANDS = {176, 400, 22, 21, 20, 17}  # DO_SET_MODE, ARM_DISARM, NAV_TAKEOFF, NAV_LAND, NAV_RTL, NAV_LOITER_UNLIM


async def search_then_cut(rig: Rig, restore: Callable[[], bool] | None, **kw: Any) -> tuple[asyncio.Task[MissionResult],
                                                                                          float]:  # fmt: skip
    """Start the mission and cut the link 3 s (vehicle time) into the offboard search, until ``restore()``
    (None: for good) and the runner has said the link is lost (a shorter gap is no loss for it). Returns
    the mission task and the wall time of the restore (``time.time()``, the tlog's clock)."""
    lis = rig.listener
    task = asyncio.create_task(run_mission(rig.config(limits=CUT_LIMITS, **kw)))

    def searching() -> bool:
        return task.done() or (lis.mode == "OFFBOARD" and lis.modes[-1][0] + 3.0 < lis.t)

    await asyncio.to_thread(lis.wait, searching, 90.0, "3 s of offboard search")
    assert not task.done(), f"the mission ended before the cut: {task.result().reasons}"
    rig.t_cut = lis.t
    rig.pxp.cut()
    if restore is None:
        return task, math.inf

    def over() -> bool:
        return restore() and any(x.startswith("mission: ABORT (link-lost)") for x in rig.lines)

    await asyncio.to_thread(lis.wait, over, 60.0, "the end of the cut and the runner noticing")
    rig.t_back = lis.t
    rig.pxp.restore()
    return task, time.time()


def commands_after(tlog: Path, wall_t: float) -> list[str]:
    """Mode, arming, take-off and landing commands and offboard setpoints the SITL received after ``wall_t``."""
    log = mavutil.mavlink_connection(str(tlog), dialect="common")
    out = []
    while (m := log.recv_match(type=["COMMAND_LONG", "COMMAND_INT", "SET_MODE", "SET_POSITION_TARGET_LOCAL_NED"])):
        if m.get_srcSystem() != 1 and m._timestamp > wall_t and (m.get_type().startswith("SET_") or
                                                                  m.command in COMMANDS):  # fmt: skip
            out.append(f"{m.get_type()} {getattr(m, 'command', '')} at {m._timestamp - wall_t:+.2f} s")
    log.close()
    return out


@pytest.mark.asyncio
async def test_5_s_cut_vehicle_holds_runner_lands_it_after_a_fresh_heartbeat(rigs: Callable[..., Rig]) -> None:
    rig = rigs(Faults(), CUT_SPEED)
    task, _ = await search_then_cut(rig, lambda: rig.listener.t >= rig.t_cut + 5.0)
    res = await asyncio.wait_for(task, 60.0)
    lis = rig.listener
    lis.wait(lambda: not lis.armed, 10.0, "the disarm")
    print(res.to_dict(), lis.modes, lis.texts)
    during = [(t, m) for t, m, _ in lis.after(rig.t_cut) if t < rig.t_back]
    after = [(t, m) for t, m, _ in lis.after(rig.t_back)]
    # The vehicle: OFFBOARD -> hold on the offboard loss, and nothing else while cut (no data-link landing).
    assert [m for _, m in during] == ["AUTO.LOITER"] and during[0][0] - rig.t_cut < 2.0, during
    assert not any("Data link lost" in x for _, x in lis.texts) and rig.t_back - rig.t_cut < 10.0
    # The runner: saw the loss, waited for a fresh heartbeat, saw it holding, landed it.
    assert res.cause == "link-lost" and res.link_lost and res.landed and res.disarmed
    assert res.reasons[0].startswith("ABORT (link-lost): no telemetry for"), res.reasons
    assert "LINK: telemetry is back (mode AUTO.LOITER, armed)" in res.reasons, res.reasons
    assert [m for _, m in after][:1] == ["AUTO.LAND"] and after[0][0] > rig.t_back
    assert lis.pos[2] > -0.2


@pytest.mark.asyncio
@pytest.mark.parametrize("until", ["15 s and disarmed", "landing"])
async def test_15_s_cut_failsafe_lands_runner_reports_it_and_sends_nothing(rigs: Callable[..., Rig], tmp_path: Path,
                                                                          until: str) -> None:  # fmt: skip
    """The data-link failsafe fires 8-10 s (vehicle) into the cut, as the last MAVSDK heartbeat was up to 2 s
    before it, and the landing from 3 m and the disarm take about 6 s more: at 15 s the vehicle may still be
    descending. ``15 s and disarmed`` restores the link at 15 s or at the disarm, whichever comes later;
    ``landing`` restores it in the middle of the failsafe landing. Either way the runner reports the
    vehicle as it is and sends it nothing (no hold, no land, no setpoint)."""
    tlog = tmp_path / "cut.tlog"
    rig = rigs(Faults(), CUT_SPEED, tlog=tlog)
    lis = rig.listener
    if until == "landing":
        def restore() -> bool:
            return lis.mode == "AUTO.LAND" and lis.pos[2] < -1.0 and lis.t > lis.modes[-1][0] + 0.5
    else:
        def restore() -> bool:
            return lis.t >= rig.t_cut + 15.0 and not lis.armed
    task, wall_back = await search_then_cut(rig, restore)
    res = await asyncio.wait_for(task, 60.0)
    lis.wait(lambda: not lis.armed, 15.0, "the disarm")
    print(res.to_dict(), lis.modes, lis.texts, rig.t_back - rig.t_cut)
    during = [m for t, m, _ in lis.after(rig.t_cut) if t < rig.t_back]
    # The vehicle: hold (offboard loss), then its data-link failsafe landed it, all while cut.
    assert during[:2] == ["AUTO.LOITER", "AUTO.LAND"], lis.modes
    assert any(x.startswith("Data link lost: landing") for _, x in lis.texts)
    # The runner reports what it found when the link came back, as it was, and how it ended.
    assert res.cause == "link-lost" and res.link_lost and res.landed and res.disarmed, res.to_dict()
    if until == "landing":
        assert "LINK: telemetry is back (mode AUTO.LAND, armed)" in res.reasons, res.reasons
        assert rig.lines.index("mission: landed and disarmed") > rig.lines.index(
            "mission: LINK: telemetry is back (mode AUTO.LAND, armed)"), rig.lines  # it waited for the disarm
    else:
        assert [r for r in res.reasons if r.startswith("LINK:")][-2:] == [
            f"LINK: telemetry is back (mode {lis.mode}, disarmed)",
            "LINK: the vehicle already landed and disarmed (autopilot failsafe)"], res.reasons  # fmt: skip
    rig.close_sitl()
    # ... and sent the vehicle nothing once the link was back.
    assert commands_after(tlog, wall_back) == []


@pytest.mark.asyncio
async def test_permanent_cut_runner_gives_up_vehicle_lands_by_itself(rigs: Callable[..., Rig]) -> None:
    rig = rigs(Faults(), CUT_SPEED)
    task, _ = await search_then_cut(rig, None, link_grace_s=3.0)
    res = await asyncio.wait_for(task, 60.0)
    lis = rig.listener
    await asyncio.to_thread(lis.wait, lambda: not lis.armed, 60.0, "the failsafe landing and disarm")
    print(res.to_dict(), lis.modes, lis.texts)
    # The runner: gave up, and says the vehicle's state at the end is unknown (the last it saw is in the
    # reasons), not the stale "in the air, armed" of before the cut.
    assert res.cause == "link-lost" and res.link_lost
    assert res.landed is None and res.disarmed is None, res.to_dict()
    assert res.reasons[0].startswith("ABORT (link-lost): no telemetry for"), res.reasons
    assert res.reasons[-1].startswith("LINK: still down after 3 s: the autopilot's failsafe is in charge "
                                      "(last seen: mode OFFBOARD, armed, "), res.reasons
    assert [m for _, m, _ in lis.after(rig.t_cut)][:2] == ["AUTO.LOITER", "AUTO.LAND"]
    assert lis.pos[2] > -0.2 and not lis.armed
    rig.close_sitl()
    rep = rig.pxp.close()
    assert rep["cut_now"] and rep["cuts"][0]["end_s"] is None and rep["b->a"]["tx_units"] > 0


@pytest.mark.asyncio
async def test_a_late_offboard_heartbeat_is_not_leaving_offboard(rigs: Callable[..., Rig]) -> None:
    """Every HEARTBEAT from the vehicle is lost for 3 s (vehicle) from the switch to offboard on, while the
    rest of the telemetry flows: the switch is acknowledged, the vehicle flies offboard, but the runner
    has seen no heartbeat that says so. It must not take the mode of the last heartbeat it saw
    (AUTO.LOITER, from before the switch) for the vehicle leaving offboard. Found at 30 % loss each way:
    "ABORT (offboard-lost): the vehicle left offboard on its own (mode AUTO.LOITER)" 1.5 s after a switch
    whose heartbeats were lost, with the vehicle in offboard all along."""
    speed = 2.0
    rig = rigs(Faults(), speed, thread=True)
    px = rig.thread
    assert px is not None

    def say(line: str) -> None:
        rig.lines.append(line)
        if "starting the search" in line:  # the next thing the runner does is the switch to offboard
            px.set_faults("a->b", Faults(drop_ids=frozenset({mav.MAVLINK_MSG_ID_HEARTBEAT})))
            threading.Timer(3.0 / speed, px.set_faults, ("a->b", Faults())).start()

    cfg = replace(rig.config(limits=replace(SafetyLimits(), time_limit_s=15.0)), say=say)
    res = await asyncio.wait_for(run_mission(cfg), 90.0)
    print(res.to_dict(), rig.listener.modes)
    assert px.report()["a->b"]["dropped_filter"] >= 2  # the switch's heartbeat and a periodic one at least
    assert res.cause == "time-limit", res.reasons  # it searched until its time limit, then landed
    assert [m for _, m, _ in rig.listener.modes].count("OFFBOARD") == 1 and res.landed and res.disarmed
