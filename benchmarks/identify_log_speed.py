"""Speed of ``windseek identify --log``: the whole command on a 2-minute ULog of the identification manoeuvre.

    .venv/bin/python benchmarks/identify_log_speed.py [--minutes 2] [--repeat 3] [--keep DIR]

The paper's manoeuvre (5 s hover + ``--minutes`` of excitation) is flown in-process in ``calm`` (world seed
1, the nasa-quad's blade-element truth) and written as PX4 would log it (tests/flight_logs.py: IMU 250 Hz,
attitude / position / ESC 50 Hz, actuator outputs 250 Hz); then ``windseek identify --log LOG --vehicle
nasa-quad -o OUT --json`` is run as a separate process, holding out the last 30 % for validation, and
timed: wall clock and the child's CPU time (user + system), interpreter start-up and imports included.
"One core": the child runs with ``OPENBLAS_NUM_THREADS=1`` (the identification's many small least-squares
problems gain nothing from BLAS threads, and on a loaded machine threads waiting for a busy core cost
several times their work); the default threading is timed too. The stages in-process (reading, the
identification, the excitation screen) are printed once, single-threaded, after a warm-up.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # this process's own stage timings: one core

import argparse  # noqa: E402
import json  # noqa: E402
import resource  # noqa: E402
import statistics  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from toolchain import numba_cache  # noqa: E402

numba_cache.configure()
from flight_logs import write_ulog  # noqa: E402

from identify.design import ManoeuvreSpec, design  # noqa: E402
from identify.excitation import screen  # noqa: E402
from identify.fly.world import fly  # noqa: E402
from identify.log_outputs import motor_map  # noqa: E402
from identify.logs import read_log, split_record  # noqa: E402
from identify.pipeline import identify  # noqa: E402
from sitl.scenario import load_scenario  # noqa: E402
from vehicle.vehicle_file import load_vehicle  # noqa: E402


def _command(log: Path, out: Path, threads: str | None) -> tuple[float, float, dict]:
    """(wall s, child CPU s, its JSON) of one ``windseek identify --log`` process."""
    env = dict(os.environ)
    env.pop("OPENBLAS_NUM_THREADS", None)
    if threads is not None:
        env["OPENBLAS_NUM_THREADS"] = threads
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    p = subprocess.run([sys.executable, "-m", "windseek.cli", "identify", "--log", str(log), "--vehicle", "nasa-quad",
                        "-o", str(out), "--json"], capture_output=True, text=True, env=env, cwd=ROOT)  # fmt: skip
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if p.returncode != 0:
        raise SystemExit(f"windseek identify failed ({p.returncode}): {p.stderr.strip()}")
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu, json.loads(p.stdout)


def _stages(log: Path) -> None:
    v = load_vehicle("nasa-quad")
    for warm in (True, False):
        t0 = time.process_time()
        flight = read_log(log, v)
        t1 = time.process_time()
        fit, val, _ = split_record(flight.data)
        ident = identify(fit, v, val)
        t2 = time.process_time()
        screen(ident, v)
        t3 = time.process_time()
        if not warm:
            print(f"stages in-process (CPU s, one thread, warm): read {t1 - t0:.2f}, identify {t2 - t1:.2f}, "
                  f"screen {t3 - t2:.3f} ({flight.data.n} IMU samples, {ident.n_fit} + {ident.n_validation} "
                  "regression samples at 50 Hz)")  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--minutes", type=float, default=2.0, help="excitation length, min (default 2)")
    ap.add_argument("--repeat", type=int, default=3, help="runs of the command per setting (median printed)")
    ap.add_argument("--keep", help="directory to write the log and the vehicle file into (default: a temp dir)")
    args = ap.parse_args()
    out_dir = Path(args.keep or tempfile.mkdtemp(prefix="identify-log-speed-"))
    out_dir.mkdir(parents=True, exist_ok=True)
    sc = load_scenario("calm")
    v = load_vehicle(sc.vehicle)
    t0 = time.perf_counter()
    hover_dt = v.n_rotors * v.control["hover_speed"] ** 2
    data = fly(sc, 1, design(ManoeuvreSpec(duration_s=60.0 * args.minutes), hover_dt), v)
    log = write_ulog(out_dir / "manoeuvre.ulg", data, motor_map(v))
    print(f"log: {log} ({log.stat().st_size / 1e6:.1f} MB, {data.duration_s:.0f} s, {data.n} IMU samples; flown and "
          f"written in {time.perf_counter() - t0:.1f} s)")  # fmt: skip
    print(f"machine: {os.cpu_count()} cores, load average {os.getloadavg()[0]:.2f} at the start")
    _stages(log)
    res: dict = {}
    for label, threads in (("one core (OPENBLAS_NUM_THREADS=1)", "1"), ("default BLAS threads", None)):
        runs = [_command(log, out_dir / "identified.toml", threads) for _ in range(max(1, args.repeat))]
        res = runs[-1][2]
        walls, cpus = [r[0] for r in runs], [r[1] for r in runs]
        print(f"windseek identify --log, {label}: wall median {statistics.median(walls):.1f} s "
              f"(runs {', '.join(f'{w:.1f}' for w in walls)}), CPU median {statistics.median(cpus):.1f} s")
    print(f"load average {os.getloadavg()[0]:.2f} at the end")
    print("axis   R^2 %   fit TIC   val TIC   (fit: first 70 %, validation: last 30 % of the record)")
    for a, m in res["axes"].items():
        print(f"  {a.upper()}  {m['r2_pct']:7.2f}  {m['fit_tic']:8.4f}  {m['val_tic']:8.4f}")


if __name__ == "__main__":
    main()
