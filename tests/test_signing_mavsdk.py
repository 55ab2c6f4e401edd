"""Signing for the project's other programs against a signed SITL (issue 14.5):

- MAVSDK 4.1 has no signing: its commands to a signed SITL are dropped (shown here), so
  ``windseek mission`` runs MAVSDK over ``raw://`` through ``wire.signing_bridge``, which signs what
  MAVSDK sends and hands MAVSDK only correctly signed frames: arm, take-off and landing work and a
  forged unsigned HEARTBEAT never reaches MAVSDK.
- ``windseek estimator --signing-key``: its WIND_COV reaches the SITL signed; its JSON summary has
  the signing counts and never the key.
"""

from __future__ import annotations

import asyncio
import json
import socket
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
from link_support import autopilot, first, free_port, running, udp_to, wait_until

from mission.runners.autopilot import find_autopilot
from sitl.scenario import load_scenario
from wire import signing
from wire.dialect import mavlink as M  # noqa: N812
from wire.signing_bridge import SigningBridge, strip_signature

pytest.importorskip("mavsdk")
from mavsdk.asyncio import ComponentType, Configuration, Mavsdk  # noqa: E402
from mavsdk.asyncio.plugins.action import ActionAsync  # noqa: E402
from mavsdk.asyncio.plugins.telemetry import TelemetryAsync  # noqa: E402

KEY = signing.parse_key("c0ffee00" * 8, "test")
ROOT = Path(__file__).resolve().parents[1]


def _gcs() -> Mavsdk:
    return Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION))


def test_strip_signature_gives_the_plain_frame() -> None:
    signed_enc, plain_enc = M.MAVLink(None, 1, 1), M.MAVLink(None, 1, 1)
    signing.configure(signed_enc, KEY)
    msg = M.MAVLink_command_long_message(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0)
    signed = bytes(msg.pack(signed_enc))
    assert len(signed) == len(bytes(msg.pack(plain_enc))) + 13
    assert strip_signature(signed) == bytes(msg.pack(plain_enc))
    parsed = M.MAVLink(None).parse_buffer(strip_signature(signed))
    assert parsed and parsed[0].get_type() == "COMMAND_LONG" and parsed[0].param1 == 1


@pytest.mark.asyncio
async def test_mavsdk_without_signing_is_refused_by_a_signed_sitl() -> None:
    port = free_port()
    with running([udp_to(port)], signing_key=KEY) as link:
        async with _gcs() as sdk:
            # MAVSDK parses the signed telemetry without checking it, so it finds the autopilot ...
            drone = await autopilot(sdk, f"udpin://127.0.0.1:{port}", 20.0)
            assert drone is not None
            wait_until(lambda: link.sim.t > 0.3, 5.0, "a GNSS fix")
            # ... but everything it sends is unsigned: dropped, counted, never acted on.
            with pytest.raises(Exception):  # noqa: B017 - mavsdk ActionError (timeout) or our bound
                await asyncio.wait_for(ActionAsync(drone).arm(), 15.0)
            assert not link.sim.fc.armed and link.counters["rx_unauthenticated"] > 0


@pytest.mark.asyncio
async def test_mavsdk_through_the_signing_bridge_flies() -> None:
    port = free_port()
    with running([udp_to(port)], signing_key=KEY) as link:
        sim = link.sim
        async with _gcs() as sdk:
            bridge = SigningBridge(sdk._mavsdk, f"udpin://127.0.0.1:{port}", KEY).start()
            try:
                await sdk.add_any_connection("raw://")
                drone = await find_autopilot(sdk, 20.0)
                assert drone is not None, bridge.stats()
                tel, action = TelemetryAsync(drone), ActionAsync(drone)
                await first(tel.subscribe_health_all_ok(), bool, 15.0, "health all ok")
                await action.arm()
                await action.takeoff()
                await first(tel.subscribe_position(), lambda p: p.relative_altitude_m > 2.0, 30.0, "climb")
                # A forged unsigned HEARTBEAT "from the autopilot" (allowlisted by PX4's rules, so
                # pymavlink accepts it) is not trusted: MAVSDK never sees it.
                forger = M.MAVLink(None, 1, 1)
                hb = forger.heartbeat_encode(2, 12, 0, 0, 6).pack(forger)  # MAV_STATE_EMERGENCY
                with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as forge:
                    forge.sendto(bytes(hb), ("127.0.0.1", port))
                wait_until(lambda: bridge.stats().get("rx_unsigned_allowed_dropped", 0) >= 1, 5.0, "forgery dropped")
                await action.land()
                await first(tel.subscribe_armed(), lambda a: not a, 60.0, "landed and disarmed")
                st = bridge.stats()
                assert st["tx_signed"] > 0 and st["rx_passed"] > 0, st
                assert link.counters["rx_unauthenticated"] == 0, dict(link.counters)
                assert link.endpoint.signing_counts()["signed_ok"] > 0
                assert not sim.fc.armed and sim.fc.on_ground
            finally:
                bridge.close()


def test_estimator_signs_its_wind_cov(tmp_path: Path) -> None:
    key_file = tmp_path / "key.hex"
    key_file.write_text(KEY.secret.hex())
    port = free_port()
    # Hovering from the start (paper-s1): the estimator publishes once it has judged the model to fit.
    with running([udp_to(port)], sc=load_scenario("paper-s1"), signing_key=KEY) as link:
        got: dict[str, Any] = {"authentic": 0, "other": 0}

        def on_rx(msg: Any, _lk: Any) -> None:
            if msg.get_type() == "WIND_COV":
                got["authentic" if link.endpoint.authentic(msg) else "other"] += 1

        link.endpoint.rx_hooks.append(on_rx)
        res = subprocess.run(
            [sys.executable, "-m", "windseek.cli", "estimator", "--connect", f"udpin://127.0.0.1:{port}",
             "--signing-key", str(key_file), "--duration", "10", "--json",
             "--connect-timeout", "60", "--link-timeout", "20"],
            capture_output=True, text=True, timeout=240, cwd=ROOT)  # fmt: skip
    assert res.returncode == 0, res.stderr[-3000:]
    s = json.loads(res.stdout.strip().splitlines()[-1])
    assert s["wind_cov_published"] > 0 and s["signing"]["signed_ok"] > 0 and s["signing"]["rejected"] == 0, s
    assert got["authentic"] > 0 and got["other"] == 0
    assert link.counters["rx_unauthenticated"] == 0
    assert KEY.secret.hex() not in res.stdout + res.stderr and "signing on" in res.stderr
