"""windseek as PX4's simulator over real TCP sockets, against a pymavlink stand-in for PX4's
simulator_mavlink (tests/hil_support.py): lockstep ordering and clock, the motor mapping on the wire,
the bounded wait, and bad input (NaN outputs, a wrong airframe, no lockstep flag, PX4 disconnecting
and coming back rebooted): a clear message, the world held safe, nothing crashes."""

from __future__ import annotations

import time

import numpy as np
from hil_support import (
    ARMED,
    DISARMED,
    FakePx4,
    Policy,
    bridge,
    hover_output,
    outputs_const,
    place_in_air,
    serving,
    wait_for,
)

from sitl.hil.runner import HilOptions, Sync


def _said(said: list[str], text: str) -> bool:
    return any(text in s for s in said)


def test_lockstep_waits_for_every_answer_and_the_clock_steps_4_ms() -> None:
    b, said = bridge()
    hold_at = 600_000  # the step whose answer PX4 delays (us)
    seen_during_hold: list[float] = []

    def outputs(t_us: int) -> list[float]:
        if t_us == hold_at:
            seen_during_hold.append(b.world.t)
            time.sleep(0.4)  # PX4 busy: the world must not step meanwhile
            seen_during_hold.append(b.world.t)
        return [0.0] * 16

    with serving(b, said) as runner:
        px4 = FakePx4(runner.link.port, policy=Policy(outputs=outputs))  # type: ignore[attr-defined]
        wait_for(lambda: len(px4.seen.sensor_us) > 400, what="400 steps")
        px4.close()
    assert runner.counters["lockstep_timeouts"] == 0
    assert _said(said, "PX4 in lockstep")
    us = np.array(px4.seen.sensor_us)
    assert us[0] == 4000 and np.all(np.diff(us) == 4000)  # one HIL_SENSOR per 4 ms step, none skipped or repeated
    # While PX4 sat on the answer to the sensor at 0.6 s, the world stayed one step past it.
    assert seen_during_hold == [0.604, 0.604]
    i = int(np.flatnonzero(us == hold_at)[0])
    assert us[i + 1] == hold_at + 4000
    # Lockstep: PX4's first answers end the free-running start, then one answer per step.
    assert px4.answers >= len(us) - 2


def test_outputs_drive_the_rotors_in_px4_motor_order() -> None:
    b, said = bridge()
    pol = Policy(outputs=outputs_const([0.5, 0.1, 0.2, 0.3]), mode=ARMED)  # below hover: stays on the ground
    with serving(b, said) as runner:
        px4 = FakePx4(runner.link.port, policy=pol)  # type: ignore[attr-defined]
        wait_for(lambda: b.world.t > 1.0, what="1 s of simulation")
        px4.close()
    # PX4 1 FR, 2 RL, 3 FL, 4 RR -> windseek FR, RR, RL, FL at omega = 600 rad/s * output.
    assert np.allclose(b.guard.command.speeds, [300.0, 180.0, 60.0, 120.0])
    assert np.allclose(b.world.rotor_speeds, [300.0, 180.0, 60.0, 120.0], atol=1.0)  # motors followed (tau 0.04 s)
    assert b.world.on_ground and not b.world.crashed


def test_a_silent_px4_times_out_counted_and_the_world_steps_on() -> None:
    b, said = bridge()
    pol = Policy()
    with serving(b, said, options=HilOptions(speed=0.0, answer_timeout_s=0.2)) as runner:
        px4 = FakePx4(runner.link.port, policy=pol)  # type: ignore[attr-defined]
        wait_for(lambda: runner.state == Sync.LOCKSTEP and b.steps > 50, what="lockstep")
        pol.answer = False
        wait_for(lambda: runner.counters["lockstep_timeouts"] >= 3, what="3 timeouts")
        px4.close()
    assert _said(said, "within 0.2 s (PX4 stalled or an answer was lost): stepping on")
    assert np.all(np.diff(px4.seen.sensor_us) == 4000)


def test_disconnect_freezes_the_world_and_a_rebooted_px4_gets_a_safety_landing() -> None:
    b, said = bridge()
    place_in_air(b, 4.0)
    hover = outputs_const([hover_output(b)] * 4)
    with serving(b, said) as runner:
        px4 = FakePx4(runner.link.port, policy=Policy(outputs=hover, mode=ARMED))  # type: ignore[attr-defined]
        wait_for(lambda: b.world.t > 0.5, what="0.5 s in lockstep")
        px4.close()
        wait_for(lambda: _said(said, "PX4 disconnected"), what="the disconnect message")
        t_frozen = b.world.t
        alt = -b.world.position[2]  # how far it sank before the close depends on the machine's speed
        time.sleep(0.3)
        assert b.world.t == t_frozen  # no PX4, no physics
        assert not b.world.on_ground
        # PX4 comes back disarmed (it rebooted): its zero outputs would drop the vehicle from 4 m.
        px4b = FakePx4(runner.link.port, policy=Policy(mode=DISARMED))  # type: ignore[attr-defined]
        wait_for(lambda: _said(said, "safety landing done"), what="the safety landing")
        px4b.close()
    assert _said(said, f"in the air at {alt:.1f} m): the world is frozen until PX4 connects again"), said
    assert _said(said, "PX4 connected again")
    assert _said(said, "PX4 came back disarmed with the vehicle in the air")
    assert b.world.on_ground and not b.world.crashed
    assert b.world.phys.flags[2] < 2.0  # touchdown speed, m/s: a controlled descent
    assert runner.counters["reconnects"] == 1 and runner.counters["disconnects"] >= 1


def test_nan_outputs_are_held_briefly_then_the_vehicle_is_landed() -> None:
    b, said = bridge()
    place_in_air(b, 4.0)
    good = [hover_output(b)] * 4 + [0.0] * 12
    bad = [float("nan")] * 4 + [0.0] * 12
    pol = Policy(outputs=lambda t_us: good if t_us < 300_000 else bad, mode=ARMED)
    with serving(b, said) as runner:
        px4 = FakePx4(runner.link.port, policy=pol)  # type: ignore[attr-defined]
        wait_for(lambda: _said(said, "safety landing done"), what="the safety landing")
        px4.close()
    assert _said(said, "PX4 outputs refused (non_finite)")
    assert _said(said, "no valid PX4 outputs for 0.5 s: windseek's built-in controller lands the vehicle")
    assert b.guard.counters["controls_non_finite"] > 100
    assert b.world.on_ground and not b.world.crashed and b.world.phys.flags[2] < 2.0


def test_a_wrong_airframe_is_refused_and_the_rotors_stop_on_the_ground() -> None:
    b, said = bridge()
    pol = Policy(outputs=outputs_const([0.3] * 6), mode=ARMED)  # a hexacopter's six motors
    with serving(b, said) as runner:
        px4 = FakePx4(runner.link.port, policy=pol)  # type: ignore[attr-defined]
        wait_for(lambda: _said(said, "rotors stopped"), what="the stop")
        px4.close()
    assert _said(said, "PX4 outputs refused (wrong_airframe)") and _said(said, "output(s) 5, 6")
    assert np.all(b.guard.command.speeds == 0.0) and b.world.on_ground


def test_px4_without_lockstep_runs_in_real_time() -> None:
    b, said = bridge()
    with serving(b, said) as runner:
        px4 = FakePx4(runner.link.port, policy=Policy(flags=0))  # type: ignore[attr-defined]
        wait_for(lambda: runner.state == Sync.REALTIME, what="real-time mode")
        px4.close()
    assert _said(said, "PX4 does not run in lockstep (HIL_ACTUATOR_CONTROLS flags bit 0 clear")


def test_garbage_from_px4_is_counted_and_dropped() -> None:
    b, said = bridge()
    # A 5 s answer bound: on a loaded machine the stand-in's own answers may take over 2 s.
    with serving(b, said, options=HilOptions(speed=0.0, answer_timeout_s=5.0)) as runner:
        px4 = FakePx4(runner.link.port)  # type: ignore[attr-defined]
        wait_for(lambda: runner.state == Sync.LOCKSTEP, what="lockstep")
        bad = bytearray(px4.mav.heartbeat_encode(0, 12, 0, 0, 0, 3).pack(px4.mav))
        bad[-1] ^= 0xFF  # wrong CRC
        px4.sock.sendall(b"\x00\x11 garbage " + bytes(bad))  # no 0xFD/0xFE: nothing swallowed
        t = b.world.t
        wait_for(lambda: b.world.t > t + 0.5, what="lockstep going on")
        assert runner.counters["lockstep_timeouts"] == 0
        # A partial frame header would swallow the start of the next answer (pymavlink trusts its length):
        # the link parses the swallowed bytes again (wire.resync), so no answer is lost, no wait is spent.
        px4.sock.sendall(b"\xfd\x30\x00")
        t = b.world.t
        wait_for(lambda: b.world.t > t + 0.5, what="lockstep going on after the partial header")
        px4.close()
    assert runner.link.counters["rx_bad"] >= 2
    assert runner.counters["lockstep_timeouts"] == 0


def test_lockstep_speed_is_the_realised_pace_not_the_step_throughput() -> None:
    """At a requested pace (``--speed``) the summary's ``lockstep_speed`` is the pace the run went at; it used
    to be the steps' throughput (world step + PX4's answer, without the pacing sleep), e.g. "lockstep speed
    12" at --speed 1. The throughput is reported apart, as what --px4-free would allow."""
    b, said = bridge()
    with serving(b, said, options=HilOptions(speed=0.5, answer_timeout_s=2.0)) as runner:
        px4 = FakePx4(runner.link.port, policy=Policy())  # type: ignore[attr-defined]
        wait_for(lambda: runner.state == Sync.LOCKSTEP, what="lockstep")
        t0 = b.world.t
        wait_for(lambda: b.world.t > t0 + 1.0, what="1 s of simulation (2 s of wall at speed 0.5)")
        px4.close()
    s = runner.summary()
    assert 0.4 < s["lockstep_speed"] <= 0.52, s["lockstep_speed"]  # the pace asked for, as realised
    assert s["requested_speed"] == 0.5
    assert s["lockstep_throughput"] > 1.0, s["lockstep_throughput"]  # the fake PX4 answers far faster than that
    line = runner.speed_line()
    assert line.startswith(f"lockstep speed {s['lockstep_speed']:.2f}x (requested 0.5x; the steps alone would allow ")
