"""What the identification needs from a flight, however it was flown or logged.

:class:`FlightData` is the one input of the estimation (:mod:`identify.pipeline`): time series on one
clock, in SI, NED world and FRD body. The adapters fill it: the in-process flight
(:mod:`identify.fly.world`), a MAVLink flight (:mod:`identify.fly.px4`) and flight logs
(:mod:`identify.logs`). :meth:`FlightData.check` says in one line what is missing or unusable.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

#: Shortest usable record, s (the paper's manoeuvre is 125 s; a hover alone identifies little).
MIN_DURATION_S = 10.0


@dataclass(frozen=True, eq=False)
class FlightData:
    """Time series of one flight, all on the time base ``t`` (s, increasing).

    specific_force: accelerometer, FRD m/s^2 (n, 3); rates: gyroscope, FRD rad/s (n, 3);
    rotor_speeds: rad/s (n, N), the vehicle's rotor order (ESC telemetry, or actuator outputs through
    a motor model: say which in ``source``); velocity_ned: ground velocity, m/s (n, 3);
    quaternion: attitude body FRD -> NED, [w, x, y, z] (n, 4); wind_ned: the wind assumed (air-mass
    velocity NED m/s, (3,): the airspeed is ground velocity minus it); excluded: samples not to fit
    (n,) bool (saturated motors, ground contact), with ``exclusions`` saying why.
    """

    t: np.ndarray
    specific_force: np.ndarray
    rates: np.ndarray
    rotor_speeds: np.ndarray
    velocity_ned: np.ndarray
    quaternion: np.ndarray
    source: str = ""
    wind_ned: np.ndarray = field(default_factory=lambda: np.zeros(3))
    excluded: np.ndarray | None = None
    exclusions: tuple[str, ...] = ()
    rotor_commands: np.ndarray | None = None

    @property
    def n(self) -> int:
        return int(self.t.shape[0])

    @property
    def duration_s(self) -> float:
        return float(self.t[-1] - self.t[0]) if self.n > 1 else 0.0

    @property
    def mask(self) -> np.ndarray:
        """Samples to use (not excluded)."""
        return np.ones(self.n, dtype=bool) if self.excluded is None else ~self.excluded

    def check(self, n_rotors: int) -> None:
        """ValueError, one line, naming what is missing, mismatched or too short."""
        n = self.n
        parts = {"specific_force (accelerometer)": (self.specific_force, 3), "rates (gyroscope)": (self.rates, 3),
                 "rotor_speeds (ESC telemetry or actuator outputs)": (self.rotor_speeds, n_rotors),
                 "velocity_ned": (self.velocity_ned, 3), "quaternion (attitude)": (self.quaternion, 4)}  # fmt: skip
        missing = [name for name, (a, _) in parts.items() if a is None or np.size(a) == 0]
        if missing:
            raise ValueError(f"flight data ({self.source}) lacks {', '.join(missing)}: the identification needs "
                             "IMU, attitude, velocity and rotor speeds or actuator outputs")  # fmt: skip
        for name, (a, k) in parts.items():
            if a.shape != (n, k):
                raise ValueError(f"flight data ({self.source}): {name} has shape {a.shape}, expected ({n}, {k})")
            if not np.all(np.isfinite(a)):
                raise ValueError(f"flight data ({self.source}): {name} has NaN or infinite values")
        if n < 2 or not np.all(np.diff(self.t) > 0):
            raise ValueError(f"flight data ({self.source}): time must increase")
        if self.duration_s < MIN_DURATION_S:
            raise ValueError(f"flight data ({self.source}) is {self.duration_s:.1f} s long: at least "
                             f"{MIN_DURATION_S:g} s of flight is needed")  # fmt: skip
        if int(self.mask.sum()) < 200:
            raise ValueError(f"flight data ({self.source}): only {int(self.mask.sum())} usable samples after "
                             f"the exclusions ({'; '.join(self.exclusions) or 'none'})")  # fmt: skip

    def exclude(self, bad: np.ndarray, why: str) -> FlightData:
        """A copy with the samples ``bad`` (n,) bool also excluded, and ``why`` added to the reasons."""
        cur = np.zeros(self.n, dtype=bool) if self.excluded is None else self.excluded
        return replace(self, excluded=cur | bad, exclusions=self.exclusions + (why,))


def widen(bad: np.ndarray, t: np.ndarray, margin_s: float) -> np.ndarray:
    """``bad`` (n,) bool grown by ``margin_s`` seconds on both sides of every flagged sample."""
    if not bad.any():
        return bad
    idx = np.nonzero(bad)[0]
    lo = np.searchsorted(t, t[idx] - margin_s, side="left")
    hi = np.searchsorted(t, t[idx] + margin_s, side="right")
    out = np.zeros_like(bad)
    change = np.zeros(t.shape[0] + 1, dtype=np.int64)
    np.add.at(change, lo, 1)
    np.add.at(change, hi, -1)
    out[:] = np.cumsum(change)[:-1] > 0
    return out


def runs(mask: np.ndarray, t: np.ndarray) -> list[tuple[float, float]]:
    """The (start, end) times (s) of the runs of True in ``mask``."""
    out = []
    edges = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    for a, b in zip(np.nonzero(edges == 1)[0], np.nonzero(edges == -1)[0], strict=True):
        out.append((float(t[a]), float(t[b - 1])))
    return out
