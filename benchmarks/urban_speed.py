"""Urban wind field speed: solving the paper's Scenario 4 field and sampling it.

Prints, on one pinned core with one BLAS / OpenMP thread:

* the paper-s4 field (400 x 400 x 60 m, 2 m cells, 1.2 million cells) solved from scratch, per
  stage (initial parameterized field, multigrid setup, CG solve, total), as process CPU time
  (what one core spends; the goal is < 30 s) and wall time (which other jobs on the machine
  inflate; the load average is printed), with pyamg classical AMG (the default) and the
  smoothed-aggregation alternative, and scipy's Jacobi-preconditioned CG on the same system as
  the plain-library peer (solve only);
* sampling the mean wind: per point through ``urban_wind_mean_many`` (1e6 random points in the
  domain, a fifth of them inside the building block; in random order, where nearly every
  sample misses the CPU caches, and sorted in grid order, as a trajectory or a puff cloud
  samples it), per point from numba code calling ``urban_wind_mean`` / ``urban_wind_at`` one
  point at a time (what the simulator does), and per Python call of ``field.mean`` (goal:
  < 2 us per point from compiled code), in CPU and wall time;
* saving and loading the field through the cache.

Run: .venv/bin/python benchmarks/urban_speed.py
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import dataclasses  # noqa: E402
import statistics  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402
import scipy.sparse as sp  # noqa: E402
import scipy.sparse.linalg as spla  # noqa: E402
from numba import njit  # noqa: E402

from sitl.world.urban import (  # noqa: E402
    UrbanWindField,
    isolated_cube_scene,
    load_field,
    paper_s4_scene,
    save_field,
    solve_urban_wind,
    urban_wind_at,
    urban_wind_mean,
    urban_wind_mean_many,
)
from urbanflow.geometry import BuildingArrays, voxelize  # noqa: E402
from urbanflow.initial_field import initial_field  # noqa: E402
from urbanflow.solver import _poisson_matrix, divergence, zero_solid_faces  # noqa: E402

SEED = 1000
N_POINTS = 1_000_000


@njit(cache=True)
def _one_at_a_time(points: np.ndarray, *args) -> float:  # type: ignore[no-untyped-def]
    acc = 0.0
    for k in range(points.shape[0]):
        acc += urban_wind_mean(points[k], *args)[0]
    return acc


@njit(cache=True)
def _one_at_a_time_tuple(points: np.ndarray, *args) -> float:  # type: ignore[no-untyped-def]
    acc = 0.0
    for k in range(points.shape[0]):
        acc += urban_wind_at(points[k, 0], points[k, 1], points[k, 2], *args)[0]
    return acc


def _timed(fn):  # type: ignore[no-untyped-def]
    w0, c0 = time.perf_counter(), time.process_time()
    out = fn()
    return out, time.perf_counter() - w0, time.process_time() - c0


def solve_figures() -> UrbanWindField:
    print("| preconditioner | initial field | AMG setup | CG solve (iterations) | total CPU | total wall |")
    print("|---|---|---|---|---|---|")
    field = None
    for amg in ("classical", "smoothed_aggregation"):
        scene = paper_s4_scene()
        scene = dataclasses.replace(scene, options=dataclasses.replace(scene.options, amg=amg))
        f, wall, cpu = _timed(lambda s=scene: solve_urban_wind(s))
        st = f.stats
        assert st is not None
        print(f"| {amg} | {st.initial_s:.1f} s | {st.setup_s:.1f} s | {st.solve_s:.1f} s ({st.iterations}) |"
              f" {cpu:.1f} s | {wall:.1f} s |")
        field = field or f
    assert field is not None
    print(f"| scipy cg + Jacobi (peer, solve only) | | | {jacobi_cg_cpu(field)} | | |")
    print("(stages in CPU time; the total includes voxels, zones and the turbulence multiplier)")
    return field


def jacobi_cg_cpu(field: UrbanWindField) -> str:
    """CPU time and iterations of scipy's Jacobi-preconditioned CG on the same Poisson system."""
    scene = field.scene
    g = scene.grid
    nx, ny, nz = g.shape
    geom = BuildingArrays.from_buildings(scene.buildings)
    solid = voxelize(g.x_min_m, g.y_min_m, g.spacing_m, g.spacing_m, g.dz, nx, ny, nz, *geom.args()) >= 0
    u, v, w = initial_field(scene, geom)
    zero_solid_faces(u, v, w, solid)
    m = _poisson_matrix(solid, g.spacing_m, g.spacing_m, g.dz, scene.options.alpha_ratio**2)
    rhs = divergence(u, v, w, g.spacing_m, g.spacing_m, g.dz)
    rhs[solid] = 0.0
    count = [0]

    def step(_: np.ndarray) -> None:
        count[0] += 1

    c0 = time.process_time()
    spla.cg(m, rhs.ravel(), rtol=scene.options.solver_tol, maxiter=5000, M=sp.diags(1.0 / m.diagonal()), callback=step)
    return f"{time.process_time() - c0:.1f} s ({count[0]})"


def sampling_figures(field: UrbanWindField) -> None:
    rng = np.random.default_rng(SEED)
    n_block = N_POINTS // 5
    pts = np.column_stack([rng.uniform(0, 400, N_POINTS), rng.uniform(0, 400, N_POINTS), -rng.uniform(0, 60, N_POINTS)])
    pts[:n_block, :2] = rng.uniform(130.0, 290.0, (n_block, 2))  # the block: buildings, streets, wakes
    pts[:n_block, 2] = -rng.uniform(0.0, 25.0, n_block)
    args = field.kernel_args()
    # The same points in memory order of the grid (as a trajectory or a puff cloud samples it).
    g = field.scene.grid
    cell = np.floor(pts[:, 0] / g.spacing_m) * 1e6 + np.floor(pts[:, 1] / g.spacing_m) * 1e3 - pts[:, 2] / g.dz
    near = np.ascontiguousarray(pts[np.argsort(cell)])
    urban_wind_mean_many(pts[:10], *args)
    _one_at_a_time(pts[:10], *args)
    _one_at_a_time_tuple(pts[:10], *args)
    many = [_timed(lambda: urban_wind_mean_many(pts, *args))[1:] for _ in range(5)]
    many_near = [_timed(lambda: urban_wind_mean_many(near, *args))[1:] for _ in range(5)]
    single = [_timed(lambda: _one_at_a_time(near, *args))[1:] for _ in range(5)]
    single_t = [_timed(lambda: _one_at_a_time_tuple(near, *args))[1:] for _ in range(5)]
    p0 = pts[n_block]
    py_calls = [_timed(lambda: [field.mean(p0) for _ in range(20000)])[1:] for _ in range(5)]

    def per(runs: list[tuple[float, float]], n: int, unit: float) -> str:
        return " | ".join(f"{statistics.median(r[i] for r in runs) / n * unit:.0f}" for i in (1, 0))

    print("| sampling, per point (median of 5) | CPU (ns) | wall (ns) |")
    print("|---|---|---|")
    print(f"| urban_wind_mean_many, 1e6 points in random order | {per(many, N_POINTS, 1e9)} |")
    print(f"| urban_wind_mean_many, the same points in grid order | {per(many_near, N_POINTS, 1e9)} |")
    print(f"| urban_wind_mean (returns an array) from numba, one point per call | {per(single, N_POINTS, 1e9)} |")
    print(f"| urban_wind_at (returns a tuple) from numba, one point per call | {per(single_t, N_POINTS, 1e9)} |")
    print(f"| field.mean(p) from Python, one point per call | {per(py_calls, 20000, 1e9)} |")


def cache_figures(field: UrbanWindField) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        path, wall_save, _ = _timed(lambda: save_field(field, tmp))
        loaded, wall_load, _ = _timed(lambda: load_field(field.scene, tmp))
        assert loaded is not None and np.array_equal(loaded.u_n, field.u_n)
        print(f"| cache | save {wall_save:.2f} s, load {wall_load:.2f} s, file {path.stat().st_size / 1e6:.0f} MB |")


def main() -> None:
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})  # one core
    solve_urban_wind(isolated_cube_scene(height_m=4.0, spacing_m=1.0))  # compile the kernels first
    print(f"load average before: {' '.join(f'{x:.1f}' for x in os.getloadavg())} (2 cores)")
    field = solve_figures()
    sampling_figures(field)
    cache_figures(field)
    print(f"load average after: {' '.join(f'{x:.1f}' for x in os.getloadavg())}")


if __name__ == "__main__":
    main()
