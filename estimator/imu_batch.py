"""A run of IMU steps in one compiled call: the filter's inputs checked, its clocks advanced and its
steps taken for many samples at once (:func:`imu_steps`, through :meth:`WindEstimator.imu_batch`).

The same sequence as calling, for each step, :meth:`WindEstimator.set_rotor_speeds` for the rotor
speed samples up to its time, then :meth:`~WindEstimator.set_attitude` and
:meth:`~WindEstimator.imu`: the same checks (:mod:`estimator.gating`, each rejection counted under
the same reason, in the order they first occurred), the same clocks (``_plan``, the force scale's
release, the body-z low-pass, :class:`estimator.imu_rate.ImuRate`), the same compiled step
(:func:`estimator.step_kernels.accel_step`) with the same arguments, so the filter's state is the
same bit for bit. The Python of those methods cost about as much as the step itself (about 10 us of
input checks, clocks and bookkeeping per step); here it runs once per call.

The filter's Python state goes in and out through a float array (``S_*``; NaN for None), its
settings through another (``C_*``), the counts through an integer array (``K_*``). The GNSS
velocity history (``_hist``) gets each step's time, attitude matrix and body velocity; the filter
forms the NED velocity ``R @ x[0:3]`` from them (numpy, as before) when it reads an entry.
Units: s, m/s^2, rad/s, rad/s; FRD body, NED world.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numba import njit

from estimator.gating import ACCEL_LIMIT_M_S2, GYRO_LIMIT_RAD_S, QUAT_NORM_TOL, norm, within
from estimator.imu_rate import FLOOR, MAX_FIRST_S, MIN_INTERVALS, SNAP, WEIGHT
from estimator.step_kernels import D_LEFT, accel_step
from vehicle.frames import quat_to_dcm_into
from vehicle.params import P_WMAX

# The filter's scalar state (NaN: None).
S_T, S_T_FIRST, S_FZ_REF, S_FZ_SEEN, S_EMA, S_DT_LAST, S_RELEASED, S_NIS_SEEN = range(8)
S_LAST_ATT, S_LAST_ROT, S_LAST_IMU, S_RATE_M, S_RATE_N, S_RATE_T, S_HAVE_R, S_HAVE_W = range(8, 16)
N_S = 16
# Its settings: time constants (s), the largest gap and prediction step (s), the scale's release
# (hold s, wind variance m^2/s^2, initial variance, walk density), the IMU's stated rate (Hz), the
# rotors' top speed (rad/s).
C_TAU_TR, C_TAU_FZ, C_TAU_BASE, C_MAX_GAP, C_MAX_STEP, C_TAU_VW = range(6)
C_HOLD, C_REL_VAR, C_VAR0, C_WALK_VAR, C_RATE_HZ, C_WMAX = range(6, 12)
N_C = 12
# Counts: accepted inputs, numerical failures, rejections by reason.
COUNTS = (("accepted", "attitude"), ("accepted", "rotors"), ("accepted", "imu"), ("rejected", "numerical"),
          ("rejected", "attitude:bad_time"), ("rejected", "attitude:duplicate_or_out_of_order"),
          ("rejected", "attitude:bad_value"), ("rejected", "rotors:bad_time"),
          ("rejected", "rotors:duplicate_or_out_of_order"), ("rejected", "rotors:bad_value"),
          ("rejected", "imu:bad_time"), ("rejected", "imu:duplicate_or_out_of_order"), ("rejected", "imu:bad_value"),
          ("rejected", "imu:older_than_filter"), ("rejected", "imu:not_ready"))  # fmt: skip
K_ACC_ATT, K_ACC_ROT, K_ACC_IMU, K_NUMERICAL, K_ATT_TIME, K_ATT_ORDER, K_ATT_VALUE = range(7)
K_ROT_TIME, K_ROT_ORDER, K_ROT_VALUE, K_IMU_TIME, K_IMU_ORDER, K_IMU_VALUE, K_IMU_OLDER, K_IMU_NOT_READY = range(7, 15)


@njit(cache=True, inline="always")
def _count(cnt: np.ndarray, k: int, n: int = 1) -> None:
    """Add ``n`` to count ``k`` (row 0) and note the order of its first event (row 1, -1: none yet)."""
    if cnt[1, k] < 0:
        cnt[1, k] = cnt[1].max() + 1
    cnt[0, k] += n


@njit(cache=True)
def _rotors(t: float, w: np.ndarray, shape_ok: bool, s: np.ndarray, c: np.ndarray, cnt: np.ndarray,
            w_rot: np.ndarray) -> None:  # fmt: skip
    """:meth:`WindEstimator.set_rotor_speeds` (``InputGate.rotors``) into ``w_rot``."""
    if not math.isfinite(t):
        _count(cnt, K_ROT_TIME)
    elif t <= s[S_LAST_ROT]:  # False while NaN (no sample yet)
        _count(cnt, K_ROT_ORDER)
    elif not shape_ok or not within(w, 0.0, 2.0 * c[C_WMAX]):
        _count(cnt, K_ROT_VALUE)
    else:
        s[S_LAST_ROT] = t
        w_rot[:] = w
        s[S_HAVE_W] = 1.0
        _count(cnt, K_ACC_ROT)


@njit(cache=True)
def _attitude(t: float, q: np.ndarray, s: np.ndarray, cnt: np.ndarray, q_att: np.ndarray, R: np.ndarray) -> None:
    """:meth:`WindEstimator.set_attitude` (``InputGate.attitude``) into ``q_att`` and ``R``."""
    if not math.isfinite(t):
        _count(cnt, K_ATT_TIME)
        return
    if t <= s[S_LAST_ATT]:
        _count(cnt, K_ATT_ORDER)
        return
    nq = norm(q)
    if not abs(nq - 1.0) <= QUAT_NORM_TOL:  # also NaN / inf
        _count(cnt, K_ATT_VALUE)
        return
    s[S_LAST_ATT] = t
    for i in range(4):
        q_att[i] = q[i] / nq
    quat_to_dcm_into(q_att, R)
    s[S_HAVE_R] = 1.0
    _count(cnt, K_ACC_ATT)


@njit(cache=True)
def _imu_ok(t: float, a: np.ndarray, g: np.ndarray, s: np.ndarray, cnt: np.ndarray) -> bool:
    """``InputGate.imu``: True when the sample may be taken (its time marked), else the reason counted."""
    k = -1
    if not math.isfinite(t):
        k = K_IMU_TIME
    elif t <= s[S_LAST_IMU]:
        k = K_IMU_ORDER
    elif not within(a, -ACCEL_LIMIT_M_S2, ACCEL_LIMIT_M_S2) or not within(g, -GYRO_LIMIT_RAD_S, GYRO_LIMIT_RAD_S):
        k = K_IMU_VALUE
    elif t <= s[S_T]:  # False while NaN (the filter not started)
        k = K_IMU_OLDER
    elif s[S_HAVE_R] == 0.0 or s[S_HAVE_W] == 0.0:
        k = K_IMU_NOT_READY
    if k >= 0:
        _count(cnt, k)
        return False
    s[S_LAST_IMU] = t
    return True


@njit(cache=True)
def _plan(t: float, s: np.ndarray, c: np.ndarray, det: np.ndarray, P: np.ndarray, q_density: np.ndarray,
          i_scale: int) -> tuple[int, float, float]:  # fmt: skip
    """``WindEstimator._plan`` (with ``_maybe_release_scale``); the inputs are held (the IMU was accepted)."""
    if math.isnan(s[S_T]):
        s[S_T] = s[S_T_FIRST] = t
        return 0, 0.0, 1.0
    if s[S_RELEASED] == 0.0 and not math.isnan(s[S_T_FIRST]):
        held = t - s[S_T_FIRST]
        if held >= c[C_HOLD] and not (max(P[3, 3], P[4, 4]) > c[C_REL_VAR] and held < 3.0 * c[C_HOLD]):
            P[i_scale, :] = 0.0
            P[:, i_scale] = 0.0
            P[i_scale, i_scale] = c[C_VAR0]
            q_density[i_scale] = c[C_WALK_VAR]
            s[S_RELEASED] = 1.0
    span = t - s[S_T]
    if span > 0.0:
        det[D_LEFT] -= span
        s[S_DT_LAST] = span
        s[S_EMA] = min(1.0, span / c[C_TAU_TR])
    span = min(t - s[S_T], c[C_MAX_GAP])
    s[S_T] = max(s[S_T], t)
    if not span > 0.0:
        return 0, 0.0, 1.0
    n = max(1, math.ceil(span / c[C_MAX_STEP] - 1e-9))
    dt = span / n
    tau = c[C_TAU_VW]
    return n, dt, math.exp(-dt / tau) if tau != 0.0 else 1.0


@njit(cache=True)
def _rate_factor(t: float, s: np.ndarray, c: np.ndarray) -> float:
    """:meth:`estimator.imu_rate.ImuRate.factor` on the state ``s[S_RATE_*]``."""
    last = s[S_RATE_T]
    s[S_RATE_T] = t
    if not math.isnan(last) and t > last:
        dt = t - last
        m = s[S_RATE_M]
        if math.isnan(m):
            if dt < MAX_FIRST_S:
                s[S_RATE_M], s[S_RATE_N] = dt, 1.0
        elif 0.5 * m <= dt <= 2.0 * m:
            s[S_RATE_N] += 1.0
            s[S_RATE_M] = m + max(WEIGHT, 1.0 / s[S_RATE_N]) * (dt - m)
    m = s[S_RATE_M]
    if math.isnan(m) or s[S_RATE_N] < MIN_INTERVALS:
        return 1.0
    f = 1.0 / (m * c[C_RATE_HZ])
    return 1.0 if abs(f - 1.0) < SNAP else max(FLOOR, f)


@njit(cache=True)
def imu_steps(
    ts: np.ndarray, qs: np.ndarray, acc: np.ndarray, gyr: np.ndarray, esc_t: np.ndarray, esc_w: np.ndarray, ei: int,
    esc_ok: bool, s: np.ndarray, c: np.ndarray, cnt: np.ndarray, q_att: np.ndarray, R: np.ndarray, w_rot: np.ndarray,
    rates: np.ndarray, hist_t: np.ndarray, hist_R: np.ndarray, hist_x: np.ndarray, x: np.ndarray, P: np.ndarray,
    R_accel: np.ndarray, p: np.ndarray, q_density: np.ndarray, i_scale: int, bias_idx: np.ndarray, Wm: np.ndarray,
    Wc: np.ndarray, cc: float, det: np.ndarray, det_cfg: np.ndarray, sig: np.ndarray, sig_f: np.ndarray,
    L: np.ndarray, x_new: np.ndarray, P_new: np.ndarray, S: np.ndarray, Pxz: np.ndarray, y: np.ndarray, K: np.ndarray,
    Lz: np.ndarray, nis_y: np.ndarray, nis_S: np.ndarray,
) -> tuple[int, int]:  # fmt: skip
    """The steps at times ``ts`` (m,) s: the rotor speed samples ``esc_w`` (E, N) rad/s at ``esc_t`` (E,)
    from index ``ei`` up to each step's time (``esc_ok``: their shape fits the model), the attitude
    ``qs`` (m, 4), the IMU means ``acc``, ``gyr`` (m, 3). Each accepted step's time, attitude matrix and
    body velocity go to ``hist_*``. ``sig`` ... ``nis_S``: accel_step's scratch and last innovation, passed
    as arrays (a tuple argument costs more to pass in than the arrays). Returns (the next rotor sample's
    index, history rows written)."""
    w, m3, nis = (sig, sig_f, L, x_new, P_new), (S, Pxz, y, K, Lz), (nis_y, nis_S)
    n_hist = 0
    for j in range(ts.shape[0]):
        t = ts[j]
        while ei < esc_t.shape[0] and esc_t[ei] <= t + 1e-9:
            _rotors(esc_t[ei], esc_w[ei], esc_ok, s, c, cnt, w_rot)
            ei += 1
        _attitude(t, qs[j], s, cnt, q_att, R)
        a, g = acc[j], gyr[j]
        if not _imu_ok(t, a, g, s, cnt):
            continue
        rates[:] = g
        n_steps, dt, decay = _plan(t, s, c, det, P, q_density, i_scale)
        fz_pred = s[S_FZ_REF]
        if s[S_FZ_SEEN] != 0.0:
            s[S_FZ_REF] += min(1.0, s[S_EMA] * c[C_TAU_TR] / c[C_TAU_FZ]) * (a[2] - s[S_FZ_REF])
        else:
            s[S_FZ_REF], s[S_FZ_SEEN] = a[2], 1.0
        f = _rate_factor(t, s, c)
        failed, status = accel_step(
            x, P, a, R_accel if f == 1.0 else R_accel * f, R, rates, w_rot, p, n_steps, dt, decay, fz_pred,
            s[S_FZ_REF], q_density, i_scale, bias_idx, s[S_RELEASED] != 0.0, Wm, Wc, cc, det, det_cfg, s[S_EMA],
            min(1.0, s[S_DT_LAST] / c[C_TAU_BASE]), s[S_DT_LAST], w, m3, nis,
        )  # fmt: skip
        if status != 1:
            s[S_NIS_SEEN] = 1.0
        if failed or status:
            _count(cnt, K_NUMERICAL, failed + (status != 0))
        _count(cnt, K_ACC_IMU)
        hist_t[n_hist] = s[S_T]
        hist_R[n_hist] = R
        hist_x[n_hist] = x[0:3]
        n_hist += 1
    return ei, n_hist


def _nan(v: float | None) -> float:
    return math.nan if v is None else float(v)


def _none(v: float) -> float | None:
    return None if math.isnan(v) else float(v)


def feed(est: Any, ts: np.ndarray, qs: np.ndarray, acc: np.ndarray, gyr: np.ndarray, esc_t: np.ndarray,
         esc_w: np.ndarray, ei: int) -> int:  # fmt: skip
    """:func:`imu_steps` on the filter ``est`` (a :class:`estimator.ukf.WindEstimator`): its state packed,
    stepped, written back. Returns the index of the first rotor speed sample not taken."""
    cfg, gate, rate = est.config, est._gate, est.imu_rate
    last = gate._last_in
    c = _settings(est)
    s = np.array([_nan(est.t), _nan(est._t_first), est._fz_ref, est._fz_seen, est._ema_alpha, est._dt_last,
                  est.scale_released, est._nis_seen, _nan(last.get("attitude")), _nan(last.get("rotors")),
                  _nan(last.get("imu")), _nan(rate.interval_s), rate._n, _nan(rate._t_last), est._R is not None,
                  est._w_rot is not None], dtype=float)  # fmt: skip
    cnt = np.zeros((2, len(COUNTS)), dtype=np.int64)
    cnt[1] = -1
    n = est.n_rotors
    q_att = np.zeros(4) if est._q_att is None else est._q_att.copy()
    R = np.zeros((3, 3)) if est._R is None else est._R.copy()
    w_rot = np.zeros(n) if est._w_rot is None else est._w_rot.copy()
    rates = est._rates.copy()
    m = ts.shape[0]
    hist_t, hist_R, hist_x = np.empty(m), np.empty((m, 3, 3)), np.empty((m, 3))
    ei, n_hist = imu_steps(ts, qs, acc, gyr, esc_t, esc_w, ei, esc_w.shape[1] == n, s, c, cnt, q_att, R, w_rot, rates,
                           hist_t, hist_R, hist_x, est.x, est.P, est._R_accel, est._p, est._q_density, est._i_scale,
                           est._bias_idx, est._Wm, est._Wc, est._c, est._det, est._det_cfg, *est._w, *est._m3,
                           *est._nis)  # fmt: skip
    est.t, est._t_first, est._fz_seen = _none(s[S_T]), _none(s[S_T_FIRST]), bool(s[S_FZ_SEEN])
    # (a numpy scalar once the low-pass has run, as the Python update left it: it adds numpy's a[2])
    est._fz_ref = np.float64(s[S_FZ_REF]) if est._fz_seen else float(s[S_FZ_REF])
    est._ema_alpha, est._dt_last = float(s[S_EMA]), float(s[S_DT_LAST])
    est.scale_released, est._nis_seen = bool(s[S_RELEASED]), bool(s[S_NIS_SEEN])
    for name, k in (("rotors", S_LAST_ROT), ("attitude", S_LAST_ATT), ("imu", S_LAST_IMU)):
        if not math.isnan(s[k]):
            last[name] = float(s[k])
    rate.interval_s, rate._n, rate._t_last = _none(s[S_RATE_M]), int(s[S_RATE_N]), _none(s[S_RATE_T])
    if s[S_HAVE_R]:
        est._q_att, est._R = q_att, R
    if s[S_HAVE_W]:
        est._w_rot = w_rot
    est._rates = rates
    for k in np.argsort(cnt[1], kind="stable"):  # the counts in the order their first events came
        if cnt[0, k]:
            owner, key = COUNTS[k]
            getattr(est, owner)[key] += int(cnt[0, k])
    hist = est._hist
    if n_hist:
        hist.extend(zip(hist_t[:n_hist].tolist(), hist_R[:n_hist], hist_x[:n_hist], strict=True))
        horizon = est.t - cfg.gnss_history_s
        while hist and hist[0][0] < horizon:
            hist.popleft()
    return ei


def _settings(est: Any) -> np.ndarray:
    """The filter's settings as :func:`imu_steps` reads them (``C_*``), made once per filter (its config is frozen)."""
    c = getattr(est, "_batch_settings", None)
    if c is None:
        cfg = est.config
        c = np.array([cfg.transient_tau_s, cfg.fz_ref_tau_s, cfg.transient_baseline_tau_s, cfg.max_gap_s,
                      cfg.max_step_s, cfg.vertical_wind_tau_s or 0.0, cfg.scale_hold_s,
                      cfg.scale_release_wind_sigma_m_s**2, cfg.scale_sigma0**2, cfg.scale_walk_per_sqrt_s**2,
                      est.imu_rate.stated_rate_hz, float(est._p[P_WMAX])], dtype=float)  # fmt: skip
        est._batch_settings = c
    return c
