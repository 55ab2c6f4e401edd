"""HITL over a serial port (a pseudo-terminal here): a flight controller with SYS_HITL 1 answers without the
lockstep flag on its own clock, so windseek steps in real time, freezes the world when the outputs stop
and resumes when they come back; the peripheral component shares the serial link."""

from __future__ import annotations

import contextlib
import os
import select
import threading
import time

import numpy as np
from hil_support import ARMED, bridge, serving, wait_for

from sitl.hil.peripheral import SharedPeripheral
from sitl.hil.px4_link import SerialSimLink
from sitl.hil.runner import HilOptions, Sync
from wire.dialect import mavlink


class FakeHitl:
    """A flight controller in HITL on the pty's master side: HIL_ACTUATOR_CONTROLS at 200 Hz (wall), flags 0,
    a 1 Hz HEARTBEAT as system 3; reads what windseek sends."""

    def __init__(self, fd: int, outputs: list[float]) -> None:
        self.fd = fd
        self.mav = mavlink.MAVLink(None, 3, 1)
        self.mav.robust_parsing = True
        self.outputs = [float(v) for v in outputs] + [0.0] * (16 - len(outputs))
        self.answering = True
        self.sensor_us: list[int] = []
        self.sources: dict[str, set[tuple[int, int]]] = {}
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        next_out = next_hb = time.monotonic()
        while not self._stop.is_set():
            now = time.monotonic()
            if now >= next_hb:
                next_hb = now + 1.0
                os.write(self.fd, mavlink.MAVLink_heartbeat_message(2, 12, 128, 0, 4, 3).pack(self.mav))
            if now >= next_out:
                next_out = now + 0.005
                if self.answering:
                    msg = mavlink.MAVLink_hil_actuator_controls_message(int(now * 1e6), self.outputs, ARMED, 0)
                    os.write(self.fd, msg.pack(self.mav))
            ready, _, _ = select.select([self.fd], [], [], 0.002)
            if not ready:
                continue
            try:
                data = os.read(self.fd, 65536)
            except OSError:
                return
            for m in self.mav.parse_buffer(data) or []:
                t = m.get_type()
                self.sources.setdefault(t, set()).add((m.get_srcSystem(), m.get_srcComponent()))
                if t == "HIL_SENSOR":
                    self.sensor_us.append(int(m.time_usec))

    def close(self) -> None:
        self._stop.set()
        self._thread.join(2.0)


def test_hitl_over_a_serial_port_real_time_freeze_and_resume() -> None:
    master, slave = os.openpty()
    name = os.ttyname(slave)
    b, said = bridge()
    link = SerialSimLink(name, 921600, 1, 158)
    fc = FakeHitl(master, [0.2, 0.1, 0.1, 0.2])  # armed, below hover: on the ground
    try:
        with serving(b, said, link=link, peripheral=SharedPeripheral(link),
                     options=HilOptions(realtime_timeout_s=0.3)) as runner:  # fmt: skip
            wait_for(lambda: runner.state == Sync.REALTIME and len(fc.sensor_us) > 100, what="HITL streaming")
            fc.answering = False
            wait_for(lambda: any("the world is frozen until they come back" in s for s in said), what="the freeze")
            t_frozen = b.world.t
            time.sleep(0.3)
            assert b.world.t == t_frozen
            fc.answering = True
            wait_for(lambda: any("actuator outputs from PX4 again" in s for s in said), what="the resume")
            wait_for(lambda: b.world.t > t_frozen + 0.2, what="time moving again")
    finally:
        fc.close()
        with contextlib.suppress(OSError):
            os.close(master)
        with contextlib.suppress(OSError):
            os.close(slave)
    assert any("PX4 (HITL) answering" in s for s in said)
    us = np.array(fc.sensor_us)
    assert np.all(np.diff(us) == 4000)  # the HIL clock steps 4 ms, also across the freeze
    assert np.allclose(b.guard.command.speeds, [120.0, 120.0, 60.0, 60.0])  # PX4 order -> windseek order
    # The peripheral component rides on the same link with the flight controller's system id (learned).
    assert fc.sources["ESC_STATUS"] == {(3, 158)} and fc.sources["NAMED_VALUE_FLOAT"] == {(3, 158)}
    assert (3, 158) in fc.sources["HEARTBEAT"]
    assert runner.counters["freezes"] == 1 and runner.px4_system == 3
