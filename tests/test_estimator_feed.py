"""The in-process estimator feed's kernels (``mission.wind_source``, ``estimator.models``) against plain per-sample
code, the allocation-free force model against the allocating one, and the per-process control figures."""

import math
from dataclasses import replace

import numpy as np

from estimator.model_kernels import ForceScratch, specific_force, specific_force_into
from estimator.models import AhrsErrorModel, ahrs_attitudes
from mission.wind_source import group_means
from vehicle.frames import quat_mul
from vehicle.rotor_model import N_COEF, rotor_wrench, rotor_wrench_into
from vehicle.truth import with_control_figures
from vehicle.vehicle_file import load_vehicle


def test_ahrs_attitudes_are_the_per_sample_gauss_markov_model() -> None:
    """Batch by batch (the error carried between calls) as the former per-sample loop: e <- a e + c n, then the
    truth times the normalized small-angle quaternion [1, e / 2], normalized."""
    m = AhrsErrorModel()
    a, c = m.coefficients(1.0 / 250.0)
    assert a == math.exp(-1.0 / 250.0 / m.tau_s) and c == math.sqrt(1.0 - a * a) * math.radians(m.sigma_deg)
    rng = np.random.default_rng(4)
    q_true = rng.normal(size=(300, 4))
    q_true /= np.linalg.norm(q_true, axis=1)[:, None]
    normals = rng.normal(size=(300, 3))
    e_ref = e = rng.normal(0.0, 0.01, 3)
    ref = np.empty((300, 4))
    for k in range(300):
        e_ref = a * e_ref + c * normals[k]
        dq = np.array([1.0, 0.5 * e_ref[0], 0.5 * e_ref[1], 0.5 * e_ref[2]])
        q = quat_mul(q_true[k], dq / np.linalg.norm(dq))
        ref[k] = q / np.linalg.norm(q)
    out = np.empty((300, 4))
    e = e.copy()
    for s in range(0, 300, 25):
        ahrs_attitudes(q_true[s : s + 25], e, normals[s : s + 25], a, c, out[s : s + 25])
    np.testing.assert_allclose(out, ref, rtol=0.0, atol=1e-15)  # bit for bit where numpy's norm uses FMA (x86-64)
    np.testing.assert_allclose(e, e_ref, rtol=0.0, atol=1e-18)
    np.testing.assert_allclose(np.linalg.norm(out, axis=1), 1.0, atol=1e-15)


def test_group_means_carry_across_calls() -> None:
    """Means of every d consecutive samples, the partial sum carried into the next call: the same steps, bit for
    bit, however the samples are split into calls."""
    rng = np.random.default_rng(5)
    acc, gyr = rng.normal(size=(23, 3)), rng.normal(size=(23, 3))
    for d in (1, 2, 3):
        whole_idx, whole = np.empty(23, dtype=np.int64), np.empty((23, 2, 3))
        m, left = group_means(acc, gyr, np.zeros((2, 3)), 0, d, whole_idx, whole)
        assert m == 23 // d and left == 23 % d
        assert list(whole_idx[:m]) == list(range(d - 1, 23, d))
        first = np.zeros(3)
        for row in acc[:d]:
            first = first + row
        np.testing.assert_array_equal(whole[0, 0], first / d)
        sums, n, got = np.zeros((2, 3)), 0, []
        for lo, hi in ((0, 4), (4, 5), (5, 17), (17, 23)):
            idx, means = np.empty(hi - lo, dtype=np.int64), np.empty((hi - lo, 2, 3))
            k, n = group_means(acc[lo:hi], gyr[lo:hi], sums, n, d, idx, means)
            got.extend(means[:k])
        np.testing.assert_array_equal(np.array(got), whole[:m])


def test_force_model_into_scratch_is_the_allocating_one() -> None:
    v = load_vehicle()
    p = v.as_array()
    rng = np.random.default_rng(6)
    scratch, out, reg, wrench = ForceScratch(), np.empty(3), np.empty(N_COEF), np.empty(6)
    for _ in range(20):
        x = np.concatenate([rng.normal(0, 3, 6), [1.0 + rng.normal(0, 0.05)]])
        R = np.linalg.qr(rng.normal(size=(3, 3)))[0]
        rates, w_rot = rng.normal(0, 0.3, 3), np.concatenate([rng.uniform(300, 700, 4), np.zeros(4)])
        for i_scale in (-1, 6):
            specific_force_into(x, R, rates, w_rot, p, i_scale, -9.7, scratch, out)
            np.testing.assert_array_equal(out, specific_force(x, R, rates, w_rot, p, i_scale, -9.7))
        rotor_wrench_into(x[:3], rates, w_rot, np.zeros(8), p, reg, wrench)
        np.testing.assert_array_equal(wrench, rotor_wrench(x[:3], rates, w_rot, np.zeros(8), p))


def test_control_figures_reused_per_vehicle_and_not_shared() -> None:
    a, b = load_vehicle(), load_vehicle()
    assert a.control == b.control and a.control is not b.control
    heavier = with_control_figures(replace(a, mass_kg=a.mass_kg * 1.1))
    assert heavier.control["hover_speed"] > a.control["hover_speed"]
