"""The companions' side of the route through PX4 (their lock-on to the autopilot): the live estimator takes
rotor telemetry from windseek's component 158 when told (``esc_component``), and PX4's placeholder
ESC_STATUS (component 1) then stays out; without it, 158 is another component and is ignored."""

from __future__ import annotations

from typing import Any

from estimator.live import LiveConfig, LiveCore
from vehicle.vehicle_file import load_vehicle
from wire.dialect import mavlink


def _from(sysid: int, compid: int, msg: Any) -> Any:
    """``msg`` as it arrives from (sysid, compid): packed and parsed back (the header carries the source)."""
    frame = msg.pack(mavlink.MAVLink(None, sysid, compid))
    return mavlink.MAVLink(None, 0, 0).parse_buffer(frame)[0]


def _feed(core: LiveCore) -> None:
    core.handle(_from(2, 1, mavlink.MAVLink_heartbeat_message(2, 12, 129, 0, 4, 3)))  # PX4, system 2
    for k in range(5):
        t_us = 1_000_000 + 20_000 * k
        core.handle(_from(2, 1, mavlink.MAVLink_esc_status_message(0, t_us, [6000] * 4, [0.0] * 4, [0.0] * 4)))
        core.handle(_from(2, 158, mavlink.MAVLink_esc_status_message(0, t_us, [3750] * 4, [0.0] * 4, [0.0] * 4)))


def test_rotor_telemetry_from_the_peripheral_component_when_asked() -> None:
    core = LiveCore(LiveConfig(vehicle=load_vehicle("nasa_quad"), esc_component=158))
    _feed(core)
    assert core.target == (2, 1)
    assert core.counters["esc_other_component"] == 5  # PX4's own placeholder ESC_STATUS
    assert core.counters["other_component"] == 0  # 158's ESC_STATUS went through


def test_without_it_the_peripheral_is_another_component() -> None:
    core = LiveCore(LiveConfig(vehicle=load_vehicle("nasa_quad")))
    _feed(core)
    assert core.counters["other_component"] == 5 and core.counters["esc_other_component"] == 0
