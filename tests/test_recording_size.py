"""A batch trial's recording (issue 30): smaller than the way trials were recorded before 2026-12-06, with
the same content.

The same seeded trial is recorded twice: as a batch trial now is (``TrialRecorder(path)``: the
images as PNGs, no footer, series logged together sharing rows) and the former way (``png_images=False,
footer=True, shared_rows=False``: raw RGBA images, rerun's chunk manifest at the end, every scalar
series an entity of its own). Both are read back whole and compared entity by entity, value by value,
on the same timeline (images as decoded pixels; scalar series by name, wherever they are stored, with
their legend name, colour and width), and their blueprints view by view; then the sizes.
"""

from __future__ import annotations

import hashlib
import warnings
from pathlib import Path

import pytest
from rerun.chunk import RrdReader

from mission.runners.inprocess import run_trial
from recording.read import RrdLog
from recording.series import CARRIED, ROWS, SCALARS, carried_by, row_series
from recording.style import TIMELINE
from recording.trial import TrialRecorder

#: (scenario, strategy, seed, time limit [s]) -> new size over former size, an upper bound. Measured on
#: 2026-12-06 with these limits (short, for the suite's time): open-field surge-cast 0.626, infotaxis 0.509,
#: paper-s4 for 20 s 0.580 (0.674, 0.533, 0.609 before the series shared rows). The whole trials
#: (benchmarks/README.md, "File size"): the 143 s surge-cast trial 1,068 -> 745 kB (the footer 259 kB, the rows
#: the rotors and the chemical reading share 64 kB), infotaxis at 72 s 0.52 (the posteriors 674 -> 242 kB).
TRIALS = {("open-field", "surge-cast", 1001, 60.0): 0.645, ("open-field", "infotaxis", 1001, 60.0): 0.525,
          ("paper-s4", "surge-cast", 101, 20.0): 0.595}  # fmt: skip
IMAGE_PARTS = ("Image:", "EncodedImage:")
Content = tuple[dict[str, dict[str, object]], dict[str, list[tuple[int, str]]]]


@pytest.fixture(scope="module", params=sorted(TRIALS), ids=lambda k: f"{k[0]}-{k[1]}")
def pair(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> tuple[tuple, Path, Path]:
    scenario, strategy, seed, limit_s = request.param
    d = tmp_path_factory.mktemp(f"{scenario}-{strategy}")
    new, old = d / "new.rrd", d / "old.rrd"
    run_trial(scenario, strategy, seed=seed, time_limit_s=limit_s, recorder=TrialRecorder(new))
    run_trial(scenario, strategy, seed=seed, time_limit_s=limit_s,
              recorder=TrialRecorder(old, png_images=False, footer=True, shared_rows=False))  # fmt: skip
    return request.param, old, new


def _series_styles(static: dict[str, dict[str, object]]) -> dict[str, tuple[object, ...]]:
    """The style of each series that shares rows now (recording.series) -> (legend name, colour, width),
    taken out of ``static``: from its own entity's ``SeriesLines`` or its instance in the style of the
    entity whose rows it shares. A carried series (chem/value) had a style no plot used: dropped."""
    out: dict[str, tuple[object, ...]] = {}
    grouped = set(ROWS) | {name for cols in ROWS.values() for name, _, _ in cols}
    for entity in sorted(grouped & set(static)):
        style = static.pop(entity)
        parts = [v if isinstance(v, list) else [v] for v in
                 (style["SeriesLines:names"], style["SeriesLines:colors"], style["SeriesLines:widths"])]  # fmt: skip
        for k, series in enumerate(row_series(entity)):
            out[series] = tuple(p[k] for p in parts)
    for series in CARRIED:
        static.pop(series, None)
    return out


def _content(path: Path) -> Content:
    """Everything a recording holds, however it is cut into chunks and encoded: per entity the last
    static value of each component, the sorted (time [ns], value) rows of each temporal component; a
    scalar series by name (recording.series: its own entity or rows shared with others) with its style;
    an image's pixels (raw or PNG) as one value, its opacity and draw order under neutral names."""
    static: dict[str, dict[str, object]] = {}
    rows: dict[str, list[tuple[int, str]]] = {}
    images: set[str] = set()
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message="RRD file has no footer")
        chunks = RrdReader(path).stream().to_chunks()
    for chunk in chunks:
        rb = chunk.to_record_batch()
        entity = chunk.entity_path.strip("/")
        scalar_parts = {SCALARS, *carried_by(entity)} if not chunk.is_static else set()
        for name in (n for n in rb.schema.names if n not in ("rerun.controls.RowId", TIMELINE, *scalar_parts)):
            values = rb.column(name).to_pylist()
            if name.startswith(IMAGE_PARTS):
                images.add(entity)
                name = name.split(":", 1)[1]
                if name in ("buffer", "format", "blob", "media_type"):
                    continue  # the pixels, below
            if chunk.is_static:
                static.setdefault(entity, {})[name] = values[-1]
                continue
            t = rb.column(TIMELINE).cast("int64").to_pylist()
            rows.setdefault(f"{entity}:{name}", []).extend(
                (ti, repr(v)) for ti, v in zip(t, values, strict=True) if v is not None)
    log = RrdLog(path)
    for series in log.series():  # every value at full precision, at its time
        t, v = log.scalars(series)
        rows[f"{series}:series"] = [(round(ti * 1e9), repr(vi)) for ti, vi in zip(t, v.tolist(), strict=True)]
    static["series styles"] = dict(sorted(_series_styles(static).items()))  # type: ignore[arg-type]
    for entity in images:
        t_img, pixels = log.images(entity)
        seen = [(ti, f"{im.shape} {hashlib.sha1(im.tobytes()).hexdigest()}")
                for ti, im in zip(t_img, pixels, strict=True)]  # fmt: skip
        if any(ti != ti for ti, _ in seen):  # static (NaN time): the last one, as the viewer shows
            static.setdefault(entity, {})["pixels"] = [v for ti, v in seen if ti != ti][-1]
        rows[f"{entity}:pixels"] = [(round(ti * 1e9), v) for ti, v in seen if ti == ti]
    static.pop("__properties/recording_cost", None)  # what recording cost: differs run to run
    static.get("__properties", {}).pop("RecordingInfo:start_time", None)  # the wall clock at the start
    return static, {k: sorted(v) for k, v in rows.items()}


def test_the_new_recording_has_the_same_content(pair: tuple[tuple, Path, Path]) -> None:
    (scenario, strategy, _, _), old, new = pair
    s_old, r_old = _content(old)
    s_new, r_new = _content(new)
    assert sorted(r_new) == sorted(r_old) and sorted(s_new) == sorted(s_old)
    for key in r_old:
        assert r_new[key] == r_old[key], key
    assert s_new == s_old
    assert len(r_new["rotors/4:series"]) > 50 and len(r_new["chem/value:series"]) > 50
    log_new, log_old = RrdLog(new), RrdLog(old)  # the rows shared (recording.series), the former way not
    assert "rotors" in log_new.temporal_entity_paths() and "rotors/1" not in log_new.entity_paths()
    assert "Chem:mg_m3" in log_new.components("chem/log10") and "chem/value" not in log_new.entity_paths()
    assert {"rotors/1", "chem/value"} <= set(log_old.temporal_entity_paths())
    if strategy == "infotaxis":
        assert len(r_new["map/posterior/image:pixels"]) > 50  # the posteriors are there, pixel for pixel
        assert "EncodedImage:blob" in RrdLog(new).components("map/posterior/image")
    if scenario == "paper-s4":  # the urban layers' static images, pixel for pixel
        assert {"map/wind_field/speed", "map/buildings/fill"} <= {e for e in s_new if "pixels" in s_new[e]}
        assert "EncodedImage:blob" in RrdLog(new).components("map/wind_field/speed")
    a, b = RrdLog(old), RrdLog(new)
    assert a.application_ids == b.application_ids and a.blueprint_count == b.blueprint_count == 1
    assert sorted(a.blueprint_views()) == sorted(b.blueprint_views())
    assert a.blueprint_view_contents() == b.blueprint_view_contents()
    assert sorted(a.blueprint_time_ranges()) == sorted(b.blueprint_time_ranges())
    assert sorted(a.blueprint_value_ranges()) == sorted(b.blueprint_value_ranges())


def test_the_new_recording_is_smaller(pair: tuple[tuple, Path, Path]) -> None:
    trial, old, new = pair
    assert old.read_bytes()[-12:-4] == b"RRF2FOOT" and new.read_bytes()[-12:-4] != b"RRF2FOOT"  # the footer
    ratio = new.stat().st_size / old.stat().st_size
    assert ratio < TRIALS[trial], (trial, new.stat().st_size, old.stat().st_size)
