"""Complete a finished recording with a better summary: ``windseek demo`` after its processes exit.

The SITL writes the demo's ``.rrd`` and closes it at shutdown, before the demo has put the
mission's result next to the truth. :func:`rewrite_summary` rewrites the file with the new run
summary: every chunk is copied into a new file with the same application and recording id (the
old summary and result property left out), the new summary and the layout (rebuilt from the facts
stored in the recording) are added, and the new file replaces the old one atomically. A 5 MB
recording takes well under a second. The same rewrite merges in the mission's own recording
(``windseek mission --rrd``, :mod:`recording.mission_rrd`): its :data:`~recording.mission_rrd.MISSION_ONLY`
entities (the strategy's posterior and credible circle, the setpoints), on the same vehicle clock.
:func:`demo_summary` turns the demo's summary (the
``.json`` it writes) into a :class:`RunSummary`, keeping what only the recording knew (the phase
times on the vehicle clock, the path until within 5 m of the source, the verification sweeps).
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import rerun as rr
from rerun.chunk import RrdReader

from recording.layout import Layout, make_blueprint
from recording.mission_rrd import MISSION_ONLY
from recording.read import RrdLog
from recording.summary import RunSummary


def rewrite_summary(path: Path | str, summary: RunSummary, merge: Sequence[Path | str] = ()) -> None:
    """Replace the run summary of the closed recording ``path``, and copy the mission-only entities of the
    recordings ``merge`` (mission recordings of the same flight) into it (see the module docstring)."""
    path = Path(path)
    log = RrdLog(path)
    lay_json = log.property_value("layout", "json")
    reader = RrdReader(path)
    entry = reader.recordings()[0]
    tmp = path.with_name(path.name + ".tmp")
    out = rr.RecordingStream(entry.application_id, recording_id=entry.recording_id, send_properties=False)
    out.set_log_time_enabled(False)
    try:
        out.save(tmp)
        if log.blueprint_count:  # first: a viewer loading the file progressively opens on the final layout
            out.send_blueprint(make_blueprint(Layout.from_json(lay_json) if lay_json else None), make_active=True,
                               make_default=True)  # fmt: skip
        out.log("summary", rr.TextDocument(summary.markdown(), media_type="text/markdown"), static=True)
        out.send_property("result", rr.AnyValues(**summary.properties()))
        out.send_chunks(reader.stream().filter(content=["+ /**", "+ /__properties/**", "- /summary",
                                                        "- /__properties/result"]))
        for other in merge:  # another recording id: its chunks join this recording as they are sent here
            out.send_chunks(RrdReader(Path(other)).stream().filter(content=list(MISSION_ONLY)))
        out.flush()
        out.disconnect()
        os.replace(tmp, path)
    finally:
        with contextlib.suppress(OSError):
            tmp.unlink()


def demo_summary(demo: dict[str, Any], before: RunSummary | None = None) -> RunSummary:
    """A :class:`RunSummary` from ``windseek demo``'s summary dictionary, over ``before`` (what the
    recording's own summary had: phase times, reach path, start distance, sweeps)."""
    s = before or RunSummary()
    mission = demo.get("mission") or {}
    s.kind = "windseek demo (SITL, wind estimator and MAVSDK mission as three MAVLink processes)"
    s.scenario, s.strategy, s.seed = demo.get("scenario"), demo.get("strategy"), demo.get("seed")
    s.found, s.outcome, s.cause = bool(demo.get("found")), str(demo.get("reason", "")), demo.get("cause")
    s.declared_ned, s.confidence = demo.get("declared_ned_m"), demo.get("confidence")
    s.true_sources_ned = demo.get("true_sources_ned_m") or s.true_sources_ned
    s.error_m = demo.get("declared_error_horizontal_m")
    s.time_to_declaration_s = demo.get("time_to_declaration_s")
    s.mission_time_s = demo.get("mission_time_s")
    s.search_path_m = demo.get("search_path_m")
    s.total_path_m = demo.get("path_length_m")
    s.wind_rmse_ned_m_s = demo.get("wind_rmse_ned_m_s")
    s.wind_rmse_horizontal_m_s = demo.get("wind_rmse_horizontal_m_s")
    s.wind_scored = demo.get("wind_estimates_scored")
    s.wind_source = mission.get("wind_source") or s.wind_source
    cr = mission.get("credible_radius_m")
    s.credible_radius_m = cr if isinstance(cr, (int, float)) else None
    # The mission counts its sweeps from arming; the recording saw them on the vehicle clock.
    sweeps = mission.get("verifications") or []
    if s.verifications and len(s.verifications) == len(sweeps):
        for mine, theirs in zip(s.verifications, sweeps, strict=True):
            mine["outcome"] = theirs.get("outcome", "")
            mine["duration_s"] = theirs.get("duration_s", mine.get("duration_s"))
    elif sweeps and s.t_arm_s is not None:
        s.verifications = [{"t_start_s": round(v["t_start_s"] + s.t_arm_s, 2), "duration_s": v.get("duration_s"),
                            "outcome": v.get("outcome", "")} for v in sweeps]  # fmt: skip
    s.extra = {"landed and disarmed": "yes" if mission.get("landed") and mission.get("disarmed") else "no",
               "wall time": f"{demo.get('wall_time_s', 0.0):.0f} s at speed {demo.get('speed', 1.0):g}"}  # fmt: skip
    s.notes = [n for n in s.notes if "demo" not in n]
    return s


def add_demo_result(path: Path | str, demo: dict[str, Any], mission_rrd: Path | str | None = None) -> RunSummary:
    """Rewrite the demo's recording with its result (the summary the demo printed) and the mission's
    posterior and setpoints from ``mission_rrd`` (the mission's own recording), if given; returns the summary."""
    before = RrdLog(path).summary()
    s = demo_summary(demo, before)
    rewrite_summary(path, s, [] if mission_rrd is None else [mission_rrd])
    return s


def merge_mission(path: Path | str, mission_rrd: Path | str) -> None:
    """Copy the mission's posterior and setpoints (``windseek mission --rrd``) into the SITL's closed recording
    ``path`` of the same flight, its own summary kept."""
    rewrite_summary(path, RrdLog(path).summary() or RunSummary(kind="recording"), [mission_rrd])


def main(argv: list[str] | None = None) -> int:
    """``python -m recording.finalize SITL.rrd MISSION.rrd``: :func:`merge_mission` from the command line."""
    import argparse

    ap = argparse.ArgumentParser(prog="python -m recording.finalize",
                                 description="Merge the mission's recording (windseek mission --rrd: the strategy's "
                                 "posterior, the setpoints) into the SITL's recording of the same flight (windseek "
                                 "sitl --rrd), in place.")  # fmt: skip
    ap.add_argument("sitl_rrd")
    ap.add_argument("mission_rrd")
    a = ap.parse_args(argv)
    merge_mission(a.sitl_rrd, a.mission_rrd)
    print(f"merged {a.mission_rrd} into {a.sitl_rrd}")
    return 0


__all__ = ["add_demo_result", "demo_summary", "merge_mission", "rewrite_summary"]

if __name__ == "__main__":
    raise SystemExit(main())
