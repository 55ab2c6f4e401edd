"""PX4 SIH identified through MAVLink, then its wind estimated with the identified model and with the wrong one.

Three stages, each on a fresh PX4 SIH (airframe 10040, PX4's own physics; no wind model) instance:

1. ``windseek identify --connect udpout://127.0.0.1:<API port> --vehicle px4-sih-quadx -o <file>``: the fitting
   and validation manoeuvres in one flight (offboard attitude + thrust setpoints), identification table
   (R^2 %, TIC and NRMSE per axis on the fitting and the validation manoeuvre);
2. ``windseek estimator --connect udpout://127.0.0.1:<GCS port> --vehicle <file> --esc-order px4
   --thr-mdl-fac 0`` as its own process, while a MAVSDK check flight (:mod:`mission.runners.check_flight`:
   take-off to 10 m, hover, three waypoints at 2.5 m/s, land) records the WIND_COV PX4 forwards: horizontal
   wind RMS about zero (SIH has no wind) in the hover and on the waypoints, on SCALED_IMU (streamed by PX4 on
   that link) and on HIGHRES_IMU (the estimator's own request; EKF2's accelerometer-bias estimate in it);
3. the same with ``--vehicle nasa-quad`` (the paper's 2.8 kg vehicle): the time from the end of the take-off
   to the estimator's model-mismatch verdict (``mismatch_t_s`` in its JSON) and the verdict itself; and with
   nasa-quad's file given SIH's measured accelerometer noise (whether the verdict is the model's or the noise's).

PX4 runs at ``--speed`` (PX4_SIM_SPEED_FACTOR; the loss timeouts are scaled with it). Usage:
``WINDSEEK_PX4_BIN=.../bin/px4 python benchmarks/px4_identify.py [--speed 4] [--duration 120]
[--validation-duration 60] [--hover 30] [--keep DIR]``.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import math
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
from toolchain import numba_cache  # noqa: E402 - before any kernel module

numba_cache.configure()
from mission.runners.check_flight import CheckFlightConfig, CheckFlightResult, fly_check  # noqa: E402
from sitl.hil.px4_process import Px4Sitl, free_instance, ports, px4_binary  # noqa: E402


def _cli(*args: str) -> list[str]:
    return [sys.executable, "-m", "windseek.cli", *args]


def _last_json(text: str) -> dict[str, Any]:
    for line in reversed(text.strip().splitlines()):
        with contextlib.suppress(ValueError):
            return dict(json.loads(line))
    return {}


def identify_sih(binary: Path, out: Path, args: argparse.Namespace) -> dict[str, Any]:
    """Stage 1: the identification flight on a fresh SIH; the command's JSON (plus wall time)."""
    n = free_instance()
    p = ports(n)
    env = {"PX4_SIM_SPEED_FACTOR": str(args.speed)}
    with Px4Sitl(binary, n, out / "px4-identify", out / "px4-identify.log", sih=True, extra_env=env):
        w0 = time.monotonic()
        r = subprocess.run(_cli("identify", "--connect", f"udpout://127.0.0.1:{p['api']}", "--vehicle",
                                "px4-sih-quadx", "-o", str(out / "sih_identified.toml"), "--duration",
                                str(args.duration), "--validation-duration", str(args.validation_duration),
                                "--speed-hint", str(args.speed), "--imu", args.imu, "--plot", str(out / "sih_fit.png"),
                                "--json"),
                           cwd=REPO, capture_output=True, text=True, timeout=args.wall_limit)  # fmt: skip
    (out / "identify.log").write_text(r.stderr)
    res = _last_json(r.stdout)
    res["returncode"], res["wall_s"] = r.returncode, round(time.monotonic() - w0, 1)
    return res


def estimate_sih(binary: Path, out: Path, vehicle: str, tag: str, imu: str, args: argparse.Namespace
                 ) -> tuple[dict[str, Any], CheckFlightResult]:  # fmt: skip
    """Stages 2 and 3: the estimator (its own process, PX4's ground-station link) during a check flight. ``imu``
    ``scaled``: PX4 streams SCALED_IMU at 250 Hz on that link (``mavlink stream``, as an extras.txt line would)
    and the estimator asks for nothing, so it runs on SCALED_IMU; ``highres``: the estimator asks for the
    inputs it misses (HIGHRES_IMU at 100 Hz), its default."""
    n = free_instance()
    p = ports(n)
    env = {"PX4_SIM_SPEED_FACTOR": str(args.speed)}
    with Px4Sitl(binary, n, out / f"px4-{tag}", out / f"px4-{tag}.log", sih=True, extra_env=env) as px4, \
            open(out / f"estimator-{tag}.log", "wb") as elog, open(out / f"estimator-{tag}.json", "wb") as ejson:
        extra: list[str] = []
        if imu == "scaled":
            why = ""
            for _ in range(20):  # the client answers once PX4's mavlink instances run
                why = px4.mavlink_stream(p["gcs"], "SCALED_IMU", 250.0)
                if not why:
                    break
                time.sleep(0.5)
            if why:
                raise RuntimeError(f"mavlink stream SCALED_IMU: {why}")
            extra = ["--request-rates", "never"]
        est = subprocess.Popen(_cli("estimator", "--connect", f"udpout://127.0.0.1:{p['gcs']}", "--vehicle", vehicle,
                                    "--esc-order", "px4", "--thr-mdl-fac", "0", "--json", "--link-timeout", "60",
                                    "--connect-timeout", "60", "--progress-every", "2", *extra),
                               cwd=REPO, stdout=ejson, stderr=elog, env=dict(os.environ))  # fmt: skip
        try:
            cfg = CheckFlightConfig(connect=f"udpout://127.0.0.1:{p['api']}", hover_s=args.hover,
                                    speed_hint=args.speed, say=lambda s: print(f"  [{tag}] {s}", flush=True))
            flight = asyncio.run(fly_check(cfg))
        finally:
            if est.poll() is None:
                est.send_signal(signal.SIGTERM)
                try:
                    est.wait(30)
                except subprocess.TimeoutExpired:
                    est.kill()
                    est.wait(5)
    return _last_json((out / f"estimator-{tag}.json").read_text()), flight


def wind_rms(flight: CheckFlightResult, phase: str) -> tuple[float, int, list[float], float]:
    """In a phase: the horizontal wind's RMS about zero (m/s), the number of WIND_COV samples, their mean (N, E)
    and the median of the estimator's own horizontal 1-sigma (sqrt(var_horiz), m/s)."""
    w = flight.wind_in(phase) if phase in flight.phases else np.zeros((0, 5))
    if w.shape[0] == 0:
        return math.nan, 0, [math.nan, math.nan], math.nan
    rms = float(np.sqrt(np.mean(w[:, 1] ** 2 + w[:, 2] ** 2)))
    return rms, int(w.shape[0]), [round(float(x), 3) for x in w[:, 1:3].mean(0)], float(np.median(np.sqrt(w[:, 4])))


def nasa_quad_with_noise(identified: Path, path: Path) -> Path:
    """nasa-quad's file with the accelerometer noise the SIH identification measured: the wrong model judged
    with the right noise (so that a mismatch verdict is the model's, not the noise's)."""
    from dataclasses import replace

    from vehicle.vehicle_file import format_vehicle_file, load_vehicle

    noise = load_vehicle(str(identified)).model_info.get("accel_noise_m_s2")
    base = load_vehicle("nasa-quad")
    v = replace(base, model_info={**base.model_info, "accel_noise_m_s2": noise})
    path.write_text(format_vehicle_file(v, "nasa-quad with PX4 SIH's accelerometer noise (benchmarks/px4_identify.py)"))
    return path


def _table(ident: dict[str, Any]) -> None:
    print("axis   R^2 %   fit TIC  fit NRMSE  val TIC  val NRMSE")
    for a, m in (ident.get("axes") or {}).items():
        print(f"  {a.upper()}  {m['r2_pct']:7.2f}  {m['fit_tic']:8.4f}  {m['fit_nrmse']:9.4f}  "
              f"{m.get('val_tic') or math.nan:7.4f}  {m.get('val_nrmse') or math.nan:9.4f}")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--speed", type=float, default=4.0, help="PX4_SIM_SPEED_FACTOR (default 4)")
    ap.add_argument("--duration", type=float, default=120.0, help="fitting manoeuvre, s")
    ap.add_argument("--validation-duration", type=float, default=60.0, help="validation manoeuvre, s")
    ap.add_argument("--hover", type=float, default=30.0, help="hover of the check flights, s")
    ap.add_argument("--wall-limit", type=float, default=900.0, help="wall seconds for the identification")
    ap.add_argument("--keep", default=None, help="keep the logs, the identified file and the plot here")
    ap.add_argument("--identified", default=None, help="skip stage 1: use this identified vehicle file")
    ap.add_argument("--imu", choices=("scaled", "highres"), default="scaled", help="IMU message of the "
                    "identification (default scaled: PX4's HIGHRES_IMU carries EKF2's accelerometer-bias estimate, "
                    "0.1-0.3 m/s^2 off on SIH)")
    args = ap.parse_args()
    binary = px4_binary()
    if binary is None:
        print("PX4 SITL not available: set WINDSEEK_PX4_BIN to a built px4 binary", file=sys.stderr)
        return 2
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(args.keep or tmp)
        out.mkdir(parents=True, exist_ok=True)
        if args.identified:
            ident = {"returncode": 0, "wall_s": 0.0, "accel_noise_m_s2": None}
            (out / "sih_identified.toml").write_text(Path(args.identified).read_text())
            print(f"1. identification: {args.identified} (not flown)")
        else:
            print(f"1. identification through MAVLink (speed {args.speed:g}, {args.duration:g} s + "
                  f"{args.validation_duration:g} s) ...", flush=True)
            ident = identify_sih(binary, out, args)
        print(f"   exit {ident['returncode']}, {ident['wall_s']} s wall; abort: {ident.get('abort')}; accelerometer "
              f"noise {ident.get('accel_noise_m_s2')} m/s^2; exclusions {ident.get('exclusions')}")
        _table(ident)
        figures: dict[str, Any] = {"identification": {k: ident.get(k) for k in ("axes", "accel_noise_m_s2",
                                                                                  "abort", "wall_s")}}  # fmt: skip
        if ident["returncode"] != 0:
            print(f"identification failed: see {out / 'identify.log'}")
            return 1
        noisy = nasa_quad_with_noise(out / "sih_identified.toml", out / "nasa_quad_sih_noise.toml")
        ident_file = str(out / "sih_identified.toml")
        runs = [("identified", ident_file, "scaled"), ("identified-highres", ident_file, "highres"),
                ("nasa-quad", "nasa-quad", "scaled"), ("nasa-quad+noise", str(noisy), "scaled")]
        for tag, vehicle, imu in runs:
            print(f"2. estimator with --vehicle {vehicle} on {imu.upper()}_IMU during a check flight ...", flush=True)
            est, flight = estimate_sih(binary, out, vehicle, tag, imu, args)
            (out / f"wind-{tag}.json").write_text(json.dumps({"phases": flight.phases, "wind": flight.wind,
                                                              "takeoff_t_s": flight.takeoff_t_s}))  # fmt: skip
            hover, n_h, m_h, s_h = wind_rms(flight, "hover")
            wps, n_w, m_w, s_w = wind_rms(flight, "waypoints")
            mt = est.get("mismatch_t_s")
            to_mismatch = None if mt is None or not math.isfinite(flight.takeoff_t_s) else mt - flight.takeoff_t_s
            print(f"   {tag}: {est.get('inputs_line')}")
            print(f"   {tag}: horizontal wind RMS hover {hover:.3f} m/s ({n_h} WIND_COV, mean N/E {m_h}, own 1-sigma "
                  f"{s_h:.2f}), waypoints {wps:.3f} m/s ({n_w}, mean {m_w}, own 1-sigma {s_w:.2f}); model note: "
                  f"{est.get('model_note')}; mismatch "
                  f"{'none' if to_mismatch is None else f'{to_mismatch:.1f} s after the take-off'}; NIS mean "
                  f"{est.get('innovation_nis_mean')}; thrust ratio {est.get('thrust_ratio')}; flight abort "
                  f"{flight.abort}")  # fmt: skip
            figures[tag] = {"hover_rms": hover, "hover_n": n_h, "hover_mean": m_h, "hover_sigma": s_h,
                            "waypoints_rms": wps, "waypoints_n": n_w, "waypoints_mean": m_w, "waypoints_sigma": s_w,
                            "model_note": est.get("model_note"), "mismatch_after_takeoff_s": to_mismatch,
                            "nis_mean": est.get("innovation_nis_mean"), "thrust_ratio": est.get("thrust_ratio")}
        print(json.dumps(figures, default=str))
    return 0


if __name__ == "__main__":
    sys.exit(main())
