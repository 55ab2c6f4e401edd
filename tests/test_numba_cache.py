"""numba's kernel cache is shared by every checkout of the same sources: the cache subfolder of a kernel is
named by its project-relative directory (a fresh clone used to recompile every kernel: ~1-2 min of the suite,
and two test processes compiling one kernel at once stalled a simulation thread for tens of seconds)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

from toolchain import numba_cache
from toolchain.numba_locator import ROOT, ProjectCacheLocator, cache_subpath


def test_kernels_are_cached_under_project_relative_folders() -> None:
    assert os.environ["NUMBA_CACHE_LOCATOR_CLASSES"].startswith("toolchain.numba_locator.ProjectCacheLocator,")
    from sitl.world import kernel

    fn = kernel.advance_commanded.py_func
    loc = ProjectCacheLocator.from_function(fn, kernel.__file__)
    assert loc is not None
    path = Path(loc.get_cache_path())  # type: ignore[attr-defined]
    assert path == Path(os.environ["NUMBA_CACHE_DIR"]) / "project_sitl_world"
    # The same file in another checkout maps to the same folder; a file outside the project to none.
    assert cache_subpath(str(ROOT / "sitl" / "world" / "kernel.py")) == "project_sitl_world"
    assert cache_subpath("/elsewhere/clone/sitl/world/kernel.py", Path("/elsewhere/clone")) == "project_sitl_world"
    assert cache_subpath("/tmp/not_ours.py") is None
    assert ProjectCacheLocator.from_function(fn, "/tmp/not_ours.py") is None


def test_a_fresh_interpreter_hands_the_locator_to_numba_before_it_is_imported() -> None:
    code = ("from toolchain import numba_cache; numba_cache.configure(); import numba; "
            "print(numba.config.CACHE_LOCATOR_CLASSES.split(',')[0])")  # fmt: skip
    env = {k: v for k, v in os.environ.items() if not k.startswith("NUMBA_")}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, env=env, timeout=60)
    assert out.stdout.strip() == "toolchain.numba_locator.ProjectCacheLocator", out.stderr
    assert numba_cache.LOCATORS.split(",")[1:] == ["UserProvidedCacheLocator", "InTreeCacheLocator",
                                                   "UserWideCacheLocator", "IPythonCacheLocator", "ZipCacheLocator"]
