"""The templates in templates/ work: a strategy flies a trial, a wind model drives the world, a
transport carries the SITL's MAVLink (so the examples never fall behind the code)."""

from __future__ import annotations

import importlib.util
import math
import socket
import sys
import time
from pathlib import Path
from types import ModuleType

import numpy as np
import pytest

from mission.runners.inprocess import run_trial
from mission.strategies import STRATEGIES
from mission.strategies.params import PARAM_CLASSES, CommonParams
from sitl.scenario import load_scenario, parse_scenario
from sitl.simulation import Simulation
from sitl.world.wind import WIND_MODELS, register_wind_model

TEMPLATES = Path(__file__).resolve().parent.parent / "templates"


def _load(name: str) -> ModuleType:
    spec = importlib.util.spec_from_file_location(f"template_{name}", TEMPLATES / f"{name}.py")
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod
    spec.loader.exec_module(mod)
    return mod


def test_strategy_template_flies_an_in_process_trial(monkeypatch: pytest.MonkeyPatch) -> None:
    mod = _load("strategy")
    monkeypatch.setitem(STRATEGIES, "upwind-first-hit", mod.UpwindFirstHit)
    monkeypatch.setitem(PARAM_CLASSES, "upwind-first-hit", CommonParams)
    r = run_trial("open-field", "upwind-first-hit", "oracle", seed=3, time_limit_s=120.0)
    # It flies upwind into the plume and declares its first detection: downwind of the true source.
    assert r.declared_ned is not None and r.cause in ("", "declared-far"), r
    src = load_scenario("open-field").plume.plume.sources[0].position_ned  # type: ignore[union-attr]
    assert 0.0 < r.declared_ned[0] < src[0] + 5.0 and r.time_s > 5.0


def test_wind_model_template_drives_the_world(monkeypatch: pytest.MonkeyPatch) -> None:
    mod = _load("wind_model")
    monkeypatch.setitem(WIND_MODELS, "turning", mod.make_turning_wind)
    sc = parse_scenario({"name": "turning", "wind": {"model": "turning", "speed_m_s": 4.0, "from_deg": 0.0,
                                                     "options": {"turn_deg_per_min": 30.0}},
                         "start": {"position_ned": [0.0, 0.0, -5.0], "airborne": True}})  # fmt: skip
    sim = Simulation(sc, seed=1, autostart_route=False)
    assert sim.wind.kernel() is None  # sampled in Python each physics tick
    sim.run(60.0)
    w = sim.wind_at_vehicle
    assert math.degrees(math.atan2(w[1], w[0])) == pytest.approx(-180.0 + 30.0, abs=1e-6)  # turned 30 deg
    assert not sim.crashed and np.hypot(*sim.position[0:2]) < 3.0  # the autopilot held its point in it
    with pytest.raises(ValueError, match="turn_deg_per_min"):
        register_wind_model("turning", mod.make_turning_wind)
        Simulation(parse_scenario({"name": "x", "wind": {"model": "turning", "speed_m_s": 1.0, "from_deg": 0.0,
                                                         "options": {"bogus": 1}}}))  # fmt: skip


def test_transport_template_carries_the_sitl(tmp_path: Path) -> None:
    from pymavlink.dialects.v20 import common as mav2

    from sitl.link import SitlLink

    mod = _load("transport")
    server, client = str(tmp_path / "sitl.sock"), str(tmp_path / "gcs.sock")
    peer = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    peer.bind(client)
    peer.settimeout(5.0)
    link = SitlLink(Simulation(load_scenario("paper-s1"), autostart_route=False),
                    [mod.UnixDatagramTransport(server, client)], speed=5.0).start()  # fmt: skip
    try:
        parser = mav2.MAVLink(None, 255, 190)
        parser.robust_parsing = True
        seen: set[str] = set()
        end = time.monotonic() + 10.0
        while time.monotonic() < end and not {"HEARTBEAT", "PARAM_VALUE"} <= seen:
            if "HEARTBEAT" in seen:
                peer.sendto(mav2.MAVLink_param_request_read_message(1, 1, b"MPC_XY_CRUISE", -1).pack(parser), server)
            for m in parser.parse_buffer(peer.recv(65536)) or []:
                seen.add(m.get_type())
        assert {"HEARTBEAT", "PARAM_VALUE"} <= seen
    finally:
        link.close()
        peer.close()
