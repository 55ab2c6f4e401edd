"""Shared helpers of the HIL tests: a pymavlink stand-in for PX4's simulator side over real sockets,
a runner serving in a thread, a small test scenario.

:class:`FakePx4` speaks PX4's side of the simulator protocol with pymavlink's own ``common``
dialect (not windseek's): it reads HIL_SENSOR / HIL_GPS / HIL_STATE_QUATERNION and answers each
HIL_SENSOR (``id`` 0) with a HIL_ACTUATOR_CONTROLS stamped with that sensor time, as
``simulator_mavlink`` does in lockstep. What it answers (outputs, mode, flags, whether and when
it answers) is set by the test through :attr:`FakePx4.policy`.
"""

from __future__ import annotations

import contextlib
import socket
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any

from pymavlink.dialects.v20 import common as px4mav

from sitl.hil.bridge import HilBridge
from sitl.hil.px4_link import SimLink, TcpSimLink
from sitl.hil.runner import HilOptions, HilRunner
from sitl.scenario import Scenario, parse_scenario
from sitl.world.kernel import FLAG_ON_GROUND

ARMED = 128 | 1  # MAV_MODE_FLAG_SAFETY_ARMED | CUSTOM_MODE_ENABLED, as PX4 sends it
DISARMED = 1


def scenario(**extra: Any) -> Scenario:
    """Still air, a Gaussian plume 20 m north (fast to build), ground start."""
    data: dict[str, Any] = {
        "name": "hil-test", "duration_s": 600.0, "seed": 5,
        "wind": {"velocity_ned": [0.0, 0.0, 0.0]},
        "flight": {"land_speed_m_s": 1.5, "disarm_after_land_s": 0.5},
        "plume": {"model": "gaussian", "sources": [{"position_ned": [20.0, 0.0, -2.0], "rate_g_s": 1.0}],
                  "sensor": {"sample_rate_hz": 10.0}},
    }  # fmt: skip
    data.update(extra)
    return parse_scenario(data)


def hover_output(bridge: HilBridge) -> float:
    """The PX4 motor output that commands the hover rotor speed."""
    return float(bridge.world.vehicle.control["hover_speed"] / bridge.motors.omega_max)


def place_in_air(bridge: HilBridge, height_m: float) -> None:
    """Put the vehicle at ``height_m`` above its start, level, rotors at hover speed (a test set-up)."""
    ph = bridge.world.phys
    ph.x[2] = -float(height_m)
    ph.x[3:6] = 0.0
    bridge.world.set_hover_rotors()
    ph.flags[FLAG_ON_GROUND] = 0.0


@dataclass
class Policy:
    """How the fake PX4 answers: ``outputs(t_us)`` -> 16 floats, ``mode``, ``flags``, ``answer`` (False:
    stay silent), ``delay_s`` (wall seconds before each answer)."""

    outputs: Callable[[int], list[float]] = lambda t_us: [0.0] * 16
    mode: int = DISARMED
    flags: int = 1
    answer: bool = True
    delay_s: float = 0.0


@dataclass
class Seen:
    """What the fake PX4 received, by type; sensor times in order; sources (system, component) by type."""

    counts: dict[str, int] = field(default_factory=dict)
    sensor_us: list[int] = field(default_factory=list)
    sensor_fields: list[int] = field(default_factory=list)
    last: dict[str, Any] = field(default_factory=dict)
    sources: dict[str, set[tuple[int, int]]] = field(default_factory=dict)


class FakePx4:
    """PX4's simulator side over TCP (see the module docstring); ``sysid`` is its system id."""

    def __init__(self, port: int, sysid: int = 2, policy: Policy | None = None) -> None:
        self.sock = socket.create_connection(("127.0.0.1", port), timeout=5.0)
        self.sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self.mav = px4mav.MAVLink(None, sysid, 1)
        self.mav.robust_parsing = True
        self.policy = policy or Policy()
        self.seen = Seen()
        self.answers = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def send(self, msg: Any) -> None:
        self.sock.sendall(msg.pack(self.mav))

    def _run(self) -> None:
        self.send(px4mav.MAVLink_heartbeat_message(0, 12, 128, 0, 0, 3))  # as simulator_mavlink does
        self.sock.settimeout(0.05)
        while not self._stop.is_set():
            try:
                data = self.sock.recv(65536)
            except TimeoutError:
                continue
            except OSError:
                return
            if not data:
                return
            try:
                for m in self.mav.parse_buffer(data) or []:
                    self._on(m)
            except OSError:  # closed by the test while answering
                return

    def _on(self, m: Any) -> None:
        t = m.get_type()
        s = self.seen
        s.counts[t] = s.counts.get(t, 0) + 1
        s.last[t] = m
        s.sources.setdefault(t, set()).add((m.get_srcSystem(), m.get_srcComponent()))
        if t != "HIL_SENSOR" or m.id != 0:
            return
        s.sensor_us.append(int(m.time_usec))
        s.sensor_fields.append(int(m.fields_updated))
        p = self.policy
        if not p.answer:
            return
        if p.delay_s > 0:
            time.sleep(p.delay_s)
        controls = [float(v) for v in p.outputs(int(m.time_usec))]
        self.send(px4mav.MAVLink_hil_actuator_controls_message(int(m.time_usec), controls, p.mode, p.flags))
        self.answers += 1

    def close(self) -> None:
        self._stop.set()
        with contextlib.suppress(OSError):
            self.sock.shutdown(socket.SHUT_RDWR)
        self.sock.close()
        self._thread.join(2.0)


def bridge(**extra: Any) -> tuple[HilBridge, list[str]]:
    """A bridge on :func:`scenario` and the list its messages (and the runner's, see :func:`serving`) go to."""
    said: list[str] = []
    return HilBridge(scenario(**extra), say=said.append), said


@contextlib.contextmanager
def serving(bridge: HilBridge, said: list[str], link: SimLink | None = None, peripheral: Any = None,
            options: HilOptions | None = None) -> Iterator[HilRunner]:  # fmt: skip
    """A HilRunner (TCP on an ephemeral port unless ``link`` is given) serving in a thread, its messages
    appended to ``said``."""
    link = link or TcpSimLink("127.0.0.1", 0, 1, 158)
    runner = HilRunner(bridge, link, peripheral, options or HilOptions(speed=0.0, answer_timeout_s=2.0), said.append)
    errors: list[BaseException] = []

    def serve() -> None:
        try:
            runner.serve(wall_limit_s=120.0)
        except BaseException as e:  # noqa: BLE001 - reported by the test
            errors.append(e)

    th = threading.Thread(target=serve, daemon=True)
    th.start()
    try:
        yield runner
    finally:
        runner.stop()
        th.join(10.0)
        link.close()
        if peripheral is not None:
            peripheral.close()
    assert not th.is_alive(), "the runner did not stop"
    assert not errors, f"the runner raised {errors[0]!r}"


def wait_for(pred: Callable[[], bool], timeout_s: float = 20.0, what: str = "condition") -> None:
    """Poll ``pred`` until true (AssertionError naming ``what`` after ``timeout_s`` wall seconds)."""
    end = time.monotonic() + timeout_s
    while not pred():
        if time.monotonic() > end:
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(0.01)


def outputs_const(values: list[float]) -> Callable[[int], list[float]]:
    v = [float(x) for x in values] + [0.0] * (16 - len(values))
    return lambda t_us: v

