"""The compass check on the same autopilot flights: the estimator's input replayed with it on and off.

``benchmarks/autopilot_wind.py --keep DIR`` leaves, per flight, the messages ``windseek estimator`` received
(``estimator.tlog``) and windseek's recording with the truth (``windseek.rrd``, with ``--rrd``). This replays
each log through :class:`estimator.live.LiveCore` three to five times (:func:`VARIANTS`: neither the compass
check of ``estimator/compass.py`` nor the autopilot's own heading sigma, the check alone, both, and on PX4
flights whose log holds SCALED_IMU and the CAL_MAG parameters, SCALED_IMU as the input without and with the
check on its raw field), so all see the very
same samples, and scores each against the truth: RMSE of 1-s means of the horizontal wind (the issue's
figure), the 95 % coverage of the stated horizontal uncertainty, and the heading error of the autopilot's
published attitude against windseek's true one.

Time: the autopilot's boot clock is aligned to the simulation's roughly by the lift-off (the first time above
2 m in GLOBAL_POSITION_INT, else LOCAL_POSITION_NED, and in the recording's altitude), then to the 0.02 s that
best matches the estimates made without the compass to the truth (the turbulence the estimator follows makes
a 1 s slip look like 1 m/s of error; PX4 in lockstep runs on the simulation's clock, ArduCopter on its own);
estimates are scored every 0.1 s from 10 s after the lift-off to the end of the recording's truth.

Usage: ``python benchmarks/compass_replay.py DIR [--imu-average N] [--sigma-deg S]`` (``--imu-average 2`` for
PX4 flights, as the benchmark's estimator ran; 1 for ArduCopter).
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path
from typing import Any

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
from toolchain import numba_cache  # noqa: E402 - before any kernel module

numba_cache.configure()
from estimator import mavlink_decode as dec  # noqa: E402
from estimator import px4_mag  # noqa: E402
from estimator.compass import CompassConfig  # noqa: E402
from estimator.live import LiveConfig, LiveCore  # noqa: E402
from estimator.px4_mag import Px4MagCalibration  # noqa: E402
from recording.read import RrdLog  # noqa: E402
from vehicle.frames import quat_to_dcm  # noqa: E402
from vehicle.vehicle_file import load_vehicle  # noqa: E402
from wire import param_codec  # noqa: E402

CHI2_95_2DOF = 5.991


def VARIANTS(sigma_deg: float) -> dict[str, CompassConfig]:  # noqa: N802 - a table
    """before: neither the check nor the autopilot's heading sigma; compass: the check alone; both; and on PX4
    flights whose log holds SCALED_IMU and the CAL_MAG parameters (``windseek/estimator_px4_mag.py``), the
    two of :data:`SCALED_IMU_INPUT`."""
    return {"before": CompassConfig(enabled=False, autopilot_sigma=False),
            "compass": CompassConfig(sigma_deg=sigma_deg, autopilot_sigma=False),
            "both": CompassConfig(sigma_deg=sigma_deg),
            "sc-before": CompassConfig(enabled=False, autopilot_sigma=False),
            "sc-raw": CompassConfig(sigma_deg=sigma_deg)}  # fmt: skip


#: Variants on PX4's SCALED_IMU as the IMU input (no EKF2 biases taken out; it must stream about as fast as
#: HIGHRES_IMU): "sc-before" with the published heading, "sc-raw" as ``windseek estimator`` runs on PX4 today
#: (``LiveCore.use_px4_raw``: the compass check on the raw field calibrated with the log's CAL_MAG parameters).
SCALED_IMU_INPUT = ("sc-before", "sc-raw")


def px4_calibration(msgs: list[Any]) -> Px4MagCalibration | None:
    """PX4's magnetometer calibration from the PARAM_VALUE answers in a log, None without (or unusable)."""
    values = {str(m.param_id).rstrip("\x00"): float(param_codec.decode(float(m.param_value), int(m.param_type)))
              for m in msgs if m.get_type() == "PARAM_VALUE"}  # fmt: skip
    cal = px4_mag.from_params(values) if values else None
    return cal if isinstance(cal, Px4MagCalibration) else None


def read_tlog(path: Path) -> list[Any]:
    """Every message of a telemetry log (8-byte time stamp, then one MAVLink frame), in order, parsed with
    the windseek dialect (common + ArduPilot's WIND and ESC_TELEMETRY_1_TO_4 + windseek's)."""
    from wire.dialect import mavlink as dialect

    data = Path(path).read_bytes()
    rx = dialect.MAVLink(None)
    rx.robust_parsing = True  # a broken record is a BAD_DATA, not an exception
    out: list[Any] = []
    i = 0
    while i + 8 < len(data):
        i += 8
        magic = data[i]
        if magic == 0xFD:
            n = 12 + data[i + 1] + (13 if data[i + 2] & 1 else 0)
        elif magic == 0xFE:
            n = 8 + data[i + 1]
        else:  # a record that is not a frame (an older log's BAD_DATA): on to the next time stamp + frame
            i = _next_record(data, i - 8)
            continue
        out += [m for m in rx.parse_buffer(data[i : i + n]) or [] if m.get_type() != "BAD_DATA"]
        i += n
    return out


def _next_record(data: bytes, at: int) -> int:
    """The offset of the next record after the broken one at ``at``: a time stamp within a minute of the
    broken record's, followed by a frame marker."""
    t0 = int.from_bytes(data[at : at + 8], "big")
    for j in range(at + 9, len(data) - 9):
        if data[j + 8] in (0xFD, 0xFE) and abs(int.from_bytes(data[j : j + 8], "big") - t0) < 60_000_000:
            return j
    return len(data)


def lift_off_s(t: np.ndarray, alt: np.ndarray) -> float:
    above = np.flatnonzero(alt > 2.0)
    if above.size == 0:
        raise ValueError("the vehicle never climbed above 2 m")
    return float(t[above[0]])


def replay(msgs: list[Any], compass: CompassConfig, imu_average: int, scaled_imu: bool = False,
           cal: Px4MagCalibration | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:  # fmt: skip
    """(autopilot times s, wind NED, covariance) every 0.1 s of the replayed estimator's output; ``scaled_imu``:
    SCALED_IMU as the IMU input, with ``cal`` its raw field for the compass check."""
    core = LiveCore(LiveConfig(vehicle=load_vehicle("nasa_quad"), imu_average=imu_average, esc_component=158,
                               compass=compass))  # fmt: skip
    if cal is not None:
        core.use_px4_raw(cal)
    elif scaled_imu:
        core.select.switch("imu", "SCALED_IMU")
    ts, ws, cs = [], [], []
    next_t = -math.inf
    for m in msgs:
        core.handle(m)
        if m.get_type() in dec.PREFERENCE["imu"] and (o := core.output()) is not None and o.t >= next_t:
            next_t = o.t + 0.1
            ts.append(o.t)
            ws.append(o.wind_ned)
            cs.append(o.cov_ned)
    return np.array(ts), np.array(ws), np.array(cs)


def score(t_sim: np.ndarray, w: np.ndarray, c: np.ndarray, truth: tuple[np.ndarray, ...], t0: float,
          t1: float) -> dict[str, float]:  # fmt: skip
    """1-s horizontal RMSE and 95 % coverage of the estimates in [t0, t1] (simulation time)."""
    sel = (t_sim >= t0) & (t_sim <= t1)
    tt, wn, we = truth
    tn, te = np.interp(t_sim[sel], tt, wn), np.interp(t_sim[sel], tt, we)
    en, ee = w[sel, 0] - tn, w[sel, 1] - te
    var_h = c[sel, 0, 0] + c[sel, 1, 1]
    covered = float(np.mean(en**2 + ee**2 <= CHI2_95_2DOF * var_h / 2.0))
    sec = np.floor(t_sim[sel]).astype(int)
    bins = np.unique(sec)
    mn = np.array([[en[sec == b].mean(), ee[sec == b].mean()] for b in bins])
    return {"rmse_1s_h": float(np.sqrt(np.mean(np.sum(mn**2, axis=1)))), "coverage_95_h": covered,
            "seconds": float(len(bins))}  # fmt: skip


def heading_errors(msgs: list[Any], log: RrdLog, offset: float, t0: float) -> np.ndarray:
    """The published attitude's heading error against windseek's truth (deg, about NED down) after ``t0``."""
    tq, qx = log.vectors("world/vehicle", "Transform3D:quaternion")  # rerun's x, y, z, w
    out = []
    for m in msgs:
        if m.get_type() != "ATTITUDE_QUATERNION" or m.time_boot_ms * 1e-3 + offset < t0:
            continue
        ts = m.time_boot_ms * 1e-3 + offset
        j = min(int(np.searchsorted(tq, ts)), len(tq) - 1)
        x, y, z, w = qx[j]
        err = quat_to_dcm(np.array([m.q1, m.q2, m.q3, m.q4])) @ quat_to_dcm(np.array([w, x, y, z])).T
        out.append(math.degrees(0.5 * (err[1, 0] - err[0, 1])))
    return np.array(out)


def flight(d: Path, imu_average: int, sigma_deg: float) -> dict[str, Any]:
    msgs = read_tlog(d / "estimator.tlog")
    log = RrdLog(d / "windseek.rrd")
    gp = [(m.time_boot_ms * 1e-3, m.relative_alt * 1e-3) for m in msgs if m.get_type() == "GLOBAL_POSITION_INT"]
    if not gp:  # ArduCopter's companion port: the height above the local origin
        gp = [(m.time_boot_ms * 1e-3, -m.z) for m in msgs if m.get_type() == "LOCAL_POSITION_NED"]
    ta, alt = np.array(gp).T
    tr, alt_r = log.scalars("flight/altitude/vehicle")
    rough = lift_off_s(tr, alt_r) - lift_off_s(ta, alt)  # simulation time - autopilot time
    tn, wn = log.scalars("wind/north/truth")
    truth = (tn, wn, log.scalars("wind/east/truth")[1])
    t0, t1 = lift_off_s(tr, alt_r) + 10.0, float(tn[-1])
    row: dict[str, Any] = {"flight": d.name}
    cal = px4_calibration(msgs)
    n_sc = sum(1 for m in msgs if m.get_type() == "SCALED_IMU")
    fast_sc = n_sc > 0.5 * sum(1 for m in msgs if m.get_type() == "HIGHRES_IMU") and cal is not None
    runs = {name: replay(msgs, cfg, imu_average, name in SCALED_IMU_INPUT, cal if name == "sc-raw" else None)
            for name, cfg in VARIANTS(sigma_deg).items() if name not in SCALED_IMU_INPUT or fast_sc}  # fmt: skip
    t, w, _ = runs["before"]
    sel = (t + rough > t0) & (t + rough < t1 - 3.0)

    def mismatch(o: float) -> float:
        return float(np.mean((w[sel, 0] - np.interp(t[sel] + o, tn, wn)) ** 2))

    offset = min(np.arange(rough - 3.0, rough + 3.0, 0.02), key=mismatch)
    row["clock_offset_s"] = round(float(offset), 2)
    for name, (t, w, c) in runs.items():
        row[name] = score(t + offset, w, c, truth, t0, t1)
    for name in VARIANTS(sigma_deg):
        row.setdefault(name, {"rmse_1s_h": math.nan, "coverage_95_h": math.nan, "seconds": 0.0})
    herr = heading_errors(msgs, log, offset, t0)
    row["heading_error_deg"] = {"mean": float(herr.mean()), "max_abs": float(np.abs(herr).max())}
    return row


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("root", help="an autopilot_wind.py --keep directory (flights with estimator.tlog and windseek.rrd)")
    ap.add_argument("--imu-average", type=int, default=1)
    ap.add_argument("--sigma-deg", type=float, default=CompassConfig().sigma_deg)
    args = ap.parse_args()
    dirs = sorted(p.parent for p in Path(args.root).glob("*/estimator.tlog") if (p.parent / "windseek.rrd").exists())
    if not dirs:
        print(f"no flight with estimator.tlog and windseek.rrd under {args.root}", file=sys.stderr)
        return 2
    names = list(VARIANTS(args.sigma_deg))
    head = "  ".join(f"{n + ': 1-s RMSE h, cov':>24}" for n in names)
    print(f"{'flight':<18} {'heading err mean/max deg':>24}  {head}")
    rows = []
    for d in dirs:
        r = flight(d, args.imu_average, args.sigma_deg)
        rows.append(r)
        h = r["heading_error_deg"]
        cells = "  ".join(f"{r[n]['rmse_1s_h']:>17.3f}, {r[n]['coverage_95_h']:.3f}" for n in names)
        print(f"{r['flight']:<18} {h['mean']:>+11.2f} / {h['max_abs']:<10.2f}  {cells}", flush=True)
    for name in names:
        rs = [r for r in rows if r[name]["seconds"]]
        if not rs:
            continue
        pooled = math.sqrt(float(np.mean([r[name]["rmse_1s_h"] ** 2 for r in rs])))
        cov = float(np.mean([r[name]["coverage_95_h"] for r in rs]))
        print(f"pooled, {name:<8}: 1-s horizontal RMSE {pooled:.3f} m/s, coverage {cov:.3f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
