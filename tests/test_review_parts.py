"""Parts of ``windseek review`` that need no log: IMU decimation, version words, the import boundary."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from review.estimate import decimate_imu
from review.flight import FlightData, Series, state_changes
from review.vehicle_info import mav_type_name, model_caveat, sw_version


def test_decimation_keeps_block_means_and_causal_times() -> None:
    rng = np.random.default_rng(100)
    t = np.cumsum(rng.uniform(0.003, 0.005, 2000))  # ~250 Hz, jittered
    v = np.column_stack([rng.normal(0, 1, (2000, 3)), np.full((2000, 3), np.nan)])
    d = decimate_imu(Series(t, v), 50.0)
    assert 0.9 * 50 * (t[-1] - t[0]) < len(d) < 1.1 * 50 * (t[-1] - t[0]) + 2
    assert np.isin(d.t, t).all() and np.all(np.diff(d.t) > 0)  # each block timed at its last sample
    assert np.isnan(d.v[:, 3:]).all()  # no gyro stays no gyro
    b = np.floor((t - t[0]) * 50.0)
    first = b == 0
    assert d.v[0, :3] == pytest.approx(v[first, :3].mean(axis=0))
    w = np.diff(np.concatenate(([0], np.searchsorted(t, d.t, side="right"))))  # samples per block
    assert (w * d.v[:, 0]).sum() == pytest.approx(v[:, 0].sum())  # block means carry the total


def test_not_airborne_without_landed_or_arming_state() -> None:
    from pathlib import Path

    fd = FlightData(path=Path("x"), kind="ulog")
    fd.imu = Series(np.linspace(0, 10, 11), np.zeros((11, 6)))
    assert fd.airborne_segments() == []
    fd.in_air = state_changes(np.array([0.0, 2.0, 8.0]), np.array([False, True, False]))
    assert fd.airborne_segments() == [(2.0, 8.0)]


def test_versions_and_vehicle_words() -> None:
    assert sw_version(17170432) == "v1.6.0 (dev)"  # 0x01060000, PX4 "17170432" before
    assert sw_version(0x010E03FF) == "v1.14.3"
    assert sw_version(0x010F00C0) == "v1.15.0 (rc)"
    assert sw_version(0x04050080) == "v4.5.0 (beta)"
    assert mav_type_name(2) == "quadrotor" and mav_type_name(1) == "fixed wing"
    assert mav_type_name(22) == "VTOL fixedrotor"
    assert "not a quadrotor" in model_caveat("fixed wing", "nasa-quad")
    assert "not that airframe" in model_caveat("quadrotor", "nasa-quad")


@pytest.mark.parametrize(("mav_type", "says", "not_says"), [
    (12, "vehicle is a submarine, which does not fly, not a quadrotor: the model has none of buoyancy", "wing"),
    (10, "vehicle is a ground rover, which does not fly", "wing"),
    (11, "vehicle is a surface boat, which does not fly", "wing"),
    (4, "vehicle is a helicopter, not a quadrotor: the model has none of one main rotor", "wing"),
    (13, "vehicle is a multirotor (hexarotor), not a quadrotor: the model has none of its rotors beyond", "wing"),
    (14, "vehicle is a multirotor (octorotor)", "wing"),
    (22, "vehicle is a VTOL fixedrotor, not a quadrotor: the model has none of its wing lift and drag in forward",
     "control surfaces"),
    (1, "vehicle is a fixed wing, not a quadrotor: the model has none of its wing lift and drag, control surfaces",
     "does not fly"),
])  # fmt: skip
def test_model_caveat_says_what_the_vehicle_is(mav_type: int, says: str, not_says: str) -> None:
    """The caveat for a vehicle that is not a quadrotor names it from its MAV_TYPE; it used to describe
    a fixed wing's "wing lift and drag, control surfaces and forward motor" for every type."""
    text = model_caveat(mav_type_name(mav_type), "nasa-quad")
    assert says in text and not_says not in text, text


def test_review_does_not_import_the_simulator() -> None:
    code = ("import sys, review, review.tlog, review.ulog, review.dataflash, review.convert; "
            "bad = sorted(m for m in sys.modules if m == 'sitl' or m.startswith(('sitl.', 'mission'))); "
            "print(bad); sys.exit(1 if bad else 0)")  # fmt: skip
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stdout + r.stderr


def test_filter_spans_cut_at_imu_gaps() -> None:
    """A damaged time stamp far ahead must not make the filter bridge it in 20 ms steps: the span ends."""
    from pathlib import Path

    from review.estimate import MAX_IMU_GAP_S, filter_spans

    fd = FlightData(path=Path("x"), kind="tlog")
    t = np.concatenate([np.arange(0.0, 10.0, 0.01), np.arange(20.0, 30.0, 0.01), [5.0e6]])
    fd.imu = Series(t, np.zeros((len(t), 6)))
    fd.in_air = [(0.0, True)]
    spans, cuts = filter_spans(fd, fd.imu)
    assert cuts == 2 and len(spans) == 3 and MAX_IMU_GAP_S < 10.0
    assert spans[0][0] == 0.0 and spans[0][1] == pytest.approx(9.99) and spans[1][0] == pytest.approx(20.0)
    assert spans[2] == (5.0e6, 5.0e6)
