"""Start and stop a PX4 SITL binary for windseek (tests, benchmarks, scripts): a thin subprocess adapter.

``WINDSEEK_PX4_BIN`` names the ``px4`` binary of a SITL build (``build/px4_sitl_*/bin/px4``; its
ROMFS is ``../etc``, and the ``px4-*`` links next to the binary must stay there). Each run gets a
fresh working directory (parameters, dataman and logs live there, so nothing carries over) and an
instance number ``N``; the ports then are (PX4 ``px4-rc.mavlink``, ``px4-rc.mavlinksim``):

- simulator: PX4 connects to TCP ``4560 + N`` (airframe 10016, an external simulator: windseek);
- API/offboard link: PX4 binds UDP ``14580 + N`` (a client that sends there first gets the stream);
- ground-station link: PX4 binds UDP ``18570 + N``;
- payload link: PX4 binds UDP ``14280 + N`` (windseek's peripheral component talks there);
- system id ``N + 1``.

PX4 answers only the first client of each UDP link for the rest of its run.
"""

from __future__ import annotations

import fcntl
import os
import subprocess
from pathlib import Path

from sitl.autopilot_process import AutopilotProcess, ports_free
from sitl.hil.px4_params import px4_env

ENV_BIN = "WINDSEEK_PX4_BIN"
#: SIH quad X (PX4's own physics), for runs without windseek's world.
SIH_ENV = {"PX4_SYS_AUTOSTART": "10040", "PX4_SIMULATOR": "sihsim", "PX4_SIM_MODEL": "sihsim_quadx"}


def px4_binary() -> Path | None:
    """The PX4 SITL binary named by ``WINDSEEK_PX4_BIN``, or None when unset or not executable."""
    p = os.environ.get(ENV_BIN, "")
    return Path(p) if p and os.access(p, os.X_OK) else None


def ports(instance: int) -> dict[str, int]:
    """The ports of PX4 SITL instance ``instance`` (see the module docstring)."""
    n = int(instance)
    return {"sim": 4560 + n, "api": 14580 + n, "gcs": 18570 + n, "payload": 14280 + n, "gimbal": 13030 + n,
            "sysid": n + 1}  # fmt: skip


def instance_free(instance: int) -> bool:
    """True if no PX4 holds instance ``instance`` (its lock file) and its ports are free."""
    lock = Path(f"/tmp/px4_lock-{instance}")
    if lock.exists():
        try:
            with open(lock, "a") as f:
                fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
                fcntl.flock(f, fcntl.LOCK_UN)
        except OSError:
            return False
    p = ports(instance)
    return ports_free([p["sim"]], [p[k] for k in ("api", "gcs", "payload", "gimbal")])


def free_instance(first: int = 11, last: int = 60) -> int:
    """A PX4 instance number in [first, last] that is free now (RuntimeError if none)."""
    for n in range(first, last + 1):
        if instance_free(n):
            return n
    raise RuntimeError(f"no free PX4 instance in {first}..{last}")


class Px4Sitl(AutopilotProcess):
    """One PX4 SITL process (``px4 -d -i N -w WORKDIR ROMFS``), stopped with SIGTERM then SIGKILL.

    Args:
        binary: the ``px4`` binary; instance: ``N``; workdir: a fresh directory for this run;
        log: where PX4's output goes; sih: PX4's own SIH physics (airframe 10040) instead of an
            external simulator; speed: windseek's speed factor (scales PX4's link-loss timeouts);
        logging: PX4's flight log (``SDLOG_BACKEND``); extra_env: more ``PX4_PARAM_*`` or other variables.
    """

    def __init__(self, binary: Path, instance: int, workdir: Path, log: Path, sih: bool = False, speed: float = 1.0,
                 logging: bool = False, extra_env: dict[str, str] | None = None) -> None:  # fmt: skip
        super().__init__(workdir, log)
        self.binary = Path(binary)
        self.instance = int(instance)
        env = {k: v for k, v in os.environ.items() if not k.startswith("PX4_")}
        if sih:
            env.update(SIH_ENV)
            if not logging:
                env["PX4_PARAM_SDLOG_BACKEND"] = "0"
        else:
            env.update(px4_env(speed, logging=logging))
        env.update(extra_env or {})
        self.env = env
        self.ports = ports(self.instance)
        self.args = [str(self.binary), "-d", "-i", str(self.instance), "-w", str(self.workdir),
                     str(self.binary.parent.parent / "etc")]  # its ROMFS

    def mavlink_stream(self, port: int, message: str, rate_hz: float, timeout_s: float = 10.0) -> str:
        """PX4's ``mavlink stream -u PORT -s MESSAGE -r RATE`` on this instance, through the ``px4-mavlink``
        client next to the binary (what an ``etc/extras.txt`` line does on a flight controller): a stream on the
        UDP link of local port ``port`` for every client of it. Returns "" or the client's error, in one line."""
        client = self.binary.parent / "px4-mavlink"
        cmd = [str(client), "--instance", str(self.instance), "stream", "-u", str(port), "-s", message, "-r",
               f"{rate_hz:g}"]  # fmt: skip
        try:
            r = subprocess.run(cmd, cwd=self.workdir, capture_output=True, text=True, timeout=timeout_s)
        except (OSError, subprocess.TimeoutExpired) as e:
            return f"{client.name}: {e}"
        why = (r.stderr or r.stdout).strip()[-200:]
        return "" if r.returncode == 0 else f"{client.name} exit {r.returncode}: {why}"
