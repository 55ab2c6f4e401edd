"""Cache of solved urban fields: keys, identical round trips, hits, corrupt files, no import work."""

from __future__ import annotations

import dataclasses
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from sitl.world.urban import (
    BoxBuilding,
    GridSpec,
    LogWindProfile,
    UrbanScene,
    UrbanWindField,
    cache_key,
    load_field,
    load_or_solve,
    save_field,
)
from sitl.world.urban.cache import cache_path

ARRAYS = ("u_n", "v_e", "w_d", "cell_building", "zone", "turbulence_multiplier")


def _scene(height: float = 6.0, from_deg: float = 30.0, spacing: float = 2.0) -> UrbanScene:
    return UrbanScene(
        (BoxBuilding(20.0, 20.0, 8.0, 6.0, height),),
        LogWindProfile(5.0, from_deg, 10.0, 0.1),
        GridSpec(0.0, 0.0, 40.0, 40.0, 20.0, spacing),
    )


def test_key_is_stable_and_covers_every_input() -> None:
    base = _scene()
    assert cache_key(base) == cache_key(_scene())
    changed = [
        _scene(height=6.5),
        _scene(from_deg=31.0),
        _scene(spacing=1.0),
        dataclasses.replace(base, options=dataclasses.replace(base.options, rooftop=False)),
        dataclasses.replace(base, wind=dataclasses.replace(base.wind, roughness_length_m=0.2)),
        dataclasses.replace(base, buildings=(BoxBuilding(20.0, 20.0, 8.0, 6.0, 6.0, rotation_deg=5.0),)),
    ]
    keys = {cache_key(s) for s in changed}
    assert cache_key(base) not in keys and len(keys) == len(changed)
    assert cache_key(_scene(height=6)) == cache_key(_scene(height=6.0))  # int and float alike


def test_cache_hit_returns_an_identical_field(tmp_path: Path) -> None:
    scene = _scene()
    first = load_or_solve(scene, tmp_path)
    path = cache_path(scene, tmp_path)
    assert path.is_file() and path.parent == tmp_path
    second = load_or_solve(scene, tmp_path)
    for name in ARRAYS:
        assert np.array_equal(getattr(first, name), getattr(second, name))
        assert getattr(first, name).dtype == getattr(second, name).dtype
    assert second.stats == first.stats
    # It was read, not solved again: a marked file comes back as stored.
    marked = UrbanWindField(scene, first.u_n + 1.0, first.v_e, first.w_d, first.cell_building, first.zone,
                            first.turbulence_multiplier, first.stats)
    save_field(marked, tmp_path)
    third = load_or_solve(scene, tmp_path)
    assert np.array_equal(third.u_n, first.u_n + 1.0)


def test_corrupt_or_foreign_file_is_a_miss_and_replaced(tmp_path: Path) -> None:
    scene = _scene()
    path = cache_path(scene, tmp_path)
    path.write_bytes(b"not an npz at all")
    assert load_field(scene, tmp_path) is None
    field = load_or_solve(scene, tmp_path)
    assert load_field(scene, tmp_path) is not None
    # A file of another scene under this name is not used either.
    other = _scene(height=7.0)
    os.replace(cache_path(scene, tmp_path), cache_path(other, tmp_path))
    assert load_field(other, tmp_path) is None
    assert field.max_divergence_ratio() < 1e-3
    assert not list(tmp_path.glob(".urban-*"))  # no temporary files left behind


def test_default_dir_and_nothing_computed_at_import(tmp_path: Path) -> None:
    env = {**os.environ, "XDG_CACHE_HOME": str(tmp_path), "NUMBA_CACHE_DIR": str(tmp_path / "numba")}
    code = "import sitl.world.urban as u; print(u.default_cache_dir())"
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == str(tmp_path / "windseek" / "urban")
    assert not (tmp_path / "windseek").exists()  # importing wrote nothing


@pytest.mark.parametrize("bad", ["u_n", "zone"])
def test_field_rejects_wrong_shapes(bad: str) -> None:
    scene = _scene()
    nx, ny, nz = scene.grid.shape
    arrays: dict[str, np.ndarray] = {
        "u_n": np.zeros((nx + 1, ny, nz)), "v_e": np.zeros((nx, ny + 1, nz)), "w_d": np.zeros((nx, ny, nz + 1)),
        "cell_building": np.full((nx, ny, nz), -1, np.int32), "zone": np.zeros((nx, ny, nz), np.int8),
        "turbulence_multiplier": np.ones((nx, ny, nz)),
    }
    arrays[bad] = np.zeros((2, 2, 2))
    with pytest.raises(ValueError, match=bad):
        UrbanWindField(scene, **arrays)  # type: ignore[arg-type]
