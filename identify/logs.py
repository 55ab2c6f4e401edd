"""Flight logs as identification data: a PX4 ULog, a MAVLink telemetry log (.tlog) or an ArduPilot
DataFlash log (.bin), read by the review's readers (:mod:`review`: SI, NED world, FRD body) and turned
into :class:`identify.flight_data.FlightData`.

What is taken from the log:

- the time base is the IMU's: its samples inside the airborne record, in seconds from the log's start
  (the log's clock minus its whole seconds before the first sample, as ``windseek review`` counts);
- specific force (m/s^2, FRD) and rates (rad/s, FRD): the IMU, at least :data:`MIN_IMU_HZ`;
- attitude (quaternion body FRD -> NED) and ground velocity (NED, m/s) interpolated at the IMU's times
  (the quaternion's sign made continuous first, the result normalized);
- rotor speeds (rad/s, the vehicle's rotor order): ESC telemetry when the log has it; the actuator
  outputs through the vehicle's motor map (:mod:`identify.log_outputs`) are the ``rotor_commands``; a log
  without ESC telemetry gives as rotor speeds these commanded speeds through the motor's first-order
  lag (:class:`estimator.rpm_free.MotorCommandModel`, the vehicle file's time constant);
- the wind is **assumed zero**: a log does not know it (fly the identification in calm air); the wind
  there was goes into the fit's error.

The airborne record runs from the first airborne segment's start to the last one's end (the review's
:meth:`review.flight.FlightData.airborne_segments`: the landed state, else arming), cut to ``window``.
Excluded, each with its reason (:meth:`FlightData.exclude`):

- samples between airborne segments (on the ground);
- ground contact and ground effect: less than ``min_height_m`` above the ground level (the median down
  position on the ground in the :data:`GROUND_LOOKBACK_S` before the segment, else after it; without a
  position on the ground the check is not made, and a note says so);
- a motor output at its minimum or maximum (saturation; the outputs as held, +- :data:`SATURATION_MARGIN_S`);
  without outputs, an ESC speed within 1 % of the vehicle file's rotor speed limits;
- samples farther than :data:`MAX_GAP_S` from every attitude, velocity or rotor sample.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from estimator.motor_output import OutputMap
from estimator.rpm_free import MotorCommandModel
from identify.flight_data import MIN_DURATION_S, FlightData, runs, widen
from identify.log_checks import problems
from identify.log_outputs import actuator_outputs, commanded_speeds, motor_map, to_rotor_order
from review import flight as rf
from review.dataflash import read_dataflash
from review.detect import detect_format
from review.tlog import read_tlog
from review.ulog import read_ulog
from vehicle.params import VehicleParams

READERS = {"ulog": read_ulog, "tlog": read_tlog, "dataflash": read_dataflash}
KIND_WORDS = {"ulog": "PX4 ULog", "tlog": "MAVLink telemetry log", "dataflash": "DataFlash log"}
#: Slowest IMU usable: the moments come from the gyro's derivative (0.1 s Savitzky-Golay), the fit is at 50 Hz.
MIN_IMU_HZ = 50.0
SATURATION_MARGIN_S = 0.1
#: An output within this of 0 or 1 (normalized) is at its limit: half a microsecond of 1000-2000 us PWM.
SATURATION_TOL = 5e-4
GROUND_LOOKBACK_S = 30.0
MAX_GAP_S = 0.5


@dataclass(frozen=True, eq=False)
class LogFlight:
    """A log as identification data, with remarks for the user (what was used, what was not checked)
    and the review's decoding of the log."""

    data: FlightData
    notes: tuple[str, ...]
    log: rf.FlightData


def flight_data_from_log(path: Path | str, vehicle: VehicleParams, motor_order: str = "vehicle",
                         window: tuple[float, float] | None = None, *, output_profile: str = "px4",
                         thr_mdl_fac: float | None = None, min_height_m: float = 1.0) -> FlightData:  # fmt: skip
    """The identification data of the log at ``path`` for ``vehicle`` (see the module docstring).

    ``motor_order``: ``vehicle`` (its px4_outputs), ``quad-x`` or ``windseek`` (:mod:`identify.log_outputs`);
    ``window``: (start, end) s from the log's start; ``output_profile``, ``thr_mdl_fac``: the motor map.
    Raises ValueError (one line) naming what is missing or unusable."""
    return read_log(path, vehicle, motor_order, window, output_profile=output_profile, thr_mdl_fac=thr_mdl_fac,
                    min_height_m=min_height_m).data  # fmt: skip


def read_log(path: Path | str, vehicle: VehicleParams, motor_order: str = "vehicle",
             window: tuple[float, float] | None = None, *, output_profile: str = "px4",
             thr_mdl_fac: float | None = None, min_height_m: float = 1.0) -> LogFlight:  # fmt: skip
    """:func:`flight_data_from_log` with the notes and the decoded log."""
    path = Path(path)
    kind = detect_format(path)
    omap = motor_map(vehicle, motor_order, output_profile, thr_mdl_fac)
    log = READERS[kind](path, motor_order="windseek", w_max_rad_s=1.0)  # as logged: ESC / output k in column k
    outputs, out_src = actuator_outputs(path, log)
    vel = _finite(log.velocity)
    found = problems(log, vehicle, vel, outputs, MIN_IMU_HZ)
    if found:
        raise ValueError(f"{path.name}: cannot identify from this log: {'; '.join(found)}")
    origin = _origin(log)
    a, b = _record(path, log, window, origin)
    imu = _finite(log.imu.between(a, b))
    t = imu.t
    notes = [f"time 0 = {origin:.0f} s of the log's clock; airborne record {a - origin:.1f}-{b - origin:.1f} s"]
    quat = _quaternions(log.attitude, t)
    velocity = _interp(vel, t)
    speeds, commands, rotor_words, sat, sat_why = _rotors(log, (outputs, out_src), omap, vehicle, t)
    notes.append(f"rotor speeds: {rotor_words}")
    tr = t - origin
    src = log.sources
    data = FlightData(t=tr, specific_force=imu.v[:, :3], rates=imu.v[:, 3:6], rotor_speeds=speeds,
                      velocity_ned=velocity, quaternion=quat, rotor_commands=commands,
                      source=f"{KIND_WORDS[kind]} {path.name} ({log.autopilot}, {log.vehicle_type}), airborne "
                      f"{a - origin:.1f}-{b - origin:.1f} s; IMU {src['imu']} {log.imu.rate_hz:.0f} Hz, attitude "
                      f"{src['attitude']}, velocity {src['velocity']}, rotor speeds {rotor_words}; wind assumed zero")
    data = _exclude(data, ~_in_segments(t, log.airborne_segments()), "on the ground between airborne segments")
    low, ground_notes = _near_ground(log, t, min_height_m)
    notes += ground_notes
    data = _exclude(data, low, f"ground contact or ground effect (less than {min_height_m:g} m above the ground)")
    data = _exclude(data, widen(sat, t, SATURATION_MARGIN_S), sat_why)
    rotor_times = log.rotors.t if len(log.rotors) else outputs.t
    for name, ts in (("attitude", log.attitude.t), ("velocity", vel.t), ("rotor", rotor_times)):
        data = _exclude(data, _far_from(ts, t), f"no {name} sample within {MAX_GAP_S:g} s")
    usable = float(data.mask.mean()) * (b - a)
    notes.append(f"{usable:.1f} s of the {b - a:.1f} s airborne record usable after the exclusions")
    data.check(vehicle.n_rotors)
    return LogFlight(data=data, notes=tuple(notes), log=log)


def split_record(data: FlightData, holdout: float = 0.3) -> tuple[FlightData, FlightData | None, str]:
    """(fit, validation, what was done): the first ``1 - holdout`` of the record (by time) to fit, the
    rest held out as the validation manoeuvre. Each part must last :data:`MIN_DURATION_S`: a shorter
    record (under 33.3 s at 30 %) is fitted whole, without validation."""
    t_cut = data.t[0] + (1.0 - holdout) * data.duration_s
    if min(t_cut - data.t[0], data.t[-1] - t_cut) < MIN_DURATION_S:
        return data, None, (f"no validation: the {data.duration_s:.1f} s record is too short to hold out "
                            f"{holdout:.0%} with {MIN_DURATION_S:g} s in each part; the whole record is fitted")
    fit = _slice(data, data.t < t_cut, f" [first {1 - holdout:.0%}: {data.t[0]:.1f}-{t_cut:.1f} s]")
    val = _slice(data, data.t >= t_cut, f" [last {holdout:.0%}, held out: {t_cut:.1f}-{data.t[-1]:.1f} s]")
    return fit, val, f"validation: the last {holdout:.0%} of the record ({t_cut:.1f}-{data.t[-1]:.1f} s) held out"


def _slice(data: FlightData, keep: np.ndarray, label: str) -> FlightData:
    def cut(a: np.ndarray | None) -> np.ndarray | None:
        return None if a is None else a[keep]

    return FlightData(t=data.t[keep], specific_force=data.specific_force[keep], rates=data.rates[keep],
                      rotor_speeds=data.rotor_speeds[keep], velocity_ned=data.velocity_ned[keep],
                      quaternion=data.quaternion[keep], source=data.source + label, wind_ned=data.wind_ned,
                      excluded=cut(data.excluded), exclusions=data.exclusions,
                      rotor_commands=cut(data.rotor_commands))  # fmt: skip


def _origin(log: rf.FlightData) -> float:
    """The whole seconds of the log's clock before its first sample (``review.rrd.time_origin``'s rule)."""
    t0 = log.time_range[0]
    return float(math.floor(t0)) if math.isfinite(t0) else 0.0


def _record(path: Path, log: rf.FlightData, window: tuple[float, float] | None, origin: float) -> tuple[float, float]:
    segs = log.airborne_segments()
    a, b = segs[0][0], segs[-1][1]
    if window is not None:
        a, b = max(a, origin + window[0]), min(b, origin + window[1])
        if b <= a:
            raise ValueError(f"{path.name}: the window {window[0]:g}-{window[1]:g} s holds no airborne time "
                             f"(airborne {segs[0][0] - origin:.1f}-{segs[-1][1] - origin:.1f} s)")  # fmt: skip
    if b - a < MIN_DURATION_S:
        raise ValueError(f"{path.name}: too short: {b - a:.1f} s airborne, at least {MIN_DURATION_S:g} s of flight "
                         "is needed")  # fmt: skip
    return a, b


def _finite(s: rf.Series) -> rf.Series:
    if not len(s.t):
        return s
    ok = np.all(np.isfinite(s.v.reshape(len(s.t), -1)), axis=1)
    return s if ok.all() else rf.Series(s.t[ok], s.v[ok], s.name)


def _interp(s: rf.Series, t: np.ndarray) -> np.ndarray:
    return np.column_stack([np.interp(t, s.t, s.v[:, k]) for k in range(s.v.shape[1])])


def _quaternions(s: rf.Series, t: np.ndarray) -> np.ndarray:
    """Attitude at ``t``: q and -q are one attitude, so the sign is made continuous before interpolating."""
    q = s.v.copy()
    flip = np.cumsum(np.concatenate([[0], np.einsum("ij,ij->i", q[1:], q[:-1]) < 0.0])) % 2 == 1
    q[flip] *= -1.0
    out = _interp(rf.Series(s.t, q), t)
    return out / np.linalg.norm(out, axis=1, keepdims=True)


def _rotors(log: rf.FlightData, logged_outputs: tuple[rf.Series, str], omap: OutputMap, vehicle: VehicleParams,
            t: np.ndarray) -> tuple[np.ndarray, np.ndarray | None, str, np.ndarray, str]:  # fmt: skip
    """(rotor speeds, commanded speeds or None, in words, saturated samples, why) at the IMU times ``t``."""
    n = vehicle.n_rotors
    outputs, out_src = logged_outputs
    commands = None
    if len(outputs):
        k = np.clip(np.searchsorted(outputs.t, t, side="right") - 1, 0, len(outputs.t) - 1)
        held = outputs.v[k, :n]
        sat = np.any((held <= SATURATION_TOL) | (held >= 1.0 - SATURATION_TOL), axis=1)
        sat_why = "motor output at its minimum or maximum"
        cmd_at_outputs = commanded_speeds(to_rotor_order(outputs.v, omap), omap)
        commands = _interp(rf.Series(outputs.t, cmd_at_outputs), t)
        out_words = f"the actuator outputs ({out_src}) through the motor map"
    if len(log.rotors):
        speeds = to_rotor_order(_interp(log.rotors, t), omap)
        words = f"ESC telemetry ({log.sources['rotors']})" + (f"; commands: {out_words}" if commands is not None
                                                              else "; no actuator outputs")  # fmt: skip
        if commands is None:
            lo, hi = 1.01 * vehicle.rotor_speed_min_rad_s, 0.99 * vehicle.rotor_speed_max_rad_s
            sat = np.any((speeds <= lo) | (speeds >= hi), axis=1)
            sat_why = "ESC speed within 1 % of the vehicle file's rotor speed limits (no actuator outputs)"
        return speeds, commands, words, sat, sat_why
    assert commands is not None
    lag = MotorCommandModel(vehicle.motor_time_constant_s, vehicle.rotor_speed_max_rad_s)
    lagged = np.array([lag.update(tk, c) for tk, c in zip(outputs.t, cmd_at_outputs, strict=True)])
    speeds = _interp(rf.Series(outputs.t, lagged), t)
    return speeds, commands, out_words + " and the motor lag (no ESC telemetry)", sat, sat_why


def _in_segments(t: np.ndarray, segs: list[tuple[float, float]]) -> np.ndarray:
    inside = np.zeros(len(t), dtype=bool)
    for a, b in segs:
        inside |= (t >= a) & (t <= b)
    return inside


def _near_ground(log: rf.FlightData, t: np.ndarray, min_height_m: float) -> tuple[np.ndarray, list[str]]:
    """Samples less than ``min_height_m`` above the ground level of their segment, and notes on segments
    whose ground level is unknown (no position on the ground near them)."""
    low = np.zeros(len(t), dtype=bool)
    pos = _finite(log.position)
    segs = log.airborne_segments()
    if not len(pos):
        return low, ["ground contact not checked: the log has no position"]
    notes = []
    origin = _origin(log)
    on_ground = ~_in_segments(pos.t, segs)
    for a, b in segs:
        before = on_ground & (pos.t >= a - GROUND_LOOKBACK_S) & (pos.t < a)
        after = on_ground & (pos.t > b) & (pos.t <= b + GROUND_LOOKBACK_S)
        sel = before if before.any() else after
        if not sel.any():
            notes.append(f"ground contact not checked for {a - origin:.1f}-{b - origin:.1f} s: no position logged "
                         f"on the ground within {GROUND_LOOKBACK_S:g} s of it")  # fmt: skip
            continue
        ground = float(np.median(pos.v[sel, 2]))
        seg = (t >= a) & (t <= b)
        low[seg] = ground - np.interp(t[seg], pos.t, pos.v[:, 2]) < min_height_m
    return low, notes


def _far_from(ts: np.ndarray, t: np.ndarray) -> np.ndarray:
    """True where the nearest of the times ``ts`` is farther than :data:`MAX_GAP_S` from ``t``."""
    j = np.clip(np.searchsorted(ts, t), 1, len(ts) - 1) if len(ts) > 1 else np.zeros(len(t), dtype=int)
    d = np.minimum(np.abs(ts[j] - t), np.abs(ts[j - 1] - t)) if len(ts) > 1 else np.abs(ts[0] - t)
    return d > MAX_GAP_S


def _exclude(data: FlightData, bad: np.ndarray, why: str) -> FlightData:
    """``data`` with ``bad`` excluded and the reason with its share and first spans; unchanged if none."""
    if not bad.any():
        return data
    spans = runs(bad, data.t)
    text = ", ".join(f"{a:.1f}-{b:.1f} s" for a, b in spans[:5]) + (f" and {len(spans) - 5} more" if len(spans) > 5
                                                                     else "")  # fmt: skip
    return data.exclude(bad, f"{why}: {bad.mean() * 100:.1f} % of samples ({text})")
