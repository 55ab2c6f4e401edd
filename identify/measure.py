"""From a flight to equation-error data: the measured forces and moments, and the Eq. 46 regressors.

Equation error (Klein & Morelli ch. 5): the outputs are the forces and moments the vehicle felt,
computed from measurements, and the model is linear in its coefficients, ``z = X theta + v``:

- forces: ``[X, Y, Z] = m f`` with ``f`` the accelerometer's specific force (FRD, N);
- moments: ``[L, M, N] = I omega_dot + omega x I omega`` (Eq. 4, principal axes) minus the terms the
  model does not identify (the rotors' gyroscopic and reaction moments, J from the vehicle file);
  ``omega_dot`` is the smoothed derivative of the gyroscope (Savitzky-Golay, 0.1 s);
- regressors: :func:`vehicle.rotor_model.regressor_matrix`, the estimator's own Eq. 46 code, at the
  airspeed ``R^T (V - W)`` with the assumed wind ``W``.

All series are brought to one uniform clock (the median sample rate), low-passed without phase lag
(4th-order Butterworth at ``cutoff_hz``, forward and backward), and decimated to ``rate_hz`` for the
regression. Mass and inertia are the vehicle file's (known, as in the paper).

Rotor speeds: ESC telemetry is noisy (2 rad/s at 50 Hz on windseek's ESC model), and in Eq. 46 the
noise enters the regressors; when the autopilot's commands are known the rotor speed is a
complementary blend: the commands through the motor's first-order lag (the vehicle file's time
constant) above ``blend_hz``, the ESC speeds below it (they correct the motor model's gain and any
lag error at low frequency).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.signal import butter, lfilter, savgol_filter, sosfiltfilt

from identify.flight_data import FlightData
from vehicle.frames import quat_to_dcm
from vehicle.params import VehicleParams
from vehicle.rotor_model import known_moment_matrix, regressor_matrix

#: Table 3's variables, in its order, for the identified domain.
DOMAIN_VARIABLES = ("u", "v", "w", "p", "q", "r", "delta_t", "delta_a", "delta_e", "delta_r", "omega")


@dataclass(frozen=True, eq=False)
class EquationError:
    """Outputs ``z`` (m, 6: X, Y, Z N, L, M, N N*m), regressors ``X`` (m, N_COEF), on times ``t`` (s), with the
    samples' airspeed (m, 3) FRD, rates (m, 3), rotor speeds (m, N) and the ``use`` mask (m,)."""

    t: np.ndarray
    z: np.ndarray
    X: np.ndarray
    airspeed: np.ndarray
    rates: np.ndarray
    rotor_speeds: np.ndarray
    use: np.ndarray


def _uniform(data: FlightData) -> tuple[np.ndarray, float]:
    dt = float(np.median(np.diff(data.t)))
    return np.arange(data.t[0], data.t[-1] + 0.5 * dt, dt), dt


def _interp(t_new: np.ndarray, t: np.ndarray, y: np.ndarray) -> np.ndarray:
    return np.stack([np.interp(t_new, t, y[:, k]) for k in range(y.shape[1])], axis=1)


def rotor_speeds(data: FlightData, t: np.ndarray, tau_s: float, blend_hz: float = 1.0) -> np.ndarray:
    """Rotor speeds (rad/s) on the uniform clock ``t``: the ESC speeds, or with commands the complementary
    blend of the module docstring (motor model above ``blend_hz``, ESC below)."""
    esc = _interp(t, data.t, data.rotor_speeds)
    if data.rotor_commands is None:
        return esc
    dt = float(t[1] - t[0])
    cmd = _interp(t, data.t, data.rotor_commands)
    a = 1.0 - math.exp(-dt / tau_s)  # the motor's first-order lag, exact for a command held over a sample
    model = lfilter([a], [1.0, a - 1.0], cmd, axis=0, zi=np.tile((1.0 - a) * esc[0], (1, 1)))[0]
    sos = butter(2, blend_hz, fs=1.0 / dt, output="sos")
    return model + sosfiltfilt(sos, esc - model, axis=0)


def equation_error(data: FlightData, vehicle: VehicleParams, p: np.ndarray, rate_hz: float = 50.0,
                   cutoff_hz: float = 5.0) -> EquationError:  # fmt: skip
    """The equation-error data of ``data`` for ``vehicle`` with parameter array ``p`` (its domain
    constants apply to the regressors). See the module docstring."""
    t, dt = _uniform(data)
    fs = 1.0 / dt
    cut = min(cutoff_hz, 0.4 * fs)
    sos = butter(4, cut, fs=fs, output="sos")

    def smooth(y: np.ndarray) -> np.ndarray:
        yi = _interp(t, data.t, y)
        return sosfiltfilt(sos, yi, axis=0) if yi.shape[0] > 30 else yi

    acc = smooth(data.specific_force)
    gyr = smooth(data.rates)
    rot = rotor_speeds(data, t, vehicle.motor_time_constant_s)
    rot = sosfiltfilt(sos, rot, axis=0) if rot.shape[0] > 30 else rot
    vel = smooth(data.velocity_ned)
    q = _interp(t, data.t, data.quaternion)
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    win = max(5, int(round(0.1 * fs)) | 1)
    gyr_dot = savgol_filter(gyr, win, 2, deriv=1, delta=dt, axis=0)
    rot_dot = savgol_filter(rot, win, 2, deriv=1, delta=dt, axis=0)
    bad = np.interp(t, data.t, (~data.mask).astype(float)) > 0.0
    step = max(1, int(round(fs / rate_hz)))
    sel = slice(0, None, step)
    t, acc, gyr, rot, vel, q, gyr_dot, rot_dot, bad = (a[sel] for a in (t, acc, gyr, rot, vel, q, gyr_dot, rot_dot,
                                                                        bad))  # fmt: skip
    R = np.array([quat_to_dcm(qq) for qq in q])
    airspeed = np.einsum("nji,nj->ni", R, vel - data.wind_ned)
    inertia = np.asarray(vehicle.inertia_kg_m2)
    moments = gyr_dot * inertia + np.cross(gyr, gyr * inertia)
    known = known_moment_matrix(gyr, rot, rot_dot, p)
    z = np.concatenate([vehicle.mass_kg * acc, moments - known], axis=1)
    X = regressor_matrix(airspeed, gyr, rot, p)
    return EquationError(t=t, z=z, X=X, airspeed=airspeed, rates=gyr, rotor_speeds=rot, use=~bad)


def domain_table(ee: EquationError, mixing: np.ndarray) -> dict[str, list[float]]:
    """Table 3: the 5th and 95th percentiles of the identification data (SI: m/s, rad/s, (rad/s)^2)."""
    u = ee.use
    w = ee.rotor_speeds[u]
    delta = (w**2) @ mixing.T
    cols = [ee.airspeed[u, 0], ee.airspeed[u, 1], ee.airspeed[u, 2], ee.rates[u, 0], ee.rates[u, 1],
            ee.rates[u, 2], delta[:, 0], delta[:, 1], delta[:, 2], delta[:, 3], w.ravel()]  # fmt: skip
    return {name: [float(np.percentile(c, 5)), float(np.percentile(c, 95))]
            for name, c in zip(DOMAIN_VARIABLES, cols, strict=True)}  # fmt: skip


def domain_limits(ee: EquationError, floor_m_s: float = 1.0) -> tuple[float, float]:
    """Where the identified model's airspeed regressors saturate (m/s): 1.5 times the 99th percentile of
    the horizontal and of the vertical airspeed the fit saw (the model is fitted with them applied), at
    least ``floor_m_s`` (a hover record has no airspeed to speak of; a zero limit would divide by it)."""
    u = ee.use
    vh = np.hypot(ee.airspeed[u, 0], ee.airspeed[u, 1])
    vz = np.abs(ee.airspeed[u, 2])
    return (max(floor_m_s, 1.5 * float(np.percentile(vh, 99))),
            max(floor_m_s, 1.5 * float(np.percentile(vz, 99))))  # fmt: skip
