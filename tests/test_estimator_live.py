"""The live estimation core (``estimator.live.LiveCore``) on real MAVLink: simulated flights packed with
the project dialect and parsed back (``estimator_stream``), as a receiver on the link gets them.

Lock-on with a second system on the link, an autopilot reboot mid-stream, rotor speeds from actuator
outputs (no ESC telemetry), the one-line input statement and what it says when an input is missing,
ArduPilot's IMU units, a non-quadrotor HEARTBEAT, and the ground gate.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from estimator_stream import Flight, autopilot_messages, over_the_wire, record

from estimator.live import LiveConfig, LiveCore
from estimator.mavlink_decode import PREFERENCE
from estimator.motor_output import PX4_QUAD_X, OutputMap
from sitl.simulation import T_WIND
from vehicle.vehicle_file import load_vehicle
from windseek.cmd_estimator import Publisher
from wire.dialect import mavlink

IMU_TYPES = frozenset(PREFERENCE["imu"])
# Horizontal RMSE (m/s) against the true wind at the vehicle (10 m/s, turbulent) from 5 s on. Measured on
# this flight: 0.27 with every IMU sample (250 Hz) and ESC telemetry; 0.29 with 50 Hz IMU samples and rotor
# speeds from actuator outputs, or ArduPilot's SCALED_IMU/RAW_IMU. The limits leave a margin.
LIMIT_SITL = 0.45
LIMIT_OUTPUTS = 0.5


@pytest.fixture(scope="module")
def flight() -> Flight:
    """paper-s1 from hover: 10 m/s wind from the north, turbulence; 20 s (the step at 23 s comes later)."""
    return record(20.0)


def _core(**kw: object) -> LiveCore:
    return LiveCore(LiveConfig(vehicle=load_vehicle(), **kw))  # type: ignore[arg-type]


def _bad(core: LiveCore) -> dict[str, int]:
    """Rejected samples other than those before the filter had attitude and rotor speeds."""
    return {k: n for k, n in core.est.rejected.items() if not k.endswith(":not_ready")}


class Track:
    """The estimates after every IMU message: time on the autopilot's clock (s), wind NED (m/s)."""

    def __init__(self) -> None:
        self.t: list[float] = []
        self.wind: list[np.ndarray] = []


def _run(core: LiveCore, msgs: list, pub: Publisher | None = None, track: Track | None = None) -> list:
    """Feed every message; returns the WIND_COV messages a ``windseek estimator`` would have sent."""
    sent = []
    for m in msgs:
        core.handle(m)
        if pub is not None and (wc := pub.due()) is not None:
            sent.append(wc)
            pub.sent += 1
        if track is not None and m.get_type() in IMU_TYPES and (out := core.output()) is not None:
            track.t.append(out.t)
            track.wind.append(out.wind_ned)
    return sent


def _rmse_h(track: Track, f: Flight, t_from: float, offset: float = 0.0) -> float:
    """Horizontal RMSE (m/s) of the tracked estimates from ``t_from`` (flight time, s) against the true
    wind at the vehicle at the same instants (``offset``: autopilot clock - flight time)."""
    t = np.array(track.t) - offset
    w = np.array(track.wind)
    sel = t >= t_from
    truth = np.array([np.interp(t[sel], f.truth[:, 0], f.truth[:, T_WIND.start + i]) for i in range(2)]).T
    assert sel.sum() > 100 and abs(t[-1] - f.imu[-1][0]) < 0.05
    return float(np.sqrt(np.mean(np.sum((w[sel, :2] - truth) ** 2, axis=1))))


def test_one_line_input_statement_and_estimate_on_sitl_stream(flight: Flight) -> None:
    core = _core()
    tr = Track()
    _run(core, over_the_wire([(1, 1, autopilot_messages(flight))]), track=tr)
    notes = core.take_notes()
    assert notes[0] == "autopilot system 1 component 1"
    assert notes[1] == ("inputs: IMU HIL_SENSOR 250 Hz, attitude ATTITUDE_QUATERNION, velocity LOCAL_POSITION_NED, "
                        "rotor speeds ESC_STATUS")  # fmt: skip
    assert len(notes) == 2 and core.model_note is None
    assert _rmse_h(tr, flight, 5.0) < LIMIT_SITL
    assert core.est.accepted["imu"] > 4500 and _bad(core) == {}
    assert core.status_line() == "estimating" and core.counters["other_system"] == 0


def test_lock_on_ignores_a_second_system_with_later_clock(flight: Flight) -> None:
    """A second system (id 7) on the link, with its clock 500 s ahead and another flight's data: it
    is counted and named once, never fed to the filter; no real frame is rejected as out of order."""
    other = record(20.0, scenario="paper-s2", seed=5)
    stream = over_the_wire([(1, 1, autopilot_messages(flight)), (7, 1, autopilot_messages(other, t_offset=500.0))])
    core = _core()
    pub = Publisher(core, 10.0)
    tr = Track()
    sent = _run(core, stream, pub, tr)
    n7 = sum(1 for m in stream if m.get_srcSystem() == 7)
    assert core.target == (1, 1)
    # Every message of system 7 counted: before the lock-on (system 1's HEARTBEAT came first at t = 0,
    # so at most the ones packed before it) or as another system.
    assert core.counters["other_system"] + core.counters["before_lock"] == n7 and core.counters["before_lock"] <= 2
    notes = core.take_notes()
    assert sum("another MAVLink system on the link: 7:1" in n for n in notes) == 1, notes
    assert not any("out_of_order" in k for k in core.est.rejected), dict(core.est.rejected)
    assert core.counters["clock_resets"] == 0
    assert _rmse_h(tr, flight, 5.0) < LIMIT_SITL
    assert len(sent) > 120 and all(wc.time_usec < 100e6 for wc in sent)  # ~10 Hz once judged, on system 1's clock


def test_target_system_option_locks_on_to_the_named_autopilot(flight: Flight) -> None:
    other = record(6.0, scenario="paper-s2", seed=5)
    stream = over_the_wire([(7, 1, autopilot_messages(other)), (1, 1, autopilot_messages(flight))])
    core = _core(target_system=1)
    tr = Track()
    _run(core, stream, track=tr)
    assert core.target == (1, 1) and core.counters["other_system"] > 1000
    assert _rmse_h(tr, flight, 5.0) < LIMIT_SITL


def test_autopilot_reboot_restarts_the_filter_and_publishing_resumes(flight: Flight) -> None:
    """The autopilot reboots after 12 s: its clock starts again near 0. The filter restarts (counted),
    WIND_COV stops while the new filter has no estimate and comes back on the new clock."""
    before = [(t, m) for t, m in autopilot_messages(flight) if t < 12.0]
    after = [(t, m) for t, m in autopilot_messages(flight, t_offset=-11.5) if t >= 12.0]
    stream = over_the_wire([(1, 1, before)]) + over_the_wire([(1, 1, after)])
    core = _core()
    pub = Publisher(core, 10.0)
    tr = Track()
    sent = _run(core, stream, pub, tr)
    assert core.counters["clock_resets"] == 1 and core.restarts == 1
    assert any("autopilot clock reset" in n for n in core.take_notes())
    t_sent = np.array([wc.time_usec * 1e-6 for wc in sent])
    k = int(np.argmax(np.diff(t_sent) < 0)) + 1  # the first WIND_COV on the new clock
    assert t_sent[k - 1] > 11.5 and 0.5 <= t_sent[k] < 2.0, t_sent[k - 3 : k + 3]
    assert np.all(np.diff(t_sent[k:]) > 0) and len(t_sent) - k > 60  # published again, on the new clock
    # The new filter converges on its own data (no out-of-order rejections for ever after).
    assert core.est.accepted["imu"] > 1500
    assert not any("out_of_order" in r for r in core.est.rejected), dict(core.est.rejected)
    k = int(np.argmax(np.diff(tr.t) < 0)) + 1  # the new filter's estimates
    tr.t, tr.wind = tr.t[k:], tr.wind[k:]
    assert _rmse_h(tr, flight, 12.0 + 5.0, offset=-11.5) < LIMIT_SITL


def test_system_time_going_back_is_a_reboot(flight: Flight) -> None:
    """SYSTEM_TIME's time_boot_ms going back restarts at once; the stamps that follow on the new clock
    are not a second reset."""
    before = [(t, m) for t, m in autopilot_messages(flight) if t < 6.0]
    boot = [(6.0, mavlink.MAVLink_system_time_message(1_700_000_000_000_000, 300))]
    after = [(t, m) for t, m in autopilot_messages(flight, t_offset=-5.7) if t >= 6.0]
    core = _core()
    _run(core, over_the_wire([(1, 1, before + boot + after)], order="concat"))
    assert core.counters["clock_resets"] == 1 and core.counters["clock_behind"] == 0
    assert any("SYSTEM_TIME time_boot_ms went back" in n for n in core.take_notes())
    out = core.output()
    assert out is not None and out.t == pytest.approx(flight.imu[-1][0] - 5.7, abs=0.01)


def test_a_single_stale_time_stamp_is_dropped_not_a_reset(flight: Flight) -> None:
    msgs = autopilot_messages(flight)[:3000]
    stale = mavlink.MAVLink_attitude_quaternion_message(100, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, [0.0] * 4)
    msgs.insert(2500, (msgs[2500][0], stale))
    core = _core()
    _run(core, over_the_wire([(1, 1, msgs)], order="concat"))
    assert core.counters["clock_behind"] == 1 and core.counters["clock_resets"] == 0 and core.restarts == 0


@pytest.mark.parametrize("kind", ["ACTUATOR_OUTPUT_STATUS", "SERVO_OUTPUT_RAW"])
def test_rotor_speeds_from_px4_actuator_outputs(flight: Flight, kind: str) -> None:
    """PX4 without ESC telemetry: HIGHRES_IMU at 50 Hz and the simulator's true rotor commands as PX4
    outputs (quad-X order, PWM 1000-2000 = rotor speed min..max). The filter runs through the motor
    lag; the estimate stays within 0.7 m/s of the mean true wind (horizontal, last 3 s)."""
    v = load_vehicle()
    outputs = OutputMap.for_vehicle(v, "px4")
    assert outputs.order == PX4_QUAD_X
    msgs = autopilot_messages(flight, imu="HIGHRES_IMU", imu_every=5, rotors=kind, outputs=outputs)
    core = _core(outputs=outputs)
    tr = Track()
    _run(core, over_the_wire([(1, 1, msgs)]), track=tr)
    notes = core.take_notes()
    assert notes[1] == (f"inputs: IMU HIGHRES_IMU 50 Hz, attitude ATTITUDE_QUATERNION, velocity LOCAL_POSITION_NED, "
                        f"rotor speeds from {kind} through the motor model (no ESC telemetry)")  # fmt: skip
    assert core.est.accepted["rotors"] == core.est.accepted["imu"] > 900
    assert _rmse_h(tr, flight, 5.0) < LIMIT_OUTPUTS


def test_output_map_px4_order_and_thrust_curves() -> None:
    """PX4 quad-X outputs 1-4 (front-right, rear-left, front-left, rear-right) land on the project's rotors
    1 front-right, 3 rear-left, 4 front-left, 2 rear-right; both curves invert; disarmed = stopped.
    (The motor order does not change the estimate: the force model depends on the rotor speeds
    through their collective terms only; it matters to the moments.)"""
    v = load_vehicle()
    m = OutputMap.for_vehicle(v, "px4")
    w = m.speeds([1000.0, 1250.0, 1500.0, 2000.0])
    assert w is not None and np.allclose(w, [100.0, 600.0, 225.0, 350.0])
    assert np.allclose(m.speeds([900.0] * 4), 0.0)  # PX4's disarmed PWM: motors stopped
    assert m.speeds([1500.0, float("nan"), 1500.0, 1500.0]) is None and m.speeds([1500.0] * 3) is None
    omega = np.array([380.0, 410.0, 395.0, 402.0])
    for f in (None, 0.0, 0.3, 1.0):
        mf = OutputMap.for_vehicle(v, "px4", thr_mdl_fac=f)
        back = mf.speeds(mf.raw_outputs(omega))
        assert back is not None and np.allclose(back, omega, rtol=1e-9)
    # THR_MDL_FAC = 0.3: half the command gives 0.3 * 0.25 + 0.7 * 0.5 = 42.5 % of the thrust range.
    half = OutputMap.for_vehicle(v, "px4", thr_mdl_fac=0.3).speed(0.5)
    assert half**2 == pytest.approx(100.0**2 + 0.425 * (600.0**2 - 100.0**2))
    sitl = OutputMap.for_vehicle(v, "sitl")
    assert sitl.speeds([1000.0, 1500.0, 2000.0, 1655.0]) == pytest.approx([0.0, 300.0, 600.0, 393.0])
    with pytest.raises(ValueError, match="permutation"):
        OutputMap(order=(0, 0, 1, 2))


def test_missing_rotor_speeds_are_named_and_nothing_is_published(flight: Flight) -> None:
    msgs = [(t, m) for t, m in autopilot_messages(flight)[:4000] if m.get_type() != "ESC_STATUS"]
    core = _core()
    pub = Publisher(core, 10.0)
    sent = _run(core, over_the_wire([(1, 1, msgs)]), pub)
    assert core.status_line() == ("waiting for inputs: no rotor speeds (no ESC_STATUS, ESC_TELEMETRY_1_TO_4, RAW_RPM, "
                                  "ACTUATOR_OUTPUT_STATUS "
                                  "or SERVO_OUTPUT_RAW seen)")  # fmt: skip
    assert (
        "rotor speeds none (no ESC_STATUS, ESC_TELEMETRY_1_TO_4, RAW_RPM, ACTUATOR_OUTPUT_STATUS or SERVO_OUTPUT_RAW "
        "seen)" in (core.take_notes()[1])
    )
    assert sent == [] and core.output() is None and core.summary()["wind_ned_m_s"] is None


def test_failed_esc_telemetry_is_named(flight: Flight) -> None:
    info = mavlink.MAVLink_esc_info_message(0, 1000, 1, 4, 5, 15, [0, 32, 0, 0], [0] * 4, [2500] * 4)
    msgs = autopilot_messages(flight)[:2000]
    msgs.insert(5, (0.0, info))  # after the HEARTBEAT
    core = _core()
    _run(core, over_the_wire([(1, 1, msgs)], order="concat"))
    assert core.output() is None
    assert core.status_line() == "waiting for inputs: no rotor speeds (ESC_INFO reports the ESC of rotor 2 failed)"


@pytest.mark.parametrize("kind", ["SCALED_IMU", "RAW_IMU"])
def test_ardupilot_imu_units(flight: Flight, kind: str) -> None:
    """SCALED_IMU (mG, mrad/s per common.xml) and RAW_IMU (ArduPilot fills it in the same units)."""
    msgs = autopilot_messages(flight, imu=kind, imu_every=5)
    core = _core()
    tr = Track()
    _run(core, over_the_wire([(1, 1, msgs)]), track=tr)
    assert core.select.chosen["imu"] == kind and _bad(core) == {}
    assert _rmse_h(tr, flight, 5.0) < LIMIT_OUTPUTS


def test_a_hexarotor_heartbeat_is_a_model_mismatch(flight: Flight) -> None:
    msgs = autopilot_messages(flight, mav_type=mavlink.MAV_TYPE_HEXAROTOR)[:2000]
    core = _core()
    _run(core, over_the_wire([(1, 1, msgs)]))
    assert core.model_note is not None and "HEXAROTOR" in core.model_note and "biased" in core.model_note
    assert core.model_note in core.take_notes() and core.summary()["model_note"] == core.model_note
    flagged = _core(airframe="PX4 SIH quadrotor")
    assert flagged.model_note is not None and "PX4 SIH quadrotor" in flagged.model_note


def _lowered(m: Any, dz: float = 1.0) -> Any:
    """The message as if the vehicle were ``dz`` m lower (LOCAL_POSITION_NED; others unchanged)."""
    if m.get_type() != "LOCAL_POSITION_NED":
        return m
    return mavlink.MAVLink_local_position_ned_message(m.time_boot_ms, m.x, m.y, m.z + dz, m.vx, m.vy, m.vz)


@pytest.mark.parametrize("heights", [True, False])
def test_not_landed_is_not_airborne_until_the_vehicle_has_climbed_clear(flight: Flight, heights: bool) -> None:
    """PX4 says "not landed" (TAKEOFF) while the rotors spin up on the ground: no samples until the vehicle
    has climbed 0.5 m above its height on the ground, or, in a stream without heights, for 5 s."""
    base = [(t, m) for t, m in autopilot_messages(flight, velocity=heights)[:7500]
            if m.get_type() != "EXTENDED_SYS_STATE"]  # fmt: skip

    def seg(state: int, t0: float, t1: float, climbed: float = 0.0) -> list:
        out = [(t, _lowered(m, -climbed)) for t, m in base if t0 <= t < t1]
        out.insert(1 if t0 == 0.0 else 0, (t0, mavlink.MAVLink_extended_sys_state_message(0, state)))
        return out

    core = _core()
    _run(core, over_the_wire([(1, 1, seg(1, 0.0, 2.0))], order="concat"))  # on the ground
    _run(core, over_the_wire([(1, 1, seg(3, 2.0, 4.0))], order="concat"))  # TAKEOFF, still on the ground
    assert core.est.accepted["imu"] == 0 and core.output() is None
    _run(core, over_the_wire([(1, 1, seg(3, 4.0, 5.0, climbed=0.4))], order="concat"))
    assert core.est.accepted["imu"] == 0  # 0.4 m is not clear
    _run(core, over_the_wire([(1, 1, seg(3, 5.0, 6.9, climbed=0.6))], order="concat"))
    assert (core.est.accepted["imu"] > 0) is heights  # 0.6 m is; without heights 4.9 s is not 5
    _run(core, over_the_wire([(1, 1, seg(2, 6.9, 9.0, climbed=0.6))], order="concat"))
    # the filter runs (its wind is published once the model has been judged to fit: estimator.model_fit)
    assert core.est.accepted["imu"] > 0 and core.est.t is not None and core.restarts == 0


def test_ground_gate_pauses_and_replaces_a_flown_filter_at_the_next_lift_off(flight: Flight) -> None:
    """EXTENDED_SYS_STATE on the ground or landing withholds the inputs; a filter that flew is replaced at
    the next lift-off (one that never flew is not) and the chosen inputs carry over."""
    base = [(t, m) for t, m in autopilot_messages(flight)[:6000] if m.get_type() != "EXTENDED_SYS_STATE"]

    def landed(state: int, t0: float, t1: float) -> list:
        seg = [(t, _lowered(m) if state == 1 else m) for t, m in base if t0 <= t < t1]  # the ground 1 m down
        seg.insert(1 if t0 == 0.0 else 0, (t0, mavlink.MAVLink_extended_sys_state_message(0, state)))
        return seg  # (at t = 0 after the HEARTBEAT the core locks on to)

    core = _core()
    _run(core, over_the_wire([(1, 1, landed(1, 0.0, 2.0))], order="concat"))  # on the ground
    assert core.paused() and core.output() is None and core.est.accepted["imu"] == 0
    first = core.est
    _run(core, over_the_wire([(1, 1, landed(2, 2.0, 5.0))], order="concat"))  # lift-off
    assert core.est is first and core.restarts == 0 and core.est.t is not None
    n = first.accepted["imu"]
    pub = Publisher(core, 10.0)
    assert _run(core, over_the_wire([(1, 1, landed(4, 5.0, 6.0))], order="concat"), pub) == []  # landing
    assert core.est is first and first.accepted["imu"] == n
    _run(core, over_the_wire([(1, 1, landed(2, 6.0, 8.0))], order="concat"))  # the next lift-off
    assert core.est is not first and core.restarts == 1 and core.est.accepted["imu"] > 0
    assert core.select.chosen["attitude"] == "ATTITUDE_QUATERNION"
