"""The ``windseek`` command line: one entry point, one module per subcommand.

Each subcommand module in :data:`COMMANDS` provides ``add_parser(subparsers)`` (registering
its parser with ``set_defaults(func=run)``) and ``run(args) -> int``. Errors are printed as
one clear line; ``--verbose`` shows the traceback.
"""

from __future__ import annotations

import argparse
import importlib
import sys

from windseek import numba_cache

#: Subcommand modules, in the order shown by ``windseek --help``.
COMMANDS = [
    "windseek.cmd_sim",
    "windseek.cmd_search",
    "windseek.cmd_estimate",
    "windseek.cmd_sitl",
    "windseek.cmd_mission",
    "windseek.cmd_review",
    # issue 7: the live estimator process and the three-process demo
    "windseek.cmd_estimator",
    "windseek.cmd_demo",
]


def build_parser() -> argparse.ArgumentParser:
    numba_cache.configure()  # before any kernel module is imported by a subcommand
    parser = argparse.ArgumentParser(
        prog="windseek",
        description="SITL harness for wind-aware chemical source localization with small multirotors.",
    )
    parser.add_argument("--verbose", "-v", action="store_true", help="show tracebacks and debug output")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for name in COMMANDS:
        importlib.import_module(name).add_parser(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
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
