"""Recordings readable in the viewer without the summary (the "Rerun 0.41 web viewer" issue), read back
from real ``.rrd`` files: a review of real third-party logs shows the flight (altitude, velocity,
attitude, battery, GPS and its track on the map), its summary has no search tables and carries the
model caveat; the plots name their series; wind directions never jump by 360 deg; wind axes hold two
whole units (two labels); the declared source is drawn over the vehicle; a trial has an altitude plot.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from mission.runners.inprocess import run_trial
from recording.read import RrdLog
from recording.recorder import RunRecorder
from recording.trial import TrialRecorder
from review import review
from review.dataflash import read_dataflash

_CANDIDATES = [Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "logs", Path("/work/shared/data/logs")]
LOGS = next((p.resolve() for p in _CANDIDATES if (p / "SOURCES.md").is_file()), Path("/nonexistent"))
pytestmark = pytest.mark.skipif(not LOGS.is_dir(), reason="third-party logs not found at ../shared/data/logs")


def _names(log: RrdLog, entity: str) -> list[str]:
    _, names = log.column(entity, "SeriesLines:names")
    return [n for row in names for n in row]


@pytest.fixture(scope="module")
def hover(tmp_path_factory: pytest.TempPathFactory) -> tuple[object, RrdLog]:
    out = tmp_path_factory.mktemp("hover") / "hover.rrd"
    res = review(LOGS / "px4-sitl-quad-hover.ulg", out)
    return res, RrdLog(out)


def test_review_of_a_px4_hover_shows_the_flight(hover: tuple[object, RrdLog]) -> None:
    _, log = hover
    n = {e: len(log.scalars(e)[0]) for e in log.temporal_entity_paths() if e.startswith("flight/")}
    # vehicle_local_position 313 rows (308 with z valid), vehicle_attitude 622 (one per 25-Hz bin: 621),
    # velocity where v_xy is valid, battery_status 157, vehicle_gps_position 583.
    assert n["flight/altitude/vehicle"] == 308 and n["flight/attitude/roll"] == n["flight/attitude/yaw"] == 621
    assert n["flight/velocity/north"] > 200 and n["flight/battery/voltage"] == 156 and n["flight/gps/fix"] == 583
    t, alt = log.scalars("flight/altitude/vehicle")
    assert 1.8 < alt.max() < 2.5 and abs(float(np.median(alt[t < 14.0]))) < 0.5  # on the ground, then ~2 m up
    tg, gps_alt = log.scalars("flight/altitude/gps")  # on the local origin (ref_alt): agrees with it in the hover
    assert abs(float(np.interp(25.0, tg, gps_alt)) - float(np.interp(25.0, t, alt))) < 0.5
    _, v = log.scalars("flight/battery/voltage")
    _, rem = log.scalars("flight/battery/remaining")
    # Remaining in %: it drains in the flight (the SITL battery refills at the disarm).
    assert 15.0 < v.min() <= v.max() < 16.5 and rem[0] > 95.0 and rem.min() < 80.0
    assert "flight/battery/current" not in log.temporal_entity_paths()  # PX4 SITL logs -1 A: unknown, not drawn
    _, sats = log.scalars("flight/gps/satellites")
    _, fix = log.scalars("flight/gps/fix")
    assert fix.max() == 3 and set(sats) == {10.0}
    _, yaw = log.scalars("flight/attitude/yaw")
    assert np.abs(np.diff(yaw)).max() < 180.0
    # Every flight series has a legend name; the map has the GPS track (one strip of every fix).
    assert _names(log, "flight/velocity/down") == ["down"] and _names(log, "flight/altitude/gps") == ["GPS"]
    _, strips = log.column("map/gps", "LineStrips2D:strips")
    assert len(strips) == 1 and len(strips[0][0]) > 400
    views = {(c, o, name) for c, o, name in log.blueprint_views()}
    for origin in ("flight/altitude", "flight/velocity", "flight/attitude", "flight/gps"):
        assert any(c == "TimeSeries" and o == origin for c, o, _ in views), origin
    lay = log.layout()
    assert lay is not None and lay.first_tab == "flight"
    assert {"altitude", "velocity", "attitude", "voltage", "gps"} <= set(lay.y_ranges)


def test_review_summary_has_no_search_and_carries_the_model_caveat(hover: tuple[object, RrdLog]) -> None:
    res, log = hover
    doc = log.document("summary") or ""
    for gone in ("Path (horizontal", "search start", "declared", "plume", "verification"):
        assert gone not in doc, gone
    model = res.summary["model"]  # type: ignore[attr-defined]
    assert model.startswith("model: ") and model in doc
    assert "model in use: nasa-quad" in doc
    s = log.summary()
    assert s is not None and s.search is False and s.t_arm_s is not None


def test_review_of_ardupilot_logs_shows_what_they_hold(tmp_path: Path) -> None:
    tl = RrdLog(review(LOGS / "ardupilot-quadplane-sitl.tlog", tmp_path / "t.rrd").out)
    for e in ("flight/altitude/vehicle", "flight/attitude/pitch", "flight/velocity/east", "flight/gps/satellites"):
        assert len(tl.scalars(e)[0]) > 700, e
    # SYS_STATUS says 0 mV, -1 cA, -1 %: this SITL simulates no battery, so no battery plot at all.
    assert not any(e.startswith("flight/battery") for e in tl.temporal_entity_paths())
    assert not any(o == "flight/battery" for _, o, _ in tl.blueprint_views())
    # The GPS altitude (first fix moved onto the position there) follows the local altitude: 100+ m climbs.
    t, alt = tl.scalars("flight/altitude/vehicle")
    tg, ga = tl.scalars("flight/altitude/gps")
    assert alt.max() > 50.0 and np.abs(np.interp(tg, t, alt) - ga).max() < 10.0
    df = RrdLog(review(LOGS / "ardupilot-dataflash-excerpt.BIN", tmp_path / "d.rrd").out)
    _, volt = df.scalars("flight/battery/voltage")
    assert len(volt) == 8 and 12.0 < volt.min() < 12.5  # BAT.Volt of the excerpt
    # The GPS track on the EKF origin (ORGN) lands on the EKF's own position (NKF1 PN, PE) at its fixes.
    fd = read_dataflash(LOGS / "ardupilot-dataflash-excerpt.BIN")
    _, strips = df.column("map/gps", "LineStrips2D:strips")
    first = np.asarray(strips[0][0][0])  # map (east, -north)
    p0 = fd.position.v[np.searchsorted(fd.position.t, fd.gps.t[0])]
    assert math.hypot(first[0] - p0[1], -first[1] - p0[0]) < 2.0


def test_wind_series_are_named_and_directions_never_jump(tmp_path: Path) -> None:
    path = tmp_path / "w.rrd"
    with RunRecorder(path) as rec:
        for i in range(80):  # a wind turning twice round the compass, small (a 0.3 m/s breeze)
            t = 0.1 * i
            d = (20.0 * i) % 360.0 - 180.0  # in -180..180: crosses +-180 and 0 every 18 samples
            rec.wind(t, truth_ned=[0.3, -0.2, 0.05], est_ned=[0.25, -0.1, 0.0], sigma_ned=[0.1, 0.1, 0.1])
            rec.wind_speed_dir(t, 0.3, d, dir_filt_deg=d, truth_speed=0.3, truth_dir_deg=d)
            rec.altitude(t, 2.0)
    log = RrdLog(path)
    for a, k in (("north", "N"), ("east", "E"), ("down", "D")):
        assert _names(log, f"wind/{a}/truth") == [f"truth {k}"] and _names(log, f"wind/{a}/band") == [f"±2σ band {k}"]
        assert _names(log, f"wind/{a}/estimate") == [f"estimate {k}"]
        lo, hi = log.layout().y_ranges[a]  # type: ignore[union-attr]
        assert math.floor(hi) - math.ceil(lo) >= 1, (a, lo, hi)  # two whole units: two axis labels
    for name in ("raw", "filtered", "truth"):
        _, d = log.scalars(f"wind/direction/{name}")
        assert len(d) == 80 and np.abs(np.diff(d)).max() == pytest.approx(20.0)
    # The legends are shown on every plot (none hidden); all plots open on one time range.
    assert all(log._blueprint_values("PlotLegend:visible"))
    assert len(set(log.blueprint_time_ranges())) == 1
    # A steady altitude is one row (then one per ALT_GAP_S), not one per call.
    assert len(log.scalars("flight/altitude/vehicle")[0]) == 2


def test_trial_has_altitude_and_a_visible_declaration(tmp_path: Path) -> None:
    path = tmp_path / "trial.rrd"
    result = run_trial("open-field", "surge-cast", seed=1001, time_limit_s=150.0, recorder=TrialRecorder(path))
    log = RrdLog(path)
    t, alt = log.scalars("flight/altitude/vehicle")
    assert 50 < len(t) < 400 and alt.min() == pytest.approx(0.0, abs=0.05) and 2.0 < alt.max() < 5.0
    assert ("TimeSeries", "flight/altitude") in {(c, o) for c, o, _ in log.blueprint_views()}
    # The declared source: larger than the vehicle's marker and drawn over it and the wind arrows.
    assert result.declared_ned is not None  # type: ignore[attr-defined]
    _, order = log.column("map/sources/declared", "Points2D:draw_order")
    _, v_order = log.column("map/vehicle", "Points2D:draw_order")
    _, radii = log.column("map/sources/declared", "Points2D:radii")
    _, v_radii = log.column("map/vehicle", "Points2D:radii")
    assert order[-1][0] > max(v_order[-1][0], 30.0) and abs(radii[-1][0]) > abs(v_radii[-1][0])
    assert "map/sources/declared/halo" in log.entity_paths()
