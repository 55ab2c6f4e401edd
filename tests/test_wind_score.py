"""The simulator's scoring of wind estimates by source: the estimator's WIND_COV, the autopilot's own (PX4 EKF2's
WIND_COV from component 1, ArduPilot EKF3's WIND), RMSE of 1-s means and the stated-uncertainty coverage.
Messages are real MAVLink frames, packed and parsed by pymavlink."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sitl.hil.summary import TruthScore
from wire.dialect import mavlink as M  # noqa: N812


def _frame(msg: object, comp: int) -> object:
    mav = M.MAVLink(None, 1, comp)
    return M.MAVLink(None, 0, 0).parse_char(msg.pack(mav))  # type: ignore[attr-defined]


def _wind_cov(t: float, w: tuple[float, float, float], var_h: float, comp: int) -> object:
    return _frame(M.MAVLink_wind_cov_message(int(t * 1e6), *w, var_h, 0.1, 10.0, 1.0, 1.0), comp)


def _flight(score: TruthScore, t_end: float = 30.0) -> None:
    """Truth at 50 Hz: airborne from t = 0 at 5 m, wind (5, 0, 0) m/s with a 1 Hz wiggle of 1 m/s on E."""
    for k in range(int(t_end * 50) + 1):
        t = k / 50
        score.add(t, np.array([0.0, 0.0, -5.0]), np.array([5.0, math.sin(2 * math.pi * t), 0.0]))


def test_estimates_are_scored_by_source_and_never_mixed() -> None:
    s = TruthScore()
    _flight(s)
    for k in range(20, 200):  # 10 Hz for 18 s from t = 2
        t = k / 10
        s.on_message(_wind_cov(t, (5.3, 0.0, 0.0), 0.5, comp=191))  # windseek's estimator: 0.3 N off
        s.on_message(_wind_cov(t, (3.0, 0.0, 0.0), 0.02, comp=1))  # PX4 EKF2: 2 m/s off, claims 0.1 m/s
    d = s.to_dict([])
    assert d["wind_estimates_received"] == 180 and d["wind_estimates_scored"] == 180
    assert d["wind_rmse_ned_m_s"][0] == pytest.approx(0.3, abs=1e-6)
    # 1-s means take out the 1 Hz wiggle on E the estimate does not follow; per estimate it stays.
    assert d["wind_rmse_1s_ned_m_s"][1] < 0.05 < d["wind_rmse_ned_m_s"][1]
    assert d["wind_coverage_95_horizontal"] > 0.9  # 0.3-0.9 m/s of error inside a 1.2 m/s circle
    a = d["autopilot_wind"]
    assert a["scored"] == 180 and a["rmse_ned_m_s"][0] == pytest.approx(2.0, abs=1e-6)
    assert a["coverage_95_horizontal"] == 0.0  # overconfident: the error never inside its 0.35 m/s circle
    assert a["rmse_ned_after_settle_m_s"][0] == pytest.approx(2.0, abs=1e-6) and a["scored_after_settle"] == 100


def test_ardupilots_wind_message_is_the_autopilots_estimate_at_the_newest_truth() -> None:
    s = TruthScore()
    _flight(s, 5.0)
    # EKF3: from 10 deg at 5 m/s, 0.2 m/s down: the air moves towards 190 deg.
    s.on_message(_frame(M.MAVLink_wind_message(10.0, 5.0, 0.2), comp=1))
    a = s.to_dict([])["autopilot_wind"]
    assert a["scored"] == 1 and a["coverage_95_horizontal"] is None
    assert a["last_estimate_ned_m_s"] == pytest.approx([-5 * math.cos(math.radians(10)),
                                                        -5 * math.sin(math.radians(10)), 0.2], abs=1e-3)
    assert s.to_dict([])["wind_estimates_scored"] == 0  # nothing from the estimator
