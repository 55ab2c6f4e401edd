"""Eq. 46 in the paper's units against the SI implementation; hover, mass, drag (the paper's Table 5 model,
``nasa_quad_table5.toml``); the identified model of the blade-element truth is tested in test_identify*.py."""

import math

import numpy as np
import pytest

from vehicle.params import FT, FT_LBF, LBF, MIX
from vehicle.rotor_model import hover_rotor_speed, rotor_wrench, wrench
from vehicle.vehicle_file import load_vehicle

# Table 2, paper units (ft, slug, s).
RHO, R, B, V0 = 0.002377, 0.5833, 0.6681, 17.43


@pytest.fixture(scope="module")
def veh():
    return load_vehicle("nasa-quad-table5")


def test_hand_computed_force_and_moment_in_ft_lbf_match_si(veh):
    """Eq. 46a, 46c and 46f evaluated by hand in ft, slug, s, converted to N and N*m."""
    w = np.array([400.0, 380.0, 390.0, 410.0])  # rad/s
    u, v, wz, r = 8.0, -3.0, 1.0, 0.2  # ft/s, ft/s, ft/s, rad/s  (wz inside the identified domain)
    k = RHO * math.pi * R**2
    rt = w.sum()
    dt = (w**2).sum()
    rr = w @ MIX[3]
    dr = (w**2) @ MIX[3]
    ra = w @ MIX[1]
    re = w @ MIX[2]
    vh = math.hypot(u, v)
    x_lbf = k * u * (-1.6667e-02 * R * rt + 4 * (-6.1079e-04 * abs(u) + 7.3582e-02 * wz))
    z_lbf = -k * (
        1.1429e-02 * R**2 * dt + 1.7573e-03 * R * V0 * rt - 1.1186e-03 * R * vh * rt
        + 2.0740e-02 * R * wz * rt - 4 * 4.9559e-02 * vh**2
    )
    # Eq. 46f; C_n_r_dt carries a length (ft) because its regressor is a force.
    n_ftlbf = k * (
        1.3812e-02 * R**3 * dr - 3.3331e-02 * R**2 * V0 * rr
        + B * (-7.2825e-02) * (u * ra + v * re) - 1.1517 * B**2 * r * rt
    )
    si = wrench(veh, np.array([u, v, wz]) * FT, [0.0, 0.0, r], w)
    # The SI model adds the rotor reaction term J * d(rr)/dt (zero here) and nothing else.
    assert si[0] == pytest.approx(x_lbf * LBF, rel=1e-3)
    assert si[2] == pytest.approx(z_lbf * LBF, rel=1e-3)
    assert si[5] == pytest.approx(n_ftlbf * FT_LBF, rel=1e-3)
    assert abs(si[2]) > 20.0  # sanity: about the weight


def test_hover_speed_in_training_domain_and_mass(veh):
    w = hover_rotor_speed(veh)
    assert 318.0 <= w <= 465.0  # Table 3 5th-95th percentile
    f = wrench(veh, [0, 0, 0], [0, 0, 0], [w] * 4)
    assert -f[2] == pytest.approx(veh.mass_kg * veh.gravity_m_s2, rel=1e-9)
    # Eq. 46c at the paper's hover (sum of rotor speeds ~1560 rad/s) implies 2.8 kg within 3 %,
    # and momentum theory on v0 (T = 2 rho A v0^2 per rotor) gives the same mass.
    m46 = -wrench(veh, [0, 0, 0], [0, 0, 0], [390.0] * 4)[2] / veh.gravity_m_s2
    assert m46 == pytest.approx(2.8, rel=0.03)
    a = math.pi * veh.rotor_radius_m**2
    m_mom = 4 * 2 * veh.air_density_kg_m3 * a * veh.hover_induced_velocity_m_s**2 / veh.gravity_m_s2
    assert m_mom == pytest.approx(2.8, rel=0.03)
    assert veh.mass_kg == pytest.approx(2.8, rel=0.03)


@pytest.mark.parametrize("heading_deg", range(0, 360, 45))
def test_drag_opposes_airspeed(veh, heading_deg):
    w = hover_rotor_speed(veh)
    h = math.radians(heading_deg)
    va = np.array([4.0 * math.cos(h), 4.0 * math.sin(h), 0.0])
    f = wrench(veh, va, [0, 0, 0], [w] * 4)
    assert f[0:2] @ va[0:2] < -0.5 * np.linalg.norm(va)  # at least 0.5 N per m/s opposing
    # and it grows with airspeed
    f2 = wrench(veh, 2 * va, [0, 0, 0], [w] * 4)
    assert np.linalg.norm(f2[0:2]) > 1.8 * np.linalg.norm(f[0:2])


def test_mixing_signs(veh):
    """Eq. 42: more thrust on the left rotors rolls right-wing-down (+L); front: nose up (+M);
    rotors 1 and 3 faster: +N (their reaction torque)."""
    w0 = hover_rotor_speed(veh)
    base = np.full(4, w0)
    left = base + np.array([0, 0, 10, 10])
    front = base + np.array([10, 0, 0, 10])
    yaw13 = base + np.array([10, 0, 10, 0])
    assert wrench(veh, [0, 0, 0], [0, 0, 0], left)[3] > 0
    assert wrench(veh, [0, 0, 0], [0, 0, 0], front)[4] > 0
    assert wrench(veh, [0, 0, 0], [0, 0, 0], yaw13)[5] > 0


def test_gyroscopic_term(veh):
    """Spinning rotors 1 and 3 faster while pitching gives a roll moment J*(w1-w2+w3-w4)*q."""
    w = np.array([420.0, 380.0, 420.0, 380.0])
    p = veh.as_array()
    m0 = rotor_wrench(np.zeros(3), np.zeros(3), w, np.zeros(4), p)
    m1 = rotor_wrench(np.zeros(3), np.array([0.0, 0.5, 0.0]), w, np.zeros(4), p)
    assert m1[3] - m0[3] == pytest.approx(veh.rotor_inertia_kg_m2 * 80.0 * 0.5, rel=1e-9)


def test_perturbed_model_stays_inside_confidence_intervals(veh):
    rng = np.random.default_rng(3)
    pv = veh.perturbed(rng)
    for name, val in veh.coefficients.items():
        assert abs(pv.coefficients[name] - val) <= veh.ci95.get(name, 0.0) + 1e-15
    assert pv.mass_kg != veh.mass_kg
    assert abs(pv.mass_kg / veh.mass_kg - 1) <= 0.05
