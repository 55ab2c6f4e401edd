"""The urban likelihood of infotaxis (mission.strategies.ste_urban*, ste_city): backward paths through
the urban diagnostic wind, the open-field limit, and bad input (no model, readings from inside a
building, NaN / negative readings) handled with a message and the open-field plume."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mission.obstacles import Building, Obstacles
from mission.strategies import Observation, WindInfo
from mission.strategies.infotaxis import Infotaxis
from mission.strategies.params import InfotaxisParams
from mission.strategies.ste_city import MISMATCH_READINGS, CitySupport
from mission.strategies.ste_model import accumulate, meander_nodes, model_constants
from mission.strategies.ste_urban import SOLID_LOG_PENALTY, UrbanModel, accumulate_urban, is_solid
from mission.strategies.ste_urban_field import UrbanModelError, build_plane, uniform_plane

P = InfotaxisParams()
MC = model_constants(P.stability, P.source_radius_m, P.intermittency_length_m, P.detection_limit_mg_m3,
                     P.false_alarm, P.upwind_reach_m, P.meander_fraction, math.radians(P.meander_deg))
NODES, LOG_WTS = meander_nodes(7)
#: A wind from the north at the flight altitude (air moving south) [m/s NED].
WIND = np.array([-4.0, 0.0])


def _box(n: float, e: float, size: float, height: float, name: str = "") -> Building:
    h = size / 2.0
    fp = np.array([[n - h, e - h], [n + h, e - h], [n + h, e + h], [n - h, e + h]])
    return Building(fp, height, name)


def _hit_likelihood(model: UrbanModel, rx: float, ry: float, n: np.ndarray, e: np.ndarray) -> np.ndarray:
    """P(hit) of one reading at (rx, ry) for sources at (n, e) (2 m high, 0.04 g/s)."""
    k = len(n)
    acc, alpha = np.zeros((k, len(NODES))), np.full((k, len(NODES)), -1.0)
    paths, lens = model.paths(np.array([rx]), np.array([ry]))
    gp, _, _, solid = model.plane.args()
    accumulate_urban(acc, alpha, n, e, np.full(k, 2.0), np.full(k, 0.04), np.ones(k), np.zeros(k), paths[0],
                     int(lens[0]), 2.0, True, 1.0, 0.5, NODES, MC, gp, solid, model.mix_rate)
    return np.exp(acc + LOG_WTS).sum(axis=1)


def test_open_field_limit_is_the_straight_plume() -> None:
    """Without buildings the backward path is the straight upwind line: the urban likelihood equals
    the open-field plume's (same x, y, wind speed), for sources up- and downwind and to the sides."""
    model = UrbanModel(uniform_plane((-4.0, 0.0), (-50.0, 250.0, -100.0, 100.0)), 3.0, 240.0)
    rng = np.random.default_rng(3)
    k = 200
    n, e = rng.uniform(-5.0, 200.0, k), rng.uniform(-30.0, 30.0, k)
    h, q, cd, sd = rng.uniform(1.0, 3.0, k), 10.0 ** rng.uniform(-2, 1, k), np.ones(k), np.zeros(k)
    acc_u, al_u = np.zeros((k, 7)), np.full((k, 7), -1.0)
    acc_o, al_o = np.zeros((k, 7)), np.full((k, 7), -1.0)
    paths, lens = model.paths(np.array([0.0]), np.array([0.0]))
    gp, _, _, solid = model.plane.args()
    for hit in (True, False, True):
        accumulate_urban(acc_u, al_u, n, e, h, q, cd, sd, paths[0], int(lens[0]), 2.0, hit, 0.8, 0.5, NODES, MC, gp,
                         solid, model.mix_rate)
        accumulate(acc_o, al_o, n, e, h, q, cd, sd, 0.0, 0.0, 2.0, -1.0, 0.0, 4.0, hit, 0.8, 0.5, NODES, MC)
    np.testing.assert_allclose(acc_u, acc_o, rtol=1e-9, atol=1e-9)


def test_backward_path_goes_round_a_building_not_through_it() -> None:
    """A reading straight downwind of a block: its backward path leads upwind around the block, never
    inside it, and a source in the block's lee right behind the reading is less likely than one
    upwind of the block along the deflected flow; the open-field line would run through the block."""
    block = _box(0.0, 0.0, 20.0, 15.0)
    plane = build_plane([block], WIND, 2.0)
    model = UrbanModel(plane)
    paths, lens = model.paths(np.array([-45.0]), np.array([14.0]))
    pts = paths[0, : lens[0], :2]
    gp, _, _, solid = plane.args()
    assert lens[0] > 30
    assert not any(is_solid(gp, solid, float(a), float(b)) for a, b in pts)
    assert pts[:, 0].max() > 20.0  # it got past the block, upwind
    # Sources: in the lee close behind the block's east half, and upwind of the block's east corner.
    lik = _hit_likelihood(model, -45.0, 14.0, np.array([-14.0, 30.0]), np.array([6.0, 14.0]))
    assert lik[1] > lik[0]


def test_source_inside_a_building_is_penalized() -> None:
    """A hypothesis inside a known building loses the fixed factor per reading, hit or miss."""
    plane = build_plane([_box(0.0, 0.0, 20.0, 15.0)], WIND, 2.0)
    lik = _hit_likelihood(UrbanModel(plane), -45.0, 14.0, np.array([0.0]), np.array([0.0]))
    assert lik[0] == pytest.approx(math.exp(SOLID_LOG_PENALTY), rel=1e-12)


def test_no_model_without_buildings_or_usable_wind() -> None:
    with pytest.raises(UrbanModelError, match="no buildings"):
        build_plane([], WIND, 2.0)
    with pytest.raises(UrbanModelError, match="no usable inflow"):
        build_plane([_box(0.0, 0.0, 20.0, 15.0)], np.array([math.nan, 0.0]), 2.0)
    city = CitySupport(Obstacles([_box(0.0, 0.0, 20.0, 15.0)]), 4.0, 3.0, 240.0, 0.15, 0.15)
    assert city.build(np.array([0.0, 0.0]), 2.0) is None
    assert "open-field plume is used" in city.messages[-1]


def _obs(t: float, pos: tuple[float, float], chem: float, wind: WindInfo) -> Observation:
    return Observation(t=t, position_ned=np.array([pos[0], pos[1], -2.0]), velocity_ned=np.zeros(3), chem_mg_m3=chem,
                       detected=chem != 0.0, chem_new=True, wind=wind)


def test_urban_strategy_bad_input_falls_back_and_says_so() -> None:
    """Readings from inside a building (the layout does not match the flight), NaN and negative
    concentrations: nothing crashes, each is said once, the urban model is dropped for the open-field
    plume, and the strategy then declines to declare."""
    s = Infotaxis()
    s.set_obstacles(Obstacles([_box(60.0, 0.0, 20.0, 12.0, "block")]))
    p = InfotaxisParams(plume_model="urban", n_particles=300, plan_particles=30, urban_probe_s=0.5)
    s.reset(np.zeros(3), p, seed=0)
    wind = WindInfo(wind_ned=np.array([-4.0, 0.0, 0.0]), cov_ned=None, upwind_rad=0.0)
    t, states = 0.0, []
    while s.inflow is None and t < 5.0:  # the inflow is measured above the roof first
        obs = Observation(t=t, position_ned=np.array([0.0, 0.0, -s.city.probe_height_m]), velocity_ned=np.zeros(3),
                          chem_mg_m3=0.0, detected=False, chem_new=True, wind=wind)
        states.append(s.update(obs).state)
        t += 0.1
    assert states[0] == "measure-inflow" and s.inflow is not None
    for k in range(10):
        s.update(_obs(t + 0.1 * k, (10.0, 0.0), [math.nan, -1.0][k % 2], wind))
    assert s.post.urban is not None
    for k in range(40):  # inside the block
        s.update(_obs(t + 1.0 + 0.1 * k, (60.0, 0.0), 1.0 if k % 3 == 0 else 0.0, wind))
    lines = s.pop_messages()
    assert any("NaN or negative" in m for m in lines)
    assert any("urban plume model: wind field" in m for m in lines)
    assert any("dropped" in m for m in lines)
    assert s.post.urban is None and s.post.n_fallback >= MISMATCH_READINGS
    assert s.model_unusable and not s._sure(t + 10.0, s._center)


def test_urban_strategy_waits_for_wind_over_the_roofs_not_at_the_search_height() -> None:
    """On the climb to the probe height the estimated wind can fall below what gives a direction (a start in a
    building's lee, paper-s4 seed 1001 through the MAVSDK runner): the strategy waits for it where it is going,
    over the roofs, instead of sending the search height between two probe setpoints (the flip-flop braked the
    climb and tripped the live estimator's innovation check)."""
    s = Infotaxis()
    s.set_obstacles(Obstacles([_box(60.0, 0.0, 20.0, 12.0, "block")]))
    p = InfotaxisParams(plume_model="urban", n_particles=300, plan_particles=30, urban_probe_s=0.5)
    s.reset(np.zeros(3), p, seed=0)
    assert s.city is not None
    calm = WindInfo(wind_ned=np.array([-0.2, 0.0, 0.0]), cov_ned=None, upwind_rad=0.0)  # below min_wind_m_s
    wind = WindInfo(wind_ned=np.array([-4.0, 0.0, 0.0]), cov_ned=None, upwind_rad=0.0)
    heights = []
    for k, w in enumerate([wind, calm, wind, calm, calm, wind]):  # mid-climb, at 8 m
        sp = s.update(Observation(t=0.1 * k, position_ned=np.array([0.0, 0.0, -8.0]), velocity_ned=np.zeros(3),
                                  chem_mg_m3=0.0, detected=False, chem_new=True, wind=w))
        heights.append((sp.state, -float(sp.position_ned[2])))
    assert {st for st, _ in heights} == {"measure-inflow", "wait-wind"}
    assert all(h > 8.0 for _, h in heights), heights  # always on the way up, never back to 2 m
