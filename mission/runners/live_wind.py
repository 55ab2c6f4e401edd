"""Wind sources of a mission flown over MAVLink: the live UKF (``estimated``), WIND_COV (``mavlink``), none.

``estimated``: the paper's UKF on the vehicle's telemetry, run by the estimator's own live core
(:class:`~estimator.live.LiveCore`: lock-on, input selection and the inputs line, the ground gate,
clock resets, rotor speeds from ESC telemetry or from actuator outputs through the motor model) in
a worker thread behind a bounded queue (:class:`~estimator.worker.EstimatorWorker`: IMU samples
thinned, then the oldest inputs dropped when the filter falls behind, all counted). MAVSDK's
callback thread only submits messages, so the asyncio loop that keeps the setpoints and the safety
checks alive never runs the filter. Until the filter has made an estimate there is no wind: the
mission loop aborts with the missing inputs named rather than fly with a zero wind.

Conventions: SI, NED, wind = air-mass velocity NED; vehicle time.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from estimator.live import LiveConfig, LiveCore
from estimator.mavlink_decode import PREFERENCE
from estimator.worker import EstimatorWorker
from mission.safety import Abort, EstimatorWatch
from mission.strategies.base import WindInfo
from mission.wind_source import UpwindFilter
from vehicle.params import VehicleParams

#: Messages the live core reads: every input it may choose, and what it needs for lock-on, the
#: ground gate and clock resets.
ESTIMATOR_MESSAGES = tuple(sorted({m for names in PREFERENCE.values() for m in names}
                                  | {"HEARTBEAT", "EXTENDED_SYS_STATE", "SYSTEM_TIME", "ESC_INFO"}))  # fmt: skip


class _Msg:
    """A pymavlink-like view of a mavlink_direct message: fields as attributes, the type and the sender."""

    def __init__(self, mtype: str, fields: dict[str, Any], sysid: int, compid: int) -> None:
        self.__dict__.update(fields)
        self._mtype, self._src = mtype, (sysid, compid)

    def get_type(self) -> str:
        return self._mtype

    def get_srcSystem(self) -> int:  # noqa: N802 - pymavlink's name
        return self._src[0]

    def get_srcComponent(self) -> int:  # noqa: N802 - pymavlink's name
        return self._src[1]


class EstimatedLiveWind:
    """``estimated``: the live UKF in a worker thread (see the module docstring).

    Build it before the first telemetry arrives (loading the kernels holds the GIL briefly)."""

    mode = "estimated"

    def __init__(self, vehicle_params: VehicleParams, upwind: UpwindFilter, target_system: int | None = None,
                 max_queue: int = 2000, esc_component: int | None = None) -> None:  # fmt: skip
        self.core = LiveCore(LiveConfig(vehicle=vehicle_params, target_system=target_system,
                                        esc_component=esc_component))  # fmt: skip
        self.worker = EstimatorWorker(self.core, max_queue=max_queue)
        self.worker.start()
        self.upwind = upwind
        self.watch = EstimatorWatch()

    def sink(self, name: str, fields: dict[str, Any], t: float, sysid: int = 1, compid: int = 1) -> None:
        """One message from MAVSDK's thread (never blocks)."""
        if name in ESTIMATOR_MESSAGES:
            self.worker.submit(_Msg(name, fields, sysid, compid))

    def stop(self) -> None:
        self.worker.stop()

    def info(self, t: float) -> WindInfo:
        snap = self.worker.snapshot()
        if not snap.ready:
            return self.upwind.make(np.zeros(3), np.eye(3) * 100.0)
        return self.upwind.make(snap.wind_ned, snap.cov_ned)

    def ready(self) -> bool:
        return self.worker.snapshot().ready

    def missing(self) -> str:
        return self.worker.snapshot().status

    def fault(self, t: float) -> Abort | None:
        snap = self.worker.snapshot()
        if snap.withheld is not None:  # the vehicle is not the model's: no wind, rather than a wrong one
            return Abort("estimator-fault", snap.withheld)
        if not snap.ready:
            return None
        return self.watch.check(t, snap.wind_ned, snap.cov_ned, dict(snap.rejected), snap.accepted.get("imu", 0),
                                snap.vehicle_time_s)  # fmt: skip

    def describe(self) -> str:
        snap = self.worker.snapshot()
        line = snap.inputs_line or "the live UKF on the telemetry (worker thread)"
        return f"{line}; {snap.model_note}" if snap.model_note else line

    def report(self) -> dict[str, Any]:
        """The estimator's figures at the end of the mission (stops the worker: the core is then ours)."""
        self.stop()
        snap, c = self.worker.snapshot(), self.worker.counts
        summary = self.core.summary()
        return {"accepted": dict(snap.accepted), "rejected": dict(snap.rejected),
                "imu_message": summary["inputs"].get("imu", ""), "inputs": summary["inputs"],
                "inputs_line": summary["inputs_line"], "model_note": summary["model_note"],
                "span_s": float(self.core.est.span_s), "restarts": snap.restarts,
                "imu_decimated": int(c["decimated_imu"]), "dropped": int(c["dropped_imu"] + c["dropped_other"]),
                "queue_high_water": int(c["high_water"]), "errors": int(c["errors"]),
                "wind_ned_m_s": summary["wind_ned_m_s"]}  # fmt: skip


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
