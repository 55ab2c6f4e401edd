"""The sensors' compiled sampling: one call per control period for the IMU and ESC samples of the truth rows the
physics wrote, one call per slow tick for GNSS, barometer and magnetometer; the samples written as rows of arrays
(:class:`SampleLog`), made into Python objects only when drained (:meth:`sitl.world.sensors.SensorSuite.drain`).

The random draws come from each sensor's own numpy ``Generator``, drawn ahead in blocks (:class:`NormalStreams`): a
``Generator`` fills an array in order and keeps no state between normals, so the values are those of drawing them one
call at a time, in the same order. The arithmetic is the sensor model's (:mod:`sitl.world.sensors`) in numpy's
order, so every sample is bit for bit what the per-sample Python model produced.

Units and frames: as :mod:`sitl.world.sensors` (m/s^2 and rad/s FRD, rad/s rotor speeds, NED m and m/s, Pa,
deg C, gauss FRD); times s.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from vehicle.frames import quat_to_dcm

EARTH_RADIUS_M = 6_378_137.0

# The packed configuration (:func:`sitl.world.sensors.pack_config`), read by the kernels.
C_ACC_N, C_GYR_N, C_ACC_W, C_GYR_W, C_ESC_N = 0, 1, 2, 3, 4  # IMU white noise, bias walk per sample; ESC noise
C_GNSS_H, C_GNSS_V, C_GNSS_VEL, C_GNSS_LAT, C_GNSS_SATS = 5, 6, 7, 8, 9  # GNSS noise, latency s, satellites
C_BARO_N, C_TEMP_N, C_TEMP_SEA = 10, 11, 12  # Pa, deg C, deg C
C_HOME_LAT, C_HOME_LON, C_HOME_ALT = 13, 14, 15  # deg, deg, m AMSL
C_MAG_N, C_MAG_FIELD = 16, 17  # gauss, field NED (3)
N_CFG = 20

#: The normal streams (rows of :class:`NormalStreams`) and the sample logs (index into the counts), in one order.
S_IMU, S_ESC, S_GNSS, S_BARO, S_MAG = 0, 1, 2, 3, 4
N_STREAMS = 5
#: Columns of the logs: IMU t, accel (3), gyro (3); ESC t, speeds (N); GNSS t, pos (3), vel (3), lat, lon, alt,
#: satellites; baro t, pressure, pressure altitude, temperature; magnetometer t, field (3).
IMU_COLS, GNSS_COLS, BARO_COLS, MAG_COLS = 7, 11, 4, 4
#: Index in the counts array of the GNSS fixes delivered (their latency elapsed; the rest are pending).
K_GNSS_DELIVERED = N_STREAMS
#: Due flags of :func:`slow_sensors`.
DUE_GNSS, DUE_BARO, DUE_MAG = 1, 2, 4


@njit(cache=True)
def _low(nat: np.ndarray, nz_len: int, need: np.ndarray, cnt: np.ndarray, logs_cap: np.ndarray) -> int:
    """Bit s: stream s has fewer than ``need[s]`` normals left; bit 8 + s: log s has fewer than ``need[5 + s]``
    free rows."""
    low = 0
    for s in range(N_STREAMS):
        if nat[s] + need[s] > nz_len:
            low |= 1 << s
        if cnt[s] + need[N_STREAMS + s] > logs_cap[s]:
            low |= 1 << (8 + s)
    return low


@njit(cache=True)
def imu_period(
    rows: np.ndarray, nrow: int, n_rot: int, esc_first: int, esc_every: int, cfg: np.ndarray, acc_bias: np.ndarray,
    gyr_bias: np.ndarray, nz: np.ndarray, nat: np.ndarray, imu_log: np.ndarray, esc_log: np.ndarray, cnt: np.ndarray,
    need: np.ndarray, logs_cap: np.ndarray,
) -> int:  # fmt: skip
    """The IMU samples of truth rows ``rows[:nrow]`` (one batch) and the ESC samples of rows ``esc_first``,
    ``esc_first + esc_every`` ..., appended to ``imu_log`` and ``esc_log`` (counts in ``cnt``). The biases walk by
    the walk step x a normal per sample, accumulated over the batch from its starting bias (numpy's running sum),
    then truth + bias + noise; ESC: truth + noise, never negative (``np.maximum(., 0)``). Returns the
    :func:`_low` bits after the call."""
    ca, cg = np.zeros(3), np.zeros(3)
    a0, g0 = acc_bias.copy(), gyr_bias.copy()
    an, gn, aw, gw = cfg[C_ACC_N], cfg[C_GYR_N], cfg[C_ACC_W], cfg[C_GYR_W]
    n = nz[S_IMU]
    k = nat[S_IMU]
    m = cnt[S_IMU]
    for i in range(nrow):
        out = imu_log[m + i]
        out[0] = rows[i, 0]
        for j in range(3):
            ca[j] += n[k + 6 + j] * aw
            cg[j] += n[k + 9 + j] * gw
            ab, gb = a0[j] + ca[j], g0[j] + cg[j]
            out[1 + j] = rows[i, 1 + j] + ab + an * n[k + j]
            out[4 + j] = rows[i, 4 + j] + gb + gn * n[k + 3 + j]
            acc_bias[j], gyr_bias[j] = ab, gb
        k += 12
    nat[S_IMU] = k
    cnt[S_IMU] = m + nrow
    e = nz[S_ESC]
    k = nat[S_ESC]
    m = cnt[S_ESC]
    noise = cfg[C_ESC_N]
    for i in range(esc_first, nrow, esc_every):
        out = esc_log[m]
        out[0] = rows[i, 0]
        for j in range(n_rot):
            v = rows[i, 7 + j] + noise * e[k]
            out[1 + j] = v if (v >= 0.0 or v != v) else 0.0  # np.maximum(v, 0.0): NaN and -0.0 kept
            k += 1
        m += 1
    nat[S_ESC] = k
    cnt[S_ESC] = m
    return _low(nat, nz.shape[1], need, cnt, logs_cap)


@njit(cache=True)
def slow_sensors(
    t: float, x: np.ndarray, due: int, cfg: np.ndarray, nz: np.ndarray, nat: np.ndarray, gnss_log: np.ndarray,
    baro_log: np.ndarray, mag_log: np.ndarray, cnt: np.ndarray, need: np.ndarray, logs_cap: np.ndarray,
) -> int:  # fmt: skip
    """The slow sensors at time ``t`` [s] on state ``x`` (NED position, velocity, attitude): a GNSS fix taken when
    ``due & DUE_GNSS`` (delivered once its latency has elapsed: ``cnt[K_GNSS_DELIVERED]``), a barometer and a
    magnetometer sample when due; then the fixes whose latency has elapsed are delivered. Returns the :func:`_low`
    bits after the call."""
    if due & DUE_GNSS:
        n, k, m = nz[S_GNSS], nat[S_GNSS], cnt[S_GNSS]
        out = gnss_log[m]
        out[0] = t
        out[1] = x[0] + n[k] * cfg[C_GNSS_H]
        out[2] = x[1] + n[k + 1] * cfg[C_GNSS_H]
        out[3] = x[2] + n[k + 2] * cfg[C_GNSS_V]
        for j in range(3):
            out[4 + j] = x[3 + j] + n[k + 3 + j] * cfg[C_GNSS_VEL]
        lat0 = cfg[C_HOME_LAT]
        out[7] = lat0 + math.degrees(out[1] / EARTH_RADIUS_M)
        out[8] = cfg[C_HOME_LON] + math.degrees(out[2] / (EARTH_RADIUS_M * math.cos(math.radians(lat0))))
        out[9] = cfg[C_HOME_ALT] - out[3]
        out[10] = cfg[C_GNSS_SATS]
        nat[S_GNSS] = k + 6
        cnt[S_GNSS] = m + 1
    if due & DUE_BARO:
        n, k, m = nz[S_BARO], nat[S_BARO], cnt[S_BARO]
        alt = cfg[C_HOME_ALT] - x[2]
        pres = 101325.0 * (1.0 - 2.25577e-5 * alt) ** 5.25588 + cfg[C_BARO_N] * n[k]
        temp = cfg[C_TEMP_SEA] - 0.0065 * alt
        temp += cfg[C_TEMP_N] * n[k + 1]
        out = baro_log[m]
        out[0], out[1], out[3] = t, pres, temp
        out[2] = (1.0 - (pres / 101325.0) ** (1.0 / 5.25588)) / 2.25577e-5
        nat[S_BARO] = k + 2
        cnt[S_BARO] = m + 1
    if due & DUE_MAG:
        n, k, m = nz[S_MAG], nat[S_MAG], cnt[S_MAG]
        f = quat_to_dcm(x[6:10]).T @ cfg[C_MAG_FIELD:C_MAG_FIELD + 3]  # numpy's product (BLAS), as the model
        out = mag_log[m]
        out[0] = t
        for j in range(3):
            out[1 + j] = f[j] + cfg[C_MAG_N] * n[k + j]
        nat[S_MAG] = k + 3
        cnt[S_MAG] = m + 1
    d = cnt[K_GNSS_DELIVERED]
    while d < cnt[S_GNSS] and gnss_log[d, 0] + cfg[C_GNSS_LAT] <= t + 1e-9:
        d += 1
    cnt[K_GNSS_DELIVERED] = d
    return _low(nat, nz.shape[1], need, cnt, logs_cap)
