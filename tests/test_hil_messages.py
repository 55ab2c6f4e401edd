"""What windseek sends as PX4's simulator (no sockets: the bridge's output per lockstep step): HIL_SENSOR
fields, units, bits and its 4 ms clock; HIL_GPS at 10 Hz with realistic accuracy; HIL_STATE_QUATERNION
truth at the rate asked (capped); the companion messages (ESC_STATUS, CHEM, true wind) and their rates."""

from __future__ import annotations

import math
from collections import Counter
from typing import Any

import numpy as np
import pytest
from hil_support import hover_output, place_in_air, scenario

from sitl.hil.bridge import HilBridge
from sitl.hil.messages import HIL_ACCEL, HIL_BARO, HIL_GYRO, HIL_MAG
from sitl.world.sensors import isa_pressure_pa, ned_to_geodetic

SECONDS = 2.0


def _run(b: HilBridge, seconds: float) -> tuple[list[Any], list[Any]]:
    px4: list[Any] = []
    comp: list[Any] = []
    for _ in range(int(round(seconds / b.imu_period_s))):
        out = b.step()
        assert out.to_px4[-1].get_type() == "HIL_SENSOR"  # the step's sensor goes last (it sets PX4's clock)
        assert out.t_us == out.to_px4[-1].time_usec
        px4 += out.to_px4
        comp += out.to_companion
    return px4, comp


def _of(msgs: list[Any], mtype: str) -> list[Any]:
    return [m for m in msgs if m.get_type() == mtype]


def test_hil_sensor_at_rest_fields_units_bits_and_clock() -> None:
    b = HilBridge(scenario(), say=lambda s: None)
    px4, _ = _run(b, SECONDS)
    sens = _of(px4, "HIL_SENSOR")
    n = int(round(SECONDS / 0.004))
    assert len(sens) == n
    us = np.array([m.time_usec for m in sens])
    assert us[0] == 4000  # never 0: PX4 reads 0 as "clock not set"
    assert np.all(np.diff(us) == 4000)
    assert all(m.id == 0 for m in sens)
    f = np.array([m.fields_updated for m in sens])
    assert np.all(f & (HIL_ACCEL | HIL_GYRO) == HIL_ACCEL | HIL_GYRO)
    # Magnetometer and barometer: every 5th step (50 Hz), all bits of the group or none.
    for mask in (HIL_MAG, HIL_BARO):
        groups = f & mask
        assert set(groups.tolist()) == {0, mask}
        assert int(np.sum(groups == mask)) == pytest.approx(n / 5, abs=1)
    acc = np.array([[m.xacc, m.yacc, m.zacc] for m in sens])
    gyr = np.array([[m.xgyro, m.ygyro, m.zgyro] for m in sens])
    assert acc.mean(axis=0) == pytest.approx([0.0, 0.0, -9.81], abs=0.1)  # specific force FRD at rest, m/s^2
    assert 0.02 < acc[:, 0].std() < 0.1  # MEMS noise, not a constant
    assert np.abs(gyr.mean(axis=0)).max() < 0.01
    last = sens[-1]
    home = b.scenario.sensors.home
    assert last.abs_pressure == pytest.approx(isa_pressure_pa(home.alt_m) / 100.0, abs=0.1)  # hPa
    assert last.pressure_alt == pytest.approx(home.alt_m, abs=1.0)
    assert last.temperature == pytest.approx(15.0 - 0.0065 * home.alt_m, abs=0.5)
    field = np.array(b.scenario.sensors.mag.field_ned_gauss)  # yaw 0, level: FRD = NED
    assert [last.xmag, last.ymag, last.zmag] == pytest.approx(field, abs=0.02)


def test_hil_gps_10_hz_with_realistic_accuracy() -> None:
    b = HilBridge(scenario(), say=lambda s: None)
    px4, _ = _run(b, SECONDS)
    gps = _of(px4, "HIL_GPS")
    assert len(gps) == pytest.approx(10 * SECONDS, abs=1)
    cfg = b.scenario.sensors.gnss
    lat, lon, alt = ned_to_geodetic(np.zeros(3), b.scenario.sensors.home)
    for g in gps:
        assert g.fix_type == 3 and g.satellites_visible == cfg.satellites >= 6
        assert g.eph == round(100 * cfg.pos_noise_h_m) and g.epv == round(100 * cfg.pos_noise_v_m)  # 1-sigma, cm
        assert abs(g.lat - lat * 1e7) < 100 and abs(g.lon - lon * 1e7) < 150  # 3.5 sigma of 0.3 m (degE7)
        assert abs(g.alt - alt * 1000) < 3000  # mm
        assert g.cog == 65535 or 0 <= g.cog < 36000
        assert g.time_usec > 1_600_000_000 * 1_000_000  # UNIX time
    assert sum(g.cog == 65535 for g in gps) > len(gps) / 2  # standing still: course mostly unknown (< 0.1 m/s)
    t = np.array([g.time_usec for g in gps])
    assert np.allclose(np.diff(t), 100_000, atol=1)


def test_hil_state_quaternion_truth_and_rate() -> None:
    b = HilBridge(scenario(), say=lambda s: None)
    place_in_air(b, 8.0)
    assert b.on_controls([hover_output(b)] * 4 + [0.0] * 12, 129)
    px4, _ = _run(b, 1.0)
    st = _of(px4, "HIL_STATE_QUATERNION")
    assert len(st) == pytest.approx(50, abs=1)  # 50 Hz until PX4 asks
    s = st[-1]
    assert np.linalg.norm(s.attitude_quaternion) == pytest.approx(1.0, abs=1e-6)
    alt = b.scenario.sensors.home.alt_m - b.world.position[2]
    assert s.alt == pytest.approx(alt * 1000, abs=100)  # mm AMSL
    assert s.zacc == pytest.approx(-1000, abs=60)  # mG: hovering, specific force -g
    b.set_state_rate(5000)  # PX4 asks 200 Hz: capped at 50 Hz
    assert len(_of(_run(b, 1.0)[0], "HIL_STATE_QUATERNION")) == pytest.approx(50, abs=1)
    b.set_state_rate(20000)
    assert len(_of(_run(b, 1.0)[0], "HIL_STATE_QUATERNION")) == pytest.approx(50, abs=1)
    b.set_state_rate(100000)
    assert len(_of(_run(b, 1.0)[0], "HIL_STATE_QUATERNION")) == pytest.approx(10, abs=1)
    b.set_state_rate(-1)
    assert not _of(_run(b, 0.5)[0], "HIL_STATE_QUATERNION")


def test_companion_messages_esc_chem_truth() -> None:
    b = HilBridge(scenario(), say=lambda s: None)
    place_in_air(b, 2.0)
    assert b.on_controls([hover_output(b)] * 4 + [0.0] * 12, 129)
    _, comp = _run(b, SECONDS)
    kinds = Counter(m.get_type() if m.get_type() != "NAMED_VALUE_FLOAT" else m.name for m in comp)
    assert kinds["ESC_STATUS"] == pytest.approx(50 * SECONDS, abs=1)
    assert kinds["CHEM"] == pytest.approx(10 * SECONDS, abs=1)
    for name in ("TRUEWN", "TRUEWE", "TRUEWD"):
        assert kinds[name] == pytest.approx(5 * SECONDS, abs=1)
    esc = _of(comp, "ESC_STATUS")[-1]
    w_hover = hover_output(b) * b.motors.omega_max
    assert np.array(esc.rpm) * 2 * math.pi / 60 == pytest.approx([w_hover] * 4, abs=15)  # rad/s, noisy
    assert esc.time_usec == pytest.approx(b.world.t * 1e6, abs=25_000)
