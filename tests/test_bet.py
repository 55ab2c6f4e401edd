"""The blade-element rotor (vehicle/bet.py) against what it must agree with: numerical quadrature of the
same blade-element loads, a time-marched flap equation, momentum theory in hover, climb and forward
flight, the gyroscope a stiff rotor becomes, and the mirror image a clockwise rotor is."""

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from vehicle.bet import (
    B_A,
    B_CD,
    B_CHORD,
    B_IB,
    B_KB,
    B_NB,
    B_R,
    B_TH0,
    B_TTW,
    N_BLADE,
    _flapping,
    _inplane,
    _thrust,
    rotor_loads,
)

TH0, TTW, CDA = math.radians(28.0), math.radians(-19.0), 0.025 / 5.5
RHO = 1.225


def _blade(kb: float = 9.0, ib: float = 1.26e-4) -> np.ndarray:
    bp = np.zeros(N_BLADE)
    bp[B_NB], bp[B_CHORD], bp[B_A], bp[B_TH0], bp[B_TTW] = 2, 0.028, 5.5, TH0, TTW
    bp[B_CD], bp[B_IB], bp[B_KB], bp[B_R] = 0.025, ib, kb, 0.1778
    return bp


def _element_loads(mu, lam, pb, qb, b0, b1c, b1s, n_r=48, n_psi=96):
    """Per-blade loads over rho a c (Omega R)^2 R (torque: ... R^2) by quadrature of the element loads
    (paper Eqs. 13-24) with the exact geometry of a flapped blade (no small-angle series)."""
    r, wr = np.polynomial.legendre.leggauss(n_r)
    r, wr = 0.5 * (r + 1.0), 0.5 * wr
    psi = np.linspace(0.0, 2 * math.pi, n_psi, endpoint=False)
    R_, P_ = np.meshgrid(r, psi, indexing="ij")
    beta = b0 + b1c * np.cos(P_) + b1s * np.sin(P_)
    dbeta = -b1c * np.sin(P_) + b1s * np.cos(P_)
    e_r = np.stack([-np.cos(P_), -np.sin(P_), np.zeros_like(P_)])
    z = np.array([0.0, 0.0, 1.0])[:, None, None]
    e_t = np.stack([np.sin(P_), -np.cos(P_), np.zeros_like(P_)])
    n = -np.sin(beta) * e_r + np.cos(beta) * z
    s = R_ * (np.cos(beta) * e_r + np.sin(beta) * z)
    w = np.array([pb, qb, 1.0])[:, None, None]
    v_el = np.array([mu, 0.0, 0.0])[:, None, None] + np.cross(w, s, axis=0) + R_ * dbeta * n
    uT = (v_el * e_t).sum(0)
    uP = (v_el * n).sum(0) + lam
    theta = TH0 + TTW * R_
    fz = 0.5 * (uT**2 * theta - uP * uT)
    fx = 0.5 * (uP * uT * theta - uP**2) + 0.5 * CDA * uT**2
    F = fz * n - fx * e_t
    avg = lambda a: float((a.mean(axis=1) * wr).sum())  # noqa: E731
    return avg(F[0]), avg(F[1]), avg(F[2]), avg(R_ * fx)


@pytest.mark.parametrize("mu, lam, pb, qb", [(0.0, 0.08, 0.0, 0.0), (0.06, 0.05, 0.0, 0.0), (0.15, 0.03, 0.0, 0.0),
                                            (0.1, 0.06, 0.002, -0.003), (0.3, -0.01, -0.002, 0.001)])  # fmt: skip
def test_closed_form_loads_equal_quadrature_of_the_element_loads(mu, lam, pb, qb):
    b0, b1c, b1s = 0.03, -0.02, 0.015  # flap angles of the size the rotor shows
    fx, fy, tq = _inplane(mu, lam, pb, qb, TH0, TTW, CDA, b0, b1c, b1s)
    fz = _thrust(mu, lam, pb, qb, TH0, TTW, b0, b1c, b1s)
    qx, qy, qz, qq = _element_loads(mu, lam, pb, qb, b0, b1c, b1s)
    # The closed form keeps every term to second order in the flap angles and rates: the rest is
    # third order, ~1e-5 of loads ~1e-2.
    assert fz == pytest.approx(qz, abs=2e-5)
    assert fx == pytest.approx(qx, abs=2e-5)
    assert fy == pytest.approx(qy, abs=2e-5)
    assert tq == pytest.approx(qq, abs=2e-5)
    assert abs(qz) > 0.015  # not a trivially small thrust


def test_flapping_is_the_periodic_solution_of_the_flap_equation():
    """The harmonic balance against the flap equation marched in time to its periodic state, with the
    aerodynamic moment integrated numerically over the blade at every instant."""
    mu, lam, pb, qb, gam, lb2 = 0.12, 0.05, 0.003, -0.002, 2.5, 1.4
    r, wr = np.polynomial.legendre.leggauss(24)
    r, wr = 0.5 * (r + 1.0), 0.5 * wr

    def rhs(psi, y):
        beta, dbeta = y
        uT = r + mu * math.sin(psi)
        uP = lam + r * dbeta + mu * beta * math.cos(psi) - r * pb * math.sin(psi) + r * qb * math.cos(psi)
        m_aero = gam * float((r * 0.5 * (uT**2 * (TH0 + TTW * r) - uP * uT) * wr).sum())
        return [dbeta, m_aero - lb2 * beta + 2 * pb * math.cos(psi) + 2 * qb * math.sin(psi)]

    sol = solve_ivp(rhs, (0, 60 * math.pi), [0.0, 0.0], max_step=0.05, rtol=1e-9, atol=1e-12, dense_output=True)
    psi = np.linspace(58 * math.pi, 60 * math.pi, 400, endpoint=False)
    beta = sol.sol(psi)[0]
    got = (beta.mean(), 2 * (beta * np.cos(psi)).mean(), 2 * (beta * np.sin(psi)).mean())
    b0, b1c, b1s = _flapping(mu, lam, pb, qb, TH0, TTW, gam, lb2)
    # The element model's u_T here drops the second-order terms: agreement to a few 1e-4 rad.
    assert got == pytest.approx((b0, b1c, b1s), abs=4e-4)
    assert abs(b1c) > 5e-3 and abs(b1s) > 5e-3


def _settle(v_hub, rates, omega, spin, bp, vi0=5.0):
    out = np.zeros(6)
    vi = vi0
    for _ in range(4000):
        vi += 5e-4 * rotor_loads(np.asarray(v_hub, float), np.asarray(rates, float), omega, spin, vi, RHO, bp, out)
    return out.copy(), vi


def test_hover_is_momentum_theory_and_the_bemt_closed_form():
    bp = _blade()
    omega = 393.0
    f, vi = _settle([0, 0, 0], [0, 0, 0], omega, 1.0, bp)
    R = bp[B_R]
    area = math.pi * R**2
    thrust = -f[2]
    assert thrust == pytest.approx(2 * RHO * area * vi**2, rel=1e-6)  # momentum theory
    sigma_a = bp[B_NB] * bp[B_CHORD] * bp[B_A] / (math.pi * R)
    th75 = TH0 + 0.75 * TTW
    lam = sigma_a / 16 * (math.sqrt(1 + 64 * th75 / (3 * sigma_a)) - 1)  # uniform-inflow BEMT, linear twist
    assert vi / (omega * R) == pytest.approx(lam, rel=5e-4)  # the BEMT formula leaves out coning (cos beta)
    assert f[0] == pytest.approx(0.0, abs=1e-9) and f[1] == pytest.approx(0.0, abs=1e-9)
    assert f[5] > 0.0  # a CCW rotor yaws the body clockwise from above = +z (down)


@pytest.mark.parametrize("v_hub", [[0, 0, -2.0], [0, 0, 1.0], [5.0, 0, 0], [8.0, 3.0, -1.0]])
def test_inflow_settles_on_glauerts_momentum_value(v_hub):
    """Climb (-z), mild descent (+z) and forward flight: 2 rho A v_i sqrt(V_ip^2 + (v_i - V_z)^2) = T."""
    bp = _blade()
    f, vi = _settle(v_hub, [0, 0, 0], 393.0, 1.0, bp)
    area = math.pi * bp[B_R] ** 2
    vip = math.hypot(v_hub[0], v_hub[1])
    assert 2 * RHO * area * vi * math.hypot(vip, vi - v_hub[2]) == pytest.approx(-f[2], rel=1e-5)


def test_thrust_grows_with_forward_speed_and_falls_in_climb():
    bp = _blade()
    hover = -_settle([0, 0, 0], [0, 0, 0], 393.0, 1.0, bp)[0][2]
    assert -_settle([6.0, 0, 0], [0, 0, 0], 393.0, 1.0, bp)[0][2] > 1.05 * hover  # translational lift
    assert -_settle([0, 0, -2.0], [0, 0, 0], 393.0, 1.0, bp)[0][2] < 0.95 * hover  # climbing: less thrust


def test_drag_and_blowback_in_edgewise_flight():
    bp = _blade()
    f, _ = _settle([4.0, 0, 0], [0, 0, 0], 393.0, 1.0, bp)
    assert f[0] < -0.05  # H-force and the tilted thrust oppose the motion
    assert f[4] > 0.0  # the disc flaps back: nose-up hub moment (FRD +M)
    f2, _ = _settle([0, -4.0, 0], [0, 0, 0], 393.0, 1.0, bp)  # moving left
    assert f2[1] > 0.05 and f2[3] > 0.0  # drag to the right, the disc flaps right: +L


def test_a_clockwise_rotor_is_the_mirror_image():
    bp = _blade()
    v, w = [3.0, 2.0, -0.5], [0.3, -0.2, 0.1]
    ccw, vi1 = _settle(v, w, 400.0, 1.0, bp)
    cw, vi2 = _settle([v[0], -v[1], v[2]], [-w[0], w[1], -w[2]], 400.0, -1.0, bp)
    assert vi1 == pytest.approx(vi2, rel=1e-12)
    # Forces mirror like vectors (y flips), moments like pseudo-vectors (x and z flip).
    assert np.allclose(cw, ccw * np.array([1, -1, 1, -1, 1, -1]), atol=1e-12)


def test_a_stiff_rotor_is_a_gyroscope():
    """Very stiff hinge: the hub moment from flapping becomes the blades' gyroscopic moment
    n_b I_b Omega (z_up x omega); in FRD for a CCW rotor that is n_b I_b Omega [q, -p, 0]."""
    ib, omega, rates = 1.26e-4, 400.0, np.array([0.4, -0.3, 0.0])
    bp = _blade(kb=1e6, ib=ib)
    bp[B_A] = 1e-9  # no aerodynamics: the inertia alone
    out = np.zeros(6)
    rotor_loads(np.zeros(3), rates, omega, 1.0, 0.0, RHO, bp, out)
    expected = 2 * ib * omega * np.array([rates[1], -rates[0]])
    assert out[3:5] == pytest.approx(expected, rel=2e-3)


def test_stopped_rotor_makes_no_load_and_its_inflow_decays():
    out = np.ones(6)
    d = rotor_loads(np.array([5.0, 0, 0]), np.zeros(3), 0.0, 1.0, 2.0, RHO, _blade(), out)
    assert np.all(out == 0.0) and d < 0.0


def test_vortex_ring_region_stays_bounded():
    """Descending at the hover induced velocity: momentum theory has no solution; the inflow is bounded."""
    bp = _blade()
    f, vi = _settle([0, 0, 5.3], [0, 0, 0], 393.0, 1.0, bp)
    assert np.all(np.isfinite(f)) and 0.0 < vi < 2.0 * 5.3
    assert 0.0 < -f[2] < 20.0
    assert bp[B_KB] == 9.0 and bp[B_IB] > 0 and bp[B_CD] > 0
