"""The mission's side of a run (``windseek mission --rrd``, :mod:`recording.mission_rrd`) and its merge into
the SITL's recording (:func:`recording.finalize.rewrite_summary`), without a vehicle: a stand-in mission
loop with a known Gaussian posterior drives the recorder as the MAVSDK runner does. The end-to-end check
with the real infotaxis through MAVSDK and the SITL is ``tests/test_mission_mavsdk.py``."""

from __future__ import annotations

import math
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np

from mission.strategies.base import WindInfo
from mission.vehicle import VehicleState
from recording.finalize import main as merge_main
from recording.mission_rrd import MissionRecorder
from recording.read import RrdLog
from recording.recorder import RunRecorder
from wire.names import declaration_fields, state_fields


class _Gaussian:
    """A probabilistic strategy's stand-in: a posterior peaked at (30, -5) m, its credible radius 4 m."""

    centre = (30.0, -5.0)

    def posterior_map(self, cell_m: float = 1.0) -> tuple[np.ndarray, tuple[float, float, float, float]]:
        extent = (0.0, 60.0, -20.0, 20.0)
        n = np.arange(extent[0], extent[1], cell_m) + 0.5 * cell_m
        e = np.arange(extent[2], extent[3], cell_m) + 0.5 * cell_m
        p = np.exp(-0.5 * (((n[:, None] - self.centre[0]) / 3.0) ** 2 + ((e[None, :] - self.centre[1]) / 2.0) ** 2))
        return p / p.sum(), extent

    def credible_region(self) -> tuple[np.ndarray, float]:
        return np.array(self.centre), 4.0


class _Vehicle:
    """The vehicle's side the recorder taps: its state, the setpoints and the status it sends."""

    def __init__(self) -> None:
        self.state = VehicleState(armed=True, mode="OFFBOARD", pos=np.zeros(3))
        self.sent: list[Any] = []
        self.published: list[tuple[str, str]] = []

    def send_setpoint(self, pos: np.ndarray | None, vel: np.ndarray | None, yaw: float | None) -> None:
        self.sent.append(pos)

    def publish(self, pairs: list[tuple[str, str]]) -> None:
        self.published += pairs


def _fly(path: Path) -> tuple[_Vehicle, list[float], MissionRecorder]:
    """10 s of search ticks at 10 Hz (t = 20 .. 30 s) with a setpoint each, two states and a declaration."""
    v = _Vehicle()
    ticks: list[float] = []
    wind = WindInfo(wind_ned=np.array([-5.0, 0.0, 0.0]), cov_ned=np.eye(3) * 0.04, upwind_rad=0.0)
    loop = SimpleNamespace(v=v, strategy=_Gaussian(), on_tick=ticks.append, wind_info=wind)
    rec = MissionRecorder(path, strategy="infotaxis", seed=3)
    rec.attach(loop)  # type: ignore[arg-type]  # the parts of a MissionLoop it listens to
    for k in range(101):
        t = 20.0 + 0.1 * k
        v.state.t, v.state.pos = t, np.array([2.0 * k * 0.1, 0.0, -3.0])
        loop.on_tick(t)
        v.send_setpoint(np.array([v.state.pos[0] + 1.0, 0.0, -3.0]), None, 0.0)
        if k in (0, 50):
            v.publish([state_fields("search" if k == 0 else "exploit")])
    v.publish(declaration_fields(30.0, [30.0, -5.0, -2.0], 0.9))
    rec.close(None)
    return v, ticks, rec


def test_the_mission_recording_holds_the_posterior_setpoints_and_states(tmp_path: Path) -> None:
    v, ticks, rec = _fly(tmp_path / "mission.rrd")
    assert len(ticks) == 101 and len(v.sent) == 101 and len(v.published) == 6  # the taps pass everything on
    log = RrdLog(tmp_path / "mission.rrd")
    t_img, _ = log.images("map/posterior/image")
    np.testing.assert_allclose(t_img, np.arange(20.0, 30.5, 1.0), atol=1e-6)  # 1 Hz of vehicle time
    assert rec.posteriors == 11 and rec.posterior_cpu_s > 0.0
    t_sp, sp = log.vectors("world/setpoint", "Points3D:positions")
    assert len(t_sp) == 101 and np.allclose(sp[-1], [21.0, 0.0, -3.0])
    assert [s for _, s in log.states("phases/strategy")] == ["search", "exploit"]
    assert "world/vehicle" in log.entity_paths() and "map/sources/declared" in log.entity_paths()
    t_w, w = log.scalars("wind/north/estimate")
    assert len(t_w) >= 40 and np.allclose(w, -5.0)
    assert log.property_value("posterior", "logged") == 11


def test_the_merge_adds_only_what_the_mission_alone_knows(tmp_path: Path) -> None:
    """The SITL's file keeps its own path, states and summary; it gains the posterior and the setpoints."""
    _fly(tmp_path / "mission.rrd")
    sitl = tmp_path / "sitl.rrd"
    with RunRecorder(sitl, scenario="open-field", strategy="infotaxis") as rec:
        for k in range(400):  # the SITL's truth, 0 .. 40 s
            rec.vehicle(0.1 * k, [0.1 * k, 0.0, -3.0], [1.0, 0.0, 0.0, 0.0])
    before = RrdLog(sitl)
    s = before.summary()
    assert s is not None and "map/posterior/image" not in before.entity_paths()
    n_path = len(before.column("map/path", "LineStrips2D:strips")[0])
    assert merge_main([str(sitl), str(tmp_path / "mission.rrd")]) == 0  # python -m recording.finalize SITL MISSION
    log = RrdLog(sitl)
    assert log.application_ids == ["windseek"]  # one recording: the mission's chunks joined the SITL's
    paths = set(log.entity_paths())
    assert {"map/posterior/image", "map/posterior/credible", "map/setpoint", "world/setpoint"} <= paths
    assert "phases/strategy" not in paths and "map/sources/declared" not in paths  # the mission's copies stay out
    assert len(log.column("map/path", "LineStrips2D:strips")[0]) == n_path  # the path is the SITL's alone
    t_img, imgs = log.images("map/posterior/image")
    _, tr = log.vectors("map/posterior/image", "Transform3D:translation")
    assert len(t_img) == 11
    img = imgs[-1]
    h, w = img.shape[:2]
    row, col = np.unravel_index(np.argmax(img[..., 3]), (h, w))
    north, east = -(tr[-1][1] + row + 0.5), tr[-1][0] + col + 0.5  # 1 m cells
    assert math.hypot(north - 30.0, east + 5.0) <= 1.0
    _, labels = log.column("map/posterior/credible", "LineStrips2D:labels")
    assert labels[-1] == ["credible 4.0 m"]
    after = log.summary()
    assert after is not None and after.kind == s.kind and not after.kind.startswith("windseek mission")


class _Broken(_Gaussian):
    def posterior_map(self, cell_m: float = 1.0) -> tuple[np.ndarray, tuple[float, float, float, float]]:
        raise MemoryError("no room for the grid")


def test_a_failing_recording_never_stops_the_mission(tmp_path: Path) -> None:
    """The first failure (here the strategy's posterior_map) stops the recording, said once; every tick,
    setpoint and status still reaches the loop and the vehicle, and the file closes with why."""
    v, lines, ticks = _Vehicle(), [], []
    v.say = lines.append  # type: ignore[attr-defined]
    loop = SimpleNamespace(v=v, strategy=_Broken(), on_tick=ticks.append, wind_info=None)
    rec = MissionRecorder(tmp_path / "m.rrd")
    rec.attach(loop)  # type: ignore[arg-type]
    for k in range(30):
        v.state.t = 10.0 + 0.1 * k
        loop.on_tick(v.state.t)
        v.send_setpoint(np.zeros(3), None, None)
    v.publish([state_fields("search")])
    rec.close(None)
    assert len(ticks) == 30 and len(v.sent) == 30 and len(v.published) == 1
    assert rec.failed is not None and "no room" in rec.failed
    assert len(lines) == 1 and "recording stopped" in lines[0], lines
    s = RrdLog(tmp_path / "m.rrd").summary()
    assert s is not None and any("stopped mid-flight" in n for n in s.notes)
