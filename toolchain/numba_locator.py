"""numba's cache locator for this project's kernels: the cache subfolder named by the kernel file's directory
relative to the project, not by a hash of its absolute path, so every checkout of the same sources shares the
compiled kernels (see :mod:`toolchain.numba_cache`, which hands this class to numba through
``NUMBA_CACHE_LOCATOR_CLASSES``). Imported by numba when it first caches a kernel, never by the project."""

from __future__ import annotations

import os
from pathlib import Path

from numba.core import config
from numba.core.caching import UserProvidedCacheLocator

#: The project's root: the folder that holds ``toolchain/``.
ROOT = Path(__file__).resolve().parent.parent


def cache_subpath(py_file: str, root: Path = ROOT) -> str | None:
    """The cache subfolder of a kernel file under ``root`` (its directory relative to the project), or None for a
    file outside it (numba's own locators handle those)."""
    try:
        rel = Path(os.path.abspath(py_file)).parent.relative_to(root)
    except ValueError:
        return None
    return "project_" + ("_".join(rel.parts) or "root")


class ProjectCacheLocator(UserProvidedCacheLocator):
    """numba's locator for ``NUMBA_CACHE_DIR`` with a project-relative subfolder (numba still checks each
    source file's content hash before it uses a cached kernel)."""

    def __init__(self, py_func: object, py_file: str) -> None:
        super().__init__(py_func, py_file)
        self._cache_path = os.path.join(config.CACHE_DIR, cache_subpath(py_file) or "")  # type: ignore[attr-defined]

    @classmethod
    def from_function(cls, py_func: object, py_file: str) -> object:
        if cache_subpath(py_file) is None or not config.CACHE_DIR:  # type: ignore[attr-defined]
            return None
        return super().from_function(py_func, py_file)
