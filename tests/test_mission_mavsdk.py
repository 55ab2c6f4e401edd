"""End-to-end: the MAVSDK mission runner against the real ``windseek sitl`` (a subprocess) over UDP.

1. The runner finds the source of ``open-field-low`` (surge-cast, the live UKF on the telemetry),
   lands at the declared source and disarms; the declaration is scored against the scenario's
   true source, which only this test knows.
2. The link is cut mid-search (a UDP relay between the SITL and MAVSDK stops forwarding): the
   runner says why and gives up after its grace time; the vehicle, watched on a second UDP link
   by a listener that sends nothing, holds (offboard loss) and then lands (data-link loss,
   NAV_DLL_ACT) and disarms on the ground near where the link was cut.
3. Infotaxis, the posterior strategy, runs the same way and declares its credible region.
"""

from __future__ import annotations

import asyncio
import json
import math
import select
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from link_support import free_port

from mission.runners.inprocess import SUCCESS_RADIUS_M
from mission.runners.mavsdk_runner import MissionConfig, run_mission
from mission.safety import SafetyLimits
from sitl.scenario import load_scenario
from wire.dialect import mavlink as mav
from wire.names import STATE_PREFIX
from wire.px4_modes import name as px4_mode_name

pytestmark = pytest.mark.e2e

pytest.importorskip("mavsdk")

ROOT = Path(__file__).resolve().parents[1]
SCENARIO = "open-field-low"
SPEED = 5.0


class Sitl:
    """``windseek sitl`` in a subprocess, streaming to the given UDP peers."""

    def __init__(self, peers: list[int], speed: float = SPEED, *extra: str) -> None:
        self.port = free_port()
        cmd = [sys.executable, "-m", "windseek.cli", "sitl", SCENARIO, "--speed", str(speed), "--true-wind-hz", "0",
               "--udp-bind", f"127.0.0.1:{self.port}", *extra]  # fmt: skip
        for p in peers:
            cmd += ["--udp", f"127.0.0.1:{p}"]
        self.proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT)
        line = self.proc.stdout.readline()  # printed once the link is built, just before it serves
        assert line.startswith("windseek sitl:"), f"SITL did not start: {line!r} {self.proc.stderr.read()}"

    def close(self) -> None:
        self.proc.terminate()
        try:
            _, err = self.proc.communicate(timeout=10)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            _, err = self.proc.communicate(timeout=5)
        print(err[-2000:])  # shown when a test fails: the SITL's own account (lag, counters)


class Observer(threading.Thread):
    """Listens (never sends: it must not keep the SITL's data link alive) and records the state."""

    def __init__(self) -> None:
        super().__init__(daemon=True)
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.port = self.sock.getsockname()[1]
        self.parser = mav.MAVLink(None, 250, 1)
        self.parser.robust_parsing = True
        self.t = 0.0  # vehicle time, s
        self.mode = ""
        self.armed = False
        self.pos = np.zeros(3)
        self.modes: list[tuple[float, str, bool]] = []  # (t, mode, armed) at every change
        self.track: list[tuple[float, np.ndarray]] = []
        self.texts: list[tuple[float, str]] = []
        self.mission_texts: list[str] = []
        self.params: dict[str, float] = {}
        self.stop = threading.Event()

    def run(self) -> None:
        while not self.stop.is_set():
            r, _, _ = select.select([self.sock], [], [], 0.1)
            if not r:
                continue
            data = self.sock.recv(65536)
            for m in self.parser.parse_buffer(data) or []:
                mtype = m.get_type()
                if mtype == "LOCAL_POSITION_NED":
                    self.t = m.time_boot_ms * 1e-3
                    self.pos = np.array([m.x, m.y, m.z])
                    self.track.append((self.t, self.pos))
                elif mtype == "HEARTBEAT" and (m.get_srcSystem(), m.get_srcComponent()) == (1, 1):
                    mode, armed = px4_mode_name(m.custom_mode), bool(m.base_mode & 128)
                    if (mode, armed) != (self.mode, self.armed):
                        self.modes.append((self.t, mode, armed))
                    self.mode, self.armed = mode, armed
                elif mtype == "PARAM_VALUE":
                    self.params[m.param_id] = m.param_value  # REAL32 only here (see set_param)
                elif mtype == "STATUSTEXT":
                    self.texts.append((self.t, m.text))
                    if m.get_srcSystem() != 1:  # forwarded (sitl --forward): the mission's own texts
                        self.mission_texts.append(m.text)

    def set_param(self, sitl_port: int, name: str, value: float) -> None:
        """PARAM_SET (REAL32) straight to the SITL until its PARAM_VALUE echoes it; no HEARTBEAT is sent,
        so the observer still does not count as a data link."""
        enc = mav.MAVLink(None, 250, 1)
        frame = enc.param_set_encode(1, 1, name.encode(), value, mav.MAV_PARAM_TYPE_REAL32).pack(enc)
        end = time.monotonic() + 30.0  # a just-started SITL on a loaded machine: >10 s seen with 2 busy loops
        while self.params.get(name) != pytest.approx(value):
            assert time.monotonic() < end, f"the SITL did not take {name} = {value}"
            self.sock.sendto(frame, ("127.0.0.1", sitl_port))
            time.sleep(0.2)

    def wait(self, pred, timeout: float, what: str) -> None:
        end = time.monotonic() + timeout
        while not pred():
            assert time.monotonic() < end, f"timed out after {timeout} s waiting for {what}"
            time.sleep(0.02)


class Relay(threading.Thread):
    """UDP relay SITL <-> MAVSDK; ``cut`` drops everything from then on, both ways."""

    def __init__(self, client_port: int) -> None:
        super().__init__(daemon=True)
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.port = self.sock.getsockname()[1]
        self.client = ("127.0.0.1", client_port)
        self.sitl: tuple[str, int] | None = None
        self.cut = threading.Event()
        self.stop = threading.Event()

    def run(self) -> None:
        while not self.stop.is_set():
            r, _, _ = select.select([self.sock], [], [], 0.1)
            if not r:
                continue
            data, addr = self.sock.recvfrom(65536)
            if self.cut.is_set():
                continue
            if addr == self.client:
                if self.sitl is not None:
                    self.sock.sendto(data, self.sitl)
            else:
                self.sitl = addr
                self.sock.sendto(data, self.client)


@pytest.fixture
def observer() -> Iterator[Observer]:
    obs = Observer()
    obs.start()
    yield obs
    obs.stop.set()
    obs.join(2)
    obs.sock.close()


def _config(port: int, lines: list[str], **kw: object) -> MissionConfig:
    return MissionConfig(connect=f"udpin://127.0.0.1:{port}", strategy="surge-cast", speed_hint=SPEED,
                         say=lines.append, seed=1, **kw)  # fmt: skip


@pytest.mark.asyncio
async def test_mavsdk_mission_finds_the_source_and_lands_on_it(observer: Observer, tmp_path: Path) -> None:
    port = free_port()
    summary = tmp_path / "sitl-summary.json"
    sitl = Sitl([port, observer.port], SPEED, "--forward", "--exit-summary", str(summary))
    # PX4's offboard-loss timeout (1 s) is vehicle time: at speed 5 only 0.2 s of wall clock, shorter
    # than a scheduling hiccup on a loaded 2-core machine. Scale it to 1 s of wall clock, as on a real
    # vehicle in real time (the runner's own rate under load: benchmarks/runner_under_load.py).
    observer.set_param(sitl.port, "COM_OF_LOSS_T", 1.0 * SPEED)
    lines: list[str] = []
    wall0 = time.monotonic()
    try:
        res = await asyncio.wait_for(run_mission(_config(port, lines)), 80.0)
    finally:
        sitl.close()
    wall = time.monotonic() - wall0
    print("\n".join(lines))
    print(res.to_dict())
    src = np.asarray(load_scenario(SCENARIO).plume.plume.sources[0].position_ned, dtype=float)  # the truth
    assert res.cause == "declared", res.reasons
    assert res.reasons == []  # no safety stop, no clamped altitude
    err = float(np.hypot(*(np.asarray(res.declared_ned[0:2]) - src[0:2])))
    assert err <= SUCCESS_RADIUS_M, f"declared {res.declared_ned}, true source {src}: {err:.1f} m off"
    # Landed at the declared source and disarmed (seen by the runner and by the independent listener).
    assert res.disarmed and res.landed
    assert float(np.hypot(*(np.asarray(res.final_ned[0:2]) - np.asarray(res.declared_ned[0:2])))) < 1.0
    # The sweep that declared is the last verification, found nothing, tested the declared point.
    last = res.verifications[-1]
    assert last["outcome"] == "verified" and last["candidate_ne"] == pytest.approx(res.declared_ned[0:2], abs=1e-3)
    assert last["t_start_s"] > 0.0 and last["t_start_s"] + last["duration_s"] == pytest.approx(res.time_s, abs=0.01)
    observer.wait(lambda: not observer.armed and observer.t > 0, 5.0, "listener sees the disarm")
    assert observer.pos[2] > -0.2, "not on the ground"
    assert [m for _, m, _ in observer.modes].count("OFFBOARD") == 1
    assert "AUTO.LAND" in [m for _, m, _ in observer.modes]
    # Strategy ticks at its 10 Hz of vehicle time, each sent as an offboard setpoint (MAVSDK also
    # repeats the last one at 20 Hz wall).
    assert res.tick_rate_hz >= 8.0 and res.setpoint_rate_hz >= 8.0, (res.tick_rate_hz, res.ticks_skipped)
    assert 0.0 < res.time_s < res.mission_time_s <= 300.0
    assert res.path_m >= 0.9 * math.hypot(*src[0:2])
    # The live UKF ran on every IMU sample from lift-off (it is paused on the ground) to the
    # touchdown, and saw the wind from the north (air-mass velocity south).
    acc = res.estimator["accepted"]
    span = res.estimator["span_s"]
    assert res.mission_time_s - 15.0 < span < res.mission_time_s
    # Every IMU sample (250 Hz) was accepted, or decimated / dropped and counted when the filter fell
    # behind (a loaded machine): nothing is lost silently, and the filter never blocks the loop.
    handled = acc["imu"] + res.estimator.get("imu_decimated", 0) + res.estimator.get("dropped", 0)
    assert res.estimator["imu_message"] == "HIL_SENSOR" and handled > 150 * span, res.estimator
    bad = {k: v for k, v in res.estimator["rejected"].items() if not k.endswith("not_ready")}
    assert sum(bad.values()) < 0.01 * acc["imu"], bad
    assert wall < 85.0
    # The runner published its strategy states (STATUSTEXT "state: ...", forwarded to the listener) and
    # the declaration (NAMED_VALUE_FLOAT SRC_N/E/D/CONF, scored by the SITL's exit summary).
    states = [x for x in observer.mission_texts if x.startswith(STATE_PREFIX)]
    assert states and states[-1] == STATE_PREFIX + res.state, (states, res.state)
    assert all(a != b for a, b in zip(states, states[1:], strict=False)), states  # on change only
    truth = json.loads(summary.read_text())
    assert truth["statustexts_received"] >= len(states)
    assert truth["declared"] is not None, truth
    assert truth["declared"]["declared_ned"] == pytest.approx(res.declared_ned, abs=1e-3)
    assert truth["declared"]["confidence"] == pytest.approx(res.confidence, abs=1e-3)
    assert truth["declared_error_horizontal_m"] == pytest.approx(err, abs=0.01)


@pytest.mark.asyncio
async def test_infotaxis_through_mavsdk_declares_a_credible_region_and_lands(observer: Observer,
                                                                           tmp_path: Path) -> None:
    """The same Infotaxis object the batch evaluation runs in-process, here at the SITL's real-time
    pace (speed 5) behind MAVSDK and the live UKF: its move choice (3 ms of CPU a bin) keeps the
    10 Hz loop, it declares within its 3 m success radius with the credible region and confidence
    it states, and the SITL's own scoring sees the same declaration. Both sides record it (``windseek
    sitl --rrd``, the mission's ``MissionRecorder`` as ``windseek mission --rrd``), merged as ``windseek
    demo`` merges them: the SITL's recording then shows the posterior, see :func:`_check_posterior_rrd`."""
    from mission.strategies import params_from_table
    from recording.mission_rrd import MissionRecorder

    port = free_port()
    summary, sitl_rrd, mission_rrd = tmp_path / "sitl-summary.json", tmp_path / "sitl.rrd", tmp_path / "mission.rrd"
    sitl = Sitl([port, observer.port], SPEED, "--forward", "--exit-summary", str(summary), "--rrd", str(sitl_rrd))
    observer.set_param(sitl.port, "COM_OF_LOSS_T", 1.0 * SPEED)  # 1 s of wall clock, as in the search above
    lines: list[str] = []
    recorder = MissionRecorder(mission_rrd, strategy="infotaxis", seed=1)
    res = None
    try:
        cfg = replace(_config(port, lines), strategy="infotaxis", observe=recorder.attach)
        res = await asyncio.wait_for(run_mission(cfg), 80.0)
    finally:
        recorder.close(res)
        sitl.close()
    print("\n".join(lines))
    p = params_from_table("infotaxis", None)
    src = np.asarray(load_scenario(SCENARIO).plume.plume.sources[0].position_ned, dtype=float)
    assert res.cause == "declared" and res.reasons == [], (res.cause, res.reasons)
    err = float(np.hypot(*(np.asarray(res.declared_ned[0:2]) - src[0:2])))
    # One real-time run (not lockstep: not reproducible) of a strategy that states >= 0.9 probability of being
    # within its 3 m success radius: by its own statement up to one run in ten may land beyond it (the
    # evaluation, 50 seeds in-process: 98 % of declarations within 3 m; one CI run declared 4.7 m off). The
    # test holds it to twice the radius, which a declaration in the wrong place (the start, a far lobe of the
    # posterior) fails; the rate within 3 m is the benchmarks' to measure.
    assert err <= 2.0 * p.success_radius_m, f"declared {res.declared_ned}, true source {src}: {err:.1f} m off"
    assert 0.0 < res.credible_radius_m <= p.declare_radius_m and res.confidence >= p.declare_confidence
    assert res.disarmed and res.landed
    assert float(np.hypot(*(np.asarray(res.final_ned[0:2]) - np.asarray(res.declared_ned[0:2])))) < 1.0
    assert res.tick_rate_hz >= 8.0, (res.tick_rate_hz, res.ticks_skipped)
    truth = json.loads(summary.read_text())
    assert truth["declared"]["confidence"] == pytest.approx(res.confidence, abs=1e-3)
    assert truth["declared_error_horizontal_m"] == pytest.approx(err, abs=0.01)
    cost_ms = 1e3 * recorder.posterior_cpu_s / max(recorder.posteriors, 1)
    print(f"mission recording: {recorder.posteriors} posteriors, {cost_ms:.2f} ms CPU each; "
          f"{mission_rrd.stat().st_size / 1e6:.2f} MB")  # fmt: skip
    _check_posterior_rrd(sitl_rrd, mission_rrd, src, res.declared_ned)


def _check_posterior_rrd(sitl_rrd: Path, mission_rrd: Path, src: np.ndarray, declared: list[float]) -> None:
    """Merged into the SITL's recording (as ``windseek demo`` does), the mission's posterior and credible
    circle lie on the SITL's timeline within the flight (several of them), the posterior's last peak is
    near the true source, the last circle is about the declared source; the SITL's own entities stay."""
    from recording.finalize import merge_mission
    from recording.read import RrdLog

    before = RrdLog(sitl_rrd)
    assert "map/posterior/image" not in before.entity_paths()  # the SITL alone has no posterior
    s = before.summary()
    assert s is not None and s.t_arm_s is not None and s.t_disarm_s is not None, s
    merge_mission(sitl_rrd, mission_rrd)
    log = RrdLog(sitl_rrd)
    paths = set(log.entity_paths())
    assert {"map/posterior/image", "map/posterior/credible", "map/setpoint", "world/vehicle", "summary"} <= paths
    t_img, imgs = log.images("map/posterior/image")
    inside = (t_img >= s.t_arm_s) & (t_img <= s.t_disarm_s)
    assert inside.sum() >= 5 and inside.all(), (t_img, s.t_arm_s, s.t_disarm_s)
    t_veh, _ = log.vectors("world/vehicle", "Transform3D:translation")  # the SITL's truth, its clock
    assert t_veh[0] < t_img[0] and t_img[-1] < t_veh[-1]
    _, tr = log.vectors("map/posterior/image", "Transform3D:translation")
    _, sc = log.vectors("map/posterior/image", "Transform3D:scale")
    img = imgs[-1]
    row, col = np.unravel_index(np.argmax(img[..., 3]), img.shape[:2])
    east, north = tr[-1][0] + (col + 0.5) * sc[-1][0], -(tr[-1][1] + (row + 0.5) * sc[-1][1])
    assert np.hypot(north - src[0], east - src[1]) <= 4.0, ((north, east), src)
    t_c, strips = log.column("map/posterior/credible", "LineStrips2D:strips")
    assert len(t_c) >= 5 and ((t_c >= s.t_arm_s) & (t_c <= s.t_disarm_s)).all()
    ring = np.array(strips[-1][0])
    assert np.hypot(ring[:, 0].mean() - declared[1], -ring[:, 1].mean() - declared[0]) <= 0.5


@pytest.mark.asyncio
async def test_mavsdk_mission_link_cut_vehicle_holds_then_lands(observer: Observer) -> None:
    mport = free_port()
    relay = Relay(mport)
    relay.start()
    # Slower than the search test: COM_OF_LOSS_T (1 s of vehicle time) must stay well above the
    # runner's scheduling hiccups on a loaded machine, or the vehicle holds before the cut.
    sitl = Sitl([relay.port, observer.port], speed=3.0)
    lines: list[str] = []
    limits = replace(SafetyLimits(), link_timeout_s=1.5)
    try:
        task = asyncio.create_task(run_mission(_config(mport, lines, limits=limits, link_grace_s=2.0)))

        def searching() -> bool:
            return observer.mode == "OFFBOARD" and observer.modes[-1][0] + 5.0 < observer.t

        await asyncio.to_thread(observer.wait, searching, 40.0, "5 s of offboard search")
        assert not task.done()
        t_cut, p_cut = observer.t, observer.pos.copy()
        relay.cut.set()
        res = await asyncio.wait_for(task, 15.0)
        await asyncio.to_thread(observer.wait, lambda: not observer.armed, 30.0, "landing and disarm after the cut")
    finally:
        sitl.close()
        relay.stop.set()
    print("\n".join(lines))
    print(observer.modes, observer.texts)
    # The runner noticed, said why, and left the vehicle to its failsafe.
    assert res.cause == "link-lost"
    assert any(r.startswith("ABORT (link-lost): no telemetry for") for r in res.reasons), res.reasons
    assert any("still down" in r for r in res.reasons), res.reasons
    # The vehicle: OFFBOARD -> hold (offboard setpoints stopped) -> land (data link lost) -> disarmed.
    after = [(t, m, a) for t, m, a in observer.modes if t >= t_cut]
    names = [m for _, m, _ in after]
    assert names[:2] == ["AUTO.LOITER", "AUTO.LAND"], after
    t_hold, t_land = after[0][0], after[1][0]
    assert t_hold - t_cut < 2.0, "did not hold within the offboard-loss timeout"
    assert t_land - t_hold > 3.0, "did not hold before landing"
    assert t_land - t_cut <= 10.0 + 0.5, "did not land within COM_DL_LOSS_T of the last heartbeat"
    assert any(txt.startswith("Data link lost: landing") for _, txt in observer.texts)
    assert not observer.armed and observer.pos[2] > -0.2
    # It held and landed where it was: no fly-away after the cut. The vehicle may be flying at up
    # to 3 m/s when the link goes; hold brakes to a stop point ahead of it, and on a loaded machine
    # the observer's "cut" position lags. A fly-away over the ~10 s before landing would be 20+ m.
    drift = max(float(np.hypot(*(p[0:2] - p_cut[0:2]))) for t, p in observer.track if t >= t_cut)
    assert drift < 7.0, f"drifted {drift:.1f} m after the link was cut"
