"""Review a real flight: read a log, re-run the wind estimator offline, write a Rerun recording, report.

:func:`review` reads a ``.tlog`` (:mod:`review.tlog`), ``.ulg`` (:mod:`review.ulog`) or ArduPilot
DataFlash ``.bin`` (:mod:`review.dataflash`), recognised by content (:mod:`review.detect`), re-runs a
fresh :class:`~estimator.ukf.WindEstimator` over each airborne segment (:mod:`review.estimate`),
marks which samples of the estimate are trusted (:mod:`review.trust`), writes a ``.rrd`` with the
live runs' layout (:mod:`review.rrd`) and builds the summary (:mod:`review.summary`).

Airborne segments come from the landed state, else arming, else none (never airborne). A log from
which nothing could be decoded (a truncated or corrupt file) gives a result with ``usable`` False,
no recording, and the reason in ``summary["error"]``.
"""

from __future__ import annotations

import os
import stat
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from estimator.ukf import EstimatorConfig
from review.airborne import judge_airborne
from review.detect import detect_format
from review.estimate import EstimatorTrack, run_estimator
from review.flight import FlightData
from review.progress import NoProgress
from review.rrd import write_rrd
from review.summary import missing_inputs, summarize
from review.trust import Trust, trust_mask
from review.vehicle_info import model_caveat
from vehicle.vehicle_file import load_vehicle


def read_flight(path: Path | str, motor_order: str = "auto", w_max_rad_s: float | None = None,
                progress: NoProgress | None = None) -> FlightData:  # fmt: skip
    """Read a ``.tlog``, ``.ulg`` or DataFlash ``.bin`` (recognised by its content) into :class:`FlightData`."""
    path = Path(path)
    kind = detect_format(path)
    w_max = 600.0 if w_max_rad_s is None else w_max_rad_s
    tick = (progress or NoProgress()).stage("reading")
    if kind == "ulog":
        from review.ulog import read_ulog

        fd = read_ulog(path, motor_order, w_max)
    elif kind == "dataflash":
        from review.dataflash import read_dataflash

        fd = read_dataflash(path, motor_order, w_max)
    else:
        from review.tlog import read_tlog

        fd = read_tlog(path, motor_order, w_max, progress=tick)
    judge_airborne(fd)
    suffixes = {"tlog": (".tlog",), "ulog": (".ulg", ".ulog"), "dataflash": (".bin",)}[kind]
    if path.suffix.lower() not in suffixes:
        fd.notes.append(f"read as a {kind} by its content (the file name ends in {path.suffix or 'nothing'})")
    return fd


@dataclass
class ReviewResult:
    """Outcome of :func:`review`: the decoded log, our estimate, the report and the output file."""

    flight: FlightData
    track: EstimatorTrack | None
    out: Path
    missing: list[str]
    summary: dict[str, Any]

    @property
    def usable(self) -> bool:
        return bool(self.summary.get("usable", True))


def _unusable(fd: FlightData, out: Path) -> ReviewResult:
    reason = "nothing usable in the log (no time series could be decoded)"
    if fd.warnings:
        reason += ": " + "; ".join(fd.warnings)
    s = {"file": str(fd.path), "kind": fd.kind, "autopilot": fd.autopilot, "usable": False, "error": reason,
         "notes": fd.notes, "warnings": fd.warnings, "messages": dict(sorted(fd.counts.items())),
         "out": None}  # fmt: skip
    return ReviewResult(fd, None, out, [], s)


def _check_writable(out: Path) -> None:
    """Fail before the work, not after it, when the recording cannot be written there. A folder
    without any write bit counts as read-only even for root (a shared data folder, for one)."""
    parent = next((p for p in (out.parent, *out.parent.parents) if p.exists()), Path("."))
    no_bits = not parent.stat().st_mode & (stat.S_IWUSR | stat.S_IWGRP | stat.S_IWOTH)
    if out.is_dir() or no_bits or not os.access(parent, os.W_OK) or (out.exists() and not os.access(out, os.W_OK)):
        raise PermissionError(f"{out}: cannot write the recording there (give another place with -o)")


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
    imu_rate_hz: float | None = None,
    progress: NoProgress | None = None,
) -> ReviewResult:
    """Convert one log to a ``.rrd`` (default: next to the input, suffix ``.rrd``) and report.

    Args:
        path: ``.tlog``, ``.ulg`` or ``.bin``.
        out: output ``.rrd`` path.
        vehicle: vehicle file of the force model (name or ``.toml`` path).
        motor_order: ESC/output -> rotor order, ``auto``, ``windseek`` or ``quad-x``.
        config: estimator tuning.
        rate_hz: rate [Hz] of the estimate, pose and rotor series in the recording.
        settle_s: seconds at the start of each airborne segment whose estimate is not trusted.
        min_height_m: estimate samples lower than this above the ground [m] are not trusted.
        imu_rate_hz: IMU rate fed to the estimator: None (auto: decimated only on long logs), 0
            (every sample) or a rate [Hz] (see :mod:`review.estimate`).
        progress: progress display (:class:`review.progress.Stages`), silent by default.
    """
    path = Path(path)
    out = path.with_suffix(".rrd") if out is None else Path(out)
    _check_writable(out)
    progress = progress or NoProgress()
    params = load_vehicle(vehicle)
    fd = read_flight(path, motor_order, params.rotor_speed_max_rad_s, progress)
    if not fd.has_data:
        return _unusable(fd, out)
    missing, can = missing_inputs(fd)
    track: EstimatorTrack | None = None
    trust: Trust | None = None
    if can:
        track = run_estimator(fd, params, config, rate_hz, imu_rate_hz, progress.stage("estimating"))
        trust = trust_mask(fd, track, settle_s, min_height_m)
    model = model_caveat(fd.vehicle_type, str(vehicle), simulated=fd.family == "windseek SITL")
    summary = summarize(fd, track, trust, missing, out, settle_s, min_height_m, model)
    tick = progress.stage("writing")
    write_rrd(fd, track, None if trust is None else trust.ok, out, missing, rate_hz, figure=summary)
    if tick is not None:
        tick(1.0)
    return ReviewResult(fd, track, out, missing, summary)


__all__ = ["ReviewResult", "read_flight", "review"]
