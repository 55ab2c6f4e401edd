"""MEMS-grade sensor models: IMU, ESC rotor-speed telemetry, GNSS, barometer, magnetometer,
air temperature. Seeded, vectorized over batches of truth samples; the IMU (250 Hz, called once
per control period or, over HIL, per 4 ms step) is one compiled call on noise drawn in blocks.

Units and frames: accelerometer specific force in m/s^2 and gyro rates in rad/s, both FRD
body; rotor speeds rad/s; GNSS position NED m (plus WGS-84 lat/lon/alt about the home point)
and velocity NED m/s; pressure Pa; magnetic field gauss in FRD; temperature deg C.

Default noise levels are representative of a current autopilot (ICM-42688/BMI088 class IMU,
u-blox M9 class GNSS, MS5611/BMP388 barometer); every value is a config field.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field

import numpy as np
from numba import njit

EARTH_RADIUS_M = 6_378_137.0
#: IMU noise rows drawn at once (12 normals per sample): the same stream as drawing them sample by
#: sample, without numpy's per-call cost on every control period.
IMU_NOISE_BLOCK = 250


@dataclass(frozen=True)
class ImuConfig:
    """IMU: white noise per sample plus a bias random walk, at ``rate_hz``."""

    rate_hz: float = 250.0
    accel_noise_m_s2: float = 0.05  # 1-sigma white noise per sample
    gyro_noise_rad_s: float = 0.003
    accel_bias_init_m_s2: float = 0.02  # 1-sigma of the turn-on bias
    gyro_bias_init_rad_s: float = 0.002
    accel_bias_walk_m_s2_sqrt_s: float = 5e-4  # bias random walk, per sqrt(s)
    gyro_bias_walk_rad_s_sqrt_s: float = 2e-5


@dataclass(frozen=True)
class EscConfig:
    """ESC rotor-speed telemetry (like DShot bidirectional / ESC_STATUS)."""

    rate_hz: float = 50.0
    noise_rad_s: float = 2.0


@dataclass(frozen=True)
class GnssConfig:
    """GNSS receiver: position and velocity with white noise and a fixed latency."""

    rate_hz: float = 10.0
    pos_noise_h_m: float = 0.3
    pos_noise_v_m: float = 0.5
    vel_noise_m_s: float = 0.05
    latency_s: float = 0.1
    satellites: int = 14


@dataclass(frozen=True)
class BaroConfig:
    rate_hz: float = 50.0
    noise_pa: float = 1.2


@dataclass(frozen=True)
class MagConfig:
    rate_hz: float = 50.0
    noise_gauss: float = 0.004
    #: Earth field in NED, gauss: a scenario without one gets the World Magnetic Model's at its home
    #: (:mod:`vehicle.geomag`, as the autopilots assume it); this default is that at the default home.
    field_ned_gauss: tuple[float, float, float] = (0.215199, 0.012868, 0.432424)


@dataclass(frozen=True)
class TemperatureConfig:
    noise_c: float = 0.1
    sea_level_c: float = 15.0


@dataclass(frozen=True)
class HomeConfig:
    """Geodetic origin of the NED frame (PX4 SITL's default home by default)."""

    lat_deg: float = 47.397742
    lon_deg: float = 8.545594
    alt_m: float = 488.0


@dataclass(frozen=True)
class SensorSuiteConfig:
    imu: ImuConfig = field(default_factory=ImuConfig)
    esc: EscConfig = field(default_factory=EscConfig)
    gnss: GnssConfig = field(default_factory=GnssConfig)
    baro: BaroConfig = field(default_factory=BaroConfig)
    mag: MagConfig = field(default_factory=MagConfig)
    temperature: TemperatureConfig = field(default_factory=TemperatureConfig)
    home: HomeConfig = field(default_factory=HomeConfig)

    def validate(self, physics_rate_hz: float) -> None:
        """Raise ValueError naming the field and the allowed values."""
        for group in ("imu", "esc", "gnss", "baro", "mag", "temperature"):
            for name, value in asdict(getattr(self, group)).items():
                if isinstance(value, (int, float)) and not (math.isfinite(value) and value >= 0):
                    raise ValueError(f"sensors.{group}.{name} = {value!r}: must be finite and >= 0")
        if not (-90 <= self.home.lat_deg <= 90 and -180 <= self.home.lon_deg <= 180):
            raise ValueError("sensors.home: lat_deg in [-90, 90], lon_deg in [-180, 180]")
        for group in ("imu", "esc", "gnss", "baro", "mag"):
            rate = getattr(self, group).rate_hz
            ratio = physics_rate_hz / rate if rate > 0 else 0.0
            if rate <= 0 or abs(ratio - round(ratio)) > 1e-9 or ratio < 1:
                raise ValueError(
                    f"sensors.{group}.rate_hz = {rate}: must divide the physics rate "
                    f"({physics_rate_hz} Hz) into a whole number of ticks"
                )


def ned_to_geodetic(pos_ned: np.ndarray, home: HomeConfig) -> tuple[float, float, float]:
    """Flat-earth NED (m) to latitude, longitude (deg) and altitude AMSL (m)."""
    lat = home.lat_deg + math.degrees(pos_ned[0] / EARTH_RADIUS_M)
    lon = home.lon_deg + math.degrees(
        pos_ned[1] / (EARTH_RADIUS_M * math.cos(math.radians(home.lat_deg)))
    )
    return lat, lon, home.alt_m - float(pos_ned[2])


def geodetic_to_ned(lat: float, lon: float, alt: float, home: HomeConfig) -> np.ndarray:
    """Inverse of :func:`ned_to_geodetic`."""
    n = math.radians(lat - home.lat_deg) * EARTH_RADIUS_M
    e = math.radians(lon - home.lon_deg) * EARTH_RADIUS_M * math.cos(math.radians(home.lat_deg))
    return np.array([n, e, home.alt_m - alt])


def isa_pressure_pa(alt_amsl_m: float | np.ndarray) -> float | np.ndarray:
    """International Standard Atmosphere static pressure (troposphere), Pa."""
    return 101325.0 * (1.0 - 2.25577e-5 * np.asarray(alt_amsl_m)) ** 5.25588


def isa_altitude_m(pressure_pa: float) -> float:
    """Pressure altitude (m) from static pressure (Pa), inverse of :func:`isa_pressure_pa`."""
    return (1.0 - (pressure_pa / 101325.0) ** (1.0 / 5.25588)) / 2.25577e-5


@dataclass
class GnssSample:
    t: float  # time of validity, s (the sample is delivered latency_s later)
    pos_ned: np.ndarray
    vel_ned: np.ndarray
    lat_deg: float
    lon_deg: float
    alt_m: float
    satellites: int


@dataclass
class BaroSample:
    t: float
    pressure_pa: float
    altitude_m: float  # pressure altitude AMSL, m
    temperature_c: float


@dataclass
class MagSample:
    t: float
    field_gauss: np.ndarray  # FRD


class SensorSuite:
    """All sensors of the vehicle with their own random streams (spawned from one seed)."""

    def __init__(self, config: SensorSuiteConfig, seed: np.random.SeedSequence) -> None:
        self.config = config
        s_imu, s_esc, s_gnss, s_baro, s_mag = seed.spawn(5)
        self._rng_imu = np.random.default_rng(s_imu)
        self._rng_esc = np.random.default_rng(s_esc)
        self._rng_gnss = np.random.default_rng(s_gnss)
        self._rng_baro = np.random.default_rng(s_baro)
        self._rng_mag = np.random.default_rng(s_mag)
        c = config.imu
        self.accel_bias = self._rng_imu.normal(0.0, c.accel_bias_init_m_s2, 3)
        self.gyro_bias = self._rng_imu.normal(0.0, c.gyro_bias_init_rad_s, 3)
        self._gnss_queue: list[GnssSample] = []
        self._imu_buf, self._imu_next = np.empty((0, 12)), 0

    def imu(self, truth_f: np.ndarray, truth_w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Measure a batch of K IMU samples from true specific force and rates (K,3 each)."""
        c = self.config.imu
        k = truth_f.shape[0]
        sq = math.sqrt(1.0 / c.rate_hz)
        acc, gyr = np.empty((k, 3)), np.empty((k, 3))
        _imu_kernel(truth_f, truth_w, self._imu_normals(k), self.accel_bias, self.gyro_bias,
                    c.accel_noise_m_s2, c.gyro_noise_rad_s, c.accel_bias_walk_m_s2_sqrt_s * sq,
                    c.gyro_bias_walk_rad_s_sqrt_s * sq, acc, gyr)  # fmt: skip
        return acc, gyr

    def _imu_normals(self, k: int) -> np.ndarray:
        """The next ``k`` rows of 12 standard normals of the IMU's stream (white accel, white gyro,
        accel bias walk, gyro bias walk), drawn ``IMU_NOISE_BLOCK`` rows at a time: numpy's
        Generator fills an array in order, so the values are those of drawing row by row."""
        buf, i = self._imu_buf, self._imu_next
        if i + k <= buf.shape[0]:
            self._imu_next = i + k
            return buf[i : i + k]
        rest = buf[i:]
        self._imu_buf = self._rng_imu.standard_normal((max(IMU_NOISE_BLOCK, k - rest.shape[0]), 12))
        self._imu_next = k - rest.shape[0]
        return np.concatenate((rest, self._imu_buf[: self._imu_next]))

    def esc(self, truth_rotor: np.ndarray) -> np.ndarray:
        """Measured rotor speeds (K,4) rad/s, never negative."""
        n = self._rng_esc.standard_normal(truth_rotor.shape)
        return np.maximum(truth_rotor + self.config.esc.noise_rad_s * n, 0.0)

    def gnss_measure(self, t: float, pos: np.ndarray, vel: np.ndarray) -> None:
        """Take a fix of the true state at time t; it is delivered after the latency."""
        c = self.config.gnss
        n = self._rng_gnss.standard_normal(6)
        p = pos + n[:3] * np.array([c.pos_noise_h_m, c.pos_noise_h_m, c.pos_noise_v_m])
        v = vel + n[3:] * c.vel_noise_m_s
        lat, lon, alt = ned_to_geodetic(p, self.config.home)
        self._gnss_queue.append(GnssSample(t, p, v, lat, lon, alt, c.satellites))

    def gnss_deliver(self, now: float) -> list[GnssSample]:
        """Fixes whose latency has elapsed at time ``now``."""
        lat = self.config.gnss.latency_s
        out = [s for s in self._gnss_queue if s.t + lat <= now + 1e-9]
        if out:
            self._gnss_queue = self._gnss_queue[len(out):]
        return out

    def baro(self, t: float, pos: np.ndarray) -> BaroSample:
        c = self.config
        alt = c.home.alt_m - float(pos[2])
        pres = float(isa_pressure_pa(alt)) + c.baro.noise_pa * self._rng_baro.standard_normal()
        temp = c.temperature.sea_level_c - 0.0065 * alt
        temp += c.temperature.noise_c * self._rng_baro.standard_normal()
        return BaroSample(t, pres, isa_altitude_m(pres), temp)

    def mag(self, t: float, dcm_body_to_ned: np.ndarray) -> MagSample:
        c = self.config.mag
        f = dcm_body_to_ned.T @ np.asarray(c.field_ned_gauss)
        return MagSample(t, f + c.noise_gauss * self._rng_mag.standard_normal(3))


@njit(cache=True)
def _imu_kernel(truth_f: np.ndarray, truth_w: np.ndarray, n: np.ndarray, accel_bias: np.ndarray,
                gyro_bias: np.ndarray, accel_noise: float, gyro_noise: float, accel_walk: float,
                gyro_walk: float, acc: np.ndarray, gyr: np.ndarray) -> None:  # fmt: skip
    """K IMU samples (rows of ``acc``, ``gyr``): the truth plus the bias, which walks by ``*_walk`` x
    a normal per sample (the biases are updated in place), plus white noise; ``n`` (K,12) holds the
    normals. The sums are formed in numpy's order (a running sum of the walk steps added to the bias,
    then truth + bias + noise), so the samples are bit for bit those of the vectorized model."""
    ca, cg = np.zeros(3), np.zeros(3)
    a0, g0 = accel_bias.copy(), gyro_bias.copy()
    for i in range(n.shape[0]):
        for j in range(3):
            ca[j] += n[i, 6 + j] * accel_walk
            cg[j] += n[i, 9 + j] * gyro_walk
            ab, gb = a0[j] + ca[j], g0[j] + cg[j]
            acc[i, j] = truth_f[i, j] + ab + accel_noise * n[i, j]
            gyr[i, j] = truth_w[i, j] + gb + gyro_noise * n[i, 3 + j]
            accel_bias[j], gyro_bias[j] = ab, gb
