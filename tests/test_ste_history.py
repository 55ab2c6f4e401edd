"""The STE posterior's reading history (issue 19): particles redrawn at a resampling are weighed
against every reading so far. NED, SI; the source 60 m north of home at 2 m, wind from the north."""

from __future__ import annotations

import math

import numpy as np

from mission.strategies import params_from_table
from mission.strategies.ste_filter import PriorBox, SourcePosterior
from mission.strategies.ste_history import ReadingHistory
from mission.strategies.ste_model import detection_prob, meander_nodes, model_constants

SOURCE = np.array([60.0, 0.0])


def _mc() -> np.ndarray:
    p = params_from_table("infotaxis", None)
    return model_constants(p.stability, p.source_radius_m, p.intermittency_length_m, p.detection_limit_mg_m3,
                           p.false_alarm, p.upwind_reach_m, p.meander_fraction, math.radians(p.meander_deg))


def _readings(seed: int) -> list[tuple[float, float, float, bool]]:
    """(t, north, east, hit) drawn from the model along crosswind lines 40-63 m north."""
    rng, mc, out, t = np.random.default_rng(seed), _mc(), [], 0.0
    for n in (40.0, 50.0, 55.0, 58.0, 59.0, 61.0, 63.0):
        for e in np.arange(-6.0, 6.01, 0.5):
            for _ in range(3):
                p = detection_prob(SOURCE[0] - n, e - SOURCE[1], 2.0, 2.0, 4.5, 5.0, mc)
                out.append((t, float(n), float(e), bool(rng.random() < p)))
                t += 0.5
    return out


def test_history_likelihood_prefers_the_source_to_a_place_the_readings_rule_out():
    hist, mc = ReadingHistory(), _mc()
    for t, n, e, hit in _readings(1):
        hist.add(t, n, e, 2.0, hit, -1.0, 0.0, 5.0, 1.0, math.radians(7.0))
    one = np.ones(2)
    parts = (np.array([60.0, 45.0]), np.zeros(2), 2.0 * one, 4.5 * one, one, np.zeros(2))
    nodes, lw = meander_nodes(3)
    ll = hist.log_likelihood(parts, mc, nodes, lw, 0.5, 8.0)
    assert ll[0] > ll[1] + 20.0  # 45 m north: hits upwind of it, misses in its near field
    # Only the first rows: before any reading both are equally likely.
    assert np.allclose(hist.log_likelihood(parts, mc, nodes, lw, 0.5, 8.0, 0), 0.0)


def test_redrawn_particles_carry_the_history():
    post = SourcePosterior(2000, _mc(), 1.0, 0.1, np.random.default_rng(2), 7, 8.0, 0.5, 0.1, (25.0, 8.0), True)
    post.init_prior(PriorBox(origin_ne=(0.0, 0.0), upwind_rad=0.0, ahead=120.0, back=10.0, half_width=40.0,
                             h_range=(1.0, 3.0), q_range=(0.1, 100.0), delta_sigma=math.radians(5.0)))
    for t, n, e, hit in _readings(2):
        post.update(t, n, e, 2.0, hit, math.pi, 5.0)
    assert post.n_resamples > 0
    post._resample()
    sel = post._pending
    assert sel is not None and len(sel) == 200
    steps = 0
    while post.weigh_step(40):
        steps += 1
    assert post._pending is None and steps >= 4
    d = np.hypot(post.pn[sel] - SOURCE[0], post.pe[sel] - SOURCE[1])
    resampled = np.setdiff1d(np.arange(post.n), sel)
    w = post.w[sel] / post.w[resampled].max()
    assert np.all(w <= 1.0 + 1e-9)  # never heavier than a resampled particle
    assert np.mean(w[d > 10.0]) < 0.2 * np.mean(w[d < 3.0])  # ruled-out places stay out


def test_a_free_tick_weighs_fewer_particles_as_the_history_grows():
    """The weighing costs particles x readings: up to a 300 s mission's 600 readings a free tick weighs
    ``WEIGH_PER_TICK`` particles, beyond that fewer, so the tick's CPU stays bounded however long
    the mission (the same particles are weighed over more ticks)."""
    from mission.strategies.infotaxis import WEIGH_BUDGET, WEIGH_PER_TICK, weigh_count

    assert weigh_count(0) == weigh_count(600) == WEIGH_PER_TICK
    assert weigh_count(1200) == WEIGH_PER_TICK // 2
    for n in (601, 1000, 2400, 10_000):
        assert 1 <= weigh_count(n) < WEIGH_PER_TICK and weigh_count(n) * n <= WEIGH_BUDGET
    assert weigh_count(10**9) == 1  # never stalls
