"""What the identification records from a PX4's MAVLink stream, and the :class:`~identify.flight_data.FlightData`
made from it.

Messages (decoded by :mod:`estimator.mavlink_decode`, the live estimator's own decoders):

- IMU: HIGHRES_IMU (m/s^2, rad/s) or SCALED_IMU (mG, mrad/s), the one chosen (the other if it is missing):
  the time base of the record. PX4 subtracts EKF2's accelerometer-bias estimate from HIGHRES_IMU, not from
  SCALED_IMU; on PX4 SIH (no sensor bias) that estimate is 0.1-0.3 m/s^2 off in x and y in hover, a force
  the identification and the wind estimate would take as drag;
- attitude: ATTITUDE_QUATERNION, else ATTITUDE (Euler);
- velocity: LOCAL_POSITION_NED (also the position the guard and the velocity loop use);
- rotor commands: ACTUATOR_OUTPUT_STATUS, else SERVO_OUTPUT_RAW port 0, through the vehicle's motor map
  (:class:`estimator.motor_output.OutputMap`: PX4 output -> rotor by the vehicle file's ``px4_outputs``,
  PWM range, THR_MDL_FAC read from the autopilot); they are the ``rotor_commands`` and, without ESC
  telemetry, also the ``rotor_speeds`` (the motor lag is applied by the estimation,
  :func:`identify.measure.rotor_speeds`);
- rotor speeds: ESC_STATUS (rpm) only when asked for (``esc_component``): PX4 SITL's own ESC_STATUS is a
  placeholder (rpm = 6000 x output, ``SimulatorMavlink.cpp`` 158). Which rotor ESC i is: ``esc_order``
  (:data:`ESC_ORDERS`): ``px4`` (default), ESC i = PX4 output i, as on a real vehicle whose ESCs are on PX4's
  outputs; ``rotors``, ESC i = the vehicle file's rotor i, as windseek's ESC telemetry component numbers them
  (``sitl/hil/peripheral.py``). With the wrong one the roll, pitch and yaw moments are fitted on swapped rotor
  speeds (``windseek sitl --px4`` with nasa-quad: L/M/N R^2 near 30 % instead of 97 %).

Commands are held until the next message (zero-order hold), the other series are interpolated linearly
onto the IMU's time stamps. Excluded: samples where a motor output is at either end of its range (0.1 s
either side, as :mod:`identify.fly.world`) and samples inside a gap of any stream (longer than five of
its median intervals and 0.1 s), each with its reason.

Thread use: :meth:`Recorder.sink` runs on MAVSDK's callback thread and only appends; readers take
copies. Times are the autopilot's boot clock (s).
"""

from __future__ import annotations

import math
import threading
from collections import Counter
from typing import Any

import numpy as np

from estimator import mavlink_decode as dec
from estimator.motor_output import OutputMap
from identify.flight_data import FlightData, runs, widen
from vehicle.frames import tilt_angle

#: Messages the recorder reads (subscribed through mavlink_direct).
MESSAGES = ("HIGHRES_IMU", "SCALED_IMU", "ATTITUDE_QUATERNION", "ATTITUDE", "LOCAL_POSITION_NED",
            "ACTUATOR_OUTPUT_STATUS", "SERVO_OUTPUT_RAW", "ESC_STATUS")  # fmt: skip
#: The IMU messages: PX4's HIGHRES_IMU carries EKF2's accelerometer and gyro bias estimates subtracted
#: (``streams/HIGHRES_IMU.hpp``), SCALED_IMU the calibrated sensor without them (``streams/SCALED_IMU.hpp``).
IMU_MESSAGES = ("HIGHRES_IMU", "SCALED_IMU")
#: How ESC_STATUS numbers its ESCs (see the module docstring).
ESC_ORDERS = ("px4", "rotors")
#: A sample this close (fraction of the range) to either end of the output range is saturated.
SATURATION_TOL = 0.002


class _Msg:
    """A pymavlink-like view of a decoded mavlink_direct message (for :mod:`estimator.mavlink_decode`)."""

    def __init__(self, mtype: str, fields: dict[str, Any]) -> None:
        self.__dict__.update(fields)
        self._mtype = mtype

    def get_type(self) -> str:
        return self._mtype

    def __getattr__(self, name: str) -> Any:  # a field the message lacks
        raise AttributeError(name)


class Recorder:
    """The identification's messages of one autopilot (system ``target[0]``), see the module docstring."""

    def __init__(self, outputs: OutputMap, n_rotors: int, esc_component: int | None = None,
                 imu: str = "HIGHRES_IMU", esc_order: str = "px4") -> None:  # fmt: skip
        if imu not in IMU_MESSAGES:
            raise ValueError(f"IMU message {imu!r}: choose one of {', '.join(IMU_MESSAGES)}")
        if esc_order not in ESC_ORDERS:
            raise ValueError(f"ESC order {esc_order!r}: choose one of {', '.join(ESC_ORDERS)}")
        self.esc_order = esc_order
        self.imu = imu
        self.outputs = outputs
        self.n_rotors = n_rotors
        self.esc_component = esc_component
        self.target: tuple[int, int] | None = None
        self.counts: Counter[str] = Counter()
        self.series: dict[str, list[tuple[float, np.ndarray]]] = {m: [] for m in MESSAGES}
        self.quaternion: np.ndarray | None = None  # the newest attitude (the guard's)
        self.outputs_u: tuple[float, np.ndarray] | None = None  # the newest normalized motor outputs
        self.ignored_esc = 0
        self._lock = threading.Lock()

    # ------------------------------------------------------------------ MAVSDK's thread
    def sink(self, name: str, f: dict[str, Any], t: float, sysid: int, compid: int) -> None:
        """One message (a :data:`mission.runners.mavsdk_vehicle.Sink`); never raises on a bad one."""
        if name not in self.series or not math.isfinite(t) or not 0.0 < t < dec.MAX_BOOT_TIME_S:
            return
        if self.target is not None and sysid != self.target[0]:
            return
        if name == "ESC_STATUS":
            if self.esc_component is None or compid != self.esc_component:
                self.ignored_esc += 1
                return
        elif self.target is not None and compid != self.target[1]:
            return
        try:
            value = self._decode(name, _Msg(name, f))
        except (KeyError, TypeError, ValueError):
            self.counts[f"{name}:bad"] += 1
            return
        if value is None:
            return
        with self._lock:
            self.series[name].append((t, value))
            self.counts[name] += 1
        primary = name == "ACTUATOR_OUTPUT_STATUS" or not self.counts["ACTUATOR_OUTPUT_STATUS"]
        if name in ("ACTUATOR_OUTPUT_STATUS", "SERVO_OUTPUT_RAW") and primary:
            self.outputs_u = (t, (value - self.outputs.raw_min) / (self.outputs.raw_max - self.outputs.raw_min))

    def _decode(self, name: str, msg: _Msg) -> np.ndarray | None:
        if name in ("HIGHRES_IMU", "SCALED_IMU"):
            acc, gyr = dec.imu(msg)
            return np.concatenate([acc, gyr])
        if name in ("ATTITUDE_QUATERNION", "ATTITUDE"):
            q = dec.attitude(msg)
            if q is not None and (name == "ATTITUDE_QUATERNION" or not self.counts["ATTITUDE_QUATERNION"]):
                self.quaternion = q  # the guard's: ATTITUDE only while no ATTITUDE_QUATERNION came
            return q
        if name == "LOCAL_POSITION_NED":
            return np.array([msg.x, msg.y, msg.z, msg.vx, msg.vy, msg.vz], dtype=float)
        if name == "SERVO_OUTPUT_RAW" and int(getattr(msg, "port", 0)) != 0:
            return None
        if name == "ESC_STATUS":
            index, speeds = dec.rotor_telemetry(msg)
            return np.array([float(index), *speeds])
        raw = np.array(dec.actuator_outputs(msg)[: len(self.outputs.order)], dtype=float)
        return raw if raw.size == len(self.outputs.order) and np.all(np.isfinite(raw)) else None

    # ------------------------------------------------------------------ readers
    def tilt_rad(self) -> float | None:
        """The newest attitude's tilt from level (rad), or None before the first attitude."""
        q = self.quaternion
        return None if q is None else float(tilt_angle(q))

    def snapshot(self, name: str) -> list[tuple[float, np.ndarray]]:
        with self._lock:
            return list(self.series[name])

    def rates_hz(self, t0: float, t1: float) -> dict[str, float]:
        """Messages per second of autopilot time between ``t0`` and ``t1`` (s), per message type."""
        out = {}
        for name in MESSAGES:
            n = sum(1 for t, _ in self.snapshot(name) if t0 <= t <= t1)
            out[name] = n / max(t1 - t0, 1e-9)
        return out

    def flight_data(self, t0: float, t1: float, source: str) -> FlightData:
        """The record between ``t0`` and ``t1`` (s, autopilot clock) as flight data on a time base from 0
        at ``t0`` (ValueError naming a missing stream)."""
        other = next(m for m in IMU_MESSAGES if m != self.imu)
        imu_name = self.imu if self.counts[self.imu] else other
        att_name = "ATTITUDE_QUATERNION" if self.counts["ATTITUDE_QUATERNION"] else "ATTITUDE"
        out_name = "ACTUATOR_OUTPUT_STATUS" if self.counts["ACTUATOR_OUTPUT_STATUS"] else "SERVO_OUTPUT_RAW"
        need = {"IMU (HIGHRES_IMU or SCALED_IMU)": imu_name, "attitude": att_name,
                "velocity (LOCAL_POSITION_NED)": "LOCAL_POSITION_NED",
                "motor outputs (ACTUATOR_OUTPUT_STATUS or SERVO_OUTPUT_RAW)": out_name}  # fmt: skip
        got = {name: _window(self.snapshot(name), t0 - 0.5, t1 + 0.5) for name in set(need.values())}
        missing = [what for what, name in need.items() if got[name][0].size < 2]
        if missing:
            raise ValueError(f"no {', '.join(missing)} between t = {t0:.1f} and {t1:.1f} s: the identification "
                             "needs them (see the stream rates line)")  # fmt: skip
        ti, imu = got[imu_name]
        keep = (ti >= t0) & (ti <= t1)
        t, imu = ti[keep], imu[keep]
        ta, q = got[att_name]
        q = _continuous(q)
        tp, pv = got["LOCAL_POSITION_NED"]
        to, raw = got[out_name]
        cmd_out = _hold(t, to, raw)
        cmd = np.array([self.outputs.speeds(r) for r in cmd_out])
        speeds = cmd
        esc_note = f"rotor speeds = commands ({out_name} through the motor map; no ESC telemetry used)"
        if self.esc_component is not None and self.counts["ESC_STATUS"]:
            speeds = self._esc_speeds(t)
            esc_note = (f"rotor speeds from ESC_STATUS of component {self.esc_component} (ESC order "
                        f"{self.esc_order}), commands from {out_name}")
        data = FlightData(t=t - t0, specific_force=imu[:, 0:3], rates=imu[:, 3:6], rotor_speeds=speeds,
                          velocity_ned=_lerp(t, tp, pv[:, 3:6]), quaternion=_lerp(t, ta, q), rotor_commands=cmd,
                          source=f"{source}; IMU {imu_name}, attitude {att_name}, velocity LOCAL_POSITION_NED; "
                          f"{esc_note}")  # fmt: skip
        u = (cmd_out - self.outputs.raw_min) / (self.outputs.raw_max - self.outputs.raw_min)
        sat = np.any((u <= SATURATION_TOL) | (u >= 1.0 - SATURATION_TOL), axis=1)
        if sat.any():
            bad = widen(sat, data.t, 0.1)
            spans = ", ".join(f"{a:.1f}-{b:.1f} s" for a, b in runs(bad, data.t)[:5])
            data = data.exclude(bad, f"motor output at its limit: {bad.mean() * 100:.1f} % of samples ({spans})")
        for name, (ts, _) in got.items():
            gap = _gaps(t, ts)
            if gap.any():
                data = data.exclude(gap, f"gap in {name}: {gap.mean() * 100:.1f} % of samples")
        return data

    def _esc_speeds(self, t: np.ndarray) -> np.ndarray:
        rows = self.snapshot("ESC_STATUS")
        order = self.outputs.order if self.esc_order == "px4" else tuple(range(self.n_rotors))
        cur = np.full(self.n_rotors, np.nan)
        ts, vals = [], []
        for te, v in rows:
            i0 = int(v[0])
            for k, w in enumerate(v[1:]):
                if i0 + k < len(order):
                    cur[order[i0 + k]] = w
            if np.all(np.isfinite(cur)):
                ts.append(te)
                vals.append(cur.copy())
        if len(ts) < 2:
            raise ValueError(f"ESC_STATUS of component {self.esc_component}: no complete set of rotor speeds")
        return _lerp(t, np.array(ts), np.array(vals))


def _window(rows: list[tuple[float, np.ndarray]], t0: float, t1: float) -> tuple[np.ndarray, np.ndarray]:
    """(times, values) of the rows between t0 and t1, sorted, duplicates of a time stamp dropped."""
    sel = sorted(((t, v) for t, v in rows if t0 <= t <= t1), key=lambda r: r[0])  # stable: a repeated stamp
    if not sel:
        return np.zeros(0), np.zeros((0, 1))
    t = np.array([s[0] for s in sel])
    v = np.array([s[1] for s in sel])
    keep = np.concatenate([[True], np.diff(t) > 0])
    return t[keep], v[keep]


def _lerp(t: np.ndarray, ts: np.ndarray, v: np.ndarray) -> np.ndarray:
    return np.stack([np.interp(t, ts, v[:, k]) for k in range(v.shape[1])], axis=1)


def _hold(t: np.ndarray, ts: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Zero-order hold of (ts, v) at the times t (before the first sample: the first)."""
    idx = np.clip(np.searchsorted(ts, t, side="right") - 1, 0, ts.size - 1)
    return v[idx]


def _continuous(q: np.ndarray) -> np.ndarray:
    """Quaternions with the sign flipped where needed so consecutive ones agree (q and -q are one attitude)."""
    out = q.copy()
    for i in range(1, out.shape[0]):
        if float(np.dot(out[i], out[i - 1])) < 0.0:
            out[i] = -out[i]
    return out


def _gaps(t: np.ndarray, ts: np.ndarray) -> np.ndarray:
    """Samples at times ``t`` in a gap of the stream ``ts`` (longer than 5 median intervals and 0.1 s), its two
    edges included (so a gap of the time base itself stays excluded when it is resampled), and beyond its ends."""
    if ts.size < 3:
        return np.zeros(t.shape, dtype=bool)
    d = np.diff(ts)
    limit = max(5.0 * float(np.median(d)), 0.1)
    bad = np.zeros(t.shape, dtype=bool)
    for i in np.nonzero(d > limit)[0]:
        bad |= (t >= ts[i]) & (t <= ts[i + 1])
    bad |= (t < ts[0] - limit) | (t > ts[-1] + limit)
    return bad
