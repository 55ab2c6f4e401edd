"""The ``windseek`` command line: one entry point, one module per subcommand.

Each subcommand module in :data:`COMMANDS` provides ``add_parser(subparsers)`` (registering
its parser with ``set_defaults(func=run)``) and ``run(args) -> int``. Errors are printed as
one clear line; ``--verbose`` shows the traceback.
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys

# One BLAS thread unless the user says otherwise, set before numpy loads: the identification's many
# small least-squares fits ran 2-5x slower with OpenBLAS's threads on a 2-core machine
# (benchmarks/README.md, "Identification"); nothing else here does large dense linear algebra.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

from toolchain import numba_cache  # noqa: E402

#: Subcommand modules, in the order shown by ``windseek --help``.
COMMANDS = [
    "windseek.cmd_sim",
    "windseek.cmd_search",
    "windseek.cmd_campaign",
    "windseek.cmd_estimate",
    # issue 29: the paper's system identification, for any vehicle
    "windseek.cmd_identify",
    "windseek.cmd_sitl",
    "windseek.cmd_mission",
    "windseek.cmd_review",
    # issue 7: the live estimator process and the three-process demo
    "windseek.cmd_estimator",
    "windseek.cmd_demo",
    # issue 14.7: a faulty link between two MAVLink endpoints
    "windseek.cmd_link_proxy",
]


def command_name(module: str) -> str:
    """The subcommand a module registers: ``windseek.cmd_link_proxy`` -> ``link-proxy``."""
    return module.rsplit(".cmd_", 1)[1].replace("_", "-")


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    """The parser with every subcommand, or with the one named ``only`` (a subcommand module imports
    what it runs: scipy, numba kernels, MAVSDK; importing all of them cost ~1.3 s of CPU before any
    command started, paid by every SITL, estimator and proxy process)."""
    numba_cache.configure()  # before any kernel module is imported by a subcommand
    parser = argparse.ArgumentParser(
        prog="windseek",
        description="SITL harness for wind-aware chemical source localization with small multirotors.",
    )
    parser.add_argument("--verbose", "-v", action="store_true", help="show tracebacks and debug output")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for name in COMMANDS:
        if only is None or command_name(name) == only:
            importlib.import_module(name).add_parser(sub)
    return parser


def _requested_command(argv: list[str]) -> str | None:
    """The subcommand named on the command line (the first argument that is not an option), if it
    is one; None otherwise (then the full parser reports the error or prints the help)."""
    first = next((a for a in argv if not a.startswith("-")), None)
    return first if first in {command_name(m) for m in COMMANDS} else None


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    parser = build_parser(_requested_command(argv))
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except KeyboardInterrupt:
        print("windseek: interrupted", file=sys.stderr)
        return 130
    except Exception as e:  # one clear line unless --verbose
        if args.verbose:
            raise
        print(f"windseek {args.command}: error: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
