"""Review a real flight: re-run the wind estimator offline on a log and write a Rerun recording.

:func:`review` reads a ``.tlog`` (:mod:`review.tlog`) or ``.ulg`` (:mod:`review.ulog`), runs a
fresh :class:`~estimator.ukf.WindEstimator` over each airborne segment on the recorded
sensors (IMU, attitude, velocity, rotor speeds; rotor speeds implied by the actuator outputs
through the motor lag of ``estimator.rpm_free`` when there is no ESC telemetry), and writes a
``.rrd`` with the same entity layout and blueprint as a live run (``recording.rerun_log``):

    world/vehicle, world/trail            the flown path (whenever the log has positions)
    world/wind/{truth,estimate}           arrows at the vehicle
    wind/{north,east,down}/estimate       our estimate, +- 2 sigma in .../band
    wind/{north,east,down}/truth          simulation truth (project SITL logs only)
    wind/{north,east,down}/autopilot      the autopilot's own estimate (PX4 WIND_COV / wind
                                          topic, ArduPilot WIND), for comparison
    wind/speed/*, wind/direction/*        horizontal speed and from-direction (deg)
    chem/value                            chemical reading, mg/m^3
    rotors/{1..4}                         rotor speeds, rad/s (measured, or implied)
    log/events                            mode, arming and autopilot messages
    log/review                            what was present and what was missing

It also says what was missing and what that cost (:attr:`ReviewResult.missing`), e.g. "no ESC
telemetry: estimator ran on rotor speeds implied by the actuator outputs" or "no IMU: wind not
estimated". Times on the ``vehicle_time`` timeline are the log's boot-clock seconds.

Airborne segments come from the landed state (else arming); on the ground the rotor model
does not apply (the ground carries the weight), so the estimator only runs in the air and
starts afresh for each segment. Accuracy figures skip the first ``settle_s`` of each segment
(the filter starts with no wind prior).
"""

from __future__ import annotations

import bisect
import math
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from estimator.direction import from_direction_deg
from estimator.rpm_free import MotorCommandModel
from estimator.ukf import EstimatorConfig, WindEstimator
from recording.recorder import RunRecorder
from recording.sim_hook import wind_speed_from_deg
from recording.summary import RunSummary
from review.flight import FlightData
from vehicle.params import VehicleParams, load_vehicle

ULOG_MAGIC = b"ULog\x01\x12\x35"


def read_flight(path: Path | str, motor_order: str = "auto", w_max_rad_s: float | None = None) -> FlightData:
    """Read a ``.tlog`` or ``.ulg`` (by its first bytes, else its suffix) into :class:`FlightData`."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such file")
    with path.open("rb") as f:
        head = f.read(7)
    w_max = 600.0 if w_max_rad_s is None else w_max_rad_s
    if head == ULOG_MAGIC or path.suffix.lower() in (".ulg", ".ulog"):
        from review.ulog import read_ulog

        return read_ulog(path, motor_order, w_max)
    from review.tlog import read_tlog

    return read_tlog(path, motor_order, w_max)


@dataclass
class EstimatorTrack:
    """Our estimate at ``rate_hz`` (K rows): t [s], wind and 1-sigma [m/s NED], horizontal
    speed [m/s], from-direction raw and Butterworth-filtered [deg]."""

    t: np.ndarray
    wind: np.ndarray
    sigma: np.ndarray
    speed: np.ndarray
    direction_deg: np.ndarray
    direction_filtered_deg: np.ndarray
    segment_start: np.ndarray  # start time [s] of the airborne segment each row belongs to
    imu_steps: int = 0
    rejected: Counter[str] = field(default_factory=Counter)


def missing_inputs(fd: FlightData) -> tuple[list[str], bool]:
    """What the log lacks, as sentences, and whether the wind can be estimated at all."""
    tl = fd.kind == "tlog"
    out: list[str] = []
    can = True
    if "imu" not in fd.sources:
        out.append("no IMU (" + ("HIL_SENSOR/HIGHRES_IMU/SCALED_IMU" if tl else "sensor_combined")
                   + "): wind not estimated")  # fmt: skip
        can = False
    if "attitude" not in fd.sources:
        out.append("no attitude (" + ("ATTITUDE/ATTITUDE_QUATERNION" if tl else "vehicle_attitude")
                   + "): wind not estimated")  # fmt: skip
        can = False
    if "velocity" not in fd.sources:
        out.append("no velocity (" + ("LOCAL_POSITION_NED/GLOBAL_POSITION_INT/GPS_RAW_INT" if tl
                   else "vehicle_local_position/sensor_gps") + "): wind not estimated")  # fmt: skip
        can = False
    if "rotors" not in fd.sources:
        esc = "ESC_STATUS/RAW_RPM" if tl else "esc_status"
        if "rotor_cmd" in fd.sources:
            out.append(f"no ESC telemetry ({esc}): "
                       + ("estimator ran" if can else "estimator would run")
                       + f" on rotor speeds implied by the actuator outputs ({fd.sources['rotor_cmd']})")  # fmt: skip
        else:
            out.append(f"no ESC telemetry ({esc}) and no actuator outputs: wind not estimated")
            can = False
    if "position" not in fd.sources:
        out.append("no position: no trajectory")
    if "chem" not in fd.sources:
        out.append("no chemical readings")
    if "autopilot_wind" not in fd.sources:
        out.append("no autopilot wind estimate to compare with")
    return out, can


def run_estimator(
    fd: FlightData,
    params: VehicleParams,
    config: EstimatorConfig | None = None,
    rate_hz: float = 25.0,
) -> EstimatorTrack:
    """Run a fresh estimator over each airborne segment of ``fd`` and sample it at ``rate_hz``."""
    use_cmd = "rotors" not in fd.sources and "rotor_cmd" in fd.sources
    times = [r.t for r in fd.inputs]
    rows: list[np.ndarray] = []
    rejected: Counter[str] = Counter()
    steps = 0
    dt_out = 1.0 / rate_hz
    for t0, t1 in fd.airborne_segments():
        est = WindEstimator(params, config)
        motor = MotorCommandModel(params.motor_time_constant_s, params.rotor_speed_max_rad_s)
        t_next = -math.inf
        for r in fd.inputs[bisect.bisect_left(times, t0) : bisect.bisect_right(times, t1)]:
            kind = r.kind
            if kind == "imu":
                if est.imu(r.t, r.value[0], r.value[1]):
                    steps += 1
                    e = est.estimate()
                    if r.t >= t_next:
                        t_next = r.t + dt_out
                        extra = [e.speed_h, e.direction_deg, e.direction_filtered_deg]
                        rows.append(np.concatenate(([r.t, t0], e.wind_ned, e.sigma_ned, extra)))
            elif kind == "attitude":
                est.set_attitude(r.t, r.value)
            elif kind == "velocity":
                est.gnss_velocity(r.t, r.value)
            elif kind == "rotors" and not use_cmd:
                est.set_rotor_speeds(r.t, r.value)
            elif kind == "rotor_cmd" and use_cmd:
                w = motor.update(r.t, r.value)
                if w is not None:
                    est.set_rotor_speeds(r.t, w)
        rejected.update(est.rejected)
    a = np.array(rows) if rows else np.zeros((0, 11))
    return EstimatorTrack(
        t=a[:, 0], segment_start=a[:, 1], wind=a[:, 2:5], sigma=a[:, 5:8], speed=a[:, 8],
        direction_deg=a[:, 9], direction_filtered_deg=a[:, 10], imu_steps=steps, rejected=rejected,
    )  # fmt: skip


def _interp(t_src: np.ndarray, v_src: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Linear interpolation of (N, k) rows at t, and the mask of t inside the source's span."""
    inside = (t >= t_src[0]) & (t <= t_src[-1]) if len(t_src) else np.zeros(len(t), dtype=bool)
    out = np.full((len(t), v_src.shape[1]), np.nan)
    if len(t_src):
        for k in range(v_src.shape[1]):
            out[:, k] = np.interp(t, t_src, v_src[:, k])
    return out, inside


def _rmse(est: np.ndarray, ref: np.ndarray) -> dict[str, float | None]:
    d = est - ref
    out: dict[str, float | None] = {}
    for k, a in enumerate("NED"):
        col = d[:, k][np.isfinite(d[:, k])]
        out[a] = round(float(np.sqrt(np.mean(col**2))), 3) if len(col) else None
    h = np.hypot(d[:, 0], d[:, 1])
    h = h[np.isfinite(h)]
    out["horizontal"] = round(float(np.sqrt(np.mean(h**2))), 3) if len(h) else None
    return out


#: The recorder of a review: the autopilot's own wind estimate is a RunRecorder series now.
ReviewRecorder = RunRecorder


@dataclass
class ReviewResult:
    """Outcome of :func:`review`: the decoded log, our estimate, the report and the output file."""

    flight: FlightData
    track: EstimatorTrack | None
    out: Path
    missing: list[str]
    summary: dict


def _decimate(t: np.ndarray, dt: float) -> np.ndarray:
    """Indices of samples at least ``dt`` apart (the first always)."""
    keep: list[int] = []
    nxt = -math.inf
    for i, ti in enumerate(t):
        if ti >= nxt:
            keep.append(i)
            nxt = ti + dt
    return np.asarray(keep, dtype=int)


def write_rrd(fd: FlightData, track: EstimatorTrack | None, out: Path, missing: list[str],
              rate_hz: float = 25.0) -> None:  # fmt: skip
    """Write the recording (see the module docstring for the entities)."""
    dt = 1.0 / rate_hz
    t0, _ = fd.time_range
    t0 = 0.0 if not math.isfinite(t0) else t0
    with ReviewRecorder(out, scenario=fd.path.name, strategy="review") as rec:
        used = ", ".join(f"{k} <- {v}" for k, v in sorted(fd.sources.items()))
        rec.text(t0, f"review of {fd.path.name} ({fd.kind}, {fd.autopilot}): inputs {used}", "INFO", channel="review")
        for m in missing:
            rec.text(t0, m, "WARN", channel="review")
        for n in fd.notes:
            rec.text(t0, n, "DEBUG", channel="review")
        for t, text, level in fd.texts:
            rec.autopilot_event(t, text, level)  # mode and arming changes also give the flight phases
        att = fd.attitude
        tw = fd.truth_wind
        if len(fd.position):
            for i in _decimate(fd.position.t, dt):
                t = float(fd.position.t[i])
                p = fd.position.v[i]
                j = np.searchsorted(att.t, t, side="right") - 1 if len(att) else -1
                q = att.v[j] if j >= 0 else np.array([1.0, 0.0, 0.0, 0.0])
                rec.vehicle(t, p, q)
                w_true = None
                if len(tw) and tw.t[0] <= t <= tw.t[-1]:
                    w_true = np.array([np.interp(t, tw.t, tw.v[:, k]) for k in range(3)])
                w_est = None
                if track is not None and len(track.t):
                    k = np.searchsorted(track.t, t, side="right") - 1
                    if k >= 0 and t - track.t[k] <= 0.5:
                        w_est = track.wind[k]
                if w_true is not None or w_est is not None:
                    rec.wind_arrows(t, p, w_true, w_est)
        for i in range(len(tw)):
            t = float(tw.t[i])
            rec.wind(t, truth_ned=tw.v[i])
            s, d = wind_speed_from_deg(tw.v[i])
            rec.wind_speed_dir(t, None, None, truth_speed=s, truth_dir_deg=d)
        if track is not None:
            for i in range(len(track.t)):
                t = float(track.t[i])
                rec.wind(t, est_ned=track.wind[i], sigma_ned=track.sigma[i])
                rec.wind_speed_dir(t, track.speed[i], track.direction_deg[i], speed_filt=None,
                                   dir_filt_deg=track.direction_filtered_deg[i])  # fmt: skip
        for i in range(len(fd.autopilot_wind)):
            rec.autopilot_wind(float(fd.autopilot_wind.t[i]), fd.autopilot_wind.v[i])
        for i in range(len(fd.chem)):
            rec.chem(float(fd.chem.t[i]), float(fd.chem.v[i]))
        if len(fd.rotors):
            for i in _decimate(fd.rotors.t, dt):
                rec.rotors(float(fd.rotors.t[i]), fd.rotors.v[i])
        if len(fd.position):
            rec.set_scene([fd.position.v[0][:2]])
        rec.summary(RunSummary(kind=f"flight log review ({fd.kind} from {fd.autopilot}, {fd.duration_s:.1f} s)",
                               scenario=fd.path.name, wind_source="our estimator re-run offline on the logged "
                               "sensors" if track is not None and len(track.t) else "none: wind not estimated",
                               missing=list(missing), extra={"inputs": used or "none"}))  # fmt: skip


def summarize(fd: FlightData, track: EstimatorTrack | None, missing: list[str], out: Path,
              settle_s: float = 5.0, min_height_m: float = 1.0) -> dict:  # fmt: skip
    """The review summary as a JSON-able dictionary (m/s NED, deg from-direction).

    The wind figures leave out the first ``settle_s`` of each airborne segment and, when the log
    has positions, the samples less than ``min_height_m`` above the segment's take-off point.
    """
    segs = fd.airborne_segments()
    s: dict = {
        "file": str(fd.path),
        "kind": fd.kind,
        "autopilot": fd.autopilot,
        "duration_s": round(fd.duration_s, 3),
        "airborne_s": round(sum(b - a for a, b in segs), 3),
        "airborne_segments": len(segs),
        "messages": dict(sorted(fd.counts.items())),
        "sources": dict(sorted(fd.sources.items())),
        "missing": missing,
        "notes": fd.notes,
        "wind_estimated": bool(track is not None and len(track.t)),
        "out": str(out),
    }
    if not s["wind_estimated"]:
        return s
    ok = track.t >= track.segment_start + settle_s
    if len(fd.position) and min_height_m > 0:
        # Ground contact and ground effect: the landed state comes a fraction of a second to seconds
        # after touchdown (the autopilot's land detector), and the rotor model does not hold there.
        # Ground level: the lowest point of the segment and of the 30 s before it (the take-off point
        # or the touchdown; the in-air state may come only once the take-off is done).
        pt, pz = fd.position.t, fd.position.v[:, 2]
        z = np.interp(track.t, pt, pz)
        ground = {}
        for a, b in fd.airborne_segments():
            sel = (pt >= a - 30.0) & (pt <= b)
            ground[a] = float(pz[sel].max()) if sel.any() else math.nan
        z_ground = np.array([ground.get(a, math.nan) for a in track.segment_start])
        ok &= ~((z_ground - z) < min_height_m)  # NaN (no position there): kept
    if not ok.any():
        ok = np.ones(len(track.t), dtype=bool)
    w = track.wind[ok]
    mean = w.mean(axis=0)
    s["settle_s"] = settle_s
    s["min_height_m"] = min_height_m if len(fd.position) else None
    s["samples_scored"] = int(ok.sum())
    s["imu_steps"] = track.imu_steps
    s["wind_mean_ned_ms"] = [round(float(v), 3) for v in mean]
    s["wind_std_ned_ms"] = [round(float(v), 3) for v in w.std(axis=0)]
    s["wind_speed_mean_ms"] = round(float(math.hypot(mean[0], mean[1])), 3)
    s["wind_from_mean_deg"] = round(float(from_direction_deg(mean[0], mean[1])), 1)
    s["rejected"] = dict(track.rejected)
    t = track.t[ok]
    for key, ser in (("rmse_vs_truth_ms", fd.truth_wind), ("diff_vs_autopilot_ms", fd.autopilot_wind)):
        if len(ser):
            ref, inside = _interp(ser.t, ser.v, t)
            s[key] = _rmse(w[inside], ref[inside]) if inside.any() else None
        else:
            s[key] = None
    return s


def review(
    path: Path | str,
    out: Path | str | None = None,
    *,
    vehicle: str | Path = "nasa-quad",
    motor_order: str = "auto",
    config: EstimatorConfig | None = None,
    rate_hz: float = 25.0,
    settle_s: float = 5.0,
    min_height_m: float = 1.0,
) -> ReviewResult:
    """Convert one log to a ``.rrd`` (default: next to the input, suffix ``.rrd``) and report.

    Args:
        path: ``.tlog`` or ``.ulg``.
        out: output ``.rrd`` path.
        vehicle: vehicle file of the force model (name or ``.toml`` path).
        motor_order: ESC/output -> rotor order, ``auto``, ``windseek`` or ``quad-x``.
        config: estimator tuning.
        rate_hz: rate [Hz] of the estimate, pose and rotor series in the recording.
        settle_s: seconds at the start of each airborne segment left out of the figures.
        min_height_m: samples lower than this above the take-off point [m] are left out of the
            figures (touchdown comes before the landed state; ``windseek sitl`` scores the live
            estimate the same way).
    """
    path = Path(path)
    out = path.with_suffix(".rrd") if out is None else Path(out)
    params = load_vehicle(vehicle)
    fd = read_flight(path, motor_order, params.rotor_speed_max_rad_s)
    missing, can = missing_inputs(fd)
    track = None
    if can:
        track = run_estimator(fd, params, config, rate_hz)
        if not len(track.t):
            missing.append("the estimator produced no output (no airborne time with all inputs present)")
    write_rrd(fd, track, out, missing, rate_hz)
    return ReviewResult(fd, track, out, missing, summarize(fd, track, missing, out, settle_s, min_height_m))


def format_summary(s: dict) -> str:
    """The summary as a few human-readable lines."""
    lines = [
        f"{s['file']}: {s['kind']} from {s['autopilot']}, {s['duration_s']:.1f} s "
        f"({s['airborne_s']:.1f} s airborne in {s['airborne_segments']} segment(s))",
        "messages: " + ", ".join(f"{k} {v}" for k, v in s["messages"].items()),
        "inputs: " + (", ".join(f"{k} <- {v}" for k, v in s["sources"].items()) or "none"),
    ]
    lines += [f"missing: {m}" for m in s["missing"]]
    lines += [f"note: {n}" for n in s["notes"]]
    if s["wind_estimated"]:
        m, sd = s["wind_mean_ned_ms"], s["wind_std_ned_ms"]
        above = "" if s.get("min_height_m") is None else f", above {s['min_height_m']:g} m"
        lines.append(f"wind estimate (after {s['settle_s']:g} s per segment{above}): mean N {m[0]:.2f} E {m[1]:.2f} "
                     f"D {m[2]:.2f} m/s, std {sd[0]:.2f} {sd[1]:.2f} {sd[2]:.2f} m/s; "
                     f"{s['wind_speed_mean_ms']:.2f} m/s from {s['wind_from_mean_deg']:.0f} deg")  # fmt: skip
        for key, what in (("rmse_vs_truth_ms", "RMSE vs simulation truth"),
                          ("diff_vs_autopilot_ms", "RMS difference vs the autopilot's estimate")):  # fmt: skip
            r = s.get(key)
            if r:
                vals = "  ".join(f"{a} {r[a]:.3f}" for a in ("N", "E", "D", "horizontal") if r[a] is not None)
                lines.append(f"{what}: {vals} m/s")
            else:
                lines.append(f"{what}: n/a")
        if s["rejected"]:
            lines.append(f"rejected inputs: {s['rejected']}")
    else:
        lines.append("wind not estimated")
    lines.append(f"wrote {s['out']}")
    return "\n".join(lines)


__all__ = [
    "EstimatorTrack",
    "ReviewRecorder",
    "ReviewResult",
    "format_summary",
    "missing_inputs",
    "read_flight",
    "review",
    "run_estimator",
    "summarize",
    "write_rrd",
]
