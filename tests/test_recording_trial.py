"""Recording an in-process trial (``run_trial(recorder=TrialRecorder(...))``) and a strategy's posterior.

The trial's recording is read back and compared with the trial's own result: the summary, the
phase markers on the vehicle clock, the time range the plots open on. The recorder must not change
the trial. The posterior layer is checked with a synthetic Gaussian grid whose centre is known.
"""

from __future__ import annotations

import math
import warnings
from pathlib import Path

import numpy as np
import pytest

from mission.runners.inprocess import run_trial
from recording.read import RrdLog
from recording.recorder import RunRecorder
from recording.trial import TrialRecorder, record_posterior

SEED = 1001  # declares after about 60 s of flight


@pytest.fixture(scope="module")
def trial(tmp_path_factory: pytest.TempPathFactory) -> tuple[object, RrdLog]:
    path = tmp_path_factory.mktemp("trial") / "trial.rrd"
    result = run_trial("open-field", "surge-cast", seed=SEED, time_limit_s=150.0, recorder=TrialRecorder(path))
    return result, RrdLog(path)


def test_recorder_does_not_change_the_trial(trial: tuple[object, RrdLog]) -> None:
    result, _ = trial
    plain = run_trial("open-field", "surge-cast", seed=SEED, time_limit_s=150.0)
    for key in ("success", "declared_ned", "error_m", "time_s", "path_m", "reach_path_m", "verifications"):
        assert getattr(plain, key) == getattr(result, key), key


def test_trial_summary_matches_the_result(trial: tuple[object, RrdLog]) -> None:
    result, log = trial
    assert result.success  # this seed finds the source: the recording must say so
    s = log.summary()
    assert s is not None and s.found is True and s.kind.startswith("in-process trial")
    assert s.error_m == pytest.approx(result.error_m) and s.declared_ned == result.declared_ned
    assert s.t_declared_s == pytest.approx(result.time_s)
    assert s.time_to_declaration_s == pytest.approx(result.time_s - s.t_arm_s, abs=0.01)
    assert s.search_path_m == pytest.approx(result.path_m, abs=0.01)
    assert s.path_ratio == pytest.approx(result.path_ratio, rel=1e-3)
    assert s.reach_ratio == pytest.approx(result.reach_ratio, rel=1e-3)
    assert s.wind_rmse_horizontal_m_s is not None and 0.0 < s.wind_rmse_horizontal_m_s < 1.5
    assert len(s.verifications) == len(result.verifications)
    doc = log.document("summary")
    assert doc is not None and "**FOUND**" in doc and f"declared error {result.error_m:.1f} m" in doc
    assert log.property_value("result", "found") is True
    # What recording cost the trial (benchmarks/recording_cost.py reads it): a part of the process's CPU.
    cost = {k: log.property_value("recording_cost", k) for k in ("recorder_cpu_s", "rerun_cpu_s", "process_cpu_s")}
    assert 0.0 < cost["recorder_cpu_s"] < cost["process_cpu_s"] and cost["rerun_cpu_s"] >= 0.0, cost
    assert log.property_value("recording_cost", "sim_s") >= result.time_s - 0.05  # the recording spans the trial


def test_trial_markers_on_the_vehicle_clock(trial: tuple[object, RrdLog]) -> None:
    result, log = trial
    t_dec = log.scalars("markers/declared")[0][0::3]
    np.testing.assert_allclose(t_dec, [result.time_s], atol=1e-6)
    t_ver = log.scalars("markers/verify")[0][0::3]
    np.testing.assert_allclose(t_ver, [v["t_start_s"] for v in result.verifications], atol=0.11)
    t_phase = log.scalars("markers/phase")[0][0::3]
    assert t_phase[0] == pytest.approx(0.0, abs=0.11)  # take-off at arming, the trial's t = 0
    strategy = [s for _, s in log.states("phases/strategy")]
    assert strategy[0] == "acquire" and "verify" in strategy and strategy[-1] in ("descend", "done")
    # The plots open on the whole flight (plus room for the legends) ...
    lay = log.layout()
    assert lay is not None and lay.t_range[0] == pytest.approx(0.0) and lay.t_range[1] >= result.time_s
    for t0, t1 in log.blueprint_time_ranges():
        assert t0 == pytest.approx(0.0) and t1 > lay.t_range[1]
    # ... and the chemical plot's range shows the threshold between the floor and the peaks.
    lo, hi = lay.y_ranges["chem"]
    assert lo < math.log10(0.05) < hi and hi > 1.0
    # The filtered wind direction is unwrapped: no jumps across 0/360.
    _, d = log.scalars("wind/direction/filtered")
    assert len(d) > 100 and np.abs(np.diff(d)).max() < 30.0


class _Gaussian:
    """A stand-in for a probabilistic strategy: a Gaussian posterior moving north, its credible radius shrinking."""

    def __init__(self) -> None:
        self.t = 0.0

    def centre(self) -> tuple[float, float]:
        return 20.0 + 2.0 * self.t, -5.0

    def posterior_map(self, cell_m: float = 1.0) -> tuple[np.ndarray, tuple[float, float, float, float]]:
        extent = (0.0, 80.0, -20.0, 20.0)
        n = np.arange(extent[0], extent[1], cell_m) + 0.5 * cell_m
        e = np.arange(extent[2], extent[3], cell_m) + 0.5 * cell_m
        cn, ce = self.centre()
        p = np.exp(-0.5 * (((n[:, None] - cn) / 4.0) ** 2 + ((e[None, :] - ce) / 2.0) ** 2))
        return p / p.sum(), extent

    def credible_region(self) -> tuple[np.ndarray, float]:
        return np.array(self.centre()), 10.0 - self.t


def test_posterior_layer_with_a_synthetic_grid(tmp_path: Path) -> None:
    path = tmp_path / "posterior.rrd"
    g = _Gaussian()
    with RunRecorder(path, strategy="infotaxis") as rec:
        for k in range(5):
            g.t = float(k)
            assert record_posterior(rec, g.t, g, cell_m=2.0)
        assert not record_posterior(rec, 5.0, object())  # a strategy without a posterior: nothing
        with pytest.raises(ValueError, match="extent"):
            rec.posterior(6.0, np.ones((3, 3)), (10.0, 0.0, 0.0, 5.0))
    log = RrdLog(path)
    t, imgs = log.images("map/posterior/image")
    np.testing.assert_allclose(t, np.arange(5.0))
    # 2 m cells over 40 m east x 80 m north; only the visibly drawn cells go into the image (scene._visible_part),
    # so the image is that grid or a cut of it, on the same 2 m cells and inside the grid's corners.
    img = imgs[-1]
    h, w = img.shape[:2]
    assert 0 < w <= 20 and 0 < h <= 40 and w * h < 20 * 40, (w, h)
    _, tr = log.vectors("map/posterior/image", "Transform3D:translation")
    _, sc = log.vectors("map/posterior/image", "Transform3D:scale")
    np.testing.assert_allclose(sc[-1], [2.0, 2.0, 1.0])
    # map (x, y) = (east, -north) of the image's north-west corner, on the grid's 2 m lattice and inside it
    assert -20.0 <= tr[-1][0] <= 20.0 - 2.0 * w and -80.0 <= tr[-1][1] <= -2.0 * h
    assert tr[-1][0] % 2.0 == 0.0 and tr[-1][1] % 2.0 == 0.0
    row, col = np.unravel_index(np.argmax(img[..., 3]), img.shape[:2])
    x, y = tr[-1][0] + (col + 0.5) * 2.0, tr[-1][1] + (row + 0.5) * 2.0  # pixel centre on the map
    cn, ce = g.centre()
    assert abs(x - ce) <= 1.0 and abs(-y - cn) <= 1.0  # the most probable cell is the Gaussian's centre
    t_c, strips = log.column("map/posterior/credible", "LineStrips2D:strips")
    ring = np.array(strips[-1][0])
    np.testing.assert_allclose(np.hypot(ring[:, 0] - ce, -ring[:, 1] - cn), 6.0, atol=1e-4)  # radius 10 - t
    _, labels = log.column("map/posterior/credible", "LineStrips2D:labels")
    assert labels[-1] == ["credible 6.0 m"]


def _content(path: Path) -> tuple[dict[str, dict[str, object]], dict[str, list[tuple[float, str]]]]:
    """Everything a recording holds, independent of how it was cut into chunks: per entity the last
    static value of each component, and the sorted (time, value) rows of each temporal component."""
    from rerun.chunk import RrdReader

    from recording.style import TIMELINE

    static: dict[str, dict[str, object]] = {}
    rows: dict[str, list[tuple[float, str]]] = {}
    with warnings.catch_warnings():  # a batch trial's file has no footer (recording.stream.RecorderBase)
        warnings.filterwarnings("ignore", message="RRD file has no footer")
        chunks = RrdReader(path).stream().to_chunks()
    for chunk in chunks:
        rb = chunk.to_record_batch()
        names = [n for n in rb.schema.names if n != "rerun.controls.RowId" and n != TIMELINE]
        if chunk.is_static:
            for n in names:
                static.setdefault(chunk.entity_path, {})[n] = rb.column(n).to_pylist()[-1]
        else:
            t = rb.column(TIMELINE).cast("int64").to_pylist()
            for n in names:
                rows.setdefault(f"{chunk.entity_path}:{n}", []).extend(
                    (ti, repr(v)) for ti, v in zip(t, rb.column(n).to_pylist(), strict=True) if v is not None)
    static.pop("/__properties/recording_cost", None)  # what recording cost: differs run to run
    static.get("/__properties", {}).pop("RecordingInfo:start_time", None)  # the wall clock at the start
    return static, {k: sorted(v) for k, v in rows.items()}


def test_a_batch_trial_recording_is_smaller_with_the_same_content(tmp_path: Path) -> None:
    """Static data deferred to close (one chunk per entity, the last of each kind), one batcher flush,
    rows sent once: fewer chunks, the same data as a recording made for a live viewer."""
    live, batch = tmp_path / "live.rrd", tmp_path / "batch.rrd"
    run_trial("open-field", "surge-cast", seed=SEED, time_limit_s=40.0,
              recorder=TrialRecorder(live, live_layout=True, series_flush_s=4.0))  # fmt: skip
    run_trial("open-field", "surge-cast", seed=SEED, time_limit_s=40.0, recorder=TrialRecorder(batch))
    s_live, r_live = _content(live)
    s_batch, r_batch = _content(batch)
    assert r_batch == r_live
    # Only the styles of series that never got a row are left out.
    unused = {e for e in set(s_live) - set(s_batch)}
    assert unused and all(set(s_live[e]) <= {"SeriesLines:colors", "SeriesLines:names", "SeriesLines:widths",
                                              "SeriesLines:aggregation_policy"} for e in unused), unused  # fmt: skip
    assert all(not any(k.startswith(f"{e}:") for k in r_live) for e in unused)
    assert {e: s_live[e] for e in s_batch} == s_batch
    assert batch.stat().st_size < 0.92 * live.stat().st_size, (batch.stat().st_size, live.stat().st_size)
