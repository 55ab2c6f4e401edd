"""dronekit 2.9.2 (the last release; ArduPilot-minded) against the SITL, as against a PX4 (issue 17).

- ``vehicle.version`` after ``connect``: the SITL greets a new ground station with AUTOPILOT_VERSION
  (PX4 sends it unasked on serial links), so dronekit's version is set although the short parameter
  download ends before dronekit's once-per-heartbeat request would be answered.
- Parameters: REAL32 ones read and set as usual. dronekit sends every PARAM_SET as REAL32 and reads
  values by cast, so an INT32 parameter reads as a denormal float and its set is refused with
  PARAM_ERROR TYPE_MISMATCH, exactly as against PX4.
- ``simple_takeoff(5)`` is 5 m AMSL: accepted, no climb, PX4's STATUSTEXT; an AMSL altitude climbs.
- ``simple_goto`` (a MISSION_ITEM with current = 2, ArduPilot's guided goto): refused with a STATUSTEXT
  saying so, as PX4 explains its mission refusals.

dronekit 2.9.2 needs two shims on Python 3.10+: ``collections.MutableMapping`` (moved to
``collections.abc``) and the ``future`` package (``past.builtins``); both are test-only.
"""

from __future__ import annotations

import collections
import collections.abc
import os
import time
from typing import Any

import pytest
from link_support import free_port, running, udp_to, wait_until

from sitl.autopilot.flight_modes import Mode
from wire.dialect import mavlink as M  # noqa: N812

collections.MutableMapping = collections.abc.MutableMapping  # type: ignore[attr-defined]
dronekit = pytest.importorskip("dronekit")


def test_dronekit_version_params_takeoff() -> None:
    os.environ["MAVLINK20"] = "1"
    port = free_port()
    with running([udp_to(port)]) as link:
        for mid in (M.MAVLINK_MSG_ID_HIL_SENSOR, M.MAVLINK_MSG_ID_HIGHRES_IMU, M.MAVLINK_MSG_ID_ESC_STATUS):
            link.streams.set_interval(mid, -1, 0.0)
        wait_until(lambda: link.sim.t > 0.3, 10.0, "the SITL streaming")
        texts: list[str] = []
        v: Any = dronekit.connect(f"udpin:127.0.0.1:{port}", heartbeat_timeout=30)
        try:
            v.add_message_listener("STATUSTEXT", lambda _v, _n, m: texts.append(str(m.text)))
            # Set without any request from the user: the SITL answers dronekit's first HEARTBEAT (on a loaded
            # machine the answer can land a moment after connect() returns, hence the short bound).
            wait_until(lambda: v.version.major is not None, 5.0, "AUTOPILOT_VERSION")
            assert str(v.version) == "PX4Copter-1.15.0", v.version
            assert v.capabilities.mission_int and v.capabilities.ftp
            # REAL32: read, set, read back.
            assert v.parameters["MPC_XY_CRUISE"] == pytest.approx(link.sim.fc.config.cruise_speed_m_s)
            v.parameters["MPC_XY_CRUISE"] = 2.5
            wait_until(lambda: v.parameters["MPC_XY_CRUISE"] == pytest.approx(2.5), 5.0, "set echoed")
            assert link.sim.fc.config.cruise_speed_m_s == pytest.approx(2.5)
            # INT32: dronekit's cast reading and REAL32 set meet PX4's bytewise INT32 and its type check.
            assert 0 < v.parameters["NAV_DLL_ACT"] < 1e-40  # int32 3 seen as a float
            assert v.parameters.set("NAV_DLL_ACT", 1, retries=1) is False
            assert link.datalink.action == 3 and link.counters["params_type_mismatch"] >= 1

            v.armed = True
            wait_until(lambda: link.sim.fc.armed, 10.0, "armed")
            v.simple_takeoff(5)  # 5 m AMSL: below the vehicle
            wait_until(lambda: any("Already higher than takeoff altitude" in t for t in texts), 10.0, "reason")
            assert link.sim.fc.on_ground and link.sim.fc.mode == Mode.HOLD
            v.simple_takeoff(link.home_amsl() + 2.0)
            wait_until(lambda: -link.sim.position[2] > 1.5, 30.0, "climb to 2 m")
            # simple_goto is ArduPilot's guided goto (MISSION_ITEM current = 2), which PX4 has not: refused,
            # and the refusal says why (it used to be a bare MISSION_ACK DENIED).
            v.simple_goto(dronekit.LocationGlobalRelative(v.location.global_frame.lat, v.location.global_frame.lon, 3))
            wait_until(lambda: any("Goto (current=2) unsupported, use DO_REPOSITION" in t for t in texts), 10.0,
                       "the goto refusal's reason")  # fmt: skip
            time.sleep(0.2)
            assert link.counters["handler_errors"] == 0
        finally:
            v.close()
