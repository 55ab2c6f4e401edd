"""Infotaxis under a wandering wind (issue 19): the measured direction spread and the likelihood it
widens. NED, SI; wind = air-mass velocity (north, east) [m/s]."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mission.strategies import Observation, WindInfo, params_from_table
from mission.strategies.infotaxis import Infotaxis
from mission.strategies.ste_adapt import DirectionSpread, adapted_likelihood, mismatch_factor
from mission.strategies.ste_filter import PriorBox, SourcePosterior
from mission.strategies.ste_model import detection_prob, model_constants, set_meander


def _wind(from_deg: float, speed: float = 5.0) -> tuple[float, float]:
    """Air-mass velocity (north, east) [m/s] of a wind blowing from ``from_deg``."""
    a = math.radians(from_deg)
    return -speed * math.cos(a), -speed * math.sin(a)


def test_direction_spread_measures_the_wandering():
    steady, steps = DirectionSpread(15.0), DirectionSpread(15.0)
    rng = np.random.default_rng(1)
    for k in range(600):  # 60 s at 10 Hz; the steps: +-20 deg every 10 s
        steady.add(*_wind(float(rng.normal(0.0, 2.0))), 0.1)
        steps.add(*_wind(20.0 if (k // 100) % 2 else -20.0), 0.1)
    assert math.degrees(steady.spread_rad) < 3.0
    assert 15.0 < math.degrees(steps.spread_rad) < 25.0
    # A calm wind has no direction: skipped, the spread is kept.
    before = steps.spread_rad
    steps.add(0.01, 0.0, 0.1)
    assert steps.spread_rad == before
    assert DirectionSpread(15.0).spread_rad == 0.0


def test_mismatch_factor_leaves_the_model_alone_below_the_reference():
    ref = math.radians(10.0)
    assert mismatch_factor(math.radians(7.0), ref) == 1.0
    assert mismatch_factor(math.radians(20.0), ref) == pytest.approx(2.0)
    assert mismatch_factor(math.radians(20.0), 0.0) == 1.0  # reference 0: never adapt
    assert adapted_likelihood(1.0, 1.0, 0.12, 2.0, 1.0) == (1.0, 0.12)
    kappa, meander = adapted_likelihood(2.0, 1.0, 0.12, 2.0, 1.0)
    assert kappa == pytest.approx(0.25) and meander == pytest.approx(0.24)


def _mc(meander_deg: float) -> np.ndarray:
    p = params_from_table("infotaxis", None)
    mc = model_constants(p.stability, p.source_radius_m, p.intermittency_length_m, p.detection_limit_mg_m3,
                         p.false_alarm, p.upwind_reach_m, p.meander_fraction, math.radians(p.meander_deg))
    set_meander(mc, math.radians(meander_deg))
    return mc


def test_a_wider_meander_reaches_further_across():
    narrow, wide = _mc(7.0), _mc(14.0)
    assert detection_prob(40.0, 10.0, 2.0, 2.0, 0.3, 5.0, wide) > detection_prob(40.0, 10.0, 2.0, 2.0, 0.3, 5.0, narrow)
    assert detection_prob(40.0, 0.0, 2.0, 2.0, 0.3, 5.0, wide) < detection_prob(40.0, 0.0, 2.0, 2.0, 0.3, 5.0, narrow)


def _confidence(kappa: float, meander_deg: float) -> float:
    """Posterior mass within 3 m of its credible centre after a survey of crosswind lines 40-63 m
    north of a source 60 m north, in a plume that turns 20 deg either way every 10 s while the
    model assumes a steady wind from the north."""
    post = SourcePosterior(2000, _mc(meander_deg), kappa, 0.1, np.random.default_rng(2), 7, 8.0, 0.5, 0.02)
    post.init_prior(PriorBox(origin_ne=(0.0, 0.0), upwind_rad=0.0, ahead=120.0, back=10.0, half_width=40.0,
                             h_range=(1.0, 3.0), q_range=(0.01, 100.0), delta_sigma=math.radians(5.0)))
    truth = _mc(7.0)
    rng, t = np.random.default_rng(2), 0.0
    for n in (40.0, 50.0, 55.0, 58.0, 59.0, 61.0, 63.0):
        for e in np.arange(-6.0, 6.01, 0.5):
            for _ in range(3):
                a = math.radians(20.0 if int(t // 10) % 2 else -20.0)
                dx, dy = 60.0 - n, e
                x, y = dx * math.cos(a) - dy * math.sin(a), dx * math.sin(a) + dy * math.cos(a)
                post.update(t, n, e, 2.0, bool(rng.random() < detection_prob(x, y, 2.0, 2.0, 4.5, 5.0, truth)),
                            math.pi, 5.0)
                t += 0.5
    c, _ = post.credible_disc(0.9)
    return post.mass_within(c, 3.0)


def test_the_widened_likelihood_is_less_sure_under_a_mismatch():
    kappa, meander = adapted_likelihood(2.0, 1.0, math.radians(7.0), 2.0, 1.0)
    sharp, widened = _confidence(1.0, 7.0), _confidence(kappa, math.degrees(meander))
    assert sharp > 0.9  # the sharp model declares on these readings
    assert widened < 0.5  # the widened one wants more before it is sure


def _run(from_deg, seconds: float = 40.0, reference_deg: float = 10.0) -> Infotaxis:
    s = Infotaxis()
    s.reset(np.zeros(3), params_from_table("infotaxis", {"infotaxis": {"spread_reference_deg": reference_deg}}), seed=3)
    for k in range(int(seconds * 10)):
        wn, we = _wind(from_deg(k * 0.1))
        wind = WindInfo(wind_ned=np.array([wn, we, 0.0]), cov_ned=None, upwind_rad=math.radians(from_deg(k * 0.1)))
        s.update(Observation(t=k * 0.1, position_ned=np.array([0.0, 0.0, -2.0]), velocity_ned=np.zeros(3),
                             chem_mg_m3=0.0, detected=False, wind=wind))
    return s


def test_infotaxis_widens_only_when_the_wind_wanders():
    p = params_from_table("infotaxis", None)
    steady = _run(lambda t: 0.0, reference_deg=10.0)
    assert steady.mismatch == 1.0 and steady.post.kappa == p.tempering
    turning = _run(lambda t: 25.0 if int(t // 10) % 2 else -25.0, reference_deg=10.0)
    assert turning.mismatch > 1.5
    assert turning.post.kappa < 0.7 * p.tempering
    off = _run(lambda t: 25.0 if int(t // 10) % 2 else -25.0, reference_deg=0.0)  # off
    assert off.mismatch == 1.0 and off.post.kappa == p.tempering
