"""A batch trial's recording (issue 30): smaller than the way trials were recorded before 2026-12-06, with
the same content.

The same seeded trial is recorded twice: as a batch trial now is (``TrialRecorder(path)``: the
images as PNGs, no footer) and the former way (``png_images=False, footer=True``: raw
RGBA images, rerun's chunk manifest at the end). Both are read back whole and compared entity by
entity, value by value, on the same timeline (images as decoded pixels), and their blueprints view by
view; then the sizes.
"""

from __future__ import annotations

import hashlib
import warnings
from pathlib import Path

import pytest
from rerun.chunk import RrdReader

from mission.runners.inprocess import run_trial
from recording.read import RrdLog
from recording.style import TIMELINE
from recording.trial import TrialRecorder

#: (scenario, strategy, seed, time limit [s]) -> new size over former size, an upper bound. Measured on
#: 2026-12-06 with these limits (short, for the suite's time): open-field surge-cast 0.674, infotaxis 0.533,
#: paper-s4 for 20 s 0.609. The whole trials (benchmarks/README.md, "File size"): surge-cast 0.756 (it
#: declares at 143 s: 1,068 -> 809 kB, of which the footer 259 kB), infotaxis 0.543 (at 72 s: the posteriors
#: 674 -> 242 kB), paper-s4 for 30 s 0.629 (the urban layers' static images as PNGs too).
TRIALS = {("open-field", "surge-cast", 1001, 60.0): 0.69, ("open-field", "infotaxis", 1001, 60.0): 0.55,
          ("paper-s4", "surge-cast", 101, 20.0): 0.625}  # fmt: skip
IMAGE_PARTS = ("Image:", "EncodedImage:")
Content = tuple[dict[str, dict[str, object]], dict[str, list[tuple[int, str]]]]


@pytest.fixture(scope="module", params=sorted(TRIALS), ids=lambda k: f"{k[0]}-{k[1]}")
def pair(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> tuple[tuple, Path, Path]:
    scenario, strategy, seed, limit_s = request.param
    d = tmp_path_factory.mktemp(f"{scenario}-{strategy}")
    new, old = d / "new.rrd", d / "old.rrd"
    run_trial(scenario, strategy, seed=seed, time_limit_s=limit_s, recorder=TrialRecorder(new))
    run_trial(scenario, strategy, seed=seed, time_limit_s=limit_s,
              recorder=TrialRecorder(old, png_images=False, footer=True))  # fmt: skip
    return request.param, old, new


def _content(path: Path) -> Content:
    """Everything a recording holds, however it is cut into chunks and encoded: per entity the last
    static value of each component, the sorted (time [ns], value) rows of each temporal component; an
    image's pixels (raw or PNG) as one value, its opacity and draw order under neutral names."""
    static: dict[str, dict[str, object]] = {}
    rows: dict[str, list[tuple[int, str]]] = {}
    images: set[str] = set()
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message="RRD file has no footer")
        chunks = RrdReader(path).stream().to_chunks()
    for chunk in chunks:
        rb = chunk.to_record_batch()
        entity = chunk.entity_path.strip("/")
        for name in (n for n in rb.schema.names if n not in ("rerun.controls.RowId", TIMELINE)):
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
