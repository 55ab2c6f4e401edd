"""Urban infotaxis speed and the field solve off the tick (issue 32): the move choice's rearranged kernel
gives the per-pair formulation's numbers bit for bit, and a field solved in a worker (the MAVSDK
runner's, ``mission.runners.field_solver``) makes the strategy hover in ``solve-field`` and then search
with the same field as a solve in the tick -- or, past the bound, fall back to the open-field plume."""

from __future__ import annotations

import math
from collections.abc import Callable
from concurrent.futures import Executor, Future
from typing import Any

import numpy as np
from numba import njit

from mission.obstacles import Building, Obstacles
from mission.runners.field_solver import field_solver_for
from mission.strategies import Observation, WindInfo
from mission.strategies.infotaxis import Infotaxis
from mission.strategies.params import InfotaxisParams
from mission.strategies.ste_city import FIELD_SOLVE_LIMIT_S
from mission.strategies.ste_model import (
    EPS,
    binary_entropy,
    mean_plume_prob,
    meander_nodes,
    model_constants,
    weigh_particle,
)
from mission.strategies.ste_urban import (
    SOLID_LOG_PENALTY,
    UrbanModel,
    accumulate_urban,
    is_solid,
    near_path,
    path_frame,
    plume_in_path_frame,
)
from mission.strategies.ste_urban_field import build_plane
from mission.strategies.ste_urban_plan import expected_information_urban

P = InfotaxisParams()
MC = model_constants(P.stability, P.source_radius_m, P.intermittency_length_m, P.detection_limit_mg_m3,
                     P.false_alarm, P.upwind_reach_m, P.meander_fraction, math.radians(P.meander_deg))
WIND = WindInfo(wind_ned=np.array([-4.0, 0.0, 0.0]), cov_ned=None, upwind_rad=0.0)


def _box(n: float, e: float, size: float, height: float) -> Building:
    h = size / 2.0
    return Building(np.array([[n - h, e - h], [n + h, e - h], [n + h, e + h], [n - h, e + h]]), height, "block")


@njit(cache=False)
def _per_pair(paths: np.ndarray, lens: np.ndarray, pz: float, n: np.ndarray, e: np.ndarray, h: np.ndarray,
              q: np.ndarray, cd: np.ndarray, sd: np.ndarray, mc: np.ndarray, gp: np.ndarray, solid: np.ndarray,
              mix_rate: float, out_info: np.ndarray) -> None:
    """The move choice's expected information pair by pair (the formulation before the rearrangement)."""
    m = n.shape[0]
    for k in range(paths.shape[0]):
        pbar, hbar = 0.0, 0.0
        for i in range(m):
            p = mc[EPS]
            if not is_solid(gp, solid, n[i], e[i]):
                x0, y0, tau, mix = path_frame(paths[k], lens[k], n[i], e[i], gp[5], gp[6])
                if near_path(x0, y0, mix, cd[i], sd[i], mix_rate, mc):
                    y, g, cpk, sm, si2 = plume_in_path_frame(x0, y0, tau, mix, cd[i], sd[i], pz, h[i], q[i], gp,
                                                             mix_rate, mc)
                    p = mean_plume_prob(y, g, cpk, sm, si2, mc)
            pbar += p
            hbar += binary_entropy(p)
        out_info[k] = binary_entropy(pbar / m) - hbar / m


@njit(cache=False)
def _per_particle(acc: np.ndarray, alpha: np.ndarray, n: np.ndarray, e: np.ndarray, h: np.ndarray, q: np.ndarray,
                  cd: np.ndarray, sd: np.ndarray, path: np.ndarray, k_len: int, pz: float, hit: bool, kappa: float,
                  rho: float, nodes: np.ndarray, mc: np.ndarray, gp: np.ndarray, solid: np.ndarray,
                  mix_rate: float) -> None:
    """The update's accumulation particle by particle (the formulation before the batched coarse stage)."""
    for i in range(acc.shape[0]):
        if is_solid(gp, solid, n[i], e[i]):
            for j in range(acc.shape[1]):
                acc[i, j] += kappa * SOLID_LOG_PENALTY
            continue
        x0, y0, tau, mix = path_frame(path, k_len, n[i], e[i], gp[5], gp[6])
        y, g, cpk, sm, si2 = plume_in_path_frame(x0, y0, tau, mix, cd[i], sd[i], pz, h[i], q[i], gp, mix_rate, mc)
        weigh_particle(acc, alpha, i, y, g, cpk, sm, si2, hit, kappa, rho, nodes, mc)


#: Particles (n, e, h, q, cos delta, sin delta).
Parts = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]


def _scene() -> tuple[UrbanModel, np.ndarray, np.ndarray, Parts]:
    """Two blocks, 60 candidate paths (three of them short) and 250 particles, some inside a block."""
    plane = build_plane([_box(40.0, 0.0, 16.0, 12.0), _box(70.0, 25.0, 12.0, 10.0)], np.array([-4.0, -1.0]), 5.0)
    model = UrbanModel(plane, 3.0, 120.0)
    rng = np.random.default_rng(3)
    paths, lens = model.paths(rng.uniform(-20.0, 100.0, 60), rng.uniform(-40.0, 60.0, 60))
    lens[:3] = (1, 2, 10)  # a one-point path, and two stopped short (as by a closed corner)
    m = 250
    delta = rng.normal(0.0, 0.2, m)
    parts: Parts = (rng.uniform(0.0, 120.0, m), rng.uniform(-40.0, 60.0, m), rng.uniform(0.0, 5.0, m),
                    10.0 ** rng.uniform(-3.0, 0.0, m), np.cos(delta), np.sin(delta))
    return model, paths, lens, parts


def test_update_kernel_is_bit_identical_to_the_per_particle_formulation() -> None:
    model, paths, lens, parts = _scene()
    gp, _, _, solid = model.plane.args()
    nodes, _ = meander_nodes(7)
    kernel: Any = accumulate_urban  # numba dispatchers: mypy cannot check star arguments against them
    reference: Any = _per_particle
    for k in range(6):  # hits and misses along paths of every kind, the window's state carried on
        acc, alpha = np.zeros((250, 7)), np.full((250, 7), -1.0)
        ref, ref_alpha = acc.copy(), alpha.copy()
        for _ in range(2):
            args = (paths[k], lens[k], 2.0, k % 2 == 0, 0.8, 0.5, nodes, MC, gp, solid, model.mix_rate)
            kernel(acc, alpha, *parts, *args)
            reference(ref, ref_alpha, *parts, *args)
        assert np.array_equal(acc, ref) and np.array_equal(alpha, ref_alpha)


def test_move_choice_kernel_is_bit_identical_to_the_per_pair_formulation() -> None:
    model, paths, lens, parts = _scene()
    gp, _, _, solid = model.plane.args()
    info, phit, ref = np.empty(60), np.empty(60), np.empty(60)
    expected_information_urban(paths, lens, 5.0, *parts, MC, gp, solid, model.mix_rate, info, phit)
    _per_pair(paths, lens, 5.0, *parts, MC, gp, solid, model.mix_rate, ref)
    assert any(is_solid(gp, solid, a, b) for a, b in zip(parts[0], parts[1], strict=True))  # sources in a block
    assert np.array_equal(info, ref)


class _HeldExecutor(Executor):
    """Runs a submitted job only when ``finish()`` is called (a solve that takes as long as the test wants)."""

    def __init__(self) -> None:
        self.jobs: list[tuple[Future[Any], Callable[..., Any], tuple[Any, ...]]] = []

    def submit(self, fn: Callable[..., Any], /, *args: Any, **kwargs: Any) -> Future[Any]:
        f: Future[Any] = Future()
        self.jobs.append((f, fn, args))
        return f

    def finish(self) -> None:
        for f, fn, args in self.jobs:
            f.set_result(fn(*args))


def _fly_to_solve(s: Infotaxis, t_end: float, t: float = 0.0) -> tuple[float, list[str]]:
    states = []
    while t < t_end:
        obs = Observation(t=t, position_ned=np.array([0.0, 0.0, -s.city.probe_height_m]),  # type: ignore[union-attr]
                          velocity_ned=np.zeros(3), chem_mg_m3=0.0, detected=False, chem_new=True, wind=WIND)
        states.append(s.update(obs).state)
        t = round(t + 0.1, 6)
    return t, states


def _strategy(solver: Executor | None) -> Infotaxis:
    s = Infotaxis()
    s.set_obstacles(Obstacles([_box(60.0, 0.0, 20.0, 12.0)]))
    s.set_field_solver(solver)
    s.reset(np.zeros(3), InfotaxisParams(plume_model="urban", n_particles=300, plan_particles=30, urban_probe_s=0.5),
            seed=0)
    return s


def test_a_field_solved_off_the_tick_is_waited_for_hovering_and_is_the_same_field() -> None:
    held = _HeldExecutor()
    s = _strategy(held)
    t, states = _fly_to_solve(s, 2.0)
    assert states[0] == "measure-inflow" and states[-1] == "solve-field" and len(held.jobs) == 1
    assert s.post.urban is None and not s.post.ready  # nothing solved in a tick
    held.finish()
    t, states = _fly_to_solve(s, t + 0.2, t)
    assert states[-1] == "search" and s.post.urban is not None
    assert any("solved for the estimated inflow" in m and "off the tick" in m for m in s.pop_messages())
    ref = _strategy(None)  # the same inflow, solved in the tick
    _fly_to_solve(ref, 1.0)
    assert ref.post.urban is not None
    for a, b in zip(s.post.urban.plane.args(), ref.post.urban.plane.args(), strict=True):
        assert np.array_equal(a, b)


def test_a_field_solve_past_the_bound_leaves_the_open_field_plume_and_no_declaration() -> None:
    held = _HeldExecutor()
    s = _strategy(held)
    t, states = _fly_to_solve(s, FIELD_SOLVE_LIMIT_S + 1.5)
    assert "solve-field" in states and states[-1] == "search"
    assert s.post.urban is None and s.model_unusable
    assert any("not solved within" in m for m in s.pop_messages())


def test_the_mavsdk_runner_gets_a_worker_process_only_for_an_urban_field() -> None:
    obstacles = Obstacles([_box(60.0, 0.0, 20.0, 12.0)])
    assert field_solver_for(Infotaxis(), InfotaxisParams(), obstacles) is None  # the open-field plume
    assert field_solver_for(Infotaxis(), InfotaxisParams(plume_model="urban"), None) is None  # no buildings
    s = Infotaxis()
    pool = field_solver_for(s, InfotaxisParams(plume_model="urban"), obstacles)
    assert pool is not None and s.field_solver is pool
    try:  # the worker's field is the tick's, bit for bit
        args = (list(obstacles.buildings), np.array([-3.0, -1.0]), 5.0, 22.0, 4.0)
        got = pool.submit(build_plane, *args).result(timeout=120.0)
    finally:
        pool.shutdown(wait=False, cancel_futures=True)
    for a, b in zip(got.args(), build_plane(*args).args(), strict=True):
        assert np.array_equal(a, b)
