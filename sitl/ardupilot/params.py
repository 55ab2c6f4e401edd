"""ArduCopter parameters for windseek's vehicles: the shipped files and how they are written.

A file ``sitl/ardupilot/params/windseek_<vehicle>.parm`` (ArduPilot's ``NAME VALUE`` format, as
MAVProxy's ``param load`` and SITL's ``--defaults`` read it) describes a windseek quad X to
ArduCopter: the frame (``FRAME_CLASS 1`` quad, ``FRAME_TYPE 1`` X), motors on servo outputs 1-4
(``SERVOi_FUNCTION`` 33-36), the ESC range (``MOT_PWM_MIN/MAX`` 1000-2000 us) and ArduCopter's motor
model of windseek's rotor (``MOT_THST_EXPO``, ``MOT_THST_HOVER``, from the vehicle file:
:mod:`sitl.ardupilot.motors`; hover learning off so that every run starts alike, no battery
voltage compensation: windseek's motors do not sag), the battery (``SIM_BATT_VOLTAGE`` full charge
of the vehicle file's cells, ``BATT_CAPACITY``), the ground-station failsafe on (``FS_GCS_ENABLE 1``:
RTL after ``FS_GCS_TIMEOUT`` s without the heartbeat of system ``MAV_GCS_SYSID``, set to 245: MAVSDK's
ground-station id, so ``windseek mission`` is the ground station it follows), and ArduPilot SITL's own IMU
noise and vibration off (``SIM_ACC*_RND``, ``SIM_GYR*_RND``, ``SIM_VIB_MOT_MAX``: the IMU is windseek's).

Load it on top of ArduPilot's own SITL defaults:
``arducopter --model JSON --defaults Tools/autotest/default_params/copter.parm,windseek_nasa_quad.parm``.
:func:`parm_text` writes it from the vehicle file; a test keeps the shipped files equal to it.
``python -m sitl.ardupilot.params --vehicle NAME`` prints it.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from sitl.ardupilot.motors import PWM_MAX, PWM_MIN, SPIN_ARM, SPIN_MAX, SPIN_MIN, ardupilot_figures, check_quad_x
from vehicle.params import VehicleParams
from vehicle.vehicle_file import load_vehicle

PARAMS_DIR = Path(__file__).resolve().parent / "params"
#: The shipped parameter file of the paper's vehicle.
PARAMS_FILE = PARAMS_DIR / "windseek_nasa_quad.parm"
CELL_FULL_V = 4.2


def vehicle_params(vehicle: VehicleParams) -> list[tuple[str, float]]:
    """(name, value) of every parameter the file sets, in the file's order."""
    check_quad_x(vehicle)
    f = ardupilot_figures(vehicle)
    p: list[tuple[str, float]] = [("FRAME_CLASS", 1), ("FRAME_TYPE", 1)]
    p += [(f"SERVO{i}_FUNCTION", 32 + i) for i in range(1, 5)]
    p += [("MOT_PWM_MIN", PWM_MIN), ("MOT_PWM_MAX", PWM_MAX), ("MOT_SPIN_ARM", SPIN_ARM), ("MOT_SPIN_MIN", SPIN_MIN),
          ("MOT_SPIN_MAX", SPIN_MAX), ("MOT_THST_EXPO", round(f.thst_expo, 3)),
          ("MOT_THST_HOVER", round(f.thst_hover, 3)), ("MOT_HOVER_LEARN", 0), ("MOT_BAT_VOLT_MAX", 0)]  # fmt: skip
    p += [("BATT_MONITOR", 4), ("BATT_CAPACITY", round(vehicle.battery_capacity_mah)),
          ("SIM_BATT_VOLTAGE", round(CELL_FULL_V * vehicle.battery_cells, 2)),
          ("SIM_BATT_CAP_AH", round(vehicle.battery_capacity_mah / 1000.0, 3))]  # fmt: skip
    # The failsafe follows the heartbeats of MAV_GCS_SYSID only: windseek mission's (MAVSDK's ground-station id).
    p += [("FS_GCS_ENABLE", 1), ("FS_GCS_TIMEOUT", FS_GCS_TIMEOUT_S), ("MAV_GCS_SYSID", MAVSDK_GCS_SYSID)]
    for i in (1, 2, 3):
        p += [(f"SIM_ACC{i}_RND", 0), (f"SIM_GYR{i}_RND", 0)]
    p += [("SIM_VIB_MOT_MAX", 0)]
    return p


#: The system id MAVSDK (windseek mission) takes as a ground station.
MAVSDK_GCS_SYSID = 245
#: ArduCopter's ground-station failsafe timeout in the shipped file [s of ArduPilot's clock].
FS_GCS_TIMEOUT_S = 5.0


def speedup_params(speedup: float) -> list[tuple[str, float]]:
    """Parameters that depend on ArduPilot SITL's ``--speedup``: the ground-station failsafe timeout
    runs on ArduPilot's (simulated) clock while ground stations send their heartbeats once per wall
    second, so at speedup K it is ``K`` times the shipped 5 s (ArduPilot's maximum: 120 s)."""
    return [("FS_GCS_TIMEOUT", min(120.0, round(FS_GCS_TIMEOUT_S * max(1.0, float(speedup)), 1)))]


def _fmt(v: float) -> str:
    return str(int(v)) if float(v).is_integer() else f"{v:g}"


def parm_text(vehicle: VehicleParams) -> str:
    """The parameter file of ``vehicle`` (header comments + one ``NAME VALUE`` line per parameter)."""
    f = ardupilot_figures(vehicle)
    head = [
        f"# ArduCopter parameters of windseek's vehicle '{vehicle.name}' (written by sitl/ardupilot/params.py from the "
        "vehicle file).",
        f"# Quad X, motors 1 front right CCW, 2 rear left CCW, 3 front left CW, 4 rear right CW on outputs 1-4; ESC "
        f"command (pwm - {PWM_MIN}) / {PWM_MAX - PWM_MIN} -> rotor speed {vehicle.rotor_speed_max_rad_s:g} rad/s * "
        "command.",
        f"# Hover at ESC command {f.hover_esc:.3f}; thrust-to-weight {f.thrust_to_weight:.2f} at MOT_SPIN_MAX.",
        "# Load on top of ArduPilot's SITL defaults: --defaults .../copter.parm,<this file>.",
    ]  # fmt: skip
    return "\n".join(head + [f"{n} {_fmt(v)}" for n, v in vehicle_params(vehicle)]) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m sitl.ardupilot.params", description=__doc__.splitlines()[0])
    ap.add_argument("--vehicle", default="nasa-quad", help="vehicle name or file (default nasa-quad)")
    a = ap.parse_args(argv)
    print(parm_text(load_vehicle(a.vehicle)), end="")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
