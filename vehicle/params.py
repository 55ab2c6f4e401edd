"""Vehicle parameters: load the one vehicle file, convert the paper's units to SI once.

The file (``vehicle/vehicles/nasa_quad.toml`` by default) holds Table 2 in the paper's English
units, Table 5 as printed, and the values the paper does not give (marked as assumptions).
Everything downstream works in SI: m, s, kg, rad, N, N*m. The numba kernels take the
parameters as one flat ``float64`` array indexed by the ``P_*`` constants below.
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass, field, replace
from importlib import resources
from pathlib import Path

import numpy as np

FT = 0.3048  # m per ft
SLUG = 14.593903  # kg per slug
LBF = 4.4482216  # N per lbf
FT_LBF = FT * LBF  # N*m per ft*lbf

# Eq. 42 mixing (X configuration): rotor 1 front-right, 2 rear-right, 3 rear-left,
# 4 front-left; rows are delta_t, delta_a (roll), delta_e (pitch), delta_r (yaw).
# Rotors 1 and 3 turn counter-clockwise seen from above, 2 and 4 clockwise.
MIX = np.array(
    [
        [1.0, 1.0, 1.0, 1.0],
        [-1.0, -1.0, 1.0, 1.0],
        [1.0, -1.0, -1.0, 1.0],
        [1.0, -1.0, 1.0, -1.0],
    ]
)

#: Table 5 names in the order of the flat parameter array; absent ones are zero.
COEFFICIENT_NAMES: tuple[str, ...] = (
    "C_X_Hmu", "C_X_Hmu2", "C_X_Hmuz", "C_X_Hmuv",
    "C_Y_Hmu", "C_Y_Hmu2", "C_Y_Hmuz", "C_Y_Hmuv",
    "C_Z_T0", "C_Z_Tv", "C_Z_Tmu", "C_Z_Tz", "C_Z_Tmu2",
    "C_l_T0", "C_l_Tv", "C_l_Tmu", "C_l_Tz", "C_l_Rmu",
    "C_l_Hmu", "C_l_Hmu2", "C_l_Hmuz", "C_l_Hmuv", "C_l_p_dt", "C_l_p",
    "C_m_T0", "C_m_Tv", "C_m_Tmu", "C_m_Tz", "C_m_Rmu",
    "C_m_Hmu", "C_m_Hmu2", "C_m_Hmuz", "C_m_Hmuv", "C_m_q_dt", "C_m_q",
    "C_n_Q0", "C_n_Qv", "C_n_Qmu", "C_n_Qz", "C_n_Hmu", "C_n_r_dt", "C_n_r",
)  # fmt: skip

#: Moment coefficients whose regressor has units of force (rho*pi*R^2 * b^2 * rate * Omega,
#: rho*pi*R^2 * b * u * Omega): they carry a length, ft in the paper. Converted to m at load.
LENGTH_COEFFICIENTS = frozenset({"C_l_p_dt", "C_m_q_dt", "C_n_r_dt", "C_n_Hmu"})
#: Coefficients whose regressor (b/v0 * V^2 * rate) has units of force*time: they carry a
#: length too. Absent from Table 5 (zero) but converted the same way if a user sets them.
LENGTH_COEFFICIENTS_2 = frozenset({"C_l_p", "C_m_q", "C_n_r"})

# Indices into the flat parameter array used by the numba kernels.
P_RHO, P_R, P_B, P_H, P_V0, P_NROT, P_J, P_MASS, P_G = range(9)
P_IXX, P_IYY, P_IZZ, P_TAU, P_WMIN, P_WMAX, P_VH_MAX, P_VZ_MAX = range(9, 17)
P_COEF0 = 20  # room for new scalar parameters without renumbering the coefficients
N_PARAMS = P_COEF0 + len(COEFFICIENT_NAMES)


def coef_index(name: str) -> int:
    """Index of a Table 5 coefficient in the flat parameter array."""
    return P_COEF0 + COEFFICIENT_NAMES.index(name)


@dataclass(frozen=True)
class VehicleParams:
    """Quadrotor parameters in SI. Built from the vehicle file by :func:`load_vehicle`."""

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
        for i, name in enumerate(COEFFICIENT_NAMES):
            p[P_COEF0 + i] = self.coefficients.get(name, 0.0)
        return p

    def perturbed(
        self, rng: np.random.Generator, mass_error: float = 0.05, inertia_error: float = 0.10
    ) -> VehicleParams:
        """A copy with every Table 5 coefficient drawn uniformly inside its 95 % interval
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

    def validate(self) -> None:
        """Raise ``ValueError`` naming the field and the allowed range."""
        checks: list[tuple[str, float, float, float]] = [
            ("mass_kg", self.mass_kg, 0.05, 100.0),
            ("hub_height_m", self.hub_height_m, -1.0, 1.0),
            ("rotor_inertia_kg_m2", self.rotor_inertia_kg_m2, 0.0, 0.1),
            ("motor_time_constant_s", self.motor_time_constant_s, 1e-3, 1.0),
            ("rotor_speed_min_rad_s", self.rotor_speed_min_rad_s, 0.0, 5000.0),
            ("rotor_speed_max_rad_s", self.rotor_speed_max_rad_s, 1.0, 5000.0),
            ("crash_speed_m_s", self.crash_speed_m_s, 0.1, 100.0),
            ("domain_airspeed_m_s", self.domain_airspeed_m_s, 0.0, 1e9),
            ("domain_vertical_airspeed_m_s", self.domain_vertical_airspeed_m_s, 0.0, 1e9),
        ]
        checks += [(f"inertia_kg_m2[{i}]", v, 1e-5, 100.0) for i, v in enumerate(self.inertia_kg_m2)]
        for name, value, lo, hi in checks:
            if not (np.isfinite(value) and lo <= value <= hi):
                raise ValueError(f"vehicle.{name} = {value!r}: allowed range is [{lo}, {hi}]")
        if self.rotor_speed_min_rad_s >= self.rotor_speed_max_rad_s:
            raise ValueError(
                "vehicle.rotor_speed_min_rad_s must be below rotor_speed_max_rad_s "
                f"({self.rotor_speed_min_rad_s} >= {self.rotor_speed_max_rad_s})"
            )
        if self.n_rotors != 4:
            raise ValueError(f"vehicle.n_rotors = {self.n_rotors}: only 4 (Eq. 42 mixing) is supported")


DEFAULT_VEHICLE = "nasa_quad"


def _vehicle_path(name_or_path: str | Path) -> Path:
    p = Path(name_or_path)
    if p.suffix == ".toml" and p.exists():
        return p
    builtin = resources.files("vehicle") / "vehicles" / f"{str(name_or_path).replace('-', '_')}.toml"
    if builtin.is_file():
        return Path(str(builtin))
    raise ValueError(f"vehicle: no vehicle file {name_or_path!r} (a .toml path or 'nasa-quad')")


def load_vehicle(name_or_path: str | Path = DEFAULT_VEHICLE) -> VehicleParams:
    """Load a vehicle file and convert it to SI. Errors name the offending field."""
    path = _vehicle_path(name_or_path)
    with path.open("rb") as f:
        data = tomllib.load(f)
    try:
        paper = data["paper"]
        assumed = data["assumed"]
        raw = data["coefficients"]
        raw_ci = data.get("ci95", {})
    except KeyError as e:
        raise ValueError(f"vehicle file {path}: missing section [{e.args[0]}]") from None
    unknown = set(raw) - set(COEFFICIENT_NAMES)
    if unknown:
        raise ValueError(
            f"vehicle file {path}: unknown coefficient(s) {sorted(unknown)}; "
            f"allowed: {', '.join(COEFFICIENT_NAMES)}"
        )

    def si(name: str, value: float) -> float:
        return value * FT if name in LENGTH_COEFFICIENTS | LENGTH_COEFFICIENTS_2 else value

    try:
        params = VehicleParams(
            name=str(data.get("name", path.stem)),
            mass_kg=float(assumed["mass_kg"]),
            inertia_kg_m2=tuple(float(x) for x in assumed["inertia_kg_m2"]),  # type: ignore[arg-type]
            n_rotors=int(paper["n_rotors"]),
            air_density_kg_m3=float(paper["air_density_slug_ft3"]) * SLUG / FT**3,
            rotor_radius_m=float(paper["rotor_radius_ft"]) * FT,
            arm_length_m=float(paper["arm_length_ft"]) * FT,
            hub_height_m=float(assumed["hub_height_m"]),
            hover_induced_velocity_m_s=float(paper["hover_induced_velocity_ft_s"]) * FT,
            gravity_m_s2=float(paper["gravity_ft_s2"]) * FT,
            rotor_inertia_kg_m2=float(assumed["rotor_inertia_kg_m2"]),
            motor_time_constant_s=float(assumed["motor_time_constant_s"]),
            rotor_speed_min_rad_s=float(assumed["rotor_speed_min_rad_s"]),
            rotor_speed_max_rad_s=float(assumed["rotor_speed_max_rad_s"]),
            crash_speed_m_s=float(assumed.get("crash_speed_m_s", 3.0)),
            domain_airspeed_m_s=float(assumed.get("domain_airspeed_m_s", 1e9)),
            domain_vertical_airspeed_m_s=float(assumed.get("domain_vertical_airspeed_m_s", 1e9)),
            battery_cells=int(assumed.get("battery_cells", 6)),
            battery_capacity_mah=float(assumed.get("battery_capacity_mah", 10000.0)),
            hover_current_a=float(assumed.get("hover_current_a", 22.0)),
            coefficients={k: si(k, float(v)) for k, v in raw.items()},
            ci95={k: si(k, float(v)) for k, v in raw_ci.items()},
        )
    except KeyError as e:
        raise ValueError(f"vehicle file {path}: missing field {e.args[0]!r}") from None
    if len(params.inertia_kg_m2) != 3:
        raise ValueError("vehicle.inertia_kg_m2 must have 3 values (Ixx, Iyy, Izz)")
    params.validate()
    return params
