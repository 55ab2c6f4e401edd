"""``windseek campaign SPEC.toml`` (run or resume a campaign on Dask) and
``windseek campaign report RESULTS`` (tables and plots)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from mission.campaign.store import ResultStore


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "campaign",
        help="run a campaign of search missions on Dask (resumable), or report its results",
        description="windseek campaign SPEC.toml: fly every mission of a campaign file (a grid of scenarios, "
        "strategies, wind sources, seeds and parameters) on a local Dask cluster or an existing one, appending "
        "each result to a Parquet results folder as it finishes; re-running skips finished missions.  "
        "windseek campaign report RESULTS: success with a 95 % Wilson interval, median and p90 of the path "
        "ratios by any grouping, and PNG plots.",
    )
    p.add_argument("target", help="a campaign file (SPEC.toml), or the word 'report'")
    p.add_argument("results", nargs="?", help="report: the results folder (or a Parquet file)")
    g = p.add_argument_group("running a campaign")
    g.add_argument("--out", default=None, help="results folder (default logs/campaigns/<campaign name>)")
    g.add_argument("--scheduler", default=None, help="an existing Dask scheduler, tcp://HOST:8786 (or its "
                   "scheduler .json file); default: a local cluster")
    g.add_argument("--workers", type=int, default=None, help="local cluster: worker processes (default: one per "
                   "core)")
    g.add_argument("--retries", type=int, default=1, help="re-runs of a mission that raised (default 1)")
    g.add_argument("--flush", type=float, default=10.0, help="write finished rows at least this often [s] "
                   "(default 10)")
    g.add_argument("--dry-run", action="store_true", help="check the campaign file and count the missions to fly, "
                   "run nothing")
    g.add_argument("--no-progress", action="store_true", help="no progress display")
    r = p.add_argument_group("report")
    r.add_argument("--by", default=None, help="grouping columns, comma-separated (default: scenario, strategy, "
                   "wind and every swept parameter); parameters by name, e.g. wind_speed_m_s")
    r.add_argument("--plots", default=None, help="folder for the PNG plots (default RESULTS/plots)")
    r.add_argument("--no-plots", action="store_true", help="tables only")
    r.add_argument("--x", default=None, help="the swept parameter of the plots' x axis (default: each swept one)")
    r.add_argument("--markdown", action="store_true", help="print the table as Markdown")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    if args.target == "report":
        if not args.results:
            raise ValueError("campaign report: give the results folder (windseek campaign report RESULTS)")
        return _report(args)
    if args.results:
        raise ValueError(f"unexpected argument {args.results!r} (to report: windseek campaign report RESULTS)")
    return _run(args)


def _run(args: argparse.Namespace) -> int:
    from mission.campaign.grid import expand
    from mission.campaign.spec import load_campaign
    from mission.campaign.store import ResultStore, finished_missions

    if args.retries < 0:
        raise ValueError(f"--retries {args.retries}: must be >= 0")
    if args.flush <= 0:
        raise ValueError(f"--flush {args.flush}: must be > 0 s")
    spec = load_campaign(args.target)
    tasks = expand(spec)  # every value checked before anything runs
    out = Path(args.out) if args.out else Path("logs") / "campaigns" / spec.name
    todo = _plan(spec.name, tasks, finished_missions(out, spec.name), out)  # an unusable folder fails here
    if args.dry_run or not todo:
        return 0
    from mission.campaign.execute import connect

    client, cluster = connect(args.scheduler, args.workers)  # an unreachable scheduler fails here, before any work
    try:
        store = ResultStore(out, spec.name, flush_s=args.flush).open()
        try:
            finished = store.finished()  # again, under the lock
            return _fly(args, spec.name, client, [t for t in todo if t.key not in finished], store, out)
        finally:
            store.close()
    finally:
        client.close(timeout=10)
        if cluster is not None:
            cluster.close(timeout=20)


def _plan(name: str, tasks: list, finished: dict[str, str], out: Path) -> list:
    """The missions still to fly (and one line saying so)."""
    todo = [t for t in tasks if t.key not in finished]
    changed = sum(1 for t in tasks if t.key in finished and finished[t.key] != t.config_hash)
    print(f"campaign {name}: {len(tasks)} missions, {len(tasks) - len(todo)} already finished in {out}, "
          f"{len(todo)} to fly", file=sys.stderr)  # fmt: skip
    if changed:
        print(f"campaign {name}: note: {changed} finished missions were flown with another configuration "
              "(a scenario file or a default changed since); they are kept (use a new --out to fly them again)",
              file=sys.stderr)  # fmt: skip
    return todo


def _fly(args: argparse.Namespace, name: str, client: Any, todo: list, store: ResultStore, out: Path) -> int:
    from mission.campaign.execute import execute

    where = args.scheduler or f"a local cluster of {len(client.nthreads())} workers"
    print(f"campaign {name}: flying {len(todo)} missions on {where}", file=sys.stderr)
    try:
        rep = execute(client, todo, store, f"campaign {name}", progress=not args.no_progress, retries=args.retries)
    except KeyboardInterrupt:
        store.flush()
        print(f"campaign {name}: interrupted; {store.written} missions written to {out}; run the same command "
              "again to resume", file=sys.stderr)  # fmt: skip
        return 130
    print(f"campaign {name}: {rep.done} missions in {rep.wall_s:.0f} s ({rep.per_hour:,.0f} per hour), "
          f"{rep.errors} errors; results in {out} (windseek campaign report {out})", file=sys.stderr)  # fmt: skip
    for line in rep.error_lines[:10]:
        print(f"  error: {line}", file=sys.stderr)
    if rep.lost:
        print(f"campaign {name}: {rep.lost} missions were cancelled by the scheduler (lost connection?); "
              "run the same command again to fly them", file=sys.stderr)  # fmt: skip
    return 0 if rep.errors == 0 and rep.lost == 0 else 1


def _report(args: argparse.Namespace) -> int:
    from mission.campaign.report import group_columns, print_table, summarize_groups
    from mission.campaign.store import read_results

    table = read_results(args.results)
    if table.num_rows == 0:
        raise ValueError(f"{args.results}: no results yet")
    by = group_columns(table, args.by.split(",") if args.by else None)
    groups = summarize_groups(table, by)
    print_table(groups, by, markdown_out=args.markdown)
    if not args.no_plots:
        from mission.campaign.plots import write_plots

        folder = Path(args.plots) if args.plots else (Path(args.results) / "plots" if Path(args.results).is_dir()
                                                      else Path(args.results).with_suffix("") / "plots")  # fmt: skip
        for path in write_plots(table, folder, x=args.x):
            print(f"wrote {path}", file=sys.stderr)
    return 0
