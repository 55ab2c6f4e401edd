"""The recording of a live run: ``windseek sitl --rrd`` (:class:`recording.sitl_link.LinkRecorder`) and the
demo's rewrite with its summary (:mod:`recording.finalize`).

A real simulation is flown through the built-in autopilot's commands (arm, take off, offboard,
land) while real MAVLink messages from a mission (component 190) and an estimator (191), packed
and parsed with the project dialect, reach the recorder exactly as the endpoint hands them over:
strategy states, WIND_COV, the declaration. The .rrd is read back with ``rerun.chunk.RrdReader``.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from recording.finalize import add_demo_result
from recording.read import RrdLog
from recording.sitl_link import LinkRecorder
from sitl.autopilot.modes import Mode
from sitl.link.runner import SitlLink
from sitl.scenario import load_scenario
from sitl.simulation import Simulation
from wire.dialect import mavlink as mav
from wire.names import declaration_messages, statustext_message

MISSION, ESTIMATOR = 190, 191


def _wire(msg: Any, comp: int) -> Any:
    """``msg`` as the SITL's endpoint sees it: packed by system 1 component ``comp``, parsed back."""
    sender = mav.MAVLink(None, srcSystem=1, srcComponent=comp)
    return mav.MAVLink(None).decode(bytearray(msg.pack(sender)))


class _Flight:
    """A simulated search: take off, offboard north along the plume with states, declare, land."""

    def __init__(self, path: Path) -> None:
        self.sim = Simulation(load_scenario("open-field"), seed=1002, autostart_route=False)
        self.link = SitlLink(self.sim, [])
        self.rec = LinkRecorder(self.link, path, strategy="surge-cast",
                                geofence_ned=([-150.0, -150.0, -30.0], [150.0, 150.0, 0.0]))  # fmt: skip
        self.latest: tuple[float, np.ndarray] = (0.0, np.zeros(3))
        self.sim.step_hooks.append(lambda s: setattr(self, "latest", (s.t, s.wind_at_vehicle.copy())))

    def send(self, msg: Any, comp: int = MISSION) -> None:
        self.rec.on_message(_wire(msg, comp), None)

    def run_until(self, t_end: float) -> None:
        """Step the simulation; 10 Hz WIND_COV while airborne: the true wind of the latest mode tick
        + 0.2 m/s north, stamped with that tick's time (an estimate always refers to a past sample)."""
        sim = self.sim
        while sim.t < t_end - 1e-9:
            sim.run_until(min(t_end, sim.t + 0.1))
            if -sim.position[2] > 1.0:
                t, w = self.latest
                w = w + np.array([0.2, 0.0, 0.0])
                self.send(mav.MAVLink_wind_cov_message(int(round(t * 1e6)), *(float(v) for v in w), 0.08, 0.02,
                                                       -float(sim.position[2]), 1.0, 1.0), ESTIMATOR)

    def fly(self) -> None:
        sim, fc = self.sim, self.sim.fc
        self.run_until(2.0)
        assert fc.arm()[0] and fc.takeoff(4.0)[0]
        self.t_arm = sim.t
        self.run_until(12.0)
        fc.offboard_setpoint(sim.t, pos=np.array([0.0, 0.0, -4.0]))
        assert fc.set_mode(Mode.OFFBOARD)[0]
        self.t_search = sim.t
        self.send(statustext_message("state: acquire"))
        for k in range(40):  # north at 2 m/s for 20 s, a carrot ahead of the vehicle
            fc.offboard_setpoint(sim.t, pos=np.array([min(2.0 * k * 0.5 + 2.0, 40.0), 0.0, -4.0]))
            if k == 10:
                self.send(statustext_message("state: surge"))
            if k == 25:
                self.t_verify = sim.t
                self.send(statustext_message("state: verify"))
            self.run_until(sim.t + 0.5)
        self.t_declared = round(sim.t, 3)
        self.send(statustext_message("state: descend"))
        for m in declaration_messages(self.t_declared, [38.0, 0.5, -1.5], 0.75):
            self.send(m)
        self.send(statustext_message("holding before landing", mav.MAV_SEVERITY_WARNING), 191)
        self.run_until(sim.t + 2.0)
        assert fc.land()[0]
        self.t_land = sim.t
        t_stop = sim.t + 30.0
        while fc.armed and sim.t < t_stop:
            self.run_until(sim.t + 0.5)
        assert not fc.armed
        self.run_until(sim.t + 1.0)
        self.rec.close()


@pytest.fixture(scope="module")
def flight(tmp_path_factory: pytest.TempPathFactory) -> tuple[_Flight, Path]:
    path = tmp_path_factory.mktemp("live") / "live.rrd"
    f = _Flight(path)
    f.fly()
    return f, path


def test_wire_events_drive_phases_markers_and_events(flight: tuple[_Flight, Path]) -> None:
    f, path = flight
    log = RrdLog(path)
    phases = log.states("phases/mission")
    names = [s for _, s in phases]
    for p in ("take-off", "hover", "search", "verify", "descend", "landing", "landed"):  # armed + take-off: one tick
        assert p in names, names
    at = dict((s, t) for t, s in reversed(phases))  # first time of each phase
    assert at["search"] == pytest.approx(f.t_search, abs=0.05)
    assert at["verify"] == pytest.approx(f.t_verify, abs=0.05)
    assert at["descend"] == pytest.approx(f.t_declared, abs=0.05)  # the declaration's own time stamp
    assert [s for _, s in log.states("phases/strategy")] == ["acquire", "surge", "verify", "descend"]
    t_m, _ = log.scalars("markers/phase")
    np.testing.assert_allclose(t_m[0::3][:2], [f.t_arm, f.t_search], atol=0.05)  # take-off, search start
    np.testing.assert_allclose(log.scalars("markers/verify")[0][0::3], [f.t_verify], atol=0.05)
    np.testing.assert_allclose(log.scalars("markers/declared")[0][0::3], [f.t_declared], atol=0.01)
    mission = [b for _, b in log.texts("log/mission")]
    assert "strategy: surge – in the plume: flying upwind" in mission
    assert any(b.startswith("source declared at N 38.0 E 0.5 m") and "75 %" in b for b in mission)
    assert any(b == "estimator: holding before landing" for b in mission + [b for _, b in log.texts("log/wire")])
    _, lvl = log.column("log/wire", "TextLog:level")
    assert lvl == [["WARN"]]


def test_wire_wind_band_and_summary(flight: tuple[_Flight, Path]) -> None:
    f, path = flight
    log = RrdLog(path)
    t, est = log.scalars("wind/north/estimate")
    tb, lo, hi = log.band("wind/north/band")
    assert len(t) > 200 and len(tb) == len(t)
    np.testing.assert_allclose(hi - lo, 4.0 * math.sqrt(0.08 / 2.0), rtol=1e-5)  # 2 sigma each side
    s = log.summary()
    assert s is not None and s.kind.startswith("windseek sitl")
    assert s.found is False and s.error_m == pytest.approx(math.hypot(22.0, 0.5), abs=0.01)  # 38 m vs 60 m
    assert s.t_arm_s == pytest.approx(f.t_arm, abs=0.05) and s.t_declared_s == pytest.approx(f.t_declared, abs=0.01)
    assert s.time_to_declaration_s == pytest.approx(f.t_declared - f.t_arm, abs=0.05)
    # The estimate is the truth + 0.2 m/s north: the recorder scores it against the truth.
    assert s.wind_rmse_ned_m_s[0] == pytest.approx(0.2, abs=0.02) and s.wind_rmse_ned_m_s[1] < 0.02
    assert 30.0 < s.search_path_m < 45.0 and s.total_path_m > s.search_path_m
    assert s.start_distance_m == pytest.approx(60.0, abs=0.5) and s.reach_path_m is None  # never within 5 m
    assert "WIND_COV from system 1 component 191" in s.wind_source
    cost = {k: log.property_value("recording_cost", k) for k in ("recorder_cpu_s", "rerun_cpu_s", "process_cpu_s")}
    assert 0.0 < cost["recorder_cpu_s"] < cost["process_cpu_s"] and cost["rerun_cpu_s"] >= 0.0, cost
    assert log.property_value("recording_cost", "sim_s") == pytest.approx(f.sim.t, abs=0.01)  # the recorder began at 0
    doc = log.document("summary")
    assert doc is not None and "**NOT FOUND**" in doc and "declared error 22.0 m" in doc
    lay = log.layout()
    assert lay is not None and lay.t_range[0] == pytest.approx(max(0.0, f.t_arm - 3.0), abs=0.05)
    t_last = log.vectors("world/vehicle", "Transform3D:translation")[0][-1]
    assert lay.t_range[1] == pytest.approx(min(s.t_disarm_s + 3.0, t_last), abs=0.1)  # the plots open on the flight
    n0, n1, e0, e1 = lay.bounds_ne
    assert n1 < 100.0 and e1 - e0 < 150.0  # the search area, inside the 300 m geofence


def test_demo_rewrite_keeps_the_data_and_carries_the_printed_summary(flight: tuple[_Flight, Path],
                                                                     tmp_path: Path) -> None:  # fmt: skip
    f, path = flight
    copy = tmp_path / "demo.rrd"
    copy.write_bytes(path.read_bytes())
    before = RrdLog(copy)
    ranges = before.blueprint_time_ranges()  # read now: the blueprint is read lazily, from the file
    demo = {"scenario": "open-field", "strategy": "surge-cast", "seed": 1002, "speed": 5.0, "found": False,
            "reason": "declared 22.0 m from the true source (more than 5 m)", "cause": "declared",
            "declared_ned_m": [38.0, 0.5, -1.5], "confidence": 0.75, "true_sources_ned_m": [[60.0, 0.0, -2.0]],
            "declared_error_horizontal_m": 22.01, "time_to_declaration_s": 31.2, "mission_time_s": 45.0,
            "wall_time_s": 12.3, "search_path_m": 41.0, "path_length_m": 47.5, "wind_rmse_ned_m_s": [0.2, 0.01, 0.05],
            "wind_rmse_horizontal_m_s": 0.2, "wind_estimates_scored": 300, "landed": True, "disarmed": True,
            "mission": {"wind_source": "WIND_COV from system 1 component 191", "landed": True, "disarmed": True,
                        "verifications": [{"t_start_s": 25.0, "duration_s": 7.5, "outcome": "verified"}]}}  # fmt: skip
    s = add_demo_result(copy, demo)
    after = RrdLog(copy)
    assert after.application_ids == before.application_ids
    assert after.summary() == s and s.search_path_m == 41.0 and s.time_to_declaration_s == 31.2
    assert s.t_declared_s == pytest.approx(f.t_declared, abs=0.01)  # kept from the recording: vehicle time
    assert s.verifications[0]["outcome"] == "verified"  # the mission's outcome on the recording's sweep
    assert s.verifications[0]["t_start_s"] == pytest.approx(f.t_verify, abs=0.05)
    doc = after.document("summary")
    assert doc is not None and "path 41.0 m searched" in doc and "wall time: 12 s at speed 5" in doc
    # Nothing else changed: the same entities and rows, the same layout.
    assert after.entity_paths() == before.entity_paths()
    for e, c in (("wind/north/estimate", "Scalars:scalars"), ("chem/log10", "Chem:mg_m3"),
                 ("markers/phase", "Scalars:scalars"), ("world/vehicle", "Transform3D:translation")):
        assert len(after.column(e, c)[0]) == len(before.column(e, c)[0]) > 0, e
    assert after.blueprint_count == 1 and after.blueprint_time_ranges() == ranges and len(ranges) == 9
