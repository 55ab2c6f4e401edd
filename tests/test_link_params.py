"""PX4's parameter types on the wire (issue 16.4): INT32 where PX4 has INT32, REAL32 otherwise,
INT32 values encoded bytewise in the float field, a PARAM_SET of the wrong type refused with
PARAM_ERROR TYPE_MISMATCH as PX4's mavlink_parameters.cpp does (no PARAM_VALUE, value kept).
Peers: pymavlink (raw frames) and the real MAVSDK (``set_param_int`` / ``set_param_float``)."""

from __future__ import annotations

import asyncio
import os
import time
from collections.abc import Iterator
from typing import Any

import pytest
from link_support import autopilot, free_port, quiet_running, running, udp_to, wait_until
from pymavlink import mavutil

from sitl.link import SitlLink
from wire import param_codec
from wire.dialect import mavlink as M  # noqa: N812

#: PX4's types of the PX4-named parameters the SITL has (PX4's commander/navigator/mavlink *_params.c).
PX4_TYPES = {"GF_ACTION": "INT32", "NAV_DLL_ACT": "INT32", "COM_DL_LOSS_T": "INT32", "MAV_SYS_ID": "INT32",
             "MIS_TAKEOFF_ALT": "REAL32", "MPC_TKO_SPEED": "REAL32", "MPC_LAND_SPEED": "REAL32",
             "MPC_XY_CRUISE": "REAL32", "RTL_RETURN_ALT": "REAL32", "COM_OF_LOSS_T": "REAL32",
             "COM_DISARM_LAND": "REAL32"}  # fmt: skip


def test_codec_round_trip_is_px4_bytewise() -> None:
    # INT32 3 travels as the float whose bytes are those of int32 3 (a denormal), not as 3.0.
    assert param_codec.encode(3, M.MAV_PARAM_TYPE_INT32) == pytest.approx(4.2e-45, rel=0.1)
    for v in (0, 1, 3, 300, -1, 2**31 - 1, -(2**31)):
        assert param_codec.decode(param_codec.encode(v, M.MAV_PARAM_TYPE_INT32), M.MAV_PARAM_TYPE_INT32) == v
    assert param_codec.encode(2.5, M.MAV_PARAM_TYPE_REAL32) == 2.5


class Gcs:
    """A pymavlink ground station (system 255)."""

    def __init__(self, port: int) -> None:
        os.environ["MAVLINK20"] = "1"
        self.conn = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}", source_system=255, dialect="common")
        assert self.conn.recv_match(type="HEARTBEAT", blocking=True, timeout=10) is not None

    def recv(self, mtype: str | list[str], cond: Any = None, timeout: float = 3.0) -> Any:
        t_end = time.monotonic() + timeout
        while time.monotonic() < t_end:
            m = self.conn.recv_match(type=mtype, blocking=True, timeout=max(0.01, t_end - time.monotonic()))
            if m is not None and (cond is None or cond(m)):
                return m
        return None

    def set(self, name: str, field: float, ptype: int) -> Any:
        """PARAM_SET; the answer (PARAM_VALUE or PARAM_ERROR of this name)."""
        while self.conn.recv_match(blocking=False) is not None:
            pass
        self.conn.mav.param_set_send(1, 1, name.encode(), field, ptype)
        return self.recv(["PARAM_VALUE", "PARAM_ERROR"], lambda m: m.param_id == name)


@pytest.fixture
def sitl() -> Iterator[tuple[SitlLink, Gcs]]:
    port = free_port()
    with quiet_running(port) as link:
        gcs = Gcs(port)
        yield link, gcs
        gcs.conn.close()


def test_list_carries_px4_types_and_bytewise_ints(sitl: tuple[SitlLink, Gcs]) -> None:
    link, gcs = sitl
    gcs.conn.mav.param_request_list_send(1, 1)
    seen: dict[str, Any] = {}
    while True:
        m = gcs.recv("PARAM_VALUE")
        assert m is not None, f"list incomplete: {len(seen)} received"
        seen[m.param_id] = m
        if len(seen) == m.param_count:
            break
    types = {n: param_codec.TYPE_NAMES[m.param_type] for n, m in seen.items()}
    assert {n: types[n] for n in PX4_TYPES} == PX4_TYPES
    assert all(t == "REAL32" for n, t in types.items() if n.startswith(("CTL_", "SIM_")))
    # INT32 values decode bytewise (a cast would read 3 as 4.2e-45).
    dll = seen["NAV_DLL_ACT"]
    assert param_codec.decode(dll.param_value, dll.param_type) == link.datalink.action == 3
    assert param_codec.decode(seen["MAV_SYS_ID"].param_value, M.MAV_PARAM_TYPE_INT32) == 1
    assert param_codec.decode(seen["COM_DL_LOSS_T"].param_value, M.MAV_PARAM_TYPE_INT32) == 10


def test_set_with_the_right_type_and_refusals_as_px4(sitl: tuple[SitlLink, Gcs]) -> None:
    link, gcs = sitl
    int32, real32 = M.MAV_PARAM_TYPE_INT32, M.MAV_PARAM_TYPE_REAL32
    # INT32 set, bytewise: accepted, echoed as INT32, applied.
    m = gcs.set("NAV_DLL_ACT", param_codec.encode(1, int32), int32)
    assert m.get_type() == "PARAM_VALUE" and m.param_type == int32
    assert param_codec.decode(m.param_value, int32) == 1 and link.datalink.action == 1
    m = gcs.set("GF_ACTION", param_codec.encode(4, int32), int32)
    assert m.get_type() == "PARAM_VALUE" and link.geofence.action == 4
    # The wrong type: PARAM_ERROR TYPE_MISMATCH, no PARAM_VALUE, the value stays (PX4).
    m = gcs.set("NAV_DLL_ACT", 3.0, real32)
    assert m.get_type() == "PARAM_ERROR" and m.error == param_codec.PARAM_ERROR_TYPE_MISMATCH
    assert gcs.recv("PARAM_VALUE", lambda v: v.param_id == "NAV_DLL_ACT", timeout=0.5) is None
    assert link.datalink.action == 1
    m = gcs.set("MPC_XY_CRUISE", param_codec.encode(3, int32), int32)
    assert m.get_type() == "PARAM_ERROR" and m.error == param_codec.PARAM_ERROR_TYPE_MISMATCH
    # A type PX4 does not have (INT16): TYPE_UNSUPPORTED; an unknown name: DOES_NOT_EXIST.
    m = gcs.set("NAV_DLL_ACT", 1.0, M.MAV_PARAM_TYPE_INT16)
    assert m.get_type() == "PARAM_ERROR" and m.error == param_codec.PARAM_ERROR_TYPE_UNSUPPORTED
    m = gcs.set("NO_SUCH_PARAM", 1.0, real32)
    assert m.get_type() == "PARAM_ERROR" and m.error == M.MAV_PARAM_ERROR_DOES_NOT_EXIST
    gcs.conn.mav.param_request_read_send(1, 1, b"NO_SUCH_PARAM", -1)
    m = gcs.recv("PARAM_ERROR")
    assert m is not None and m.error == M.MAV_PARAM_ERROR_DOES_NOT_EXIST and m.param_id == "NO_SUCH_PARAM"
    # Stricter than PX4: out of range / read-only is refused with the reason, then the unchanged value.
    m = gcs.set("NAV_DLL_ACT", param_codec.encode(9, int32), int32)
    assert m.get_type() == "PARAM_ERROR" and m.error == M.MAV_PARAM_ERROR_VALUE_OUT_OF_RANGE
    echo = gcs.recv("PARAM_VALUE", lambda v: v.param_id == "NAV_DLL_ACT")
    assert param_codec.decode(echo.param_value, int32) == 1
    m = gcs.set("MAV_SYS_ID", param_codec.encode(7, int32), int32)
    assert m.get_type() == "PARAM_ERROR" and m.error == M.MAV_PARAM_ERROR_READ_ONLY
    assert link.counters["params_type_mismatch"] == 3 and link.counters["params_unknown"] == 2


mavsdk = pytest.importorskip("mavsdk")


@pytest.mark.asyncio
async def test_mavsdk_set_param_int_and_float() -> None:
    from mavsdk.asyncio import ComponentType, Configuration, Mavsdk
    from mavsdk.asyncio.plugins.param import ParamAsync

    port = free_port()
    with running([udp_to(port)]) as link:
        async with Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION)) as sdk:
            drone = await autopilot(sdk, f"udpin://127.0.0.1:{port}", 10.0)
            assert drone is not None
            param = ParamAsync(drone)
            await asyncio.wait_for(param.set_param_int("NAV_DLL_ACT", 2), 10)
            assert await asyncio.wait_for(param.get_param_int("NAV_DLL_ACT"), 10) == 2
            assert link.datalink.action == 2
            await asyncio.wait_for(param.set_param_float("MPC_XY_CRUISE", 3.5), 10)
            assert await asyncio.wait_for(param.get_param_float("MPC_XY_CRUISE"), 10) == pytest.approx(3.5)
            assert link.sim.fc.config.cruise_speed_m_s == pytest.approx(3.5)
            # The typed getter of the other type fails (MAVSDK checks the PARAM_VALUE's type).
            with pytest.raises(Exception):  # noqa: B017 - mavsdk's ParamError (WrongType)
                await asyncio.wait_for(param.get_param_float("NAV_DLL_ACT"), 10)
            # The wrong setter: refused by the autopilot (MAVSDK reports an error), the value stays.
            for coro in (param.set_param_float("NAV_DLL_ACT", 1.0), param.set_param_int("MPC_XY_CRUISE", 7)):
                with pytest.raises(Exception):  # noqa: B017 - ParamError or our bound
                    await asyncio.wait_for(coro, 20)
            assert link.datalink.action == 2 and link.sim.fc.config.cruise_speed_m_s == pytest.approx(3.5)
            wait_until(lambda: link.counters["params_type_mismatch"] >= 2, 2.0, "mismatches counted")
