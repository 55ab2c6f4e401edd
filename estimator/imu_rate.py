"""The accelerometer's noise per sample at the rate an IMU stream actually has.

:class:`estimator.config.EstimatorConfig` states the accelerometer noise per sample at
``accel_noise_rate_hz`` (250 Hz, windseek's IMU). Most of that "noise" is model error correlated over
many samples (ESC noise on the thrust, rotor speeds held between 50 Hz ESC samples), so a stream at
another rate carries about the same information per second, not per sample: the variance per sample
scales with the rate (a constant noise density, R_k = R_c / dt). Without this an autopilot's 100 Hz
HIGHRES_IMU made the filter count each sample as if it were a 250 Hz one: its stated uncertainty
~25 % too wide and the estimate noisier (in-process, open-field, development seeds 100-105, the
250 Hz IMU low-passed at 20 Hz and taken at 100 Hz as ArduCopter streams it: 95 % coverage 0.995 ->
0.980, horizontal RMSE 0.461 -> 0.439 m/s; the 250 Hz stream itself 0.987 / 0.423).

Plain code, no I/O. Time in s.
"""

from __future__ import annotations

#: Longest first interval taken as the stream's [s]; a longer one waits for the next.
MAX_FIRST_S = 1.0
#: Running-mean weight of each new interval (after the first 1 / WEIGHT, averaged plainly).
WEIGHT = 0.02
#: Intervals averaged before the factor leaves 1.
MIN_INTERVALS = 10
#: Factors within this of 1 are exactly 1 (a stream at the stated rate, with jitter, changes nothing).
SNAP = 0.02
#: Lowest factor (a stream at a tenth of the stated rate or slower).
FLOOR = 0.1


class ImuRate:
    """Running mean of an IMU stream's sample interval and the per-sample variance factor it implies."""

    def __init__(self, stated_rate_hz: float) -> None:
        if not stated_rate_hz > 0.0:
            raise ValueError(f"accel_noise_rate_hz {stated_rate_hz}: must be > 0")
        self.stated_rate_hz = float(stated_rate_hz)
        self.interval_s: float | None = None
        self._n = 0  # intervals averaged
        self._t_last: float | None = None

    def factor(self, t: float) -> float:
        """Variance factor for an accepted sample at ``t`` [s]: rate / stated rate, from the running mean
        interval (1 until :data:`MIN_INTERVALS` are known; exactly 1 within :data:`SNAP`; at least
        :data:`FLOOR`). An interval over twice the mean (a gap) or under half of it does not move the mean."""
        last, self._t_last = self._t_last, t
        if last is not None and t > last:
            dt = t - last
            m = self.interval_s
            if m is None:
                if dt < MAX_FIRST_S:
                    self.interval_s, self._n = dt, 1
            elif 0.5 * m <= dt <= 2.0 * m:
                self._n += 1
                self.interval_s = m + max(WEIGHT, 1.0 / self._n) * (dt - m)  # a plain mean at first
        return self.current()

    def current(self) -> float:
        """The factor at the current mean interval (see :meth:`factor`)."""
        m = self.interval_s
        if m is None or self._n < MIN_INTERVALS:
            return 1.0
        f = 1.0 / (m * self.stated_rate_hz)
        return 1.0 if abs(f - 1.0) < SNAP else max(FLOOR, f)
