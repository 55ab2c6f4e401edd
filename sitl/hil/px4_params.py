"""PX4 parameters for windseek's vehicles: the shipped files, and the environment that starts PX4 SITL with one.

A file ``sitl/px4/windseek_<vehicle>.params`` (QGroundControl's parameter file format, one
``system component name value type`` line per parameter, type 6 = INT32, 9 = REAL32) describes a
vehicle file's multirotor to PX4: the geometry, spin directions and torque ratio of the rotors
(``CA_ROTOR*``), the thrust curve (``THR_MDL_FAC``, :mod:`sitl.hil.motors`), the hover thrust
(``MPC_THR_HOVER``), the motor outputs of SITL (``PWM_MAIN_FUNCi``) and HITL (``HIL_ACT_FUNCi``),
and the GNSS latency of windseek's receiver model (``EKF2_GPS_DELAY``). :func:`vehicle_params`
computes them from the vehicle file; a test keeps the shipped files equal to it.

Loading it:

- PX4 SITL: every parameter as a ``PX4_PARAM_<NAME>=<value>`` environment variable, which PX4's
  SITL start script applies after the airframe (``rcS``), with airframe 10016 (``none_iris``, an
  external simulator on TCP 4560 + instance): ``eval "$(python -m sitl.hil.px4_params --speed 5)"``
  prints the ``export`` lines (:func:`px4_env`), including the link-loss timeouts scaled by the
  speed factor (PX4's timers run on simulation time in lockstep; MAVSDK's heartbeats and setpoints
  come at wall-clock rates).
- A flight controller (HITL or a real flight): QGroundControl, Vehicle Setup > Parameters >
  Tools > Load from file.
"""

from __future__ import annotations

import argparse
import math
from dataclasses import dataclass
from pathlib import Path

from sitl.hil.motors import px4_figures
from sitl.world.sensors import GnssConfig
from vehicle.params import VehicleParams
from vehicle.vehicle_file import load_vehicle

#: The shipped parameter files: ``windseek_<vehicle file stem>.params``.
PARAMS_DIR = Path(__file__).resolve().parent.parent / "px4"
#: The shipped parameter file of the paper's vehicle.
PARAMS_FILE = PARAMS_DIR / "windseek_nasa_quad.params"
INT32, REAL32 = 6, 9
#: PX4 SITL airframe with an external simulator on TCP 4560 + instance and a quad X on outputs 1-4.
SITL_AIRFRAME = 10016
SITL_MODEL = "none_iris"
#: PX4's link-loss timeouts at speed 1 (PX4 ``rcS``, ``PX4_SIM_SPEED_FACTOR``): scaled by the speed.
LOSS_TIMEOUTS_S = {"COM_DL_LOSS_T": (10.0, INT32), "COM_RC_LOSS_T": (1.0, REAL32),
                   "COM_OF_LOSS_T": (1.0, REAL32), "COM_OBC_LOSS_T": (5.0, REAL32)}  # fmt: skip


@dataclass(frozen=True)
class Param:
    name: str
    value: float
    type: int  # INT32 (6) or REAL32 (9)

    def text(self) -> str:
        """The value as PX4 prints it: an integer, or a float with up to 6 significant digits."""
        return str(int(self.value)) if self.type == INT32 else f"{self.value:.6g}"


def vehicle_params(vehicle: VehicleParams, gnss: GnssConfig | None = None) -> list[Param]:
    """PX4 parameters of a windseek multirotor (see the module docstring); rotor order is PX4's."""
    f = px4_figures(vehicle)
    g = gnss or GnssConfig()
    n = vehicle.n_rotors
    out = [Param("CA_AIRFRAME", 0, INT32), Param("CA_ROTOR_COUNT", n, INT32)]
    for i, (x, y, spin) in enumerate(f.rotors):  # PX4's CA_ROTORi_KM > 0: counter-clockwise seen from above
        out += [Param(f"CA_ROTOR{i}_PX", round(x, 4), REAL32), Param(f"CA_ROTOR{i}_PY", round(y, 4), REAL32),
                Param(f"CA_ROTOR{i}_KM", round(spin * f.km, 4), REAL32)]  # fmt: skip
    out += [Param("THR_MDL_FAC", round(f.thr_mdl_fac, 3), REAL32),
            Param("MPC_THR_HOVER", round(f.hover_thrust, 3), REAL32)]
    out += [Param(f"PWM_MAIN_FUNC{i}", 100 + i, INT32) for i in range(1, n + 1)]
    out += [Param(f"HIL_ACT_FUNC{i}", 100 + i, INT32) for i in range(1, n + 1)]
    out.append(Param("EKF2_GPS_DELAY", round(1000 * g.latency_s, 1), REAL32))
    return out


def format_params_file(params: list[Param], vehicle: VehicleParams) -> str:
    """The QGroundControl parameter file text (system 1, component 1)."""
    f = px4_figures(vehicle)
    motors = ", ".join(f"{i + 1} {_where(x, y)} {'CCW' if s > 0 else 'CW'}" for i, (x, y, s) in enumerate(f.rotors))
    head = [
        f"# PX4 parameters of windseek's vehicle {vehicle.name!r} (written by sitl/hil/px4_params.py from the "
        "vehicle file).",
        f"# Thrust: omega = {vehicle.rotor_speed_max_rad_s:g} rad/s * output; THR_MDL_FAC from the truth's static "
        f"thrust; hover {f.hover_thrust:.3f} of {f.max_thrust_n:.2f} N per rotor (T/W {f.thrust_to_weight:.2f}).",
        f"# Geometry: {vehicle.layout}, arm {vehicle.arm_length_m:.4f} m; KM = rotor torque / thrust at hover.",
        f"# Motors (PX4 order): {motors}.",
        "#",
        "# Vehicle-Id\tComponent-Id\tName\tValue\tType",
    ]
    return "\n".join(head + [f"1\t1\t{p.name}\t{p.text()}\t{p.type}" for p in params]) + "\n"


def _where(x: float, y: float) -> str:
    """'front right' ... for a rotor position (FRD, m)."""
    fb = "front" if x > 1e-6 else "rear" if x < -1e-6 else ""
    lr = "right" if y > 1e-6 else "left" if y < -1e-6 else ""
    return " ".join(w for w in (fb, lr) if w)


def read_params_file(path: Path | str = PARAMS_FILE) -> list[Param]:
    """Parameters of a QGroundControl parameter file; ValueError naming the line otherwise."""
    out = []
    for n, line in enumerate(Path(path).read_text().splitlines(), 1):
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        parts = line.split()
        try:
            name, value, typ = parts[2], float(parts[3]), int(parts[4])
        except (IndexError, ValueError):
            raise ValueError(f"{path}:{n}: expected 'system component name value type', got {line!r}") from None
        if typ not in (INT32, REAL32) or not math.isfinite(value):
            raise ValueError(f"{path}:{n}: type must be 6 (INT32) or 9 (REAL32) and the value finite")
        out.append(Param(name, value, typ))
    return out


def px4_env(speed: float = 1.0, params: list[Param] | None = None, logging: bool = True) -> dict[str, str]:
    """Environment for PX4 SITL with windseek as its simulator: airframe 10016, the vehicle's parameters,
    the link-loss timeouts scaled by ``speed`` (>= 1 is assumed: slower runs keep PX4's defaults),
    and with ``logging=False`` no flight log (PX4's logger costs lockstep time)."""
    env = {"PX4_SYS_AUTOSTART": str(SITL_AIRFRAME), "PX4_SIM_MODEL": SITL_MODEL}
    for p in read_params_file() if params is None else params:
        if not p.name.startswith("HIL_ACT_"):  # HITL's output functions: not in a SITL build
            env[f"PX4_PARAM_{p.name}"] = p.text()
    k = max(1.0, float(speed))
    for name, (value, typ) in LOSS_TIMEOUTS_S.items():
        env[f"PX4_PARAM_{name}"] = Param(name, math.ceil(value * k) if typ == INT32 else value * k, typ).text()
    if not logging:
        env["PX4_PARAM_SDLOG_BACKEND"] = "0"  # rc.logging starts no logger (SDLOG_MODE -1 does not stop it)
    return env


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m sitl.hil.px4_params",
                                 description="Print the environment (export lines) that starts PX4 SITL with "
                                 "windseek's vehicle, or write the parameter file.")  # fmt: skip
    ap.add_argument("--speed", type=float, default=1.0, help="the speed factor windseek will run at (default 1)")
    ap.add_argument("--no-log", action="store_true", help="no PX4 flight log (faster lockstep)")
    ap.add_argument("--write", metavar="PATH", help="write the parameter file of --vehicle to PATH instead")
    ap.add_argument("--vehicle", default="nasa_quad", help="vehicle file (name or path) for --write")
    a = ap.parse_args(argv)
    if a.write:
        v = load_vehicle(a.vehicle)
        Path(a.write).write_text(format_params_file(vehicle_params(v), v))
        return 0
    print("unset PX4_SIMULATOR")
    for name, value in px4_env(a.speed, logging=not a.no_log).items():
        print(f"export {name}={value}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
