"""The strategies' plume memory: detections placed where the vehicle was when the air was
sampled, every sample for the chemotaxis gradient, and the detection rate.

Frames and units: NED, SI; horizontal positions (north, east) in m, times in s, concentrations
mg/m^3.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import replace

import numpy as np

from mission.strategies.base import Observation, heading_of
from mission.strategies.params import CommonParams

#: Time constant of the detection-rate average [s].
HIT_TAU_S = 3.0
#: A reading is a hit when it exceeds the decay of the last detected reading by this many standard
#: deviations of the difference of two noisy readings: 4 sigma is a false hit in ~3e-5 readings. (With
#: 3 sensor sigmas, 2.3 sigmas of the difference, 1 % of the readings of a decay tail were hits:
#: open-field seed 200 had 10 of 254 hits in pure decay, most of them placed 2-7 m upwind of the
#: source, where the vehicle flies while a strong puff's tail lasts seconds.)
HIT_SIGMAS = 4.0


def hit_threshold(tail_value: float | np.ndarray, k: float | np.ndarray, noise: float) -> float | np.ndarray:
    """The reading [mg/m^3] a detection must exceed to be a hit: the last detected reading
    ``tail_value`` decayed by ``k`` = exp(-dt / sensor tau), plus ``HIT_SIGMAS`` standard deviations
    of the difference of two readings of noise ``noise`` (1-sigma each). Floats or arrays."""
    return tail_value * k + HIT_SIGMAS * noise * (1.0 + k * k) ** 0.5


class PlumeMemory:
    """Detections (time, lag-corrected horizontal position, value) and every sample for the
    chemotaxis gradient; times in s, positions m (north, east), values mg/m^3."""

    def __init__(self, params: CommonParams) -> None:
        self.p = params
        self.det_t: list[float] = []
        self.det_pos: list[np.ndarray] = []
        self.det_val: list[float] = []
        self.det_eligible: list[bool] = []  # a candidate whatever its value (it interrupted a verification)
        self.samples: deque[tuple[float, np.ndarray, float]] = deque()
        self.last_detect_t = -math.inf
        self.first_detect_t = math.nan
        self.n_detect = 0
        # Detection rate (fraction of readings at or above the limit), exponentially averaged
        # over HIT_TAU_S, and its value at the last detection: near a source the plume is
        # continuous (rate ~1), far downwind it is intermittent (~0.2-0.3), so a loss after a
        # high rate is a plume end, a loss after a low rate is likely a gap or a meander.
        self.hit_rate = 0.0
        self.hit_rate_at_last = 0.0
        self._t_sample = math.nan
        self._tail_value = 0.0  # the last detected reading [mg/m^3] and its time [s]: the decay tail
        self._tail_t = math.nan
        self.all_values: list[float] = []
        self.bad_readings = 0  # detections with a NaN or negative concentration (ignored)

    def add(self, obs: Observation) -> bool:
        """Record the observation's reading if it is new; returns True on a new hit.

        A hit is a detection that is not just the sensor's decay: after a strong puff the
        first-order sensor (``sensor_tau_s``) reads above the detection limit for seconds
        (ln(c / limit) tau: 4 s from 240 mg/m^3), i.e. many metres after the vehicle left the
        plume. A reading counts as a hit only if it exceeds the pure decay of the last *detected*
        reading by more than ``HIT_SIGMAS`` standard deviations of the difference of two readings
        (each with ``sensor_noise_mg_m3``); only hits place the plume. The tail is followed through
        readings below the detection limit (reported as 0): at the end of a tail the readings
        flicker about the limit, and a detection after such a 0 is still the same decay.
        """
        if not obs.chem_new:
            return False
        if obs.detected and not (math.isfinite(obs.chem_mg_m3) and obs.chem_mg_m3 > 0.0):
            self.bad_readings += 1  # NaN or negative: no detection (it would poison the decay tail)
            obs = replace(obs, detected=False)
        value = obs.chem_mg_m3 if obs.detected else 0.0
        # The decay runs on the readings' own times: a tick can carry a reading older than itself
        # (the one after a lost message), and its decay measured to the tick would look like a rise.
        tc = obs.t if math.isnan(obs.chem_t) else obs.chem_t
        hit = False
        if obs.detected:
            k = 0.0 if math.isnan(self._tail_t) else math.exp(-max(tc - self._tail_t, 0.0) / self.p.sensor_tau_s)
            hit = bool(value > hit_threshold(self._tail_value, k, self.p.sensor_noise_mg_m3))
            self._tail_value, self._tail_t = value, tc
        pos = obs.position_ned[0:2] - self.p.sensor_lag_s * obs.velocity_ned[0:2]
        dt = 0.1 if math.isnan(self._t_sample) else max(tc - self._t_sample, 0.0)
        self._t_sample = tc
        a = -math.expm1(-dt / HIT_TAU_S)
        self.hit_rate += a * ((1.0 if hit else 0.0) - self.hit_rate)
        self.samples.append((obs.t, pos, value))
        while self.samples and self.samples[0][0] < obs.t - self.p.memory_s:
            self.samples.popleft()
        if obs.detected:
            # Any detection (decay tail included) keeps the plume "found" for timing.
            self.last_detect_t = obs.t
            self.all_values.append(value)
        if not hit:
            return False
        self.det_t.append(obs.t)
        self.det_pos.append(pos)
        self.det_val.append(obs.chem_mg_m3)
        self.det_eligible.append(False)
        self.hit_rate_at_last = self.hit_rate
        if self.n_detect == 0:
            self.first_detect_t = obs.t
        self.n_detect += 1
        return True

    def since_detect(self, t: float) -> float:
        """Seconds since the last detection (inf before the first)."""
        return t - self.last_detect_t

    def most_upwind(self, u: np.ndarray) -> np.ndarray | None:
        """Lag-corrected position (north, east) of the hit furthest along ``u`` among the hits of
        at least ``candidate_min_mg_m3`` (a single weak hit is as likely noise or a stray puff)."""
        if not self.det_pos:
            return None
        P = np.asarray(self.det_pos)
        strong = (np.asarray(self.det_val) >= self.p.candidate_min_mg_m3) | np.asarray(self.det_eligible)
        if not strong.any():
            return None
        P = P[strong]
        return P[int(np.argmax(P @ u))].copy()

    def peak_near(self, point: np.ndarray, radius_m: float) -> float:
        """Largest hit value within ``radius_m`` of ``point`` (horizontal), mg/m^3."""
        if not self.det_pos:
            return 0.0
        d = np.linalg.norm(np.asarray(self.det_pos) - point, axis=1)
        v = np.asarray(self.det_val)[d <= radius_m]
        return float(v.max()) if len(v) else 0.0

    def n_near(self, point: np.ndarray, radius_m: float) -> int:
        """Detections within ``radius_m`` of ``point`` (horizontal)."""
        if not self.det_pos:
            return 0
        d = np.linalg.norm(np.asarray(self.det_pos) - point, axis=1)
        return int(np.count_nonzero(d <= radius_m))

    def centerline(self, t: float, n: np.ndarray) -> float | None:
        """Crosswind coordinate (m along ``n``) of the plume centreline: the mean of the recent
        detections' crosswind coordinates, weighted by log concentration (a few strong hits near
        the axis outweigh many weak ones at the edge); None without recent detections."""
        k = len(self.det_t)
        lo = t - self.p.memory_s
        i = k
        while i > 0 and self.det_t[i - 1] >= lo:
            i -= 1
        if i == k:
            return None
        P = np.asarray(self.det_pos[i:])
        w = np.log1p(np.asarray(self.det_val[i:]) / 0.05)
        return float((P @ n) @ w / w.sum())

    def crosswind_spread(self, t: float, n: np.ndarray, u: np.ndarray, a_up: float, depth_m: float = 10.0) -> float:
        """Crosswind extent (m along ``n``, 5th to 95th percentile) of the hits of the last
        ``memory_s`` that lie less than ``depth_m`` downwind of the along-wind coordinate
        ``a_up`` (m along ``u``): the local plume width there; 0 with fewer than two."""
        lo = t - self.p.memory_s
        i = len(self.det_t)
        while i > 0 and self.det_t[i - 1] >= lo:
            i -= 1
        if len(self.det_t) - i < 2:
            return 0.0
        P = np.asarray(self.det_pos[i:])
        P = P[P @ u >= a_up - depth_m]
        if len(P) < 2:
            return 0.0
        c = P @ n
        return float(np.percentile(c, 95) - np.percentile(c, 5))

    def gradient_heading(self) -> float | None:
        """Heading (rad) of the concentration gradient over the recent samples (least squares on
        log(1 + c / 0.05)), or None when it is not determined (too few detections, no spread)."""
        if len(self.samples) < 10:
            return None
        P = np.array([s[1] for s in self.samples])
        c = np.log1p(np.array([s[2] for s in self.samples]) / 0.05)
        if np.count_nonzero(c) < 3:
            return None
        Pc = P - P.mean(axis=0)
        A = Pc.T @ Pc
        if np.linalg.eigvalsh(A)[0] < 1.0 * len(P):  # samples along a line: one direction unknown
            A = A + np.eye(2) * len(P)  # ridge: leave the unknown direction at zero
        g = np.linalg.solve(A, Pc.T @ (c - c.mean()))
        if float(np.hypot(g[0], g[1])) < 1e-3:
            return None
        return heading_of(g)
