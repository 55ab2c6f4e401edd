"""How the project's compiled code is built and cached, below every layer.

:mod:`toolchain.numba_cache` chooses numba's cache folder; every entry point (the ``windseek``
command line, the test suite, the benchmarks, the campaign workers) calls it before a kernel module
is imported. It lives outside the command-line package so that a library layer (a campaign worker in
``mission``) can call it without importing the command line.
"""
