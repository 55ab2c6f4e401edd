"""How honest the wind UKF's stated uncertainty is, in-process, per flight, and what an autopilot's IMU
stream does to it.

Flies ``--scenario`` for each seed (development seeds by default: evaluation seeds are never used for
tuning) with the estimator fed windseek's own IMU, or that IMU as an autopilot streams it: low-passed
(``--lowpass-hz``, a 2nd-order Butterworth as ArduCopter's ``INS_ACCEL_FILTER`` / PX4's
``IMU_ACCEL_CUTOFF``) and taken at ``--stream-hz`` (ArduCopter's HIGHRES_IMU: 20 Hz, 100 Hz). Prints, over
the flights (first 5 s out): the horizontal 95 % circle's coverage (mean [worst-best] flight, the figure
``sitl/hil/wind_score.py`` scores through the autopilots), the per-axis 1-sigma coverage (0.68 for a
Gaussian), the instantaneous horizontal RMSE and the RMSE of 1-s means. ``--set KEY=VALUE`` overrides an
``EstimatorConfig`` field (e.g. ``unseen_accel_bias_m_s2=0``) to compare in the same run.

Usage: ``python benchmarks/estimator_coverage.py --scenario open-field --duration 90 --seeds 100-111
[--lowpass-hz 20 --stream-hz 100] [--set unseen_accel_bias_m_s2=0]``. Figures: benchmarks/README.md,
"What the UKF says about its uncertainty".
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
from scipy.signal import butter, sosfilt, sosfilt_zi  # noqa: E402

from estimator.config import EstimatorConfig  # noqa: E402
from estimator.metrics import accuracy  # noqa: E402
from mission.runners.estimator_run import InProcessRunner  # noqa: E402
from sitl.scenario import load_scenario  # noqa: E402
from sitl.world.kernel import N_TRUTH, T_QUAT, T_TIME, T_WIND  # noqa: E402


class StreamRunner(InProcessRunner):
    """:class:`InProcessRunner` with the IMU low-passed (``lowpass_hz``, 0 = off) and taken at ``stream_hz``."""

    def __init__(self, *args: Any, lowpass_hz: float = 0.0, stream_hz: float = 0.0, **kw: Any) -> None:
        super().__init__(*args, **kw)
        rate = self.sim.scenario.sensors.imu.rate_hz
        self._sos = butter(2, lowpass_hz, fs=rate, output="sos") if lowpass_hz > 0 else None
        self._zi: np.ndarray | None = None
        self._every = rate / stream_hz if stream_hz > 0 else 1.0
        self._k = 0

    def _filtered(self, imu: list[Any]) -> np.ndarray:
        x = np.array([np.concatenate((a, g)) for _t, a, g in imu]) if imu else np.zeros((0, 6))
        if self._sos is None or not len(x):
            return x
        if self._zi is None:  # start settled on the first sample, as the autopilot's filter is after boot
            self._zi = sosfilt_zi(self._sos)[:, :, None] * x[0][None, None, :]
        y, self._zi = sosfilt(self._sos, x, axis=0, zi=self._zi)
        return np.asarray(y)

    def _consume(self, out: dict[str, list]) -> None:
        sim, est = self.sim, self.estimator
        log = sim.truth_log
        assert log is not None
        rows = log[self._truth_idx :]
        self._truth_idx = len(log)
        truth = np.concatenate(rows) if rows else np.zeros((0, N_TRUTH))
        esc = out["esc"]
        self._pending_gnss.extend(out["gnss"])
        dt = 1.0 / sim.scenario.sensors.imu.rate_hz
        y = self._filtered(out["imu"])
        ei = 0
        for k, (t, _a, _g) in enumerate(out["imu"]):
            row = truth[k]
            q = self._attitude_measurement(row[T_QUAT], dt)
            while ei < len(esc) and esc[ei][0] <= t + 1e-9:
                est.set_rotor_speeds(esc[ei][0], esc[ei][1])
                ei += 1
            self._k += 1
            if math.floor(self._k / self._every) != math.floor((self._k - 1) / self._every):
                est.set_attitude(t, q)
                est.imu(t, y[k, :3], y[k, 3:])
            while self._pending_gnss and self._pending_gnss[0].t + self._latency <= t + 1e-9:
                g = self._pending_gnss.pop(0)
                est.gnss_velocity(g.t, g.vel_ned)
            e = est.estimate()
            self._log.append(np.concatenate(([row[T_TIME]], e.wind_ned, e.sigma_ned,
                                             [e.direction_deg, e.direction_sigma_deg, e.direction_filtered_deg],
                                             row[T_WIND])))  # fmt: skip


def _value(v: str) -> Any:
    try:
        return float(v)
    except ValueError:
        return tuple(float(x) for x in v.split(","))


def flight(scenario: str, seed: int, duration: float | None, a: argparse.Namespace, overrides: dict[str, Any]
           ) -> tuple[float, float, float, float]:  # fmt: skip
    """(95 % circle coverage, 1-sigma axis coverage, horizontal RMSE, 1-s horizontal RMSE) of one flight."""
    sc = load_scenario(scenario)
    if duration:
        sc = sc.with_duration(duration)
    r = StreamRunner(sc, seed=seed, config=EstimatorConfig.preset(a.preset, **overrides), lowpass_hz=a.lowpass_hz,
                     stream_hz=a.stream_hz)  # fmt: skip
    lg = r.run()
    m = lg.t > lg.t[0] + 5.0
    e = lg.wind_est[m] - lg.wind_true[m]
    var = lg.wind_sigma[m] ** 2
    cov95 = float(np.mean(e[:, 0] ** 2 + e[:, 1] ** 2 <= 5.991 * (var[:, 0] + var[:, 1]) / 2.0))
    one = float(np.mean(np.abs(e[:, :2]) <= np.sqrt(var[:, :2])))
    acc = accuracy(lg.t, lg.wind_est, lg.wind_sigma, lg.wind_true, lg.direction_filtered_deg, warmup_s=5.0)
    return cov95, one, float(np.sqrt(np.mean(np.sum(e[:, :2] ** 2, axis=1)))), float(acc.rmse_horizontal_avg_ms)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scenario", default="open-field")
    ap.add_argument("--duration", type=float, default=None, help="simulated seconds (default: the scenario's)")
    ap.add_argument("--seeds", default="100-105", help="A-B or a,b,c (default: development seeds 100-105)")
    ap.add_argument("--preset", default="calibrated")
    ap.add_argument("--lowpass-hz", type=float, default=0.0, help="IMU low-pass cutoff (0: none)")
    ap.add_argument("--stream-hz", type=float, default=0.0, help="IMU stream rate (0: every sample, 250 Hz)")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="EstimatorConfig override")
    a = ap.parse_args()
    lo, _, hi = a.seeds.partition("-")
    seeds = list(range(int(lo), int(hi) + 1)) if hi else [int(s) for s in a.seeds.split(",")]
    overrides = {k: _value(v) for k, v in (s.split("=", 1) for s in a.set)}
    f = np.array([flight(a.scenario, s, a.duration, a, overrides) for s in seeds])
    print(f"{a.scenario}, {len(seeds)} flights (seeds {a.seeds}), IMU low-pass {a.lowpass_hz:g} Hz, stream "
          f"{a.stream_hz or 'every sample'}{' Hz' if a.stream_hz else ''}, preset {a.preset} {overrides or ''}")
    print(f"  95 % circle coverage {f[:, 0].mean():.3f} [{f[:, 0].min():.3f}-{f[:, 0].max():.3f}]; 1-sigma per axis "
          f"{f[:, 1].mean():.3f}; horizontal RMSE {f[:, 2].mean():.3f} m/s, of 1-s means "
          f"{math.sqrt(float(np.mean(f[:, 3] ** 2))):.3f} m/s")  # fmt: skip
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
