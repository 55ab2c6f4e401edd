"""Re-run the wind estimator offline over the airborne segments of a :class:`FlightData`.

A fresh :class:`~estimator.ukf.WindEstimator` runs over each airborne segment (on the ground the
rotor model does not hold: the ground carries the weight). Its inputs are merged by time from the
columns, held inputs (attitude, rotor speeds) before the IMU sample that uses them at equal time
stamps. Without ESC telemetry, rotor speeds implied by the actuator outputs go through the motor lag
of ``estimator.rpm_free.MotorCommandModel``.

Cost: the UKF step is the review's bottleneck (about 0.5 ms per IMU sample here, each a predict and
an update). A long log's IMU is therefore decimated before the filter (:func:`decimate_imu`): block
means over 1 / rate windows (the mean specific force over the window, which is what the force model
predicts for the window), so that at most :data:`MAX_IMU_SAMPLES` samples are filtered, but never
below :data:`MIN_AUTO_IMU_RATE_HZ`; the summary says so. ``imu_rate_hz`` forces a rate (0: never
decimate). The accelerometer noise of the filter is left as tuned for single samples: scaling it
down by sqrt(n) for the means made the vertical wind of the PX4 SITL hover log worse (-0.5 m/s at
250 Hz, -12 m/s at 125 Hz: with a force model that is not the vehicle's, a filter that trusts the
IMU more puts the model error into the wind). Unscaled, the same log gives a horizontal mean within
0.03 m/s of the full rate at 100 Hz, and a vertical mean of -1.5 m/s instead of -0.5 m/s.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np

from estimator.model_fit import ModelFit
from estimator.rpm_free import MotorCommandModel
from estimator.ukf import EstimatorConfig, WindEstimator
from review.flight import FlightData, Series
from vehicle.params import VehicleParams

#: Above this many airborne IMU samples the IMU is decimated (about 100 s of UKF time here).
MAX_IMU_SAMPLES = 200_000
#: The automatic decimation goes no lower than this [Hz] (the filter's behaviour drifts below it).
MIN_AUTO_IMU_RATE_HZ = 100.0
#: A longer pause of the IMU [s] ends the filter's span; a fresh filter starts after it.
MAX_IMU_GAP_S = 5.0
#: Input kinds, in the tie-break order at equal time stamps (held inputs before the IMU sample).
K_ATT, K_ROT, K_CMD, K_IMU, K_VEL = 0, 1, 2, 3, 4
TICK_EVENTS = 4096


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
    imu_rate_in_hz: float = 0.0  # the log's IMU rate in the air
    imu_rate_used_hz: float = 0.0  # the rate the filter ran at (lower when decimated)
    gap_cuts: int = 0  # airborne segments cut at IMU gaps longer than MAX_IMU_GAP_S
    rejected: Counter[str] = field(default_factory=Counter)
    #: Does the model fit this vehicle? (``estimator.model_fit.ModelFit.summary`` and its mismatch line.)
    model_fit: dict[str, object] = field(default_factory=dict)

    @property
    def decimated(self) -> bool:
        return bool(self.imu_rate_used_hz < 0.95 * self.imu_rate_in_hz)


def decimate_imu(imu: Series, rate_hz: float) -> Series:
    """Block means of the IMU rows over windows of 1 / ``rate_hz`` s, timed at each window's last
    sample (so the held inputs before it still apply). Gyro NaN (no gyro) stays NaN."""
    if not len(imu) or rate_hz <= 0.0:
        return imu
    b = np.floor((imu.t - imu.t[0]) * rate_hz).astype(np.int64)
    starts = np.concatenate(([0], np.nonzero(np.diff(b))[0] + 1))
    n = np.diff(np.append(starts, len(b)))
    mean = np.add.reduceat(imu.v, starts, axis=0) / n[:, None]
    return Series(imu.t[starts + n - 1], mean, imu.name)


def filter_spans(fd: FlightData, imu: Series) -> tuple[list[tuple[float, float]], int]:
    """The spans a fresh filter runs over: the airborne segments, cut where the IMU stops for more than
    :data:`MAX_IMU_GAP_S` (a logging gap, or a damaged time stamp far ahead: the filter would bridge it
    in 20 ms prediction steps, millions of them). Returns the spans and how many cuts were made."""
    spans: list[tuple[float, float]] = []
    cuts = 0
    for a, b in fd.airborne_segments():
        t = imu.between(a, b).t
        if not len(t):
            continue
        gaps = np.nonzero(np.diff(t) > MAX_IMU_GAP_S)[0]
        cuts += len(gaps)
        starts = np.concatenate(([a], t[gaps + 1]))
        ends = np.concatenate((t[gaps], [b]))
        spans += [(float(s), float(e)) for s, e in zip(starts, ends, strict=True)]
    return spans, cuts


def airborne_imu(fd: FlightData) -> tuple[int, float]:
    """(IMU samples in the air, their mean rate [Hz])."""
    n, span = 0, 0.0
    for a, b in fd.airborne_segments():
        s = fd.imu.between(a, b)
        n += len(s)
        span += (s.t[-1] - s.t[0]) if len(s) > 1 else 0.0
    return n, (n / span if span > 0 else 0.0)


def _events(fd: FlightData, imu: Series, a: float, b: float, use_cmd: bool) -> tuple[list[Series], np.ndarray]:
    """The inputs of [a, b] and their merge order: (series per kind, (M, 2) array of (kind, row))."""
    parts = [fd.attitude.between(a, b), fd.rotors.between(a, b) if not use_cmd else Series.empty(4),
             fd.rotor_cmd.between(a, b) if use_cmd else Series.empty(4), imu.between(a, b),
             fd.velocity.between(a, b)]  # fmt: skip
    t = np.concatenate([p.t for p in parts])
    kind = np.concatenate([np.full(len(p), k) for k, p in enumerate(parts)])
    row = np.concatenate([np.arange(len(p)) for p in parts])
    order = np.lexsort((kind, t))
    return parts, np.column_stack([kind[order], row[order]])


def _run_segment(est: WindEstimator, motor: MotorCommandModel, parts: list[Series], ev: np.ndarray,
                 seg: tuple[float, float], dt_out: float, out: list[np.ndarray],
                 tick: Callable[[int], None] | None = None, fit: ModelFit | None = None) -> int:  # fmt: skip
    """Feed one segment's events; append output rows (every ``dt_out`` s); return the IMU steps taken.
    ``tick(n)`` is called every :data:`TICK_EVENTS` events with the number of events fed since the last call;
    ``fit`` judges the model on every IMU step (the segment is airborne)."""
    steps, t_next = 0, -math.inf
    att, rot, cmd, imu, vel = parts
    for n, (k, i) in enumerate(ev.tolist()):
        if tick is not None and n % TICK_EVENTS == TICK_EVENTS - 1:
            tick(TICK_EVENTS)
        if k == K_IMU:
            t = float(imu.t[i])
            g = imu.v[i, 3:6]
            if est.imu(t, imu.v[i, :3], None if np.isnan(g[0]) else g):
                steps += 1
                if fit is not None:
                    converged = est.wind_sigma_h() < 1.0
                    fit.sample(t, imu.v[i, :3], g, est.rotor_speeds, True, est.airspeed_body(), converged, est.last_nis)
                e = est.estimate()
                if t >= t_next:
                    t_next = t + dt_out
                    extra = [e.speed_h, e.direction_deg, e.direction_filtered_deg]
                    out.append(np.concatenate(([t, seg[0]], e.wind_ned, e.sigma_ned, extra)))
        elif k == K_ATT:
            est.set_attitude(float(att.t[i]), att.v[i])
        elif k == K_VEL:
            v = vel.v[i]
            est.gnss_velocity(float(vel.t[i]), v[:2] if np.isnan(v[2]) else v)
        elif k == K_ROT:
            est.set_rotor_speeds(float(rot.t[i]), rot.v[i])
        else:
            w = motor.update(float(cmd.t[i]), cmd.v[i])
            if w is not None:
                est.set_rotor_speeds(float(cmd.t[i]), w)
    return steps


def run_estimator(
    fd: FlightData,
    params: VehicleParams,
    config: EstimatorConfig | None = None,
    rate_hz: float = 25.0,
    imu_rate_hz: float | None = None,
    progress: Callable[[float], None] | None = None,
) -> EstimatorTrack:
    """Run a fresh estimator over each airborne segment of ``fd`` and sample it at ``rate_hz``.

    ``imu_rate_hz``: None (auto: decimate only above :data:`MAX_IMU_SAMPLES` airborne samples),
    0 (never), or the IMU rate [Hz] to decimate to.
    """
    config = config or EstimatorConfig.for_vehicle(params)
    n_imu, rate_in = airborne_imu(fd)
    target = imu_rate_hz
    if target is None:
        target = max(rate_in * MAX_IMU_SAMPLES / n_imu, MIN_AUTO_IMU_RATE_HZ) if n_imu > MAX_IMU_SAMPLES else 0.0
    imu = decimate_imu(fd.imu, target) if 0.0 < target < 0.95 * rate_in else fd.imu
    rate_used = rate_in if imu is fd.imu else min(rate_in, target)
    if imu is not fd.imu:  # the direction filter is designed for the rate it is fed at
        config = replace(config, direction_rate_hz=rate_used)
    use_cmd = not len(fd.rotors) and len(fd.rotor_cmd) > 0
    rows: list[np.ndarray] = []
    rejected: Counter[str] = Counter()
    steps = 0
    segs, cuts = filter_spans(fd, imu)
    events = [_events(fd, imu, a, b, use_cmd) for a, b in segs]
    total = max(sum(len(ev) for _, ev in events), 1)
    done = [0]

    def tick(n: int) -> None:
        done[0] += n
        if progress is not None:
            progress(min(done[0] / total, 1.0))

    fit = ModelFit(params)
    for seg, (parts, ev) in zip(segs, events, strict=True):
        est = WindEstimator(params, config)
        motor = MotorCommandModel(params.motor_time_constant_s, params.rotor_speed_max_rad_s)
        steps += _run_segment(est, motor, parts, ev, seg, 1.0 / rate_hz, rows, tick, fit)
        rejected.update(est.rejected)
    a = np.array(rows) if rows else np.zeros((0, 11))
    return EstimatorTrack(
        t=a[:, 0], segment_start=a[:, 1], wind=a[:, 2:5], sigma=a[:, 5:8], speed=a[:, 8],
        direction_deg=a[:, 9], direction_filtered_deg=a[:, 10], imu_steps=steps, imu_rate_in_hz=rate_in,
        imu_rate_used_hz=rate_used, gap_cuts=cuts, rejected=rejected,
        model_fit={**fit.summary(), "model_note": fit.mismatch},
    )  # fmt: skip


__all__ = ["MAX_IMU_SAMPLES", "EstimatorTrack", "decimate_imu", "run_estimator"]
