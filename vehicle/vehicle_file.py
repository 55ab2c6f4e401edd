"""Vehicle files: read (and write) the TOML that describes one multirotor. Built-ins in ``vehicle/vehicles/``.

Tables (every value SI unless its name says otherwise; errors name the field):

- top level: ``name``, ``description``, ``truth`` (the world's force model: ``"bet"`` blade-element
  rotors, ``"sih"`` PX4 SIH's rotors, ``"model"`` the identified Eq. 46 itself);
- ``[frame]``: ``mass_kg``, ``inertia_kg_m2`` (principal, FRD), ``layout`` (``quad-x``, ``hexa-x``) with
  ``arm_length_m``, or ``[[frame.rotors]]`` entries (``position_m`` FRD from the CG, ``spin`` "ccw"/"cw"
  seen from above), ``hub_height_m`` (hub above the CG), ``drag_area_m2`` (fuselage C_D * A per body
  axis), ``crash_speed_m_s``, optional ``px4_outputs`` (PX4 output of each rotor, 1-based);
- ``[air]``: ``density_kg_m3``, ``gravity_m_s2``;
- ``[rotor]``: ``radius_m``, ``inertia_kg_m2`` (rotating parts about the shaft), ``motor_time_constant_s``,
  ``speed_min_rad_s`` (armed idle), ``speed_max_rad_s``;
- ``[blade]`` (needed by ``truth = "bet"``): ``blades``, ``chord_m``, ``root_pitch_deg``, ``twist_deg``,
  ``lift_slope_per_rad``, ``profile_drag``, ``flap_inertia_kg_m2``, ``hinge_stiffness_n_m_rad``,
  ``hub_inertia_kg_m2``;
- ``[sih]`` (needed by ``truth = "sih"``): ``t_max_n``, ``q_max_n_m``, ``kdv_n_s_m``, ``kdw_n_m_s_rad``;
- ``[battery]``: ``cells``, ``capacity_mah``, ``hover_current_a`` (telemetry only);
- ``[model]``: the wind estimator's Eq. 46: ``units`` (``"si"``, or ``"paper"``: Table 5 as printed, the
  length-carrying coefficients in ft), ``hover_induced_velocity_m_s`` (v0; default from momentum
  theory), ``domain_airspeed_m_s`` / ``domain_vertical_airspeed_m_s`` (where the regressors saturate),
  ``[model.coefficients]``, ``[model.ci95]`` (95 % half-widths), and free-form ``[model.info]`` (source,
  fit metrics, identified domain: written by ``windseek identify``).
"""

from __future__ import annotations

import math
import tomllib
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
import tomli_w

from vehicle.params import (
    COEFFICIENT_NAMES,
    FT,
    LENGTH_COEFFICIENTS,
    LENGTH_COEFFICIENTS_2,
    Blade,
    SihRotors,
    VehicleParams,
    layout_positions,
)
from vehicle.truth import with_control_figures

DEFAULT_VEHICLE = "nasa_quad"


def _vehicle_path(name_or_path: str | Path) -> Path:
    p = Path(name_or_path)
    if p.suffix == ".toml":
        if p.exists():
            return p
        raise ValueError(f"vehicle: no file {str(p)!r}")
    builtin = resources.files("vehicle") / "vehicles" / f"{str(name_or_path).replace('-', '_')}.toml"
    if builtin.is_file():
        return Path(str(builtin))
    names = sorted(f.name.removesuffix(".toml").replace("_", "-") for f in (resources.files("vehicle") / "vehicles")
                   .iterdir() if f.name.endswith(".toml"))  # fmt: skip
    raise ValueError(f"vehicle: no vehicle file {str(name_or_path)!r} (a .toml path or one of {', '.join(names)})")


class _Reader:
    """Typed access to one TOML table with errors that name the field."""

    def __init__(self, path: Path, where: str, table: Any) -> None:
        if not isinstance(table, dict):
            raise ValueError(f"vehicle file {path}: [{where}] must be a table")
        self.path, self.where, self.t = path, where, table

    def _name(self, key: str) -> str:
        return f"{self.where}.{key}" if self.where else key

    def has(self, key: str) -> bool:
        return key in self.t

    def num(self, key: str, default: float | None = None, lo: float = -math.inf, hi: float = math.inf) -> float:
        if key not in self.t:
            if default is None:
                raise ValueError(f"vehicle file {self.path}: missing field {self._name(key)}")
            return default
        v = self.t[key]
        if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(float(v)):
            raise ValueError(f"vehicle file {self.path}: {self._name(key)} = {v!r} must be a finite number")
        if not lo <= float(v) <= hi:
            raise ValueError(f"vehicle file {self.path}: {self._name(key)} = {v!r}: allowed range is [{lo}, {hi}]")
        return float(v)

    def vec(self, key: str, n: int, default: tuple[float, ...] | None = None) -> tuple[float, ...]:
        if key not in self.t and default is not None:
            return default
        v = self.t.get(key)
        if not isinstance(v, list) or len(v) != n:
            raise ValueError(f"vehicle file {self.path}: {self._name(key)} must be a list of {n} numbers, got {v!r}")
        sub = _Reader(self.path, self._name(key), {str(i): x for i, x in enumerate(v)})
        return tuple(sub.num(str(i)) for i in range(n))

    def text(self, key: str, default: str | None = None) -> str:
        v = self.t.get(key, default)
        if not isinstance(v, str):
            raise ValueError(f"vehicle file {self.path}: missing field {self._name(key)}")
        return v

    def sub(self, key: str, required: bool = True) -> _Reader | None:
        if key not in self.t:
            if required:
                raise ValueError(f"vehicle file {self.path}: missing section [{self._name(key)}]")
            return None
        return _Reader(self.path, self._name(key), self.t[key])


def _rotors(path: Path, frame: _Reader) -> tuple[np.ndarray, np.ndarray, str, float]:
    """Hub positions (N, 3), spins (N,), the layout name and the arm length b from [frame]."""
    h = frame.num("hub_height_m", 0.0, -1.0, 1.0)
    if frame.has("rotors"):
        entries = frame.t["rotors"]
        if not isinstance(entries, list) or not entries:
            raise ValueError(f"vehicle file {path}: frame.rotors must be a list of tables")
        pos, spins = [], []
        for i, e in enumerate(entries):
            r = _Reader(path, f"frame.rotors[{i}]", e)
            pos.append(r.vec("position_m", 3))
            s = r.text("spin")
            if s not in ("ccw", "cw"):
                raise ValueError(f"vehicle file {path}: frame.rotors[{i}].spin = {s!r}: 'ccw' or 'cw'")
            spins.append(1 if s == "ccw" else -1)
        p = np.array(pos)
        arm = frame.num("arm_length_m", float(np.mean(np.hypot(p[:, 0], p[:, 1]))), 0.01, 5.0)
        return p, np.array(spins), "custom", arm
    arm = frame.num("arm_length_m", None, 0.01, 5.0)
    try:
        positions, spin_signs = layout_positions(frame.text("layout", "quad-x"), arm, h)
    except ValueError as e:
        raise ValueError(f"vehicle file {path}: {e}") from None
    return positions, spin_signs, frame.text("layout", "quad-x"), arm


def _blade(b: _Reader) -> Blade:
    return Blade(
        blades=int(b.num("blades", None, 1, 8)),
        chord_m=b.num("chord_m", None, 1e-4, 1.0),
        root_pitch_rad=math.radians(b.num("root_pitch_deg", None, -10.0, 60.0)),
        twist_rad=math.radians(b.num("twist_deg", None, -60.0, 10.0)),
        lift_slope_per_rad=b.num("lift_slope_per_rad", None, 1.0, 7.0),
        profile_drag=b.num("profile_drag", None, 0.0, 0.5),
        flap_inertia_kg_m2=b.num("flap_inertia_kg_m2", None, 1e-9, 1.0),
        hinge_stiffness_n_m_rad=b.num("hinge_stiffness_n_m_rad", None, 0.0, 1e4),
        hub_inertia_kg_m2=b.num("hub_inertia_kg_m2", None, 0.0, 0.1),
    )


def _model_table(path: Path, model: _Reader | None) -> tuple[Path, _Reader | None]:
    """The [model] table, or the one of the file its ``from`` names (a vehicle file beside this one, or
    a built-in name): an identified model kept in its own, generated file."""
    if model is None or not model.has("from"):
        return path, model
    if set(model.t) != {"from"}:
        raise ValueError(f"vehicle file {path}: a [model] with 'from' takes nothing else")
    ref = model.text("from")
    other = path.parent / ref if (path.parent / ref).exists() else _vehicle_path(ref)
    with other.open("rb") as f:
        data = tomllib.load(f)
    sub = _Reader(other, "", data).sub("model", required=False)
    if sub is None or sub.has("from"):
        raise ValueError(f"vehicle file {path}: model.from = {ref!r} has no [model] of its own")
    return other, sub


def _model(path: Path, model: _Reader | None) -> tuple[dict[str, float], dict[str, float], dict[str, Any]]:
    """Eq. 46 coefficients and half-widths in SI, and the free-form info table."""
    if model is None:
        return {}, {}, {}
    units = model.text("units", "si")
    if units not in ("si", "paper"):
        raise ValueError(f"vehicle file {path}: model.units = {units!r}: 'si' or 'paper'")
    raw = model.t.get("coefficients", {})
    raw_ci = model.t.get("ci95", {})
    for where, tbl in (("coefficients", raw), ("ci95", raw_ci)):
        unknown = set(tbl) - set(COEFFICIENT_NAMES)
        if unknown:
            raise ValueError(f"vehicle file {path}: unknown model.{where} {sorted(unknown)}; "
                             f"allowed: {', '.join(COEFFICIENT_NAMES)}")  # fmt: skip

    def si(name: str, value: float) -> float:
        if units == "paper" and name in LENGTH_COEFFICIENTS | LENGTH_COEFFICIENTS_2:
            return value * FT
        return value

    coefs = {k: si(k, _Reader(path, "model.coefficients", raw).num(k)) for k in raw}
    ci = {k: si(k, _Reader(path, "model.ci95", raw_ci).num(k, lo=0.0)) for k in raw_ci}
    info = model.t.get("info", {})
    return coefs, ci, dict(info) if isinstance(info, dict) else {}


def load_vehicle(name_or_path: str | Path = DEFAULT_VEHICLE) -> VehicleParams:
    """Load a vehicle file (a built-in name such as ``nasa-quad`` or a ``.toml`` path) in SI, with the
    autopilot's figures derived from its truth. Errors are one line naming the file and the field."""
    path = _vehicle_path(name_or_path)
    try:
        with path.open("rb") as f:
            data = tomllib.load(f)
    except tomllib.TOMLDecodeError as e:
        raise ValueError(f"vehicle file {path}: not valid TOML ({e})") from None
    top = _Reader(path, "", data)
    frame, air, rotor = top.sub("frame"), top.sub("air"), top.sub("rotor")
    assert frame is not None and air is not None and rotor is not None
    battery = top.sub("battery", required=False) or _Reader(path, "battery", {})
    pos, spins, layout, arm = _rotors(path, frame)
    n = pos.shape[0]
    rho = air.num("density_kg_m3", 1.225, 0.3, 1.5)
    g = air.num("gravity_m_s2", 9.80665, 9.7, 9.9)
    mass = frame.num("mass_kg", None, 0.01, 100.0)
    radius = rotor.num("radius_m", None, 0.005, 2.0)
    model_path, model = _model_table(path, top.sub("model", required=False))
    # v0 from momentum theory if not given (the authors' MATLAB model: sqrt(m g / (2 N rho pi R^2))).
    v0_mt = math.sqrt(mass * g / (2.0 * n * rho * math.pi * radius**2))
    coefs, ci, info = _model(model_path, model)
    blade_r, sih_r = top.sub("blade", required=False), top.sub("sih", required=False)
    outputs = frame.vec("px4_outputs", n, tuple(float(i + 1) for i in range(n)))
    params = VehicleParams(
        name=top.text("name", path.stem),
        description=top.text("description", ""),
        truth=top.text("truth", "model"),
        mass_kg=mass,
        inertia_kg_m2=frame.vec("inertia_kg_m2", 3),  # type: ignore[arg-type]
        n_rotors=n,
        rotor_positions_m=tuple(tuple(float(c) for c in row) for row in pos),  # type: ignore[misc]
        rotor_spins=tuple(int(s) for s in spins),
        px4_outputs=tuple(int(o) - 1 for o in outputs),
        layout=layout,
        air_density_kg_m3=rho,
        gravity_m_s2=g,
        rotor_radius_m=radius,
        arm_length_m=arm,
        hub_height_m=frame.num("hub_height_m", 0.0, -1.0, 1.0),
        drag_area_m2=frame.vec("drag_area_m2", 3, (0.0, 0.0, 0.0)),  # type: ignore[arg-type]
        crash_speed_m_s=frame.num("crash_speed_m_s", 3.0),
        hover_induced_velocity_m_s=model.num("hover_induced_velocity_m_s", v0_mt) if model else v0_mt,
        domain_airspeed_m_s=model.num("domain_airspeed_m_s", 1e9) if model else 1e9,
        domain_vertical_airspeed_m_s=model.num("domain_vertical_airspeed_m_s", 1e9) if model else 1e9,
        rotor_inertia_kg_m2=rotor.num("inertia_kg_m2", None),
        motor_time_constant_s=rotor.num("motor_time_constant_s", None),
        rotor_speed_min_rad_s=rotor.num("speed_min_rad_s", None),
        rotor_speed_max_rad_s=rotor.num("speed_max_rad_s", None),
        blade=_blade(blade_r) if blade_r is not None else None,
        sih=SihRotors(sih_r.num("t_max_n", None, 0.0), sih_r.num("q_max_n_m", None, 0.0),
                      sih_r.num("kdv_n_s_m", 0.0, 0.0), sih_r.num("kdw_n_m_s_rad", 0.0, 0.0))
        if sih_r is not None else None,  # fmt: skip
        battery_cells=int(battery.num("cells", 6.0, 1, 24)),
        battery_capacity_mah=battery.num("capacity_mah", 10000.0, 1.0),
        hover_current_a=battery.num("hover_current_a", 22.0, 0.0),
        coefficients=coefs,
        ci95=ci,
        model_info=info,
    )
    params.validate()
    return with_control_figures(params)


def vehicle_tables(params: VehicleParams) -> dict[str, Any]:
    """The vehicle file's tables for ``params`` (SI; :func:`load_vehicle` reads them back to the same values)."""
    frame: dict[str, Any] = {"mass_kg": params.mass_kg, "inertia_kg_m2": list(params.inertia_kg_m2)}
    if params.layout in ("quad-x", "hexa-x"):
        frame |= {"layout": params.layout, "arm_length_m": params.arm_length_m}
    else:
        frame |= {"arm_length_m": params.arm_length_m,
                  "rotors": [{"position_m": list(p), "spin": "ccw" if s > 0 else "cw"}
                             for p, s in zip(params.rotor_positions_m, params.rotor_spins, strict=True)]}  # fmt: skip
    frame |= {"hub_height_m": params.hub_height_m, "drag_area_m2": list(params.drag_area_m2),
              "crash_speed_m_s": params.crash_speed_m_s,
              "px4_outputs": [o + 1 for o in params.px4_outputs]}  # fmt: skip
    out: dict[str, Any] = {"name": params.name, "description": params.description, "truth": params.truth,
                           "frame": frame,
                           "air": {"density_kg_m3": params.air_density_kg_m3, "gravity_m_s2": params.gravity_m_s2},
                           "rotor": {"radius_m": params.rotor_radius_m, "inertia_kg_m2": params.rotor_inertia_kg_m2,
                                     "motor_time_constant_s": params.motor_time_constant_s,
                                     "speed_min_rad_s": params.rotor_speed_min_rad_s,
                                     "speed_max_rad_s": params.rotor_speed_max_rad_s}}  # fmt: skip
    if params.blade is not None:
        b = params.blade
        out["blade"] = {"blades": b.blades, "chord_m": b.chord_m, "root_pitch_deg": math.degrees(b.root_pitch_rad),
                        "twist_deg": math.degrees(b.twist_rad), "lift_slope_per_rad": b.lift_slope_per_rad,
                        "profile_drag": b.profile_drag, "flap_inertia_kg_m2": b.flap_inertia_kg_m2,
                        "hinge_stiffness_n_m_rad": b.hinge_stiffness_n_m_rad,
                        "hub_inertia_kg_m2": b.hub_inertia_kg_m2}  # fmt: skip
    if params.sih is not None:
        s = params.sih
        out["sih"] = {"t_max_n": s.t_max_n, "q_max_n_m": s.q_max_n_m, "kdv_n_s_m": s.kdv_n_s_m,
                      "kdw_n_m_s_rad": s.kdw_n_m_s_rad}  # fmt: skip
    out["battery"] = {"cells": params.battery_cells, "capacity_mah": params.battery_capacity_mah,
                      "hover_current_a": params.hover_current_a}  # fmt: skip
    model: dict[str, Any] = {"units": "si", "hover_induced_velocity_m_s": params.hover_induced_velocity_m_s,
                             "domain_airspeed_m_s": params.domain_airspeed_m_s,
                             "domain_vertical_airspeed_m_s": params.domain_vertical_airspeed_m_s}  # fmt: skip
    if params.model_info:
        model["info"] = params.model_info
    model["coefficients"] = {k: params.coefficients[k] for k in COEFFICIENT_NAMES if k in params.coefficients}
    model["ci95"] = {k: params.ci95[k] for k in COEFFICIENT_NAMES if k in params.ci95}
    out["model"] = model
    return out


def format_vehicle_file(params: VehicleParams, header: str = "") -> str:
    """The text of a vehicle file for ``params`` (TOML), with ``header`` as leading comment lines."""
    lines = [f"# {line}".rstrip() for line in header.splitlines()] if header else []
    return ("\n".join(lines) + "\n\n" if lines else "") + tomli_w.dumps(_plain(vehicle_tables(params)))


def _plain(x: Any) -> Any:
    """numpy scalars and tuples as plain TOML values (tomli-w writes only built-in types)."""
    if isinstance(x, dict):
        return {str(k): _plain(v) for k, v in x.items() if v is not None}
    if isinstance(x, list | tuple):
        return [_plain(v) for v in x]
    if isinstance(x, np.generic):
        return x.item()
    return x
