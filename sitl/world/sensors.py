"""MEMS-grade sensor models: IMU, ESC rotor-speed telemetry, GNSS, barometer, magnetometer,
air temperature. Seeded; sampled in compiled code (:mod:`sitl.world.sensor_kernel`): the IMU and ESC
samples of a control period (or, over HIL, a 4 ms step) in one call, GNSS, barometer and
magnetometer in one call per slow tick, on noise drawn ahead in blocks; the samples are kept as
rows of arrays and made into the objects below when drained.

Units and frames: accelerometer specific force in m/s^2 and gyro rates in rad/s, both FRD
body; rotor speeds rad/s; GNSS position NED m (plus WGS-84 lat/lon/alt about the home point)
and velocity NED m/s; pressure Pa; magnetic field gauss in FRD; temperature deg C.

Default noise levels are representative of a current autopilot (ICM-42688/BMI088 class IMU,
u-blox M9 class GNSS, MS5611/BMP388 barometer); every value is a config field.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from sitl.world import sensor_kernel as sk
from sitl.world.kernel import compiled_entry

EARTH_RADIUS_M = sk.EARTH_RADIUS_M
#: Normals drawn ahead per sensor stream (the IMU uses 12 a sample, 3,000 a second): the same stream as drawing
#: them sample by sample, without numpy's per-call cost at every control period.
NORMALS_AHEAD = 6000


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


def pack_config(c: SensorSuiteConfig) -> np.ndarray:
    """The sensor configuration as the compiled kernels read it (:mod:`sitl.world.sensor_kernel`, ``C_*``)."""
    sq = math.sqrt(1.0 / c.imu.rate_hz)
    cfg = np.zeros(sk.N_CFG)
    cfg[sk.C_ACC_N:sk.C_ESC_N + 1] = (c.imu.accel_noise_m_s2, c.imu.gyro_noise_rad_s, c.imu.accel_bias_walk_m_s2_sqrt_s
                                      * sq, c.imu.gyro_bias_walk_rad_s_sqrt_s * sq, c.esc.noise_rad_s)  # fmt: skip
    g = c.gnss
    cfg[sk.C_GNSS_H:sk.C_GNSS_SATS + 1] = (g.pos_noise_h_m, g.pos_noise_v_m, g.vel_noise_m_s, g.latency_s, g.satellites)
    cfg[sk.C_BARO_N:sk.C_TEMP_SEA + 1] = (c.baro.noise_pa, c.temperature.noise_c, c.temperature.sea_level_c)
    cfg[sk.C_HOME_LAT:sk.C_HOME_ALT + 1] = (c.home.lat_deg, c.home.lon_deg, c.home.alt_m)
    cfg[sk.C_MAG_N] = c.mag.noise_gauss
    cfg[sk.C_MAG_FIELD:sk.C_MAG_FIELD + 3] = c.mag.field_ned_gauss
    return cfg


class SensorSuite:
    """All sensors of the vehicle with their own random streams (spawned from one seed), sampled by the compiled
    kernels of :mod:`sitl.world.sensor_kernel` into logs of rows, kept until :meth:`drain`.

    Args:
        config: noise levels, rates, latency, home; ``config`` may be replaced in flight (the kernels read it packed).
        seed: the sensors' seed sequence (IMU, ESC, GNSS, baro, magnetometer streams, in that order).
        n_rotors: rotor speeds per ESC sample; batch_rows: the most IMU samples one :meth:`imu_batch` measures.
        maxlen: samples kept per sensor between two drains (the oldest are dropped).
    """

    def __init__(self, config: SensorSuiteConfig, seed: np.random.SeedSequence, n_rotors: int = 4,
                 batch_rows: int = 16, maxlen: int = 100_000) -> None:  # fmt: skip
        self.config = config
        rngs = [np.random.default_rng(s) for s in seed.spawn(5)]
        c = config.imu
        self.accel_bias = rngs[0].normal(0.0, c.accel_bias_init_m_s2, 3)
        self.gyro_bias = rngs[0].normal(0.0, c.gyro_bias_init_rad_s, 3)
        self.n_rotors, self.maxlen = n_rotors, maxlen
        self._rngs = rngs
        self._nz = np.empty((sk.N_STREAMS, NORMALS_AHEAD))  # each stream's next normals, drawn ahead
        self._nat = np.full(sk.N_STREAMS, NORMALS_AHEAD, dtype=np.int64)  # the next unread normal of each stream
        for s in range(sk.N_STREAMS):
            self._refill(s)
        # Normals and free log rows one call may use: IMU and ESC per batch, one GNSS fix, baro and mag sample.
        self._need = np.array([12 * batch_rows, n_rotors * batch_rows, 6, 2, 3, batch_rows, batch_rows, 1, 1, 1],
                              dtype=np.int64)  # fmt: skip
        widths = (sk.IMU_COLS, 1 + n_rotors, sk.GNSS_COLS, sk.BARO_COLS, sk.MAG_COLS)
        self._logs = [np.zeros((max(256, 4 * batch_rows), w)) for w in widths]
        self._cap = np.array([b.shape[0] for b in self._logs], dtype=np.int64)
        self._cnt = np.zeros(sk.N_STREAMS + 1, dtype=np.int64)  # rows per log, then the GNSS fixes delivered
        self._imu_fn: Callable[..., int] | None = None  # the compiled kernels (see sitl.world.kernel.compiled_entry)
        self._slow_fn: Callable[..., int] | None = None

    @property
    def config(self) -> SensorSuiteConfig:
        return self._config

    @config.setter
    def config(self, value: SensorSuiteConfig) -> None:
        self._config = value
        self._packed = pack_config(value)

    def _refill(self, s: int) -> None:
        """Stream ``s``'s unread normals moved to the front, the rest of its row drawn from its generator."""
        row, a = self._nz[s], int(self._nat[s])
        rest = row.shape[0] - a
        row[:rest] = row[a:].copy()
        self._rngs[s].standard_normal(out=row[rest:])
        self._nat[s] = 0

    def _make_room(self, low: int) -> None:
        """After a kernel said a stream or a log runs low (bits, see ``sensor_kernel._low``): refill, trim, grow."""
        for s in range(sk.N_STREAMS):
            if low & (1 << s):
                self._refill(s)
            if low & (1 << (8 + s)):
                log, n = self._logs[s], int(self._cnt[s])
                done = int(self._cnt[sk.K_GNSS_DELIVERED]) if s == sk.S_GNSS else n  # pending fixes are kept
                drop = max(0, done - self.maxlen)
                if n - drop + self._need[sk.N_STREAMS + s] > log.shape[0] // 2:
                    grown = np.zeros((2 * log.shape[0], log.shape[1]))
                    grown[: n - drop] = log[drop:n]
                    self._logs[s] = grown
                else:
                    log[: n - drop] = log[drop:n].copy()
                self._cnt[s] = n - drop
                if s == sk.S_GNSS:
                    self._cnt[sk.K_GNSS_DELIVERED] = done - drop
                self._cap[s] = self._logs[s].shape[0]

    def imu_batch(self, rows: np.ndarray, nrow: int, esc_first: int, esc_every: int) -> None:
        """IMU samples of truth rows ``rows[:nrow]`` (see :mod:`sitl.world.kernel`), ESC samples of every
        ``esc_every``-th of them from ``esc_first``."""
        args = (rows, nrow, self.n_rotors, esc_first, esc_every, self._packed, self.accel_bias, self.gyro_bias,
                self._nz, self._nat, self._logs[0], self._logs[1], self._cnt, self._need, self._cap)
        if self._imu_fn is None:  # the argument types never change: the compiled function looked up once
            self._imu_fn = compiled_entry(sk.imu_period, args)
        low = self._imu_fn(*args)
        if low:
            self._make_room(low)

    def slow_tick(self, t: float, x: np.ndarray, due: int) -> None:
        """GNSS fix, baro and magnetometer samples at time ``t`` [s] on state ``x`` as ``due`` says
        (``sensor_kernel.DUE_*``); GNSS fixes whose latency has elapsed delivered."""
        args = (float(t), x, due, self._packed, self._nz, self._nat, self._logs[2], self._logs[3], self._logs[4],
                self._cnt, self._need, self._cap)
        if self._slow_fn is None:
            self._slow_fn = compiled_entry(sk.slow_sensors, args)
        low = self._slow_fn(*args)
        if low:
            self._make_room(low)

    def _take(self, s: int, n: int, done: int) -> np.ndarray:
        """Log ``s``'s first ``done`` of ``n`` rows (the newest ``maxlen`` of them), the rest (GNSS fixes still
        pending) moved to the front."""
        log = self._logs[s]
        out = log[max(0, done - self.maxlen):done].copy()
        if n > done:
            log[: n - done] = log[done:n].copy()
        self._cnt[s] = n - done
        return out

    def drain(self) -> dict[str, list[Any]]:
        """All samples since the previous drain, by sensor, oldest first: ``imu`` (t, accel FRD (3,), gyro FRD (3,)),
        ``esc`` (t, rotor speeds (N,)), ``gnss`` :class:`GnssSample`, ``baro`` :class:`BaroSample`, ``mag``
        :class:`MagSample`. (A lockstep bridge drains every few ticks: an empty log costs a comparison.)"""
        n_imu, n_esc, n_gnss, n_baro, n_mag, n_fix = self._cnt.tolist()
        out: dict[str, list[Any]] = {"imu": [], "esc": [], "gnss": [], "baro": [], "mag": []}
        if n_imu:  # (few samples: views of each row; many: of the columns, copied once)
            r = self._take(sk.S_IMU, n_imu, n_imu)
            out["imu"] = ([(v[0], row[1:4], row[4:7]) for v, row in zip(r.tolist(), r, strict=True)] if n_imu <= 16
                          else list(zip(r[:, 0].tolist(), r[:, 1:4].copy(), r[:, 4:7].copy(), strict=True)))
        if n_esc:
            r = self._take(sk.S_ESC, n_esc, n_esc)
            out["esc"] = ([(v[0], row[1:]) for v, row in zip(r.tolist(), r, strict=True)] if n_esc <= 16
                          else list(zip(r[:, 0].tolist(), r[:, 1:].copy(), strict=True)))
        if n_fix:
            r = self._take(sk.S_GNSS, n_gnss, n_fix)
            self._cnt[sk.K_GNSS_DELIVERED] = 0
            sats = int if isinstance(self.config.gnss.satellites, int) else float
            out["gnss"] = [GnssSample(v[0], g[1:4].copy(), g[4:7].copy(), v[7], v[8], v[9], sats(v[10]))
                           for v, g in zip(r.tolist(), r, strict=True)]  # fmt: skip
        if n_baro:
            out["baro"] = [BaroSample(*v) for v in self._take(sk.S_BARO, n_baro, n_baro).tolist()]
        if n_mag:
            r = self._take(sk.S_MAG, n_mag, n_mag)
            out["mag"] = [MagSample(v[0], m[1:4].copy()) for v, m in zip(r.tolist(), r, strict=True)]
        return out
