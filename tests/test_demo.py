"""Issue 7: message forwarding, ``windseek estimator`` against ``windseek sitl``, and ``windseek demo``.

1. Forwarding (in-process SITL, raw UDP peers): a broadcast frame from one peer reaches the other
   peer unchanged and is not echoed to its sender; a frame addressed to the autopilot is not
   forwarded.
2. ``windseek estimator`` (a subprocess) against ``windseek sitl --forward --exit-summary`` (a
   subprocess) with a passive listener as a second peer: the estimator publishes WIND_COV as
   component 191, the listener receives it through the SITL's forwarding, and the SITL's exit
   summary scores it.
3. ``windseek demo``: three processes, then the .rrd and .tlog read back (vehicle, wind estimate
   from WIND_COV, chemical reading; WIND_COV frames from the estimator in the tlog) and the
   summary JSON has its keys.
"""

from __future__ import annotations

import json
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from link_support import free_port, running, udp_to, wait_until

from sitl.link.forwarding import Forwarder
from wire.dialect import mavlink as mav

pytestmark = pytest.mark.e2e

ROOT = Path(__file__).resolve().parents[1]


class Peer:
    """A raw UDP MAVLink peer: sends with its own identity, collects what it receives."""

    def __init__(self, sysid: int, compid: int) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.settimeout(0.05)
        self.port = self.sock.getsockname()[1]
        self.enc = mav.MAVLink(None, sysid, compid)
        self.parser = mav.MAVLink(None, 250, 250)
        self.parser.robust_parsing = True
        self.got: list = []

    def send(self, msg: object, addr: tuple[str, int]) -> None:
        self.sock.sendto(msg.pack(self.enc), addr)

    def pump(self, seconds: float) -> None:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            try:
                data, _ = self.sock.recvfrom(65536)
            except TimeoutError:
                continue
            self.got += [m for m in (self.parser.parse_buffer(data) or []) if m.get_type() != "BAD_DATA"]

    def named(self, name: str) -> list:
        return [m for m in self.got if m.get_type() == "NAMED_VALUE_FLOAT" and m.name.rstrip("\x00") == name]


def test_forwarding_between_udp_peers() -> None:
    a, b = Peer(1, 191), Peer(245, 190)
    with running([udp_to(a.port)]) as link:
        Forwarder(link)
        port = link.endpoint.links[0].transport.port
        b.send(mav.MAVLink_heartbeat_message(6, 8, 0, 0, 4, 3), ("127.0.0.1", port))  # b becomes a peer
        wait_until(lambda: len(link.endpoint.links[0].transport.peers) == 2, 5.0, "second peer")
        a.send(mav.MAVLink_named_value_float_message(1000, b"FWDME", 1.5), ("127.0.0.1", port))
        a.send(mav.MAVLink_param_request_read_message(1, 1, b"MPC_XY_CRUISE", -1), ("127.0.0.1", port))
        b.pump(1.0)
        a.pump(0.2)
    fwd = b.named("FWDME")
    assert len(fwd) == 1 and fwd[0].get_srcSystem() == 1 and fwd[0].get_srcComponent() == 191
    assert fwd[0].value == pytest.approx(1.5)
    assert not a.named("FWDME"), "a forwarded frame went back to its sender"
    # The autopilot's own reply to the request goes to its sender only; the request is not forwarded.
    assert not [m for m in b.got if m.get_type() == "PARAM_REQUEST_READ"]
    assert link.counters["forwarded"] >= 1


def _sitl(tmp: Path, peers: list[int], *extra: str, scenario: str = "open-field") -> subprocess.Popen:
    cmd = [sys.executable, "-m", "windseek.cli", "sitl", scenario, "--speed", "4", "--udp-bind", "127.0.0.1:0",
           "--forward", "--exit-summary", str(tmp / "truth.json"), *extra, "--udp",
           *(f"127.0.0.1:{p}" for p in peers)]  # fmt: skip
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT)
    assert proc.stdout.readline().startswith("windseek sitl:"), proc.stderr.read()
    return proc


def test_estimator_publishes_wind_cov_through_the_sitl(tmp_path: Path) -> None:
    p_est = free_port()
    listener = Peer(250, 1)
    # paper-s1 hovers from the start: the estimator publishes once it has judged the model to fit the
    # vehicle in steady flight (estimator.model_fit: a few seconds of it).
    sitl = _sitl(tmp_path, [p_est, listener.port], "--tlog", str(tmp_path / "a.tlog"), scenario="paper-s1")
    try:
        est = subprocess.Popen(
            [sys.executable, "-m", "windseek.cli", "estimator", "--connect", f"udpin://127.0.0.1:{p_est}",
             "--duration", "12", "--json", "--imu-average", "2"],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT)  # fmt: skip
        end = time.monotonic() + 90
        while est.poll() is None and time.monotonic() < end:
            listener.pump(0.2)  # keep the socket drained: the SITL streams thousands of frames a second
        est_out, est_err = est.communicate(timeout=10)
    finally:
        sitl.send_signal(signal.SIGTERM)
        sitl.communicate(timeout=20)
    assert est.returncode == 0, est_err
    out = json.loads(est_out)
    assert out["wind_cov_published"] >= 40  # 10 Hz from the verdict of fit (4-6 s) to 12 s of vehicle time
    assert out["model_fits"] is True and out["model"] == "nasa-quad"
    assert out["imu_message"] == "HIL_SENSOR"
    assert out["inputs"] == {"attitude": "ATTITUDE_QUATERNION", "velocity": "LOCAL_POSITION_NED",
                             "rotors": "ESC_STATUS"}  # fmt: skip
    wc = [m for m in listener.got if m.get_type() == "WIND_COV"]
    assert wc, "no WIND_COV forwarded to the second peer"
    assert {(m.get_srcSystem(), m.get_srcComponent()) for m in wc} == {(1, 191)}
    assert all(np.isfinite([m.wind_x, m.wind_y, m.wind_z, m.var_horiz]).all() for m in wc)
    truth = json.loads((tmp_path / "truth.json").read_text())
    assert truth["wind_estimates_received"] >= 40 and truth["forwarded_messages"] >= 40
    assert (tmp_path / "a.tlog").stat().st_size > 0


def test_demo_runs_three_processes_and_writes_logs(tmp_path: Path) -> None:
    t0 = time.monotonic()
    res = subprocess.run([sys.executable, "-m", "windseek.cli", "demo", "--logs", str(tmp_path), "--json",
                          "--time-limit", "100", "--wall-limit", "150"],
                         capture_output=True, text=True, timeout=200, cwd=tmp_path)  # fmt: skip
    wall = time.monotonic() - t0
    assert res.returncode in (0, 1), res.stderr[-3000:]
    s = json.loads(res.stdout.strip().splitlines()[-1])
    for key in ("found", "reason", "declared_ned_m", "declared_error_horizontal_m", "true_sources_ned_m",
                "time_to_declaration_s", "mission_time_s", "wall_time_s", "search_path_m", "path_length_m",
                "wind_rmse_ned_m_s", "wind_rmse_horizontal_m_s", "files", "mission", "truth"):  # fmt: skip
        assert key in s, key
    assert s["found"] == (res.returncode == 0)
    assert s["mission"]["wind"] == "mavlink" and s["truth"]["wind_estimates_scored"] > 0
    assert s["wind_rmse_horizontal_m_s"] < 2.0
    # The estimator's last WIND_COV is from before the landing (it pauses at MAV_LANDED_STATE
    # LANDING), not a touchdown "updraft" (it was about [0.2, -0.1, -9.8]).
    wn, we, wd = s["mission"]["wind_ned"]
    assert np.hypot(wn + 5.0, we) < 2.5 and abs(wd) < 1.5, s["mission"]["wind_ned"]
    rrd, tlog = Path(s["files"]["rrd"]), Path(s["files"]["tlog"])
    assert rrd.name.endswith("-open-field-surge-cast.rrd") and tlog.with_suffix(".rrd") == rrd
    for name in ("sitl", "estimator", "mission"):  # all three processes ran and left their output
        assert Path(str(rrd).replace(".rrd", f".{name}.log")).stat().st_size > 0

    from recording.read import RrdLog

    log = RrdLog(rrd)
    paths = set(log.entity_paths()) | set(log.series())  # chem/value, chem/threshold: in chem/log10's rows
    for e in ("world/vehicle", "world/trail", "world/wind/estimate", "wind/north/estimate", "wind/north/band",
              "chem/value", "chem/threshold", "world/sources/true", "world/geofence", "log/mission",
              "map/setpoint", "world/setpoint"):  # fmt: skip  # the last two: the mission's recording, merged
        assert e in paths, e
    assert not rrd.with_suffix(".mission.rrd").exists()  # merged into the one recording, then deleted
    t_sp, _ = log.vectors("world/setpoint", "Points3D:positions")  # on the SITL's clock, within the flight
    t_veh, _ = log.vectors("world/vehicle", "Transform3D:translation")
    assert len(t_sp) > 50 and t_veh[0] < t_sp[0] and t_sp[-1] < t_veh[-1]
    t, v = log.scalars("wind/north/estimate")
    assert len(t) > 50 and np.isfinite(v).all()

    from pymavlink import mavutil

    mavutil.mavlink = mav
    conn = mavutil.mavlink_connection(str(tlog))
    kinds: dict[tuple[str, int], int] = {}
    states: list[str] = []
    src: dict[str, float] = {}
    systems = set()
    while (m := conn.recv_match()) is not None:
        k = (m.get_type(), m.get_srcComponent())
        kinds[k] = kinds.get(k, 0) + 1
        systems.add(m.get_srcSystem())
        if k == ("STATUSTEXT", 190) and m.text.startswith("state: "):
            states.append(m.text[len("state: "):])
        elif k == ("NAMED_VALUE_FLOAT", 190):
            src[m.name] = m.value
    assert kinds.get(("WIND_COV", 191), 0) > 50 and kinds.get(("HIL_SENSOR", 1), 0) > 1000
    assert kinds.get(("SET_POSITION_TARGET_LOCAL_NED", 190), 0) > 10  # the mission's offboard setpoints
    # The mission itself published its strategy states and its declaration (nothing relayed them).
    assert 250 not in systems, systems
    assert states and states[-1] == s["mission"]["state"], (states, s["mission"]["state"])
    assert all(a != b for a, b in zip(states, states[1:], strict=False)), states  # on change only
    if s["declared_ned_m"]:
        got = [src.get(n) for n in ("SRC_N", "SRC_E", "SRC_D")]
        assert got == pytest.approx(s["declared_ned_m"], abs=1e-3), (got, s["declared_ned_m"])
        assert src.get("SRC_CONF") == pytest.approx(s["confidence"], abs=1e-3)
        assert s["truth"]["declared"]["declared_ned"] == pytest.approx(s["declared_ned_m"], abs=1e-3)
        assert s["truth"]["declared_error_horizontal_m"] == pytest.approx(s["declared_error_horizontal_m"], abs=0.01)
    comp = next(c for c in log.components("log/mission") if c.lower().endswith("text"))
    _, texts = log.column("log/mission", comp)
    lines = [str(x[0] if isinstance(x, list) else x) for x in texts]
    for st in set(states):  # the recording shows every strategy state the mission sent, with what it means
        assert any(ln.startswith(f"strategy: {st}") for ln in lines), (st, lines[:10])
    print(f"demo: {wall:.1f} s wall, found {s['found']}, {s['reason']}")
