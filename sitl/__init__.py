"""windseek SITL: a lightweight multirotor simulator after the paper's identified quadrotor.

Conventions used everywhere in this project:

- SI units (m, s, kg, rad, N, N*m); rotor speeds in rad/s.
- World frame NED (x north, y east, z down); the origin is the start point on the ground.
- Body frame FRD (x forward, y right, z down).
- Wind is the *air-mass velocity* expressed in NED: the velocity the air moves with.
  A 10 m/s wind *from* the north blows toward the south: [-10, 0, 0] m/s NED.
- Airspeed (vehicle velocity relative to the air) = ground velocity - wind.
- Documentation gives angles in degrees and the wind direction as the from-direction
  (meteorological convention, 0 = from north, 90 = from east).
"""

import hashlib as _hashlib
import os as _os
from pathlib import Path as _Path


def _numba_cache_dir() -> str:
    """A numba cache folder keyed by the source of every kernel module.

    Numba's own cache is invalidated only by the file that defines a function, not by the
    functions and constants it imports from other modules, so a kernel could silently keep
    stale code after an edit elsewhere. Keying the folder on all kernel sources avoids that.
    """
    root = _Path(__file__).resolve().parent.parent
    digest = _hashlib.sha1()
    for pkg in ("sitl", "vehicle", "estimator", "mission"):
        folder = root / pkg
        if folder.is_dir():
            for f in sorted(folder.rglob("*.py")):
                text = f.read_bytes()
                if b"numba" in text:  # only kernel modules: editing plain Python recompiles nothing
                    digest.update(f.name.encode() + text)
    base = _Path(_os.environ.get("XDG_CACHE_HOME") or _Path.home() / ".cache")
    return str(base / "windseek" / "numba" / digest.hexdigest()[:16])


if "NUMBA_CACHE_DIR" not in _os.environ:
    _os.environ["NUMBA_CACHE_DIR"] = _numba_cache_dir()
    try:  # numba may already be imported: its config is read at import
        import numba as _numba

        _numba.config.CACHE_DIR = _os.environ["NUMBA_CACHE_DIR"]
    except ImportError:  # pragma: no cover - numba is a hard dependency
        pass
