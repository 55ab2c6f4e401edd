"""``windseek estimator`` over a real UDP socket: a second system on the link and an autopilot reboot.

A pymavlink sender plays the autopilot (system 1) from a simulated flight, paced at 5x real time,
with another system (7, its clock 500 s ahead) interleaved; after 12 s the autopilot reboots (its
clock starts again near 0). The estimator (a subprocess) must lock on to system 1, say once that
system 7 is there, restart at the reboot and go on publishing WIND_COV on the new clock.
"""

from __future__ import annotations

import json

from estimator_process import run_estimator
from estimator_stream import autopilot_messages, record

from wire.dialect import mavlink

SPEED = 5.0  # simulated seconds per wall second


def test_estimator_locks_on_and_restarts_after_a_reboot_over_udp() -> None:
    f = record(20.0)
    other = record(20.0, scenario="paper-s2", seed=5)
    before = [(t, 1, m) for t, m in autopilot_messages(f) if t < 12.0]
    after = [(t, 1, m) for t, m in autopilot_messages(f, t_offset=-11.5) if t >= 12.0]
    seven = [(t, 7, m) for t, m in autopilot_messages(other, t_offset=500.0) if t < 20.0 and int(t * 250) % 5 == 0]
    plan = sorted(before + after + seven, key=lambda x: x[0])
    tx = {s: mavlink.MAVLink(None, srcSystem=s, srcComponent=1) for s in (1, 7)}
    rx = mavlink.MAVLink(None)
    got = []
    code, out, err = run_estimator([(t, m.pack(tx[sysid])) for t, sysid, m in plan], SPEED,
                                   lambda data, reply: got.extend(rx.parse_buffer(data) or []))
    assert code == 0, err
    s = json.loads(out)
    assert s["autopilot"] == "1:1" and s["stop_reason"] == "SIGTERM"
    assert s["counters"]["other_system"] > 1000 and s["counters"]["clock_resets"] == 1 and s["restarts"] == 1
    assert err.count("another MAVLink system on the link: 7:1") == 1, err
    assert "autopilot clock reset" in err and "inputs: IMU HIL_SENSOR 250 Hz" in err
    assert not any("out_of_order" in k for k in s["rejected"]), s["rejected"]
    wc = [m for m in got if m.get_type() == "WIND_COV"]
    assert {(m.get_srcSystem(), m.get_srcComponent()) for m in wc} == {(1, 191)}
    t = [m.time_usec * 1e-6 for m in wc]
    k = next(i for i in range(1, len(t)) if t[i] < t[i - 1])  # the first WIND_COV after the reboot
    assert t[k - 1] > 11.0 and t[k] < 3.0 and len(t) - k > 40 and t[-1] > 8.0
    assert all(x < 100.0 for x in t)  # never on system 7's clock
    assert len(wc) <= s["wind_cov_published"]  # (any sent after the last read are not in got)
