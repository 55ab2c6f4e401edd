"""Solve once per scene: a cache of solved fields keyed by a hash of the scene.

The key is the SHA-256 of a canonical JSON of everything that determines the field (buildings,
wind profile, grid, options) plus :data:`FIELD_FORMAT`, which is bumped whenever the algorithm
changes, so a stale file is never used. Files are ``urban-<key>.npz`` (float64, uncompressed:
about 45 MB for the 1.2-million-cell paper grid) in a folder the caller gives (default
``~/.cache/windseek/urban/``, under ``$XDG_CACHE_HOME`` when set), written atomically
(temporary file + rename). An unreadable or mismatching file counts as a miss and is replaced.
This is the only I/O of the package.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import tempfile
import zipfile
from pathlib import Path

import numpy as np

from urbanflow.config import UrbanScene
from urbanflow.field import UrbanWindField
from urbanflow.solve import solve_urban_wind
from urbanflow.solver import SolveStats

FIELD_FORMAT = "windseek-urban-1"
_ARRAYS = ("u_n", "v_e", "w_d", "cell_building", "zone", "turbulence_multiplier")


def default_cache_dir() -> Path:
    """``$XDG_CACHE_HOME/windseek/urban``, i.e. ``~/.cache/windseek/urban`` by default (the
    project's numba cache lives beside it)."""
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "windseek" / "urban"


def _canonical(scene: UrbanScene) -> str:
    def encode(obj: object) -> object:
        if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
            items = {f.name: encode(getattr(obj, f.name)) for f in dataclasses.fields(obj)}
            return {"type": type(obj).__name__, **items}
        if isinstance(obj, list | tuple):
            return [encode(v) for v in obj]
        if isinstance(obj, float):
            return repr(obj)  # exact, and 1 == 1.0 hash alike
        return obj

    return json.dumps({"format": FIELD_FORMAT, "scene": encode(scene)}, sort_keys=True, separators=(",", ":"))


def cache_key(scene: UrbanScene) -> str:
    """24 hex digits identifying the field of ``scene`` (names included: they are cheap)."""
    return hashlib.sha256(_canonical(scene).encode()).hexdigest()[:24]


def cache_path(scene: UrbanScene, cache_dir: str | os.PathLike[str] | None = None) -> Path:
    """Where the field of ``scene`` is stored."""
    folder = Path(cache_dir) if cache_dir is not None else default_cache_dir()
    return folder / f"urban-{cache_key(scene)}.npz"


def save_field(field: UrbanWindField, cache_dir: str | os.PathLike[str] | None = None) -> Path:
    """Write ``field`` to its cache file atomically; returns the path."""
    path = cache_path(field.scene, cache_dir)
    path.parent.mkdir(parents=True, exist_ok=True)
    stats = field.stats
    stat_values = np.array(dataclasses.astuple(stats) if stats is not None else (), dtype=np.float64)
    fd, tmp = tempfile.mkstemp(prefix=".urban-", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as fh:
            np.savez(
                fh,
                key=np.array(cache_key(field.scene)),
                canonical=np.array(_canonical(field.scene)),
                stats=stat_values,
                **{name: getattr(field, name) for name in _ARRAYS},
            )
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


def load_field(scene: UrbanScene, cache_dir: str | os.PathLike[str] | None = None) -> UrbanWindField | None:
    """The cached field of ``scene``, or None if absent, unreadable or for another scene."""
    path = cache_path(scene, cache_dir)
    if not path.is_file():
        return None
    try:
        with np.load(path, allow_pickle=False) as data:
            if str(data["key"]) != cache_key(scene) or str(data["canonical"]) != _canonical(scene):
                return None
            arrays = {name: np.ascontiguousarray(data[name]) for name in _ARRAYS}
            sv = data["stats"]
    except (OSError, KeyError, ValueError, zipfile.BadZipFile, EOFError):
        return None
    stats = None
    if sv.size == len(dataclasses.fields(SolveStats)):
        stats = SolveStats(int(sv[0]), int(sv[1]), float(sv[2]), float(sv[3]), float(sv[4]), float(sv[5]))
    try:
        return UrbanWindField(scene, stats=stats, **arrays)
    except ValueError:
        return None  # shapes do not fit the grid: treat as a miss


def load_or_solve(
    scene: UrbanScene, cache_dir: str | os.PathLike[str] | None = None
) -> UrbanWindField:
    """The field of ``scene``: from the cache if present, else solved and stored there."""
    field = load_field(scene, cache_dir)
    if field is not None:
        return field
    field = solve_urban_wind(scene)
    save_field(field, cache_dir)
    return field
