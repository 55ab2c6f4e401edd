"""The review's report: what the log held, what was missing and what that cost, and the wind figures.

:func:`summarize` builds a JSON-able dictionary (m/s NED, deg from-direction); :func:`format_summary`
turns it into a few lines for people. The wind figures come only from trusted samples
(:mod:`review.trust`); when none qualifies the summary gives no figure and says why.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from review.estimate import EstimatorTrack
from review.flight import FlightData
from review.trust import Trust, figures, no_figure_reason

#: What each reader calls the message types / topics of an input group (for the "missing" sentences).
NAMES = {
    "tlog": {"imu": "HIL_SENSOR/HIGHRES_IMU/SCALED_IMU/RAW_IMU", "attitude": "ATTITUDE/ATTITUDE_QUATERNION",
             "velocity": "LOCAL_POSITION_NED/GLOBAL_POSITION_INT/GPS_RAW_INT",
             "esc": "ESC_STATUS/ESC_TELEMETRY_1_TO_4/RAW_RPM"},
    "ulog": {"imu": "sensor_combined", "attitude": "vehicle_attitude",
             "velocity": "vehicle_local_position/sensor_gps", "esc": "esc_status"},
    "dataflash": {"imu": "IMU", "attitude": "ATT", "velocity": "XKF1/NKF1/GPS", "esc": "ESC"},
}  # fmt: skip


def missing_inputs(fd: FlightData) -> tuple[list[str], bool]:
    """What the log lacks, as sentences, and whether the wind can be estimated at all."""
    names = NAMES[fd.kind]
    out: list[str] = []
    can = True
    for group in ("imu", "attitude", "velocity"):
        if group not in fd.sources:
            out.append(f"no {'IMU' if group == 'imu' else group} ({names[group]}): wind not estimated")
            can = False
    if "rotors" not in fd.sources:
        if "rotor_cmd" in fd.sources:
            uses = "the estimator uses" if can else "the estimator would use"
            out.append(f"no ESC telemetry ({names['esc']}): {uses} rotor speeds implied by the actuator outputs "
                       f"({fd.sources['rotor_cmd']})")  # fmt: skip
        else:
            out.append(f"no ESC telemetry ({names['esc']}) and no actuator outputs: wind not estimated")
            can = False
    if "in_air" not in fd.sources:
        out.append("no landed state and no arming state: the vehicle is taken as never airborne")
    if "position" not in fd.sources:
        out.append("no position: no trajectory, and no height check on the wind figure")
    if "chem" not in fd.sources:
        out.append("no chemical readings")
    if "autopilot_wind" not in fd.sources:
        out.append("no autopilot wind estimate to compare with")
    return out, can


def summarize(fd: FlightData, track: EstimatorTrack | None, trust: Trust | None, missing: list[str], out: Path,
              settle_s: float = 5.0, min_height_m: float = 1.0, model: str = "") -> dict[str, Any]:  # fmt: skip
    """The review summary (see the module docstring). ``trust`` is that of ``track`` (None without one)."""
    segs = fd.airborne_segments()
    s: dict[str, Any] = {
        "file": str(fd.path), "kind": fd.kind, "autopilot": fd.autopilot, "vehicle_type": fd.vehicle_type,
        "usable": True, "duration_s": round(fd.duration_s, 3),
        "airborne_s": round(sum(b - a for a, b in segs), 3), "airborne_segments": len(segs),
        "airborne_from": fd.sources.get("in_air"), "messages": dict(sorted(fd.counts.items())),
        "sources": dict(sorted(fd.sources.items())), "missing": missing, "notes": fd.notes,
        "warnings": fd.warnings, "imu": fd.imu_notes, "model": model,
        "wind_estimated": bool(track is not None and len(track.t)), "wind_figure": False, "out": str(out),
    }  # fmt: skip
    if track is None or trust is None or not len(track.t):
        if "imu" in fd.sources and not segs:
            s["wind_figure_reason"] = "not airborne: " + (
                fd.not_airborne or (f"{fd.sources['in_air']} never shows the vehicle in the air"
                                    if "in_air" in fd.sources else "no in-air state"))  # fmt: skip
        elif not s["wind_estimated"]:
            s["wind_figure_reason"] = "wind not estimated (inputs missing)"
        return s
    s.update(settle_s=settle_s, min_height_m=min_height_m if len(fd.position) else None, imu_steps=track.imu_steps,
             samples_total=len(track.t), samples_settling=trust.settling, samples_near_ground=trust.near_ground,
             imu_rate_hz=round(track.imu_rate_in_hz, 1), imu_rate_used_hz=round(track.imu_rate_used_hz, 1),
             imu_decimated=track.decimated, imu_gap_cuts=track.gap_cuts, rejected=dict(track.rejected),
             model_fit=track.model_fit)  # fmt: skip
    if not trust.ok.any():
        s["wind_figure_reason"] = no_figure_reason(fd, track, trust, settle_s, min_height_m)
        return s
    s["wind_figure"] = True
    s.update(figures(fd, track, trust))
    return s


def _vals(r: dict[str, float | None]) -> str:
    return "  ".join(f"{a} {r[a]:.3f}" for a in ("N", "E", "D", "horizontal") if r.get(a) is not None)


def _wind_lines(s: dict[str, Any]) -> list[str]:
    above = "" if s.get("min_height_m") is None else f", above {s['min_height_m']:g} m"
    m, sd = s["wind_mean_ned_ms"], s["wind_std_ned_ms"]
    fit = s.get("model_fit") or {}
    # The live estimator would publish nothing here (ModelFit's verdict): the figure is shown, marked as such.
    head = ("wind estimate WITHHELD by the model check, shown for reference only (biased by the model error)"
            if fit and not fit.get("model_fits") and fit.get("model_note") else "wind estimate")  # fmt: skip
    lines = [f"{head} ({s['samples_scored']} of {s['samples_total']} samples: after {s['settle_s']:g} s per "
             f"segment{above}): mean N {m[0]:.2f} E {m[1]:.2f} D {m[2]:.2f} m/s, std {sd[0]:.2f} {sd[1]:.2f} "
             f"{sd[2]:.2f} m/s; {s['wind_speed_mean_ms']:.2f} m/s from {s['wind_from_mean_deg']:.0f} deg"]  # fmt: skip
    if s.get("rmse_vs_truth_ms"):
        lines.append(f"RMSE vs simulation truth: {_vals(s['rmse_vs_truth_ms'])} m/s")
    am = s.get("autopilot_wind_mean_ned_ms")
    if am:
        d = "n/a" if am[2] is None else f"{am[2]:.2f}"
        md = s["mean_diff_vs_autopilot_ned_ms"]
        dd = "" if md[2] is None else f" D {md[2]:+.2f}"
        lines.append(f"the autopilot's estimate ({s['sources']['autopilot_wind']}) over the same samples: mean N "
                     f"{am[0]:.2f} E {am[1]:.2f} D {d} m/s; {s['autopilot_wind_speed_mean_ms']:.2f} m/s from "
                     f"{s['autopilot_wind_from_mean_deg']:.0f} deg")  # fmt: skip
        lines.append(f"ours minus the autopilot's: mean N {md[0]:+.2f} E {md[1]:+.2f}{dd} m/s; RMS difference "
                     f"{_vals(s['diff_vs_autopilot_ms'])} m/s")  # fmt: skip
    elif "autopilot_wind" in s["sources"]:
        lines.append("the autopilot's estimate: none over the scored samples")
    return lines


def model_notes(figure: dict[str, Any] | None) -> list[str]:
    """The force model's caveat and its verdict on this log, as the command line prints them (and the
    recording's summary carries them), from :func:`summarize`'s result."""
    if not figure:
        return []
    out = [str(figure["model"])] if figure.get("model") else []
    fit = figure.get("model_fit") or {}
    if fit:
        verdict = ("fits this vehicle" if fit.get("model_fits") else
                   fit.get("model_note") or "not judged (too little steady flight)")  # fmt: skip
        out.append(f"model in use: {fit.get('model')} ({fit.get('model_source')}): {verdict}")
    return out


def format_summary(s: dict[str, Any]) -> str:
    """The summary as a few human-readable lines."""
    if not s.get("usable", True):
        return f"{s['file']}: {s.get('error', 'nothing usable')}"
    air = f"{s['airborne_s']:.1f} s airborne in {s['airborne_segments']} segment(s)"
    air += f", from {s['airborne_from']}" if s.get("airborne_from") else ""
    lines = [
        f"{s['file']}: {s['kind']} from {s['autopilot']} ({s['vehicle_type']}), {s['duration_s']:.1f} s ({air})",
        "messages: " + ", ".join(f"{k} {v}" for k, v in s["messages"].items()),
        "inputs: " + (", ".join(f"{k} <- {v}" for k, v in s["sources"].items()) or "none"),
    ]
    lines += [f"missing: {m}" for m in s["missing"]]
    lines += [f"warning: {m}" for m in s["warnings"]]
    lines += [f"note: {n}" for n in s["notes"]]
    lines += [f"imu: {n}" for n in s["imu"]]
    if s.get("imu_decimated"):
        lines.append(f"imu: decimated from {s['imu_rate_hz']:g} Hz to {s['imu_rate_used_hz']:g} Hz (block means) "
                     "for the estimator, to bound its time on a long log; the vertical figure shifts most "
                     "(--imu-rate full: every sample)")  # fmt: skip
    if s.get("imu_gap_cuts"):
        lines.append(f"imu: {s['imu_gap_cuts']} gap(s) of more than 5 s in the IMU while airborne: a fresh filter "
                     "(and its settling time) after each")  # fmt: skip
    lines += model_notes(s)
    if s["wind_figure"]:
        lines += _wind_lines(s)
    else:
        lines.append("wind figure: none (" + s.get("wind_figure_reason", "wind not estimated") + ")")
    if s.get("rejected"):
        lines.append(f"rejected inputs: {s['rejected']}")
    lines.append(f"wrote {s['out']}")
    return "\n".join(lines)


__all__ = ["format_summary", "missing_inputs", "model_notes", "summarize"]
