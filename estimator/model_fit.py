"""Does the model fit the vehicle flown? Three checks, one answer for every program that estimates the wind.

- :class:`~estimator.thrust_check.ThrustCheck`: the rotors' thrust at the measured rotor speeds against the
  vehicle's mass times its specific force, over the airspeeds the model was identified for (needs no
  wind estimate; catches gross mismatches: another airframe, a wrong vehicle file).
- :class:`DomainCheck`: the filter's airspeed against the model's identified domain (a wrong model is
  explained by a wind no identification flight went near: PX4 SIH's 1 kg vehicle with the 2.8 kg model
  by a 20 m/s vertical wind).
- :class:`InnovationCheck`: the running innovation test, the accelerometer's normalized innovation squared
  averaged over windows: a model whose errors no wind can explain (its structure, not its mass) keeps it
  far above its level in flight (0.4-0.6 with the identified model, the accelerometer noise set wide
  enough to hold the model error; 3 for a chi-square with 3 degrees of freedom).

None of them can tell a mass error of some tens of percent from the airspeed's effect on the rotors (a
rotor's thrust grows 36 % at 10 m/s and in a descent through the air): a vehicle 40 % heavier than its
model in 10 m/s of wind, or 40 % off in a 3 m/s wind with a 3-4 m/s vertical wind to explain it,
passes; twice or half the mass does not. A real updraft and a lighter vehicle look alike to the thrust
and to the filter: the thrust check allows for the filter's descent through the air only once the vehicle
has shown the model's thrust (issue 31: paper-s1's 3 m/s updraft, see :mod:`estimator.thrust_check`).

:class:`ModelFit` runs the three on every IMU sample; the first confirmed verdict is ``mismatch`` (one line,
latched), and until a verdict of fit (:attr:`ModelFit.judged`) nothing is published: the live estimator
(``estimator.live``), the mission runner (through it) and the review say which model is in use and
whether it fits. Units SI; FRD body; times in s of the autopilot's clock.
"""

from __future__ import annotations

import math

import numpy as np

from estimator.thrust_check import ThrustCheck, ThrustCheckConfig
from vehicle.params import VehicleParams


def identified_box(vehicle: VehicleParams) -> np.ndarray | None:
    """(3, 2) lower and upper body airspeed (u, v, w; m/s) the model was identified for: its domain's 5th /
    95th percentiles, widened by 50 % and 1.5 m/s (gusts and the filter's own noise: a window's mean airspeed
    in 10 m/s of turbulent wind reaches 11 m/s); None for a model without a recorded domain (the paper's
    Table 5 alone: Table 3 is not in its vehicle file)."""
    dom = vehicle.model_info.get("domain_p5_p95", {})
    if not all(k in dom for k in ("u", "v", "w")):
        return None
    box = np.array([[float(dom[k][0]), float(dom[k][1])] for k in ("u", "v", "w")])
    return box * 1.5 + np.array([-1.5, 1.5])


class DomainCheck:
    """The filter's airspeed against the model's identified domain, in steady flight.

    A model explains the vehicle's forces with some airspeed, so a wrong model (another vehicle, a wrong
    mass) shows as a wind whose airspeed lies where no identification flight went: PX4 SIH's 1 kg vehicle
    with the 2.8 kg model is explained by a 20 m/s vertical wind, PX4's 1.5 kg SITL Iris by 5 m/s. A wrong
    thrust is explained through the body-z airspeed (the rotors' thrust depends on it), so ``confirm``
    windows of ``window_s`` whose mean **vertical** airspeed lies outside :func:`identified_box` are a
    mismatch (said once, latched). A horizontal airspeed beyond the box is what a right vehicle flying fast
    in a strong wind reads (paper-s2's upwind legs: 3 m/s into 10 m/s of turbulent wind, 13.7 m/s against the
    box's 13.5): the model extrapolates there, so the estimate is withheld while such windows last
    (:attr:`excursion`, said once per excursion, :meth:`pop_note`) and published again from the first window
    back inside. Feed it every IMU sample with the filter's body airspeed once the filter has converged
    (horizontal wind 1-sigma under 1 m/s).
    """

    def __init__(self, vehicle: VehicleParams, window_s: float = 2.0, confirm: int = 2) -> None:
        self.box = identified_box(vehicle)
        self.window_s, self.confirm = window_s, confirm
        self.vehicle_name = vehicle.model_name
        self.mismatch: str | None = None
        self.excursion: str | None = None  # the horizontal airspeed outside the box, while it is (withheld)
        self.excursion_windows = 0  # windows withheld for it, in all
        self._note: str | None = None
        self.outside = 0
        self.windows = 0
        self.last_mean: np.ndarray | None = None
        self._t0, self._sum, self._n = math.nan, np.zeros(3), 0

    def sample(self, t: float, airspeed_body: np.ndarray | None, airborne: bool) -> bool:
        """One sample; True when it confirmed a mismatch (:attr:`mismatch` is set)."""
        if self.box is None or self.mismatch is not None:
            return False
        if not airborne or airspeed_body is None:
            self._t0, self._n = math.nan, 0
            return False
        if not math.isfinite(self._t0):
            self._t0, self._sum, self._n = t, np.zeros(3), 0
        self._sum += airspeed_body
        self._n += 1
        if t - self._t0 < self.window_s:
            return False
        mean = self._sum / self._n
        self._t0 = math.nan
        self.windows += 1
        self.last_mean = mean
        out = (mean < self.box[:, 0]) | (mean > self.box[:, 1])
        self._horizontal(mean, out)
        self.outside = self.outside + 1 if out[2] else 0
        if self.outside < self.confirm:
            return False
        self.mismatch = (f"model mismatch: the wind that explains this vehicle's forces puts its airspeed where "
                         f"{self.vehicle_name}'s model was never identified ({self._names(mean, out)}); this is not "
                         "the model's vehicle (or not its domain), so the estimate would be a guess: the wind "
                         "estimate is withheld")  # fmt: skip
        return True

    def pop_note(self) -> str | None:
        """The line that says an excursion began (once per excursion), or None."""
        note, self._note = self._note, None
        return note

    def _horizontal(self, mean: np.ndarray, out: np.ndarray) -> None:
        if not out[:2].any():
            self.excursion = None
            return
        if self.excursion is None:
            self._note = (f"the airspeed is outside the domain {self.vehicle_name}'s model was identified for "
                          f"({self._names(mean, out & np.array([True, True, False]))}): the wind estimate is "
                          "withheld until it is back inside (a faster identification reference widens the domain: "
                          "windseek identify --speed)")  # fmt: skip
        self.excursion = f"outside the identified domain ({self._names(mean, out & np.array([True, True, False]))})"
        self.excursion_windows += 1

    def _names(self, mean: np.ndarray, out: np.ndarray) -> str:
        assert self.box is not None
        return ", ".join(f"{n} {m:+.1f} m/s (identified {lo:+.1f}..{hi:+.1f})"
                         for n, m, (lo, hi), o in zip("uvw", mean, self.box, out, strict=True) if o)  # fmt: skip


class InnovationCheck:
    """The running innovation test (see the module docstring): ``confirm`` windows of ``window_s`` whose mean
    normalized innovation squared exceeds ``limit`` are a mismatch."""

    def __init__(self, vehicle_name: str, window_s: float = 2.0, confirm: int = 2, limit: float = 10.0) -> None:
        self.vehicle_name, self.window_s, self.confirm, self.limit = vehicle_name, window_s, confirm, limit
        self.mismatch: str | None = None
        self.outside = 0
        self.windows = 0
        self.last_mean = math.nan
        self.total, self.count = 0.0, 0
        self._t0, self._sum, self._n = math.nan, 0.0, 0

    def sample(self, t: float, nis: float, airborne: bool) -> bool:
        """One accelerometer update's NIS; True when it confirmed a mismatch."""
        if self.mismatch is not None or not airborne or not math.isfinite(nis):
            return False
        if not math.isfinite(self._t0):
            self._t0, self._sum, self._n = t, 0.0, 0
        self._sum += nis
        self._n += 1
        self.total += nis
        self.count += 1
        if t - self._t0 < self.window_s:
            return False
        self.last_mean = self._sum / self._n
        self._t0 = math.nan
        self.windows += 1
        self.outside = self.outside + 1 if self.last_mean > self.limit else 0
        if self.outside < self.confirm:
            return False
        self.mismatch = (f"model mismatch: {self.vehicle_name}'s model does not explain the accelerometer with any "
                         f"wind (mean normalized innovation {self.last_mean:.1f}, at most {self.limit:g} in flight): "
                         "the wind estimate is withheld")  # fmt: skip
        return True

    @property
    def mean(self) -> float | None:
        return self.total / self.count if self.count else None


class ModelFit:
    """The thrust check and the domain check on one vehicle file's model (see the module docstring)."""

    def __init__(self, vehicle: VehicleParams, config: ThrustCheckConfig | None = None) -> None:
        self.thrust = ThrustCheck(vehicle, config)
        self.domain = DomainCheck(vehicle, self.thrust.config.window_s, self.thrust.config.confirm)
        self.innovation = InnovationCheck(vehicle.model_name, self.thrust.config.window_s, self.thrust.config.confirm)
        self.vehicle_name = vehicle.name
        self.model_source = str(vehicle.model_info.get("source", "the vehicle file's [model]"))
        self.mismatch_t_s: float | None = None  # autopilot time (s) of the sample that confirmed the mismatch

    @property
    def mismatch(self) -> str | None:
        return self.thrust.mismatch or self.domain.mismatch or self.innovation.mismatch

    @property
    def judged(self) -> bool:
        """A verdict of fit: the thrust and the domain checks each judged ``confirm`` windows (the domain check
        only once the filter converged) and none of the three objected."""
        need = self.thrust.config.confirm
        domain_done = self.domain.box is None or self.domain.windows >= need
        return self.mismatch is None and self.thrust.windows >= need and domain_done

    @property
    def publishable(self) -> bool:
        """Judged to fit, and the airspeed inside the identified domain now (:attr:`DomainCheck.excursion`)."""
        return self.judged and self.domain.excursion is None

    @property
    def ratio(self) -> float | None:
        return self.thrust.ratio

    @property
    def band(self) -> tuple[float, float]:
        return self.thrust.band

    def sample(self, t: float, acc: np.ndarray, gyr: np.ndarray, speeds: np.ndarray | None, airborne: bool,
               airspeed_body: np.ndarray | None, converged: bool, nis: float = math.nan) -> bool:  # fmt: skip
        """One IMU sample (specific force, rates, the rotor speeds in force, the filter's airspeed, whether the
        filter has converged, its last normalized innovation squared); True when it confirmed a mismatch
        (once: the first one latches)."""
        if self.mismatch is not None:
            return False
        # The converged filter's body-z airspeed lets the thrust check allow for a descent through the air
        # (an updraft) once the vehicle has shown the model's thrust (see estimator.thrust_check).
        w_air = float(airspeed_body[2]) if converged and airspeed_body is not None else None
        found = (self.thrust.sample(t, acc, gyr, speeds, airborne, w_air)
                 or self.innovation.sample(t, nis, airborne and converged)
                 or self.domain.sample(t, airspeed_body if converged else None, airborne))
        if found:
            self.mismatch_t_s = t
        return found

    def summary(self) -> dict[str, object]:
        """What the checks found, for a program's summary."""
        m = self.domain.last_mean
        return {"model": self.vehicle_name, "model_source": self.model_source, "model_fits": self.judged,
                "thrust_ratio": None if self.ratio is None else round(self.ratio, 3),
                "thrust_band": [round(b, 3) for b in self.band],
                "airspeed_body_m_s": None if m is None else [round(float(x), 2) for x in m],
                "domain_excursion_windows": self.domain.excursion_windows,
                "innovation_nis_mean": None if self.innovation.mean is None else round(self.innovation.mean, 3),
                "mismatch_t_s": None if self.mismatch_t_s is None else round(self.mismatch_t_s, 3),
                "identified_box_m_s": None if self.domain.box is None
                else self.domain.box.round(2).tolist()}  # fmt: skip
