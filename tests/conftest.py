"""Test-suite set-up: numba's kernel cache (before any kernel module is imported), the markers."""

from windseek import numba_cache

numba_cache.configure()
