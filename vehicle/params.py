"""Vehicle parameters in SI, and the flat array the numba kernels read.

A vehicle file (``vehicle/vehicles/*.toml``, read by :mod:`vehicle.vehicle_file`) describes one
multirotor twice: as the world flies it (its *truth*: blade-element rotors, :mod:`vehicle.bet`, or PX4
SIH's simple rotors, or the identified model itself) and as the wind estimator models it (the paper's
Eq. 46 with identified coefficients, :mod:`vehicle.rotor_model`). :class:`VehicleParams` holds both;
everything downstream works in SI: m, s, kg, rad, N, N*m. The kernels take the parameters as one flat
``float64`` array indexed by the ``P_*`` constants below (up to :data:`MAX_ROTORS` rotors).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from vehicle.bet import B_A, B_CD, B_CHORD, B_IB, B_JHUB, B_KB, B_NB, B_R, B_TH0, B_TTW, N_BLADE

FT = 0.3048  # m per ft
SLUG = 14.593903  # kg per slug
LBF = 4.4482216  # N per lbf
FT_LBF = FT * LBF  # N*m per ft*lbf

#: Most rotors a vehicle may have (the kernels' arrays are this long; unused slots are zero).
MAX_ROTORS = 8

# Eq. 42 mixing of the paper's quad X: rotor 1 front-right, 2 rear-right, 3 rear-left, 4 front-left;
# rows are delta_t, delta_a (roll), delta_e (pitch), delta_r (yaw). Rotors 1 and 3 turn
# counter-clockwise seen from above, 2 and 4 clockwise. Other layouts: :func:`mixing_matrix`.
MIX = np.array(
    [
        [1.0, 1.0, 1.0, 1.0],
        [-1.0, -1.0, 1.0, 1.0],
        [1.0, -1.0, -1.0, 1.0],
        [1.0, -1.0, 1.0, -1.0],
    ]
)

#: Eq. 46 coefficient names in the order of the flat parameter array; absent ones are zero. The
#: first 42 are the paper's candidate terms (Table 5 holds the ones step-wise regression kept); then
#: the terms Assumption 1 adds (a pitch/roll rate term on X/Y) and the fuselage's parasitic drag on
#: X, Y, Z ("could also be included in a model used for wind estimation", the paper's Collected Rotor
#: Forces section), and two thrust terms with the induced velocity of edgewise flight by momentum
#: theory (Eq. 12) where Eq. 46c approximates it as linear in airspeed (Eq. 37). No bias terms: the
#: paper's regression found them small, and a constant offset in a flight's data is that flight's
#: sensor bias, not the vehicle's.
COEFFICIENT_NAMES: tuple[str, ...] = (
    "C_X_Hmu", "C_X_Hmu2", "C_X_Hmuz", "C_X_Hmuv",
    "C_Y_Hmu", "C_Y_Hmu2", "C_Y_Hmuz", "C_Y_Hmuv",
    "C_Z_T0", "C_Z_Tv", "C_Z_Tmu", "C_Z_Tz", "C_Z_Tmu2",
    "C_l_T0", "C_l_Tv", "C_l_Tmu", "C_l_Tz", "C_l_Rmu",
    "C_l_Hmu", "C_l_Hmu2", "C_l_Hmuz", "C_l_Hmuv", "C_l_p_dt", "C_l_p",
    "C_m_T0", "C_m_Tv", "C_m_Tmu", "C_m_Tz", "C_m_Rmu",
    "C_m_Hmu", "C_m_Hmu2", "C_m_Hmuz", "C_m_Hmuv", "C_m_q_dt", "C_m_q",
    "C_n_Q0", "C_n_Qv", "C_n_Qmu", "C_n_Qz", "C_n_Hmu", "C_n_r_dt", "C_n_r",
    "C_X_q_dt", "C_Y_p_dt", "C_X_D", "C_Y_D", "C_Z_D", "C_Z_Ti", "C_Z_Tiz",
)  # fmt: skip

#: Moment coefficients whose regressor has units of force (rho*pi*R^2 * b^2 * rate * Omega,
#: rho*pi*R^2 * b * u * Omega): they carry a length, ft in the paper. Converted to m at load.
LENGTH_COEFFICIENTS = frozenset({"C_l_p_dt", "C_m_q_dt", "C_n_r_dt", "C_n_Hmu"})
#: Coefficients whose regressor (b/v0 * V^2 * rate) has units of force*time: they carry a
#: length too. Absent from Table 5 (zero) but converted the same way if a user sets them.
LENGTH_COEFFICIENTS_2 = frozenset({"C_l_p", "C_m_q", "C_n_r"})

#: The world's force model: the identified Eq. 46 itself, blade-element rotors, or PX4 SIH's rotors.
TRUTH_MODEL, TRUTH_BET, TRUTH_SIH = 0, 1, 2
TRUTHS = {"model": TRUTH_MODEL, "bet": TRUTH_BET, "sih": TRUTH_SIH}

# Indices into the flat parameter array used by the numba kernels.
P_RHO, P_R, P_B, P_H, P_V0, P_NROT, P_J, P_MASS, P_G = range(9)
P_IXX, P_IYY, P_IZZ, P_TAU, P_WMIN, P_WMAX, P_VH_MAX, P_VZ_MAX = range(9, 17)
P_TRUTH, P_CDA_X, P_CDA_Y, P_CDA_Z, P_JHUB = range(17, 22)
P_SIH_TMAX, P_SIH_QMAX, P_SIH_KDV, P_SIH_KDW = range(22, 26)
# Derived at load from the truth (vehicle.truth): what the built-in autopilot knows of its vehicle.
# Thrust of one rotor at zero airspeed T = KT2 w^2 + KT1 w (N), torque / thrust KM (m), rate damping
# of the whole vehicle at hover (N*m per rad/s, <= 0), the hover rotor speed (rad/s).
P_KT2, P_KT1, P_KM, P_DAMP_P, P_DAMP_Q, P_DAMP_R, P_WHOVER = range(26, 33)
P_BLADE0 = 40  # one rotor's blade parameters (vehicle.bet B_* offsets); all rotors are alike
P_ROT0 = P_BLADE0 + N_BLADE  # per rotor i: x, y, z (FRD, m, hub centre from the CG), spin (+1 CCW)
P_MIX0 = P_ROT0 + 4 * MAX_ROTORS  # Eq. 41 M_ix, row k at P_MIX0 + k * MAX_ROTORS
# Control allocation (the built-in autopilot): per-rotor thrust = A @ [T, L, M, N], A (N, 4) the
# pseudo-inverse of the thrust and moment effectiveness of the rotors' thrusts; rotor i's row at
# P_ALLOC0 + 4 * i.
P_ALLOC0 = P_MIX0 + 4 * MAX_ROTORS
P_COEF0 = 160
N_PARAMS = P_COEF0 + len(COEFFICIENT_NAMES)
assert P_ALLOC0 + 4 * MAX_ROTORS <= P_COEF0


def coef_index(name: str) -> int:
    """Index of an Eq. 46 coefficient in the flat parameter array."""
    return P_COEF0 + COEFFICIENT_NAMES.index(name)


@dataclass(frozen=True)
class Blade:
    """Blade-element geometry of one rotor (the ``bet`` truth), SI and rad.

    chord_m: mean chord; root_pitch_rad / twist_rad: theta(r) = root + twist * r / R (linear twist);
    lift_slope_per_rad: section lift-curve slope a; profile_drag: section C_d; flap_inertia_kg_m2:
    I_b of one blade about the flap hinge; hinge_stiffness_n_m_rad: K_beta; hub_inertia_kg_m2: the
    non-flapping rotating parts (motor bell, hub) about the shaft, for their gyroscopic moment.
    """

    blades: int
    chord_m: float
    root_pitch_rad: float
    twist_rad: float
    lift_slope_per_rad: float
    profile_drag: float
    flap_inertia_kg_m2: float
    hinge_stiffness_n_m_rad: float
    hub_inertia_kg_m2: float


@dataclass(frozen=True)
class SihRotors:
    """PX4 SIH's rotor model (``src/modules/simulation/simulator_sih``): each rotor's thrust and torque
    are proportional to its command u in [0, 1] (thrust ``t_max_n * u``, torque ``q_max_n_m * u``), with
    a first-order lag; drag is linear in velocity (``kdv``, N per m/s) and in body rate (``kdw``, N*m
    per rad/s). windseek's rotor speed stands for the command: u = (w / w_max)^2."""

    t_max_n: float
    q_max_n_m: float
    kdv_n_s_m: float
    kdw_n_m_s_rad: float


@dataclass(frozen=True)
class VehicleParams:
    """One multirotor, SI (see the module docstring). Built by :func:`vehicle.vehicle_file.load_vehicle`.

    Rotor geometry: ``rotor_positions_m`` (N, 3) hub centres from the CG, FRD; ``rotor_spins`` (N,)
    +1 counter-clockwise seen from above, -1 clockwise; the kernels' rotor order is this order.
    Eq. 46 constants: ``arm_length_m`` (b), ``hub_height_m`` (h, hub above CG), ``rotor_radius_m`` (R),
    ``hover_induced_velocity_m_s`` (v0), ``coefficients`` (SI) and their ``ci95`` half-widths.
    """

    name: str
    mass_kg: float
    inertia_kg_m2: tuple[float, float, float]
    n_rotors: int
    air_density_kg_m3: float
    rotor_radius_m: float
    arm_length_m: float
    hub_height_m: float
    hover_induced_velocity_m_s: float
    gravity_m_s2: float
    rotor_inertia_kg_m2: float
    motor_time_constant_s: float
    rotor_speed_min_rad_s: float
    rotor_speed_max_rad_s: float
    crash_speed_m_s: float
    domain_airspeed_m_s: float
    domain_vertical_airspeed_m_s: float
    battery_cells: int
    battery_capacity_mah: float
    hover_current_a: float
    coefficients: dict[str, float] = field(default_factory=dict)  # SI
    ci95: dict[str, float] = field(default_factory=dict)  # SI half-widths
    truth: str = "model"
    rotor_positions_m: tuple[tuple[float, float, float], ...] = ()
    rotor_spins: tuple[int, ...] = ()
    px4_outputs: tuple[int, ...] = ()  # PX4 actuator output index (0-based) of each rotor
    layout: str = "quad-x"
    blade: Blade | None = None
    sih: SihRotors | None = None
    drag_area_m2: tuple[float, float, float] = (0.0, 0.0, 0.0)
    description: str = ""
    #: Where the Eq. 46 model came from and how well it fits: source, per-axis fit metrics, the
    #: identified domain, the wind assumed (written by ``windseek identify``; free-form tables).
    model_info: dict[str, Any] = field(default_factory=dict)
    #: What the built-in autopilot and PX4's parameters know of the vehicle, derived from the truth at
    #: load (:func:`vehicle.truth.control_figures`): kt2, kt1, km, damping (3,), hover_speed.
    control: dict[str, Any] = field(default_factory=dict)

    @property
    def mixing(self) -> np.ndarray:
        """Eq. 41 M_ix (4, N): delta = M_ix @ w^2 for this layout (:func:`mixing_matrix`)."""
        return mixing_matrix(np.array(self.rotor_positions_m), np.array(self.rotor_spins, dtype=float),
                             self.arm_length_m)  # fmt: skip

    def as_array(self) -> np.ndarray:
        """Flat float64 array for the numba kernels (see the ``P_*`` indices)."""
        p = np.zeros(N_PARAMS)
        p[P_RHO] = self.air_density_kg_m3
        p[P_R] = self.rotor_radius_m
        p[P_B] = self.arm_length_m
        p[P_H] = self.hub_height_m
        p[P_V0] = self.hover_induced_velocity_m_s
        p[P_NROT] = self.n_rotors
        p[P_J] = self.rotor_inertia_kg_m2
        p[P_MASS] = self.mass_kg
        p[P_G] = self.gravity_m_s2
        p[P_IXX], p[P_IYY], p[P_IZZ] = self.inertia_kg_m2
        p[P_TAU] = self.motor_time_constant_s
        p[P_WMIN] = self.rotor_speed_min_rad_s
        p[P_WMAX] = self.rotor_speed_max_rad_s
        p[P_VH_MAX] = self.domain_airspeed_m_s
        p[P_VZ_MAX] = self.domain_vertical_airspeed_m_s
        p[P_TRUTH] = TRUTHS[self.truth]
        p[P_CDA_X], p[P_CDA_Y], p[P_CDA_Z] = self.drag_area_m2
        p[P_JHUB] = self.rotor_inertia_kg_m2
        if self.blade is not None:
            b = self.blade
            blade = p[P_BLADE0:P_BLADE0 + N_BLADE]
            blade[B_NB], blade[B_CHORD], blade[B_A] = b.blades, b.chord_m, b.lift_slope_per_rad
            blade[B_TH0], blade[B_TTW], blade[B_CD] = b.root_pitch_rad, b.twist_rad, b.profile_drag
            blade[B_IB], blade[B_KB] = b.flap_inertia_kg_m2, b.hinge_stiffness_n_m_rad
            blade[B_JHUB] = b.hub_inertia_kg_m2
            blade[B_R] = self.rotor_radius_m
            if self.truth == "bet":
                p[P_JHUB] = b.hub_inertia_kg_m2  # the blades' own gyroscopics act through their flapping
        if self.sih is not None:
            s = self.sih
            p[P_SIH_TMAX], p[P_SIH_QMAX] = s.t_max_n, s.q_max_n_m
            p[P_SIH_KDV], p[P_SIH_KDW] = s.kdv_n_s_m, s.kdw_n_m_s_rad
        for i, (pos, spin) in enumerate(zip(self.rotor_positions_m, self.rotor_spins, strict=True)):
            p[P_ROT0 + 4 * i:P_ROT0 + 4 * i + 3] = pos
            p[P_ROT0 + 4 * i + 3] = spin
        mix = self.mixing
        for k in range(4):
            p[P_MIX0 + k * MAX_ROTORS:P_MIX0 + k * MAX_ROTORS + self.n_rotors] = mix[k]
        c = self.control
        if c:
            p[P_KT2], p[P_KT1], p[P_KM] = c["kt2"], c["kt1"], c["km"]
            p[P_DAMP_P], p[P_DAMP_Q], p[P_DAMP_R] = c["damping"]
            p[P_WHOVER] = c["hover_speed"]
            alloc = allocation_matrix(np.array(self.rotor_positions_m), np.array(self.rotor_spins, dtype=float),
                                      c["km"])  # fmt: skip
            p[P_ALLOC0:P_ALLOC0 + 4 * self.n_rotors] = alloc.ravel()
        for i, name in enumerate(COEFFICIENT_NAMES):
            p[P_COEF0 + i] = self.coefficients.get(name, 0.0)
        return p

    def perturbed(
        self, rng: np.random.Generator, mass_error: float = 0.05, inertia_error: float = 0.10
    ) -> VehicleParams:
        """A copy with every Eq. 46 coefficient drawn uniformly inside its 95 % interval
        and mass and inertia scaled by a uniform relative error (default +-5 %, +-10 %).

        Used to show what model error costs the wind estimator.
        """
        coefs = {
            k: v + rng.uniform(-1.0, 1.0) * self.ci95.get(k, 0.0)
            for k, v in self.coefficients.items()
        }
        mass = self.mass_kg * (1.0 + rng.uniform(-mass_error, mass_error))
        ix, iy, iz = (float(i * (1.0 + rng.uniform(-inertia_error, inertia_error))) for i in self.inertia_kg_m2)
        inertia = (ix, iy, iz)
        return replace(self, coefficients=coefs, mass_kg=mass, inertia_kg_m2=inertia)

    def with_overrides(self, **kwargs: object) -> VehicleParams:
        """A copy with some fields replaced (validated)."""
        out = replace(self, **kwargs)  # type: ignore[arg-type]
        out.validate()
        return out

    @property
    def model_name(self) -> str:
        """The vehicle file the Eq. 46 model comes from (this one unless given another's by :meth:`with_model_of`)."""
        return str(self.model_info.get("vehicle_file", self.name))

    def with_model_of(self, other: VehicleParams) -> VehicleParams:
        """This vehicle (truth, mass, geometry) with the Eq. 46 model of ``other`` (an identified file):
        what the estimator uses when it is given ``--vehicle``."""
        return replace(self, coefficients=dict(other.coefficients), ci95=dict(other.ci95),
                       hover_induced_velocity_m_s=other.hover_induced_velocity_m_s,
                       domain_airspeed_m_s=other.domain_airspeed_m_s,
                       domain_vertical_airspeed_m_s=other.domain_vertical_airspeed_m_s,
                       model_info={**other.model_info, "vehicle_file": other.name})  # fmt: skip

    def validate(self) -> None:
        """Raise ``ValueError`` naming the field and the allowed range."""
        checks: list[tuple[str, float, float, float]] = [
            ("mass_kg", self.mass_kg, 0.01, 100.0),
            ("hub_height_m", self.hub_height_m, -1.0, 1.0),
            ("rotor_radius_m", self.rotor_radius_m, 0.005, 2.0),
            ("arm_length_m", self.arm_length_m, 0.01, 5.0),
            ("air_density_kg_m3", self.air_density_kg_m3, 0.3, 1.5),
            ("gravity_m_s2", self.gravity_m_s2, 9.7, 9.9),
            ("hover_induced_velocity_m_s", self.hover_induced_velocity_m_s, 0.1, 50.0),
            ("rotor_inertia_kg_m2", self.rotor_inertia_kg_m2, 0.0, 0.1),
            ("motor_time_constant_s", self.motor_time_constant_s, 1e-3, 1.0),
            ("rotor_speed_min_rad_s", self.rotor_speed_min_rad_s, 0.0, 10000.0),
            ("rotor_speed_max_rad_s", self.rotor_speed_max_rad_s, 1.0, 10000.0),
            ("crash_speed_m_s", self.crash_speed_m_s, 0.1, 100.0),
            ("domain_airspeed_m_s", self.domain_airspeed_m_s, 0.0, 1e9),
            ("domain_vertical_airspeed_m_s", self.domain_vertical_airspeed_m_s, 0.0, 1e9),
        ]
        checks += [(f"inertia_kg_m2[{i}]", v, 1e-6, 100.0) for i, v in enumerate(self.inertia_kg_m2)]
        checks += [(f"drag_area_m2[{i}]", v, 0.0, 10.0) for i, v in enumerate(self.drag_area_m2)]
        for name, value, lo, hi in checks:
            if not (np.isfinite(value) and lo <= value <= hi):
                raise ValueError(f"vehicle.{name} = {value!r}: allowed range is [{lo}, {hi}]")
        for name, value in self.coefficients.items():
            if not np.isfinite(value):
                raise ValueError(f"vehicle.model.coefficients.{name} = {value!r}: must be finite")
        if self.rotor_speed_min_rad_s >= self.rotor_speed_max_rad_s:
            raise ValueError(
                "vehicle.rotor_speed_min_rad_s must be below rotor_speed_max_rad_s "
                f"({self.rotor_speed_min_rad_s} >= {self.rotor_speed_max_rad_s})"
            )
        if not 3 <= self.n_rotors <= MAX_ROTORS:
            raise ValueError(f"vehicle.n_rotors = {self.n_rotors}: allowed range is [3, {MAX_ROTORS}]")
        if len(self.rotor_positions_m) != self.n_rotors or len(self.rotor_spins) != self.n_rotors:
            raise ValueError(f"vehicle.rotors: {len(self.rotor_positions_m)} positions and {len(self.rotor_spins)} "
                             f"spins for {self.n_rotors} rotors")  # fmt: skip
        if any(s not in (-1, 1) for s in self.rotor_spins):
            raise ValueError(f"vehicle.rotors.spin: each must be 'ccw' or 'cw', got {self.rotor_spins}")
        if self.truth not in TRUTHS:
            raise ValueError(f"vehicle.truth = {self.truth!r}: choose from {', '.join(TRUTHS)}")
        if self.truth == "bet" and self.blade is None:
            raise ValueError("vehicle.truth = 'bet' needs a [blade] table")
        if self.truth == "sih" and self.sih is None:
            raise ValueError("vehicle.truth = 'sih' needs a [sih] table")


def layout_positions(layout: str, arm_m: float, hub_height_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Hub positions (N, 3) FRD m and spins (N,) of a named layout, in windseek's rotor order.

    ``quad-x``: the paper's Eq. 42 order (1 front-right CCW, 2 rear-right CW, 3 rear-left CCW, 4
    front-left CW). ``hexa-x``: PX4's hexarotor X (its motor order: 1 right CW, 2 left CCW, 3 front-left
    CW, 4 rear-right CCW, 5 front-right CCW, 6 rear-left CW; arms at 30 deg from the nose). Hubs are
    ``hub_height_m`` above the CG (z = -h in FRD).
    """
    if layout == "quad-x":
        angles_deg, spins = [45.0, 135.0, 225.0, 315.0], [1, -1, 1, -1]
    elif layout == "hexa-x":
        angles_deg, spins = [90.0, 270.0, 330.0, 150.0, 30.0, 210.0], [-1, 1, -1, 1, 1, -1]
    else:
        raise ValueError(f"vehicle.frame.layout = {layout!r}: choose quad-x, hexa-x, or give [[frame.rotors]]")
    a = np.radians(angles_deg)  # azimuth from the nose towards the right wing
    pos = np.stack([arm_m * np.cos(a), arm_m * np.sin(a), np.full(a.shape, -hub_height_m)], axis=1)
    pos[np.abs(pos) < 1e-12] = 0.0
    return pos, np.array(spins)


def mixing_matrix(positions: np.ndarray, spins: np.ndarray, arm_m: float) -> np.ndarray:
    """Eq. 41 mixing M_ix (4, N) of any layout: thrust 1, roll -sqrt(2) y / b, pitch sqrt(2) x / b, yaw
    the spin (+1 CCW). For the quad X this is exactly Eq. 42; for other layouts the identified
    coefficients absorb the scale (the paper: the model structure does not depend on the rotor count)."""
    n = positions.shape[0]
    mix = np.empty((4, n))
    mix[0] = 1.0
    mix[1] = -np.sqrt(2.0) * positions[:, 1] / arm_m
    mix[2] = np.sqrt(2.0) * positions[:, 0] / arm_m
    mix[3] = spins
    near = np.abs(mix - np.round(mix)) < 1e-9  # the quad X's +-1 exactly, not 0.9999999999999998
    mix[near] = np.round(mix[near])
    return mix


def allocation_matrix(positions: np.ndarray, spins: np.ndarray, km: float) -> np.ndarray:
    """Per-rotor thrusts (N, 4) from [collective thrust (N), roll, pitch, yaw moment (N*m)]: the
    pseudo-inverse of the effectiveness of rotor thrusts t (thrust along -z at the hub, FRD):
    T = sum t, L = -sum y t, M = sum x t, N = sum spin km t (a counter-clockwise rotor's torque yaws
    the body +z; km = torque / thrust, m)."""
    eff = np.stack([np.ones(positions.shape[0]), -positions[:, 1], positions[:, 0], spins * km])
    return np.linalg.pinv(eff)


__all__ = ["COEFFICIENT_NAMES", "FT", "FT_LBF", "LBF", "MAX_ROTORS", "MIX", "SLUG", "Blade", "SihRotors",
           "VehicleParams", "allocation_matrix", "coef_index", "layout_positions", "mixing_matrix"]  # fmt: skip
