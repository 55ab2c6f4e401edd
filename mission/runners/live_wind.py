"""Wind sources of a mission flown over MAVLink: the live UKF (``estimated``), WIND_COV (``mavlink``), none.

``estimated``: the paper's UKF runs on the vehicle's telemetry in a worker thread, never on the
asyncio loop that keeps the setpoints and the safety checks alive. MAVSDK's callback thread only
appends the estimator's inputs to a bounded queue (:meth:`EstimatedLiveWind.sink`); when the
filter falls behind (a loaded machine), IMU samples are first decimated 2:1 and, with the queue
full, the oldest inputs are dropped; both are counted and reported. The filter is paused on the
ground and while landing and cold-started at lift-off (:mod:`estimator.ground_gate`), and state
messages are held until the IMU has caught up with them (an autopilot sends its state ahead of
the raw IMU samples of the same interval).

Conventions: SI, NED, wind = air-mass velocity NED; vehicle time.
"""

from __future__ import annotations

import math
import threading
from collections import Counter, deque
from typing import Any

import numpy as np

from estimator.ground_gate import GroundGate, withheld
from estimator.mavlink_adapter import MavlinkWindAdapter
from estimator.ukf import WindEstimator
from mission.safety import Abort, EstimatorWatch
from mission.strategies.base import WindInfo
from mission.vehicle import VehicleState
from mission.wind_source import UpwindFilter
from vehicle.params import VehicleParams

#: Messages the estimator reads (the IMU: HIL_SENSOR from windseek's SITL, HIGHRES_IMU from PX4).
ESTIMATOR_MESSAGES = ("HIL_SENSOR", "HIGHRES_IMU", "ATTITUDE_QUATERNION", "LOCAL_POSITION_NED", "ESC_STATUS")
#: Inputs queued for the worker at most; above DECIMATE_AT every other IMU sample is skipped.
QUEUE_MAX = 4096
DECIMATE_AT = 1024


class _Msg:
    """A pymavlink-like view of a mavlink_direct message: fields as attributes, ``get_type()``."""

    def __init__(self, mtype: str, fields: dict[str, Any]) -> None:
        self.__dict__.update(fields)
        self._mtype = mtype

    def get_type(self) -> str:
        return self._mtype


class EstimatedLiveWind:
    """``estimated``: the live UKF in a worker thread (see the module docstring)."""

    mode = "estimated"

    def __init__(self, vehicle_params: VehicleParams, upwind: UpwindFilter, state: VehicleState) -> None:
        self.params = vehicle_params
        self.upwind = upwind
        self.state = state
        self.counters: Counter[str] = Counter()
        self.estimator = WindEstimator(vehicle_params)
        self.adapter = MavlinkWindAdapter(self.estimator)
        self.watch = EstimatorWatch()
        self.imu_message = ""
        self._highres_t0 = math.nan
        self._queue: deque[tuple[str, dict[str, Any], float, int]] = deque()
        self._cv = threading.Condition()
        self._stop = False
        self._skip = False
        self._gate = GroundGate()
        self._pending: list[_Msg] = []
        self._snapshot: tuple[float | None, np.ndarray, np.ndarray] = (None, np.zeros(3), np.eye(3) * 100.0)
        self._thread = threading.Thread(target=self._work, name="wind-estimator", daemon=True)
        self._thread.start()

    # ------------------------------------------------------------------ MAVSDK's thread
    def sink(self, name: str, fields: dict[str, Any], t: float) -> None:
        """Queue one estimator input (cheap; never blocks)."""
        if name not in ESTIMATOR_MESSAGES or not self._claim_imu(name, t):
            return
        with self._cv:
            q = self._queue
            if name == self.imu_message and len(q) > DECIMATE_AT:
                self._skip = not self._skip
                if self._skip:
                    self.counters["imu_decimated"] += 1
                    return
            if len(q) >= QUEUE_MAX:
                q.popleft()
                self.counters["dropped"] += 1
            q.append((name, fields, t, self.state.landed))
            self._cv.notify()

    def _claim_imu(self, name: str, t: float) -> bool:
        """HIL_SENSOR carries every IMU sample (windseek's SITL); HIGHRES_IMU (PX4) is the fallback
        when no HIL_SENSOR has come within 1 s of it. The first claimed stays."""
        if name not in ("HIL_SENSOR", "HIGHRES_IMU") or name == self.imu_message:
            return True
        if self.imu_message or not math.isfinite(t):
            return False
        if name == "HIGHRES_IMU":
            self._highres_t0 = t if math.isnan(self._highres_t0) else self._highres_t0
            if t - self._highres_t0 < 1.0:
                return False
        self.imu_message = name
        return True

    # ------------------------------------------------------------------ the worker
    def _work(self) -> None:
        while True:
            with self._cv:
                while not self._queue and not self._stop:
                    self._cv.wait(0.5)
                if self._stop:
                    return
                batch = list(self._queue)
                self._queue.clear()
            for name, fields, _t, landed in batch:
                try:
                    self._feed(name, fields, landed)
                except Exception:  # noqa: BLE001 - a bad input is counted, the worker goes on
                    self.counters["input_errors"] += 1
            est = self.estimator
            self._snapshot = (est.t, est.wind_ned.copy(), est.wind_cov.copy())

    def _feed(self, name: str, fields: dict[str, Any], landed: int) -> None:
        pend = self._pending
        action = self._gate.admit(withheld(landed))
        if action == "pause":
            pend.clear()
            return
        if action == "restart":
            self.estimator = WindEstimator(self.params)
            self.adapter = MavlinkWindAdapter(self.estimator)
            self.counters["restarts"] += 1
        if name == "LOCAL_POSITION_NED":
            pend.append(_Msg(name, fields))
        else:
            self.adapter.handle(_Msg(name, fields))
        est_t = self.estimator.t
        while pend and (est_t is None or float(getattr(pend[0], "time_boot_ms", 0)) * 1e-3 <= est_t + 1e-9
                        or len(pend) > 30):  # no IMU flowing (1 s at 30 Hz): do not hold velocities forever
            self.adapter.handle(pend.pop(0))

    def stop(self) -> None:
        with self._cv:
            self._stop = True
            self._cv.notify()
        self._thread.join(timeout=5.0)

    # ------------------------------------------------------------------ the loop's view
    def info(self, t: float) -> WindInfo:
        est_t, w, cov = self._snapshot
        if est_t is None:
            return self.upwind.make(np.zeros(3), np.eye(3) * 100.0)
        return self.upwind.make(w, cov)

    def ready(self) -> bool:
        return self._snapshot[0] is not None

    def missing(self) -> str:
        lack = [g for g in ("imu", "attitude", "velocity", "rotors") if g not in self.adapter.sources]
        return "no " + ", ".join(lack) + " input seen" if lack else "inputs seen but no sample accepted"

    def fault(self, t: float) -> Abort | None:
        est_t, w, cov = self._snapshot
        if est_t is None:
            return None
        est = self.estimator
        return self.watch.check(t, w, cov, dict(est.rejected), est.accepted["imu"])

    def describe(self) -> str:
        return f"the live UKF on {self.imu_message or 'the IMU'} telemetry (worker thread)"

    def report(self) -> dict[str, Any]:
        est = self.estimator
        return {"accepted": dict(est.accepted), "rejected": dict(est.rejected), "imu_message": self.imu_message,
                "span_s": est.span_s, **dict(self.counters)}  # fmt: skip


class WindCovWind:
    """``mavlink``: WIND_COV from the network (the autopilot's own estimate or a relayed estimator)."""

    mode = "mavlink"

    def __init__(self, vehicle: Any, upwind: UpwindFilter) -> None:
        self.vehicle = vehicle
        self.upwind = upwind
        self.received = 0

    def _latest(self, t: float) -> tuple[float, np.ndarray, np.ndarray] | None:
        wc = self.vehicle.wind_cov
        return None if wc is None or t - wc[0] > 5.0 else wc

    def info(self, t: float) -> WindInfo:
        wc = self._latest(t)
        if wc is None:
            return self.upwind.make(np.zeros(3), np.eye(3) * 100.0)
        return self.upwind.make(wc[1], wc[2])

    def ready(self) -> bool:
        return self.vehicle.wind_cov is not None

    def missing(self) -> str:
        return "no WIND_COV received"

    def fault(self, t: float) -> Abort | None:
        wc = self.vehicle.wind_cov
        if wc is not None and t - wc[0] > 5.0:
            return Abort("estimator-fault", f"WIND_COV stopped {t - wc[0]:.1f} s ago")
        return None

    def describe(self) -> str:
        return "WIND_COV from the network"

    def report(self) -> dict[str, Any]:
        return {}


class NoLiveWind:
    """``none``: pure chemotaxis."""

    mode = "none"

    def info(self, t: float) -> None:
        return None

    def ready(self) -> bool:
        return False

    def missing(self) -> str:
        return "no wind source (none)"

    def fault(self, t: float) -> Abort | None:
        return None

    def describe(self) -> str:
        return "none: pure chemotaxis"

    def report(self) -> dict[str, Any]:
        return {}
