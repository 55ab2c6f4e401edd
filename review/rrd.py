"""Write a review to a Rerun ``.rrd`` with the live runs' layout (``recording.recorder``):

    world/vehicle, world/trail            the flown path (whenever the log has positions)
    world/wind/{truth,estimate}           arrows at the vehicle (trusted estimate only)
    wind/{north,east,down}/estimate       our trusted estimate, +- 2 sigma in .../band
    wind/{north,east,down}/truth          simulation truth (project SITL logs only)
    wind/{north,east,down}/autopilot      the autopilot's own estimate (PX4 WIND_COV / wind topic,
                                          ArduPilot WIND, XKF2/NKF2), for comparison
    wind/speed/*, wind/direction/*        horizontal speed and from-direction (deg), trusted only
    extra/untrusted_wind_m_s/{north,east,down}
                                          estimate samples NOT trusted (first seconds of a segment,
                                          near the ground: :mod:`review.trust`), kept out of the
                                          wind plots so that a take-off transient is not read as wind
    chem/log10                            chemical reading, log10 mg/m^3; the reading in mg/m^3 in the same
                                          rows (Chem:mg_m3, the series chem/value: recording.series)
    rotors                                rotor speeds, rad/s (measured, or implied), 4 values a row (the
                                          series rotors/1 .. rotors/4)
    flight/..., map/gps                   altitude, velocity, attitude, battery, GPS and the GPS track
                                          (:mod:`review.rrd_flight`); the layout opens on them
    log/events                            mode, arming and autopilot messages
    log/review                            what was present, missing and not trusted

Time: the ``vehicle_time`` timeline of the live recordings, counted from the log's start: the log's
own clock minus its whole seconds before the first sample (:func:`time_origin`). A PX4 SITL ULog
stamped in UNIX time (1.7e9 s) then reads 0..31 s like its flight, not "+19800d"; a boot clock that
starts within its first second (the project's SITL) keeps its times. The origin is in the summary.
"""

from __future__ import annotations

import math
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from recording.recorder import RunRecorder
from recording.sim_hook import wind_speed_from_deg
from recording.style import AXES
from recording.summary import RunSummary
from review.estimate import EstimatorTrack
from review.flight import FlightData, Series
from review.rrd_flight import write_flight
from review.summary import model_notes

UNTRUSTED = "untrusted_wind_m_s"

#: The recorder of a review: the autopilot's own wind estimate is a RunRecorder series.
ReviewRecorder = RunRecorder


def decimate(t: np.ndarray, dt: float) -> np.ndarray:
    """Indices of the first sample in each ``dt``-long bin of time (``t`` sorted)."""
    if not len(t):
        return np.zeros(0, dtype=int)
    b = np.floor((t - t[0]) / dt).astype(np.int64)
    return np.concatenate(([0], np.nonzero(np.diff(b))[0] + 1))


def _at(src: Series, t: np.ndarray, max_age_s: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Latest row of ``src`` at or before each t (zero-order hold), and where one exists (within max_age_s)."""
    j = np.searchsorted(src.t, t, side="right") - 1
    ok = j >= 0
    if max_age_s is not None:
        ok &= (t - src.t[np.maximum(j, 0)]) <= max_age_s
    return src.v[np.maximum(j, 0)] if len(src) else np.zeros((len(t), src.v.shape[1])), ok


def time_origin(fd: FlightData, track: EstimatorTrack | None = None) -> float:
    """The log clock's time [s] that the recording counts from: the whole seconds before the earliest
    time stamp of anything written (data, events, in-air changes, estimates); 0 for an empty log."""
    firsts = (
        [s.t[0] for s in (*fd.all_series(), *fd.shown_series()) if len(s)]
        + ([min(t for t, *_ in fd.texts)] if fd.texts else [])  # min() of nothing raises: no in-air state
        + ([min(t for t, _ in fd.in_air)] if fd.in_air else [])
        + ([track.t[0]] if track is not None and len(track.t) else [])
    )
    firsts = [float(t) for t in firsts if math.isfinite(float(t))]
    return float(math.floor(min(firsts))) if firsts else 0.0


def _shift(s: Series, dt: float) -> Series:
    return Series(s.t - dt, s.v, s.name)


def shifted(fd: FlightData, track: EstimatorTrack | None, dt: float) -> tuple[FlightData, EstimatorTrack | None]:
    """The log and the estimate with every time stamp moved ``dt`` [s] earlier (the data are shared)."""
    if dt == 0.0:
        return fd, track
    fd2 = replace(fd, in_air=[(t - dt, a) for t, a in fd.in_air], texts=[(t - dt, x, lv) for t, x, lv in fd.texts])
    for name in ("imu", "attitude", "velocity", "rotors", "rotor_cmd", "position", "chem", "truth_wind",
                 "autopilot_wind", "battery", "gps"):  # fmt: skip
        setattr(fd2, name, _shift(getattr(fd, name), dt))
    tr2 = None if track is None else replace(track, t=track.t - dt, segment_start=track.segment_start - dt)
    return fd2, tr2


def origin_text(t0: float) -> str:
    """What time 0 of the recording is on the log's clock (a UNIX time as a date, UTC)."""
    if t0 > 1.0e9:  # after 2001-09: a UNIX time stamp, not a boot clock
        when = time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime(t0))
        return f"time 0 = {t0:.0f} s of the log's clock (UNIX time: {when})"
    return f"time 0 = {t0:.0f} s of the log's clock (the autopilot's boot clock)"


def _pose(rec: ReviewRecorder, fd: FlightData, track: EstimatorTrack | None, ok: np.ndarray | None,
          dt: float) -> None:  # fmt: skip
    """Vehicle pose and wind arrows at the decimated position times."""
    idx = decimate(fd.position.t, dt)
    t, p = fd.position.t[idx], fd.position.v[idx]
    q, has_q = _at(fd.attitude, t)
    q = np.where(has_q[:, None], q, [1.0, 0.0, 0.0, 0.0])
    tw = fd.truth_wind
    has_true = (t >= tw.t[0]) & (t <= tw.t[-1]) if len(tw) else np.zeros(len(t), dtype=bool)
    w_true = np.column_stack([np.interp(t, tw.t, tw.v[:, k]) for k in range(3)]) if len(tw) else None
    w_est, has_est = np.zeros((len(t), 3)), np.zeros(len(t), dtype=bool)
    if track is not None and ok is not None and ok.any():
        trusted = Series(track.t[ok], track.wind[ok])
        w_est, has_est = _at(trusted, t, max_age_s=0.5)
    for i in range(len(t)):
        rec.vehicle(float(t[i]), p[i], q[i])
        wt = w_true[i] if has_true[i] and w_true is not None else None
        we = w_est[i] if has_est[i] else None
        if wt is not None or we is not None:
            rec.wind_arrows(float(t[i]), p[i], wt, we)


def _estimate(rec: ReviewRecorder, track: EstimatorTrack, ok: np.ndarray) -> None:
    """Trusted samples as the wind, the others under extra/untrusted_wind_m_s."""
    for i in range(len(track.t)):
        t = float(track.t[i])
        if ok[i]:
            rec.wind(t, est_ned=track.wind[i], sigma_ned=track.sigma[i])
            rec.wind_speed_dir(t, track.speed[i], track.direction_deg[i], speed_filt=None,
                               dir_filt_deg=track.direction_filtered_deg[i])  # fmt: skip
        else:
            for k, a in enumerate(AXES):
                rec.scalar(t, f"{UNTRUSTED}/{a}", float(track.wind[i, k]))


def outcome_text(figure: dict[str, Any] | None) -> str:
    """The review's result in one line, from its summary (:func:`review.summary.summarize`)."""
    if not figure:
        return ""
    if not figure.get("wind_figure"):
        return f"no wind figure: {figure.get('wind_figure_reason') or 'wind not estimated'}"
    m = figure["wind_mean_ned_ms"]
    return (f"wind {figure['wind_speed_mean_ms']:.2f} m/s from {figure['wind_from_mean_deg']:.0f}° (mean of "
            f"{figure['samples_scored']} trusted estimates: N {m[0]:.2f} E {m[1]:.2f} D {m[2]:.2f} m/s)")  # fmt: skip


def write_rrd(fd: FlightData, track: EstimatorTrack | None, ok: np.ndarray | None, out: Path, missing: list[str],
              rate_hz: float = 25.0, figure: dict[str, Any] | None = None) -> None:  # fmt: skip
    """Write the recording (see the module docstring); ``ok`` marks the trusted rows of ``track``;
    ``figure``, the review's summary, gives the recording summary's result line."""
    dt = 1.0 / rate_hz
    origin = time_origin(fd, track)
    fd, track = shifted(fd, track, origin)
    t0 = fd.time_range[0]
    t0 = 0.0 if not math.isfinite(t0) else t0
    with ReviewRecorder(out, scenario=fd.path.name, strategy="review") as rec:
        used = ", ".join(f"{k} <- {v}" for k, v in sorted(fd.sources.items()))
        rec.text(t0, f"review of {fd.path.name} ({fd.kind}, {fd.autopilot}): inputs {used}", "INFO", channel="review")
        rec.text(t0, origin_text(origin), "INFO", channel="review")
        for m in missing + fd.warnings:
            rec.text(t0, m, "WARN", channel="review")
        for n in fd.notes + fd.imu_notes:
            rec.text(t0, n, "DEBUG", channel="review")
        if track is not None and ok is not None and (~ok).any():
            rec.text(t0, f"{int((~ok).sum())} estimate sample(s) not trusted (settling after take-off, or near the "
                     f"ground): at extra/{UNTRUSTED}, not in the wind plots", "INFO", channel="review")  # fmt: skip
        for t, text, level in fd.texts:
            rec.autopilot_event(t, text, level)  # mode and arming changes also give the flight phases
        if len(fd.position):
            _pose(rec, fd, track, ok, dt)
        tw = fd.truth_wind
        for i in range(len(tw)):
            rec.wind(float(tw.t[i]), truth_ned=tw.v[i])
            s, d = wind_speed_from_deg(tw.v[i])
            rec.wind_speed_dir(float(tw.t[i]), None, None, truth_speed=s, truth_dir_deg=d)
        if track is not None and ok is not None:
            _estimate(rec, track, ok)
        for i in range(len(fd.autopilot_wind)):
            rec.autopilot_wind(float(fd.autopilot_wind.t[i]), fd.autopilot_wind.v[i])
        for i in range(len(fd.chem)):
            rec.chem(float(fd.chem.t[i]), float(fd.chem.v[i]))
        rot = fd.rotors_display
        for i in decimate(rot.t, dt):
            rec.rotors(float(rot.t[i]), rot.v[i])
        write_flight(rec, fd, dt)
        rec.first_tab = "flight"  # a log is looked at for its flight first (altitude, velocity, attitude)
        if len(fd.position):
            rec.set_scene([fd.position.v[0][:2]])
        rec.summary(RunSummary(kind=f"flight log review ({fd.kind} from {fd.autopilot}, {fd.duration_s:.1f} s)",
                               scenario=fd.path.name, wind_source="our estimator re-run offline on the logged "
                               "sensors" if track is not None and len(track.t) else "none: wind not estimated",
                               missing=list(missing), outcome=outcome_text(figure), search=False,
                               notes=model_notes(figure),
                               extra={"clock": origin_text(origin), "inputs": used or "none"}))  # fmt: skip


__all__ = ["ReviewRecorder", "decimate", "origin_text", "outcome_text", "shifted", "time_origin", "write_rrd"]
