"""The model-fit checks (estimator/model_fit.py) by themselves, and a faulty autopilot's rotor speeds on the live
core: a 3 s burst of 1e9 rpm is rejected before it reaches the model check, and the wind is published after."""

from __future__ import annotations

import math

import numpy as np
from estimator_stream import autopilot_messages, over_the_wire, record

from estimator.live import LiveConfig, LiveCore
from estimator.model_fit import DomainCheck, InnovationCheck, ModelFit, identified_box
from vehicle.vehicle_file import load_vehicle
from wire.dialect import mavlink


def test_innovation_check_needs_two_windows_over_the_limit() -> None:
    chk = InnovationCheck("v", window_s=1.0, confirm=2, limit=10.0)
    t = 0.0
    for nis, n in ((0.5, 101), (50.0, 101), (0.5, 101), (50.0, 101)):  # one bad window at a time: fits
        for _ in range(n):
            assert not chk.sample(t, nis, True)
            t += 0.01
    assert chk.mismatch is None and chk.windows >= 3
    said = [chk.sample(t + 0.01 * k, 30.0, True) for k in range(250)]
    assert said.count(True) == 1 and chk.mismatch is not None and "normalized innovation" in chk.mismatch
    assert not chk.sample(t + 3.0, math.nan, True)  # latched; NaN (no update yet) is ignored


def test_domain_check_against_the_identified_box() -> None:
    v = load_vehicle("nasa-quad")
    box = identified_box(v)
    assert box is not None and box[2, 0] < -4.0 and box[2, 1] > 3.0  # w: the identification's climbs and descents
    assert identified_box(load_vehicle("nasa-quad-table5")) is None  # Table 5 carries no domain: check off
    chk = DomainCheck(v, window_s=1.0, confirm=2)
    inside, outside = np.array([8.0, 1.0, 0.5]), np.array([3.0, 0.0, box[2, 1] + 1.0])
    t = 0.0
    for a in (inside, outside, inside):
        for _ in range(101):
            chk.sample(t, a, True)
            t += 0.01
    assert chk.mismatch is None
    for _ in range(250):
        chk.sample(t, outside, True)
        t += 0.01
    assert chk.mismatch is not None and "w +" in chk.mismatch and "withheld" in chk.mismatch
    assert not chk.sample(t, None, False)


def test_a_horizontal_excursion_withholds_the_wind_while_it_lasts() -> None:
    """Paper-s2 through ArduCopter (seeds 1004, 1005): flying 3 m/s upwind in 10 m/s of turbulent wind put two
    2-s windows at u +13.7 m/s against the box's +13.5, and the wind was withheld for the rest of the flight.
    A horizontal airspeed beyond the box is withheld while it lasts, said once per excursion, never latched."""
    v = load_vehicle("nasa-quad")
    box = identified_box(v)
    assert box is not None
    chk = DomainCheck(v, window_s=1.0, confirm=2)
    fast, inside = np.array([box[0, 1] + 0.2, 0.5, 0.3]), np.array([8.0, 1.0, 0.5])
    t = 0.0

    def fly(a: np.ndarray, windows: int) -> list[bool]:
        nonlocal t
        said = []
        for _ in range(101 * windows):
            said.append(chk.sample(t, a, True))
            t += 0.01
        return said

    assert not any(fly(fast, 5))  # five windows beyond the box: no mismatch
    assert chk.mismatch is None and chk.excursion is not None and "u +" in chk.excursion
    note = chk.pop_note()
    assert note is not None and "withheld until it is back inside" in note and chk.pop_note() is None
    fly(inside, 2)  # (windows of 1 s do not start with the segments: two make one wholly inside)
    assert chk.excursion is None and chk.pop_note() is None
    fly(fast, 3)
    assert chk.excursion is not None and chk.pop_note() is not None  # a new excursion is said again
    assert chk.excursion_windows >= 6 and chk.mismatch is None
    fly(np.array([3.0, 0.0, box[2, 1] + 1.0]), 3)  # a vertical one is a mismatch, latched
    assert chk.mismatch is not None and "w +" in chk.mismatch


def test_model_fit_publishes_only_inside_the_domain() -> None:
    fit = ModelFit(load_vehicle("nasa-quad"))
    fit.thrust.windows = fit.domain.windows = fit.thrust.config.confirm  # as if both had judged their windows
    assert fit.judged and fit.publishable
    fit.domain.excursion = "outside the identified domain (u +13.7 m/s (identified -15.1..+13.5))"
    assert fit.judged and not fit.publishable  # still the model's vehicle; the estimate held meanwhile


def test_model_fit_is_judged_only_after_both_checks_had_their_windows() -> None:
    fit = ModelFit(load_vehicle("nasa-quad"))
    assert not fit.judged and fit.mismatch is None
    s = fit.summary()
    assert s["model"] == "nasa-quad" and str(s["model_source"]).startswith("windseek identify") and not s["model_fits"]


def test_a_burst_of_absurd_rotor_speeds_is_rejected_before_the_model_check() -> None:
    """A faulty autopilot reports 1e9 rpm for 3 s (in the air, hovering in 10 m/s of wind): the samples are
    refused at the input gate (counted), the thrust check never sees them, and the model is judged to fit."""
    flight = record(16.0)
    msgs = []
    for t, m in autopilot_messages(flight):
        if m.get_type() == "ESC_STATUS" and 4.0 <= t < 7.0:
            m = mavlink.MAVLink_esc_status_message(m.index, m.time_usec, [1_000_000_000] * 4, m.voltage, m.current)
        msgs.append((t, m))
    core = LiveCore(LiveConfig(vehicle=load_vehicle()))
    for m in over_the_wire([(1, 1, msgs)]):
        core.handle(m)
    assert core.est.rejected["rotors:bad_value"] >= 140  # 3 s at 50 Hz
    assert core.fit.mismatch is None and core.model_note is None
    assert core.fit.judged and core.output() is not None
