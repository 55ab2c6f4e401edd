"""Where numba keeps its compiled kernels: one explicit call, made by every entry point.

Numba invalidates a cached kernel only when the file that defines it changes, not when a function
or constant it imports from another module does, so after an edit elsewhere a kernel could keep
stale code. :func:`configure` points numba at a cache folder keyed by the source of every kernel
module of the project, so any edit to kernel code starts a fresh cache (compiled once, then reused).

Call it before importing any module with numba kernels (numba decides where a kernel's cache
lives when the kernel is defined): the ``windseek`` command line, the test suite
(``tests/conftest.py``), the benchmarks and the campaign workers do. A program that skips it still
works: numba then caches next to the sources, with the staleness caveat above.
``NUMBA_CACHE_DIR`` in the environment wins over both.

Numba files a kernel's cache under a folder named by a hash of its source file's *absolute* directory,
so a second checkout of the same sources (a fresh clone: CI, a worktree) compiled every kernel again,
1-2 minutes of the test suite, and two test processes compiling the same kernel at once stalled the
one whose simulation thread did it for tens of seconds. :func:`configure` therefore also puts, in front
of numba's own, a locator that names the folder by the file's path *relative to the project* (the cache
folder is already keyed by the kernels' contents, and numba checks each file's content hash itself), so
every checkout of the same sources shares one compiled cache (:mod:`toolchain.numba_locator`, given to
numba through its ``NUMBA_CACHE_LOCATOR_CLASSES`` setting).
"""

from __future__ import annotations

import hashlib
import os
import re
import sys
from pathlib import Path

#: numba's cache locators, in order (``NUMBA_CACHE_LOCATOR_CLASSES``): the project-relative one first, then
#: numba's own (as numba lists them) for code outside the project.
LOCATORS = ("toolchain.numba_locator.ProjectCacheLocator,UserProvidedCacheLocator,InTreeCacheLocator,"
            "UserWideCacheLocator,IPythonCacheLocator,ZipCacheLocator")
#: Packages whose kernels are cached (files that mention numba).
KERNEL_PACKAGES = ("sitl", "vehicle", "estimator", "mission", "urbanflow")
_configured: str | None = None
_KERNEL_TEXT = re.compile(rb"\bnumba\b")


def cache_dir(root: Path | None = None) -> Path:
    """The cache folder for the current kernel sources: ``$XDG_CACHE_HOME/windseek/numba/<digest>``."""
    root = root or Path(__file__).resolve().parent.parent
    digest = hashlib.sha1()
    for pkg in KERNEL_PACKAGES:
        folder = root / pkg
        if folder.is_dir():
            for f in sorted(folder.rglob("*.py")):
                text = f.read_bytes()
                # Only kernel modules (a mention of numba_cache alone is not one): editing plain Python
                # recompiles nothing.
                if _KERNEL_TEXT.search(text):
                    digest.update(f.relative_to(root).as_posix().encode() + text)
    base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    return base / "windseek" / "numba" / digest.hexdigest()[:16]


def configure() -> str:
    """Set numba's cache folder (unless ``NUMBA_CACHE_DIR`` is already set) and return it. Warns on
    stderr when a kernel module was imported before (its kernels then cache elsewhere)."""
    global _configured
    if _configured is not None:  # once per process: the entry point that came first decided
        return _configured
    if "NUMBA_CACHE_DIR" not in os.environ:
        os.environ["NUMBA_CACHE_DIR"] = str(cache_dir())
    path = os.environ["NUMBA_CACHE_DIR"]
    _configured = path
    if "numba" in sys.modules:  # numba reads its config at import: update the live value too
        import numba

        numba.config.CACHE_DIR = path  # type: ignore[attr-defined]
    # numba's own hook for cache locators (read when numba is imported, so set before it): ours first.
    if "NUMBA_CACHE_LOCATOR_CLASSES" not in os.environ:
        os.environ["NUMBA_CACHE_LOCATOR_CLASSES"] = LOCATORS
    if "numba" in sys.modules:
        import numba

        numba.config.CACHE_LOCATOR_CLASSES = os.environ["NUMBA_CACHE_LOCATOR_CLASSES"]  # type: ignore[attr-defined]
    early = sorted(m for m in sys.modules if m.split(".")[0] in KERNEL_PACKAGES and "." in m)
    if any(m.startswith(("sitl.world", "sitl.autopilot", "vehicle.", "estimator.")) for m in early):
        print(f"windseek: numba cache configured after kernel modules were imported ({early[0]}, ...)",
              file=sys.stderr)  # fmt: skip
    return path

