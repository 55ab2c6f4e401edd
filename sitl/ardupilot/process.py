"""Start and stop an ArduCopter SITL binary for windseek (tests, benchmarks, scripts): a thin subprocess adapter.

``WINDSEEK_ARDUPILOT_BIN`` names the ``arducopter`` binary of a SITL build
(``build/sitl/bin/arducopter`` of ArduPilot's source tree). ArduPilot's own SITL defaults
(``Tools/autotest/default_params/copter.parm``: RC calibration, compass offsets, flight modes)
are found from the binary's source tree, or named by ``WINDSEEK_ARDUPILOT_DEFAULTS``; windseek's
vehicle file goes on top (:mod:`sitl.ardupilot.params`). Each run gets a fresh working directory
(``eeprom.bin``, logs and terrain live there, so nothing carries over) and an instance number ``N``;
the ports then are (``libraries/AP_HAL_SITL/SITL_cmdline.cpp``, ``SITL_State.h``):

- servo packets to windseek: UDP ``9002 + 10 N`` (``--sim-port-out``; windseek binds it);
- MAVLink: ``SERIAL0`` TCP ``5760 + 10 N`` (the ground station's; started without ``wait`` here, so
  ArduPilot boots without a client), ``SERIAL1`` TCP ``5762 + 10 N`` (the companions'), ``SERIAL2``
  TCP ``5763 + 10 N`` (windseek's peripheral component);
- simulated RC input: UDP ``5501 + 10 N`` (ArduPilot binds it);
- system id 1 (``SYSID_THISMAV``).

The ground-station failsafe timeout is scaled by the speedup (:func:`sitl.ardupilot.params.speedup_params`,
a parameter file in the working directory, last in ``--defaults``).
"""

from __future__ import annotations

import os
from pathlib import Path

from sitl.ardupilot.params import PARAMS_FILE, speedup_params
from sitl.autopilot_process import AutopilotProcess, ports_free

ENV_BIN = "WINDSEEK_ARDUPILOT_BIN"
ENV_DEFAULTS = "WINDSEEK_ARDUPILOT_DEFAULTS"


def ardupilot_binary() -> Path | None:
    """The ArduCopter SITL binary named by ``WINDSEEK_ARDUPILOT_BIN``, or None when unset or not executable."""
    p = os.environ.get(ENV_BIN, "")
    return Path(p) if p and os.access(p, os.X_OK) else None


def copter_defaults(binary: Path) -> Path | None:
    """ArduPilot's ``copter.parm`` SITL defaults: ``WINDSEEK_ARDUPILOT_DEFAULTS``, or the binary's source tree."""
    env = os.environ.get(ENV_DEFAULTS, "")
    if env:
        return Path(env) if Path(env).is_file() else None
    for up in list(Path(binary).resolve().parents)[:5]:
        p = up / "Tools" / "autotest" / "default_params" / "copter.parm"
        if p.is_file():
            return p
    return None


def ports(instance: int) -> dict[str, int]:
    """The ports of ArduPilot SITL instance ``instance`` (see the module docstring)."""
    k = 10 * int(instance)
    return {"json": 9002 + k, "gcs": 5760 + k, "companion": 5762 + k, "peripheral": 5763 + k, "rc": 5501 + k}


def instance_free(instance: int) -> bool:
    """True if the ports of instance ``instance`` are free now."""
    p = ports(instance)
    return ports_free([p[k] for k in ("gcs", "companion", "peripheral")], [p["json"], p["rc"]])


def free_instance(first: int = 11, last: int = 60) -> int:
    """An ArduPilot instance number in [first, last] whose ports are free now (RuntimeError if none)."""
    start = first + os.getpid() % (last - first + 1)  # concurrent runs start apart
    for i in range(last - first + 1):
        n = first + (start - first + i) % (last - first + 1)
        if instance_free(n):
            return n
    raise RuntimeError(f"no free ArduPilot instance in {first}..{last}")


class ArduCopterSitl(AutopilotProcess):
    """One ArduCopter SITL process with windseek as its JSON physics, stopped with SIGTERM then SIGKILL.

    Args:
        binary: the ``arducopter`` binary; instance: ``N``; workdir: a fresh directory for this run;
        log: where its output goes; home: ``--home LAT,LON,ALT,YAW`` (windseek's origin:
            :func:`sitl.ardupilot.launch.home_arg`); speedup: ArduPilot's ``--speedup``;
        params: parameter files on top of ``copter.parm`` (default: the paper's vehicle);
        extra_args: more command-line arguments; model: ArduPilot's ``--model`` (``JSON``: windseek;
            ``quad``: ArduPilot's own multicopter physics, the peer of the benchmarks).
    """

    def __init__(self, binary: Path, instance: int, workdir: Path, log: Path, home: str, speedup: float = 1.0,
                 params: list[Path] | None = None, extra_args: list[str] | None = None,
                 model: str = "JSON") -> None:  # fmt: skip
        super().__init__(workdir, log)
        self.binary = Path(binary)
        self.instance = int(instance)
        base = copter_defaults(self.binary)
        if base is None:
            raise FileNotFoundError(f"ArduPilot's copter.parm not found from {binary}: set {ENV_DEFAULTS}")
        self.speedup_file = self.workdir / "windseek_speedup.parm"
        files = [base, *(params if params is not None else [PARAMS_FILE]), self.speedup_file]
        self._speedup = float(speedup)
        self.ports = ports(self.instance)
        self.args = [str(self.binary), "--model", model, "-I", str(self.instance), "--speedup", f"{speedup:g}",
                     "--home", home, "--defaults", ",".join(str(f) for f in files), "--serial0", "tcp:0",
                     "--sim-port-out", str(self.ports["json"]), *(extra_args or [])]  # fmt: skip

    def prepare(self) -> None:
        self.speedup_file.write_text("".join(f"{n} {v:g}\n" for n, v in speedup_params(self._speedup)))
