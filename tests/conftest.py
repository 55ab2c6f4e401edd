"""Test-suite set-up: one BLAS thread and numba's kernel cache (both before numpy and any kernel module
are imported), the markers."""

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # as the windseek command sets it (windseek/cli.py)

from toolchain import numba_cache  # noqa: E402

numba_cache.configure()
