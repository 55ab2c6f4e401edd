"""The autopilots' multirotor drag coefficients for windseek's vehicle, measured in windseek's world.

PX4's EKF2 (``EKF2_BCOEF_X/Y``, ``EKF2_MCOEF``) and ArduPilot's EKF3 (``EK3_DRAG_BCOEF_X/Y``,
``EK3_DRAG_MCOEF``) estimate the wind of a multirotor from the drag its accelerometer feels, with one
model: the specific force along a body axis is ``-(MCOEF u + rho u |u| / (2 BCOEF))`` for the airspeed
``u`` along that axis (MCOEF in 1/s: the rotors' momentum drag; BCOEF in kg/m^2: mass over drag area,
the body's). Their documentation asks for the values of the vehicle flown; here they are measured on
it as one would with a real vehicle, by hovering it in steady winds and reading its accelerometer:
windseek's built-in autopilot holds the vehicle (blade-element truth, ``calm``'s world without its
turbulence) at 30 m in a steady wind of 1-10 m/s from ahead and from the side, and the mean specific
force along that body axis over 15 s against the mean airspeed along it is fitted by least squares.
Not fitted to anything an estimator is graded on: the truth's steady hover only.

Usage: ``python benchmarks/drag_coefficients.py [--vehicle nasa-quad]``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
from toolchain import numba_cache  # noqa: E402 - before any kernel module

numba_cache.configure()
from sitl.scenario import parse_scenario  # noqa: E402
from sitl.simulation import T_QUAT, T_SPECIFIC_FORCE, T_VEL, T_WIND, Simulation  # noqa: E402
from vehicle.frames import quat_to_dcm  # noqa: E402

SPEEDS = (1.0, 2.0, 3.0, 4.0, 6.0, 8.0, 10.0)


def hover(vehicle: str, wind_ned: tuple[float, float, float], settle_s: float = 10.0, mean_s: float = 15.0
          ) -> tuple[np.ndarray, np.ndarray, float]:  # fmt: skip
    """Mean body specific force (FRD, m/s^2) and body airspeed (m/s) of a steady hover; the air density."""
    sc = parse_scenario({"name": "drag-hover", "vehicle": vehicle, "seed": 1, "duration_s": settle_s + mean_s,
                         "wind": {"velocity_ned": list(wind_ned)}, "turbulence": {"model": "none"},
                         "start": {"position_ned": [0.0, 0.0, -30.0], "airborne": True},
                         "route": {"waypoints": [{"position_ned": [0.0, 0.0, -30.0], "hold_s": 1e4}]}})  # fmt: skip
    sim = Simulation(sc, record_truth=True)
    sim.run(settle_s + mean_s)
    rows = sim.truth_array()
    rows = rows[rows[:, 0] >= settle_s]
    f = rows[:, T_SPECIFIC_FORCE].mean(axis=0)
    air = np.array([quat_to_dcm(r[T_QUAT]).T @ (r[T_VEL] - r[T_WIND]) for r in rows]).mean(axis=0)
    return f, air, float(sim.vehicle.air_density_kg_m3)


def fit(u: np.ndarray, f: np.ndarray, rho: float) -> tuple[float, float, float]:
    """(MCOEF 1/s, BCOEF kg/m^2, RMS residual m/s^2) of ``-f = MCOEF u + rho u|u| / (2 BCOEF)``."""
    a = np.column_stack([u, 0.5 * rho * u * np.abs(u)])
    (m, inv_b), *_ = np.linalg.lstsq(a, -f, rcond=None)
    res = float(np.sqrt(np.mean((a @ [m, inv_b] + f) ** 2)))
    return float(m), (float(1.0 / inv_b) if inv_b > 0 else float("inf")), res


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--vehicle", default="nasa-quad")
    a = ap.parse_args()
    out = {}
    for axis, name in ((0, "X"), (1, "Y")):
        us, fs = [], []
        for v in SPEEDS:
            w = [0.0, 0.0, 0.0]
            w[axis] = -v  # the air moves backwards (-x) or to the left (-y): airspeed +v along the axis
            f, air, rho = hover(a.vehicle, (w[0], w[1], w[2]))
            us.append(air[axis])
            fs.append(f[axis])
            print(f"  wind {v:4.1f} m/s along -{name}: airspeed {air[axis]:+6.2f} m/s, specific force "
                  f"{f[axis]:+7.3f} m/s^2", flush=True)  # fmt: skip
        out[name] = fit(np.array(us), np.array(fs), rho)
        m, b, res = out[name]
        print(f"{name}: MCOEF {m:.4f} 1/s, BCOEF {b:.1f} kg/m^2 (RMS residual {res:.3f} m/s^2)", flush=True)
    m = 0.5 * (out["X"][0] + out["Y"][0])
    bx, by = out["X"][1], out["Y"][1]
    print(f"\nArduPilot EKF3: EK3_DRAG_MCOEF {m:.3f}  EK3_DRAG_BCOEF_X {bx:.1f}  EK3_DRAG_BCOEF_Y {by:.1f}")
    print(f"PX4 EKF2:       EKF2_MCOEF {m:.3f}  EKF2_BCOEF_X {bx:.1f}  EKF2_BCOEF_Y {by:.1f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
