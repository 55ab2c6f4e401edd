"""Builders of the outgoing MAVLink messages from the simulation state and sensor samples.

What is a measurement and what is not:

- Raw sensor messages (HIL_SENSOR, HIGHRES_IMU, GPS_RAW_INT, ESC_STATUS, RAW_RPM, the
  ``CHEM`` NAMED_VALUE_FLOAT) carry the simulated, noisy sensor samples.
- State messages (ATTITUDE*, LOCAL_POSITION_NED, GLOBAL_POSITION_INT, VFR_HUD, ALTITUDE)
  carry the autopilot's state, and this autopilot flies on the true state (it has no
  estimator), so they are the truth, as in PX4 SITL with a ground-truth estimator.
- ``TRUEWN``, ``TRUEWE``, ``TRUEWD`` (NAMED_VALUE_FLOAT, m/s, air-mass velocity NED at the
  vehicle) are simulation-only debug values so a demo can compare a wind estimate with the
  truth; no real autopilot sends them and no estimator may use them as a measurement.

Named values: ``CHEM`` = chemical concentration reading in mg/m^3 (0 below the detection
limit), time_boot_ms = the sample time. All time stamps are simulation time.
"""

from __future__ import annotations

import math
import time
from typing import TYPE_CHECKING, cast

import numpy as np

from sitl.autopilot.flight_modes import Mode
from sitl.world.kernel import T_ROTOR_CMD
from sitl.world.sensors import ned_to_geodetic
from vehicle.frames import quat_to_euler
from wire import px4_modes
from wire.dialect import mavlink

#: The HEARTBEAT's MAV_TYPE by rotor count.
MAV_TYPES = {3: mavlink.MAV_TYPE_TRICOPTER, 4: mavlink.MAV_TYPE_QUADROTOR, 6: mavlink.MAV_TYPE_HEXAROTOR,
             8: mavlink.MAV_TYPE_OCTOROTOR}  # fmt: skip

if TYPE_CHECKING:
    from sitl.simulation import Simulation
    from sitl.world.chem_sensor import ChemReading
    from sitl.world.sensors import BaroSample, GnssSample, MagSample

RAD_S_TO_RPM = 60.0 / (2.0 * math.pi)

def px4_custom_mode(mode: Mode) -> int:
    """PX4 custom_mode word of a built-in autopilot mode (the Mode values are PX4's names)."""
    return px4_modes.encode(*px4_modes.from_name(mode.value))


def mode_from_px4(main: int, sub: int) -> Mode | None:
    """The mode a DO_SET_MODE (custom main/sub) asks for, or None if not supported."""
    if main == px4_modes.MAIN_AUTO and sub == px4_modes.AUTO_READY:
        return Mode.HOLD
    try:
        return Mode(px4_modes.name(px4_modes.encode(main, sub)))
    except ValueError:
        return None


# SYS_STATUS sensor bits (MAV_SYS_STATUS_SENSOR).
S_GYRO, S_ACCEL, S_MAG, S_BARO, S_GPS = 0x1, 0x2, 0x4, 0x8, 0x20
S_MOTORS, S_AHRS, S_BATTERY, S_PREARM = 0x8000, 0x200000, 0x2000000, 0x10000000
SENSORS_PRESENT = S_GYRO | S_ACCEL | S_MAG | S_BARO | S_GPS | S_MOTORS | S_AHRS | S_BATTERY | S_PREARM

# HIL_SENSOR fields_updated bits.
HIL_ACC_GYRO = 0x3F
HIL_MAG = 0x1C0
HIL_BARO = 0x200 | 0x800 | 0x1000  # abs pressure, pressure altitude, temperature


class Telemetry:
    """State kept between messages (battery, latest samples) and the message builders.

    Builders return a list of messages (possibly empty). Sample-driven builders take one
    sensor sample; the others read the simulation's current state.
    """

    def __init__(self, sim: Simulation) -> None:
        self.sim = sim
        self.home_cfg = sim.scenario.sensors.home
        v = sim.vehicle
        self.cells = int(v.battery_cells)
        self.capacity_mah = float(v.battery_capacity_mah)
        self.hover_current_a = float(v.hover_current_a)
        self.w_hover = float(v.control["hover_speed"])  # the truth's: what the motors really run at
        self.consumed_mah = 0.0
        self.current_a = 0.0
        self._last_t = sim.t
        self.latest: dict[str, object] = {}
        self.esc_counter = 0
        self._mag_new = False
        self._baro_new = False
        self.unix_epoch_us = int(time.time() * 1e6)
        # Index of a final NAV_RETURN_TO_LAUNCH item handed over to RTL mode: the mission is then
        # complete (PX4 reports MISSION_STATE_COMPLETE; MAVSDK 4 reads it as "mission finished").
        self.rtl_handover: int | None = None  # SYSTEM_TIME's UNIX time = this + sim time
        # Index of a mission LAND item being flown: PX4 stays in AUTO.MISSION through the landing (and
        # after the disarm), reporting the item reached on touchdown; the built-in autopilot lands in
        # its LAND mode, so the link reports it as PX4 would (None: no mission landing).
        self.mission_landing: int | None = None
        self._landing_reported = False

    # ------------------------------------------------------------------ state
    def ingest(self, samples: dict[str, list]) -> None:
        """Note the newest sample of each sensor (for periodic messages and REQUEST_MESSAGE)."""
        for name, lst in samples.items():
            if lst:
                self.latest[name] = lst[-1]
        if samples.get("mag"):
            self._mag_new = True
        if samples.get("baro"):
            self._baro_new = True

    def update_battery(self) -> None:
        """Integrate the battery drain since the last call (electrical power ~ rotor speed^3)."""
        sim = self.sim
        dt = sim.t - self._last_t
        self._last_t = sim.t
        if sim.fc.armed:
            w = np.asarray(sim.rotor_speeds)
            ratio = float(np.mean(w)) / self.w_hover if self.w_hover > 0 else 0.0
            self.current_a = self.hover_current_a * ratio**3
        else:
            self.current_a = 0.4  # avionics only
        self.consumed_mah += self.current_a * dt / 3.6

    @property
    def remaining(self) -> float:
        """Battery charge left, fraction in [0, 1]."""
        return max(0.0, 1.0 - self.consumed_mah / self.capacity_mah)

    @property
    def voltage_v(self) -> float:
        # Roughly linear discharge 4.15 -> 3.5 V per cell plus ~10 mOhm pack resistance.
        return self.cells * (3.5 + 0.65 * self.remaining) - 0.01 * self.current_a

    def boot_ms(self) -> int:
        return int(self.sim.t * 1000.0) & 0xFFFFFFFF

    def usec(self, t: float | None = None) -> int:
        return int((self.sim.t if t is None else t) * 1e6)

    # ingest() keeps each sensor's sample as the world produced it: "mag" a MagSample, "baro" a BaroSample.
    def _mag(self) -> MagSample | None:
        return cast("MagSample | None", self.latest.get("mag"))

    def _baro(self) -> BaroSample | None:
        return cast("BaroSample | None", self.latest.get("baro"))

    def _geo(self, pos: np.ndarray) -> tuple[float, float, float]:
        return ned_to_geodetic(pos, self.home_cfg)

    # ------------------------------------------------------------------ mission landing (PX4's view)
    def reported_mode(self) -> Mode:
        """The mode on the wire: the autopilot's, except AUTO.MISSION during and after a mission landing."""
        mode = self.sim.fc.mode
        if self.mission_landing is not None and mode in (Mode.LAND, Mode.HOLD):
            return Mode.MISSION
        return mode

    def end_mission_landing(self) -> None:
        """A command chose another mode (or armed): the mission landing is over on the wire."""
        self.mission_landing = None

    def mission_landing_step(self) -> list:
        """MISSION_ITEM_REACHED of the land item once on the ground; end the landing's reporting when the
        autopilot leaves it (another mode, or armed again in Hold)."""
        fc = self.sim.fc
        i = self.mission_landing
        if i is None:
            self._landing_reported = False
            return []
        if fc.mode not in (Mode.LAND, Mode.HOLD) or (fc.armed and fc.mode == Mode.HOLD and self._landing_reported):
            self.mission_landing = None
            return []
        if not self._landing_reported and (not fc.armed or fc.on_ground):
            self._landing_reported = True
            return [mavlink.MAVLink_mission_item_reached_message(i), *self.mission_current()]
        return []

    # ------------------------------------------------------------------ periodic builders
    def heartbeat(self) -> list:
        fc = self.sim.fc
        base = mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | mavlink.MAV_MODE_FLAG_STABILIZE_ENABLED
        if fc.armed:
            base |= mavlink.MAV_MODE_FLAG_SAFETY_ARMED
        mode = self.reported_mode()
        main, _ = px4_modes.from_name(mode.value)
        if main == px4_modes.MAIN_AUTO:
            base |= mavlink.MAV_MODE_FLAG_AUTO_ENABLED | mavlink.MAV_MODE_FLAG_GUIDED_ENABLED
        elif main == px4_modes.MAIN_OFFBOARD:
            base |= mavlink.MAV_MODE_FLAG_GUIDED_ENABLED
        elif main == px4_modes.MAIN_POSCTL:
            base |= mavlink.MAV_MODE_FLAG_MANUAL_INPUT_ENABLED
        if fc.crashed:
            status = mavlink.MAV_STATE_EMERGENCY
        elif fc.failsafe:
            status = mavlink.MAV_STATE_CRITICAL
        elif fc.armed:
            status = mavlink.MAV_STATE_ACTIVE
        else:
            status = mavlink.MAV_STATE_STANDBY
        return [
            mavlink.MAVLink_heartbeat_message(
                MAV_TYPES.get(self.sim.vehicle.n_rotors, mavlink.MAV_TYPE_GENERIC), mavlink.MAV_AUTOPILOT_PX4, base,
                px4_custom_mode(mode), status, 3
            )
        ]

    def sys_status(self) -> list:
        fc = self.sim.fc
        health = SENSORS_PRESENT
        if not fc.armed and fc.prearm_failure() is not None:
            health &= ~S_PREARM
        if fc.crashed:
            health &= ~(S_MOTORS | S_AHRS)
        pct = int(round(100 * self.remaining))
        return [
            mavlink.MAVLink_sys_status_message(
                SENSORS_PRESENT, SENSORS_PRESENT, health, 100, int(self.voltage_v * 1000),
                int(self.current_a * 100), pct, 0, 0, 0, 0, 0, 0,
            )
        ]  # fmt: skip

    def extended_sys_state(self) -> list:
        landed = int(self.sim.fc.landed_state)
        return [mavlink.MAVLink_extended_sys_state_message(mavlink.MAV_VTOL_STATE_UNDEFINED, landed)]

    def attitude(self) -> list:
        sim = self.sim
        roll, pitch, yaw = quat_to_euler(sim.quaternion)
        p, q, r = sim.rates
        return [mavlink.MAVLink_attitude_message(self.boot_ms(), roll, pitch, yaw, p, q, r)]

    def attitude_quaternion(self) -> list:
        sim = self.sim
        w, x, y, z = (float(v) for v in sim.quaternion)
        p, q, r = (float(v) for v in sim.rates)
        return [mavlink.MAVLink_attitude_quaternion_message(self.boot_ms(), w, x, y, z, p, q, r, [1.0, 0.0, 0.0, 0.0])]

    def local_position_ned(self) -> list:
        p = self.sim.position
        v = self.sim.velocity
        return [mavlink.MAVLink_local_position_ned_message(self.boot_ms(), *map(float, p), *map(float, v))]

    def global_position_int(self) -> list:
        sim = self.sim
        p, v = sim.position, sim.velocity
        lat, lon, alt = self._geo(p)
        rel = float(sim.fc.home[2] - p[2])
        hdg = math.degrees(quat_to_euler(sim.quaternion)[2]) % 360.0
        return [
            mavlink.MAVLink_global_position_int_message(
                self.boot_ms(), int(lat * 1e7), int(lon * 1e7), int(alt * 1000), int(rel * 1000),
                int(v[0] * 100), int(v[1] * 100), int(v[2] * 100), int(hdg * 100) % 36000,
            )
        ]  # fmt: skip

    def home_position(self) -> list:
        home = self.sim.fc.home
        lat, lon, alt = self._geo(home)
        return [
            mavlink.MAVLink_home_position_message(
                int(lat * 1e7), int(lon * 1e7), int(alt * 1000), float(home[0]), float(home[1]), float(home[2]),
                [1.0, 0.0, 0.0, 0.0], 0.0, 0.0, 0.0, self.usec(),
            )
        ]  # fmt: skip

    def vfr_hud(self) -> list:
        sim = self.sim
        v = sim.velocity
        air = v - sim.wind_at_vehicle
        hdg = int(math.degrees(quat_to_euler(sim.quaternion)[2]) % 360.0)
        w = sim.rotor_speeds
        throttle = int(np.clip(100.0 * (np.mean(w) / self.w_hover) * 0.5, 0, 100)) if sim.fc.armed else 0
        alt = self.home_cfg.alt_m - float(sim.position[2])
        return [
            mavlink.MAVLink_vfr_hud_message(
                float(np.linalg.norm(air[:2])), float(np.linalg.norm(v[:2])), hdg, throttle, alt, float(-v[2])
            )
        ]

    def battery_status(self) -> list:
        volts = [65535] * 10
        cell_mv = int(1000 * self.voltage_v / self.cells)
        for i in range(min(self.cells, 10)):
            volts[i] = cell_mv
        return [
            mavlink.MAVLink_battery_status_message(
                0, mavlink.MAV_BATTERY_FUNCTION_ALL, mavlink.MAV_BATTERY_TYPE_LIPO, 2500, volts,
                int(self.current_a * 100), int(self.consumed_mah), -1, int(round(100 * self.remaining)),
            )
        ]  # fmt: skip

    def altitude(self) -> list:
        sim = self.sim
        amsl = self.home_cfg.alt_m - float(sim.position[2])
        rel = float(sim.fc.home[2] - sim.position[2])
        baro = self._baro()
        monotonic = baro.altitude_m if baro is not None else amsl
        local = -float(sim.position[2])
        return [mavlink.MAVLink_altitude_message(self.usec(), monotonic, amsl, local, rel, -local, math.nan)]

    def highres_imu(self) -> list:
        # ingest() keeps the world's IMU sample as it is: (t, specific force FRD, rates FRD).
        imu = cast("tuple[float, np.ndarray, np.ndarray] | None", self.latest.get("imu"))
        if imu is None:
            return []
        t, acc, gyr = imu
        mag = self._mag()
        baro = self._baro()
        m = mag.field_gauss if mag is not None else np.zeros(3)
        pres = baro.pressure_pa / 100.0 if baro is not None else 0.0
        palt = baro.altitude_m if baro is not None else 0.0
        temp = baro.temperature_c if baro is not None else 0.0
        return [
            mavlink.MAVLink_highres_imu_message(
                self.usec(t), float(acc[0]), float(acc[1]), float(acc[2]), float(gyr[0]), float(gyr[1]), float(gyr[2]),
                float(m[0]), float(m[1]), float(m[2]), pres, 0.0, palt, temp, 0x1FFF, 0,
            )
        ]

    def servo_output_raw(self) -> list:
        pwm = self._pwm()
        return [mavlink.MAVLink_servo_output_raw_message(self.usec() & 0xFFFFFFFF, 0, *pwm, *([0] * (8 - len(pwm))))]

    def actuator_output_status(self) -> list:
        pwm = self._pwm()
        outs = [float(v) for v in pwm] + [0.0] * (32 - len(pwm))
        return [mavlink.MAVLink_actuator_output_status_message(self.usec(), len(pwm), outs)]

    def _pwm(self) -> list[int]:
        sim = self.sim
        n = sim.vehicle.n_rotors
        if not sim.fc.armed:
            return [900] * n
        wmax = float(sim.vehicle.rotor_speed_max_rad_s)
        frac = np.clip(np.asarray(sim.last_truth[T_ROTOR_CMD][:n]) / wmax, 0.0, 1.0)
        return [int(1000 + 1000 * f) for f in frac]

    def esc_info(self) -> list:
        """ESC_INFO, four ESCs a message (``index`` the first of them), as PX4 sends it."""
        n = self.sim.vehicle.n_rotors
        return [
            mavlink.MAVLink_esc_info_message(
                i, self.usec(), self.esc_counter & 0xFFFF, n, mavlink.ESC_CONNECTION_TYPE_DSHOT,
                (1 << min(4, n - i)) - 1, [0] * 4, [0] * 4, [2500] * 4,
            )
            for i in range(0, n, 4)
        ]  # fmt: skip

    def raw_rpm(self) -> list:
        esc = cast("tuple[float, np.ndarray] | None", self.latest.get("esc"))  # (t, rotor speeds rad/s), as ingested
        if esc is None:
            return []
        return [mavlink.MAVLink_raw_rpm_message(i, float(w) * RAD_S_TO_RPM) for i, w in enumerate(esc[1])]

    def system_time(self) -> list:
        return [mavlink.MAVLink_system_time_message(self.unix_epoch_us + self.usec(), self.boot_ms())]

    def timesync(self) -> list:
        return [mavlink.MAVLink_timesync_message(0, int(self.sim.t * 1e9))]

    def true_wind(self) -> list:
        w = self.sim.wind_at_vehicle
        ms = self.boot_ms()
        return [
            mavlink.MAVLink_named_value_float_message(ms, name.encode(), float(v))
            for name, v in zip(("TRUEWN", "TRUEWE", "TRUEWD"), w, strict=True)
        ]

    def mission_current(self) -> list:
        fc = self.sim.fc
        n = len(fc.mission)
        seq = min(fc.mission_index, max(n - 1, 0))
        if fc.mode == Mode.MISSION:
            self.rtl_handover = None
        if self.mission_landing is not None and not self._landing_reported:
            # Still landing on the mission's land item: PX4 reports it current and the mission active.
            return [mavlink.MAVLink_mission_current_message(self.mission_landing, n, mavlink.MISSION_STATE_ACTIVE, 1)]
        if n == 0:
            state = mavlink.MISSION_STATE_NO_MISSION
        elif fc.mission_index >= n or self.rtl_handover == fc.mission_index:
            state = mavlink.MISSION_STATE_COMPLETE
        elif fc.mode == Mode.MISSION:
            state = mavlink.MISSION_STATE_ACTIVE
        else:
            state = mavlink.MISSION_STATE_NOT_STARTED if fc.mission_index == 0 else mavlink.MISSION_STATE_PAUSED
        return [mavlink.MAVLink_mission_current_message(seq, n, state, 1 if fc.mode == Mode.MISSION else 2)]

    # ------------------------------------------------------------------ sample-driven builders
    def hil_sensor(self, imu: tuple[float, np.ndarray, np.ndarray]) -> list:
        t, acc, gyr = imu
        mag = self._mag()
        baro = self._baro()
        updated = HIL_ACC_GYRO
        m = (0.0, 0.0, 0.0)
        pres = palt = temp = 0.0
        if mag is not None:
            m = (float(mag.field_gauss[0]), float(mag.field_gauss[1]), float(mag.field_gauss[2]))
            if self._mag_new:
                updated |= HIL_MAG
                self._mag_new = False
        if baro is not None:
            pres, palt, temp = baro.pressure_pa / 100.0, baro.altitude_m, baro.temperature_c
            if self._baro_new:
                updated |= HIL_BARO
                self._baro_new = False
        return [
            mavlink.MAVLink_hil_sensor_message(
                self.usec(t), float(acc[0]), float(acc[1]), float(acc[2]), float(gyr[0]), float(gyr[1]), float(gyr[2]),
                *m, pres, 0.0, palt, temp, updated, 0,
            )
        ]

    def esc_status(self, esc: tuple[float, np.ndarray]) -> list:
        """ESC_STATUS, four ESCs a message (``index`` the first of them: a hexarotor sends two)."""
        t, w = esc
        self.esc_counter += 1
        n = len(w)
        rpm = [int(round(float(v) * RAD_S_TO_RPM)) for v in w]
        volts = float(self.voltage_v)
        amps = float(self.current_a) / n
        out = []
        for i in range(0, n, 4):
            k = min(4, n - i)
            out.append(mavlink.MAVLink_esc_status_message(i, self.usec(t), rpm[i:i + k] + [0] * (4 - k),
                                                          [volts] * k + [0.0] * (4 - k), [amps] * k + [0.0] * (4 - k)))
        return out

    def gps_raw_int(self, g: GnssSample) -> list:
        vel = g.vel_ned
        gs = float(math.hypot(vel[0], vel[1]))
        cog = int((math.degrees(math.atan2(vel[1], vel[0])) % 360.0) * 100) if gs > 0.1 else 65535
        return [
            mavlink.MAVLink_gps_raw_int_message(
                self.usec(g.t), mavlink.GPS_FIX_TYPE_3D_FIX, int(g.lat_deg * 1e7), int(g.lon_deg * 1e7),
                int(g.alt_m * 1000), 70, 100, int(gs * 100), cog, int(g.satellites),
            )
        ]  # fmt: skip

    def chem(self, s: ChemReading) -> list:
        value = getattr(s, "value_mg_m3", getattr(s, "value", math.nan))
        return [mavlink.MAVLink_named_value_float_message(int(s.t * 1000) & 0xFFFFFFFF, b"CHEM", float(value))]
