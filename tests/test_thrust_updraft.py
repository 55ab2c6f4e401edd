"""The thrust check in an updraft (issue 31): the paper's vehicle in paper-s1 after its step (10 m/s from the
north-east and a 3 m/s updraft) turns its rotors at 269 rad/s where a calm hover needs 394, and its thrust ratio
falls to 0.47-0.54, below the band the check once computed at the calm hover's rotor speed (0.48). The band is
now the model's ratio at the rotor speed that carries the weight; thrust alone cannot tell an updraft from a
lighter vehicle, so the descent the band allows for beyond still air follows the converged filter's body-z
airspeed, and only once the vehicle has shown the model's thrust (estimator/thrust_check.py)."""

from __future__ import annotations

import functools
import math

import numpy as np
import pytest
from estimator_stream import Flight, autopilot_messages, over_the_wire

from estimator import thrust_check
from estimator.live import LiveConfig, LiveCore
from estimator.model_fit import ModelFit
from estimator.thrust_check import ThrustCheck
from sitl.scenario import load_scenario
from sitl.simulation import Simulation
from vehicle.vehicle_file import load_vehicle

SECONDS = 45.0  # paper-s1's step comes at 23 s; the old check latched at 35 s on this seed


@functools.cache
def _paper_s1(seed: int = 100) -> Flight:
    """paper-s1 as shipped (step at 23 s) in windseek's world, a development seed."""
    sim = Simulation(load_scenario("paper-s1").with_duration(SECONDS), seed=seed, record_truth=True)
    sim.run(SECONDS)
    out = sim.drain()
    return Flight(sim.truth_array(), out["imu"], out["esc"])


def _speed_for(chk: ThrustCheck, ratio: float) -> float:
    """The equal rotor speed (rad/s) whose zero-airspeed thrust is ``ratio`` x the model's weight."""
    n, a, b = 4, chk._a, chk._b
    need = ratio * chk.mass * chk.g / n
    return (-b + math.sqrt(b * b + 4.0 * a * need)) / (2.0 * a)


def _hold(fit: ModelFit, t: float, seconds: float, ratio: float, w_air: float | None) -> float:
    """``seconds`` of steady hover samples at 100 Hz whose thrust ratio is ``ratio``; the filter's body airspeed
    (10 m/s horizontal and ``w_air`` down, converged) or none (not converged). The time after them (s)."""
    chk = fit.thrust
    speeds = np.full(4, _speed_for(chk, ratio))
    acc, gyr = np.array([0.0, 0.0, -chk.g]), np.zeros(3)
    air = None if w_air is None else np.array([7.0, 7.0, w_air])
    for _ in range(int(seconds * 100)):
        fit.sample(t, acc, gyr, speeds, True, air, air is not None)
        t += 0.01
    return t


def test_the_band_is_the_models_ratio_at_the_rotor_speed_that_carries_the_weight() -> None:
    v = load_vehicle()
    assert thrust_check.trimmed_ratio(v, np.zeros(3)) == pytest.approx(1.0, abs=1e-9)
    # paper-s1 after the step: 10.3 m/s horizontal, 2.2 m/s of descent through the air (the flights measured
    # 0.47-0.54 there; at the calm hover's rotor speed the model says 0.61)
    assert 0.44 < thrust_check.trimmed_ratio(v, np.array([7.0, 7.5, 2.2])) < 0.50
    chk = ThrustCheck(v)
    lo, hi = chk.band  # still air: a lighter vehicle in strong wind (half the mass: 0.40-0.43) is outside
    assert 0.46 < lo < 0.52 and 1.35 < hi < 1.5
    assert chk._band(3.2)[0] < 0.47 / 1.3  # a 3 m/s updraft the filter has seen: well inside


def test_an_updraft_after_the_vehicle_showed_the_models_thrust_is_not_a_mismatch() -> None:
    fit = ModelFit(load_vehicle())
    t = _hold(fit, 0.0, 6.0, 0.80, -1.2)  # hovering into 10 m/s: the model's vehicle (0.75-0.86)
    assert fit.thrust.shown and fit.mismatch is None
    t = _hold(fit, t, 10.0, 0.47, 2.2)  # the updraft, seen by the converged filter
    assert fit.mismatch is None and fit.thrust.windows >= 7
    assert fit.thrust.last_descent_m_s == pytest.approx(3.2) and fit.thrust.last_band[0] < 0.47
    # the same thrust with no vertical airspeed from the filter is a lighter vehicle, as far as thrust can tell
    _hold(fit, t, 6.0, 0.40, None)
    said = fit.thrust.mismatch
    assert said is not None and "slower" in said and "up to 1.0 m/s" in said


def test_a_vehicle_not_yet_shown_to_fit_is_judged_on_still_air() -> None:
    """The filter explains a lighter vehicle by an updraft too: before the vehicle has shown the model's thrust,
    its filter's vertical airspeed is not taken (half the mass in strong wind is named)."""
    fit = ModelFit(load_vehicle())
    _hold(fit, 0.0, 6.0, 0.42, 2.2)
    assert not fit.thrust.shown and fit.thrust.mismatch is not None and "slower" in fit.thrust.mismatch


def test_beyond_the_vertical_domain_the_verdict_pauses() -> None:
    fit = ModelFit(load_vehicle())
    t = _hold(fit, 0.0, 6.0, 0.80, -1.2)
    n = fit.thrust.windows
    _hold(fit, t, 6.0, 0.20, 4.5)  # a descent through the air the model was never identified for
    # (the window open when the descent began ends at the still-air airspeed it mostly held)
    assert fit.thrust.mismatch is None and fit.thrust.paused >= 2 and fit.thrust.windows <= n + 1


def test_the_papers_vehicle_in_paper_s1_is_not_refused_after_the_step() -> None:
    core = LiveCore(LiveConfig(vehicle=load_vehicle()))
    ratios = []
    for m in over_the_wire([(1, 1, autopilot_messages(_paper_s1()))]):
        n = core.fit.thrust.windows
        core.handle(m)
        if core.fit.thrust.windows > n and m.time_usec * 1e-6 > 25.0:
            ratios.append(core.fit.thrust.ratio)
    assert core.fit.mismatch is None and core.model_note is None, core.fit.mismatch
    # the case of issue 31: after the step the ratio lies below the still-air band (0.47-0.54)
    assert min(ratios) < core.fit.thrust.band[0] and max(ratios) < 0.6, ratios
    assert core.fit.judged and core.output() is not None
    assert core.fit.thrust.last_descent_m_s > 2.0
