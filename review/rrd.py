"""Write a review to a Rerun ``.rrd`` with the live runs' layout (``recording.rerun_log``):

    world/vehicle, world/trail            the flown path (whenever the log has positions)
    world/wind/{truth,estimate}           arrows at the vehicle (trusted estimate only)
    wind/{north,east,down}/estimate       our trusted estimate, +- 2 sigma in .../lower, .../upper
    wind/{north,east,down}/truth          simulation truth (project SITL logs only)
    wind/{north,east,down}/autopilot      the autopilot's own estimate (PX4 WIND_COV / wind topic,
                                          ArduPilot WIND, XKF2/NKF2), for comparison
    wind/speed/*, wind/direction/*        horizontal speed and from-direction (deg), trusted only
    extra/untrusted_wind_m_s/{north,east,down}
                                          estimate samples NOT trusted (first seconds of a segment,
                                          near the ground: :mod:`review.trust`), kept out of the
                                          wind plots so that a take-off transient is not read as wind
    chem/value                            chemical reading, mg/m^3
    rotors/{1..4}                         rotor speeds, rad/s (measured, or implied)
    log/events                            mode, arming and autopilot messages
    log/review                            what was present, missing and not trusted
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from recording.rerun_log import AXES, RunRecorder
from recording.sim_hook import wind_speed_from_deg
from review.estimate import EstimatorTrack
from review.flight import FlightData, Series

C_AUTOPILOT = (44, 160, 44)
UNTRUSTED = "untrusted_wind_m_s"


class ReviewRecorder(RunRecorder):
    """A :class:`RunRecorder` with one more series: the autopilot's own wind estimate."""

    def _send_static(self) -> None:
        super()._send_static()
        for a in AXES:
            self._style(f"wind/{a}/autopilot", "autopilot", C_AUTOPILOT, 1.5)
        self._style("wind/speed/autopilot", "autopilot", C_AUTOPILOT, 1.5)

    def __enter__(self) -> ReviewRecorder:
        return self

    def autopilot_wind(self, t: float, wind_ned: np.ndarray) -> None:
        """The autopilot's wind estimate [m/s, NED air-mass velocity]; NaN components are gaps."""
        for k, a in enumerate(AXES):
            self._push(f"wind/{a}/autopilot", t, float(wind_ned[k]))
        self._push("wind/speed/autopilot", t, math.hypot(float(wind_ned[0]), float(wind_ned[1])))
        self._maybe_flush(t)


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


def write_rrd(fd: FlightData, track: EstimatorTrack | None, ok: np.ndarray | None, out: Path, missing: list[str],
              rate_hz: float = 25.0) -> None:  # fmt: skip
    """Write the recording (see the module docstring); ``ok`` marks the trusted rows of ``track``."""
    dt = 1.0 / rate_hz
    t0 = fd.time_range[0]
    t0 = 0.0 if not math.isfinite(t0) else t0
    with ReviewRecorder(out, scenario=fd.path.name, strategy="review") as rec:
        used = ", ".join(f"{k} <- {v}" for k, v in sorted(fd.sources.items()))
        rec.text(t0, f"review of {fd.path.name} ({fd.kind}, {fd.autopilot}): inputs {used}", "INFO", channel="review")
        for m in missing + fd.warnings:
            rec.text(t0, m, "WARN", channel="review")
        for n in fd.notes + fd.imu_notes:
            rec.text(t0, n, "DEBUG", channel="review")
        if track is not None and ok is not None and (~ok).any():
            rec.text(t0, f"{int((~ok).sum())} estimate sample(s) not trusted (settling after take-off, or near the "
                     f"ground): at extra/{UNTRUSTED}, not in the wind plots", "INFO", channel="review")  # fmt: skip
        for t, text, level in fd.texts:
            rec.text(t, text, level)
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


__all__ = ["ReviewRecorder", "decimate", "write_rrd"]
