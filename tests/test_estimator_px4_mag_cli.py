"""``windseek estimator`` on a PX4 link reads PX4's magnetometer calibration and checks the heading against
SCALED_IMU's raw field (``windseek/estimator_px4_mag.py``), over a real UDP socket.

A pymavlink peer plays PX4 (HEARTBEAT autopilot 12) flying a simulated paper-s1 flight at 4x real time with its
published heading 12 deg off, a HIGHRES_IMU field that hides 8 deg of it (as EKF2's magnetometer bias estimate
does) and a raw SCALED_IMU field from an external compass turned 90 deg with hard- and soft-iron errors. It
answers PARAM_REQUEST_READ as PX4 does (INT32 values bytewise in the float field), and drops the first request
of three names, which the estimator must ask again. The estimator must say which calibration it took, ask for
SCALED_IMU, take it as its IMU input and find the whole 12 deg.
"""

from __future__ import annotations

import json
from collections.abc import Callable

import pytest
from estimator_process import run_estimator
from estimator_stream import record
from px4_mag_stream import PX4_CAL, px4_params, px4_stream

from estimator import px4_mag
from wire import param_codec
from wire.dialect import mavlink

SPEED = 4.0  # simulated seconds per wall second
INT32_NAMES = {"SENS_BOARD_ROT"} | {f"CAL_MAG{i}_{f}" for i in range(4) for f in ("ID", "PRIO", "ROT")}


@pytest.mark.parametrize("rates", ["missing", "never"])
def test_the_estimator_redoes_px4s_compass_calibration_on_the_raw_field(rates: str) -> None:
    """``rates`` never: SCALED_IMU streams at 10 Hz only and may not be asked for faster, so HIGHRES_IMU stays."""
    params = px4_params(ROT=2, **PX4_CAL)
    cal = px4_mag.from_params(params)
    assert isinstance(cal, px4_mag.Px4MagCalibration)
    plan = px4_stream(record(20.0), cal, err_deg=12.0, hidden_deg=8.0)
    tx, rx = mavlink.MAVLink(None, srcSystem=1, srcComponent=1), mavlink.MAVLink(None)
    asked: list[str] = []
    intervals: list[tuple[int, float]] = []
    dropped = {"CAL_MAG0_ID", "SENS_BOARD_ROT", "CAL_MAG0_XODIAG"}  # the first request of each goes unanswered

    def serve(data: bytes, reply: Callable[[bytes], None]) -> None:
        for m in rx.parse_buffer(data) or []:
            if m.get_type() == "COMMAND_LONG" and int(m.command) == 511:
                intervals.append((int(m.param1), float(m.param2)))
            if m.get_type() != "PARAM_REQUEST_READ":
                continue
            name = m.param_id.rstrip("\x00")
            asked.append(name)
            if name in dropped:
                dropped.discard(name)
                continue
            kind = param_codec.INT32 if name in INT32_NAMES else param_codec.REAL32
            value = param_codec.encode(params[name], kind)
            reply(mavlink.MAVLink_param_value_message(name.encode(), value, kind, len(params), 0).pack(tx))

    code, out, err = run_estimator([(t, m.pack(tx)) for t, m in plan], SPEED, serve, ("--request-rates", rates), 0.5)
    assert code == 0, err
    if rates == "never":
        assert "the field stays the IMU message's (SCALED_IMU at 10 Hz, under 100, and rates may not be asked" in err
        assert not intervals and json.loads(out)["compass"]["field"] == "imu-message"
        return
    assert "compass: PX4's raw field (SCALED_IMU) calibrated with CAL_MAG0 (device 197388; offsets +0.120, -0.050, " \
           "+0.310 G; external" in err, err
    assert asked.count("CAL_MAG0_ID") == 2 and asked.count("CAL_MAG0_XODIAG") == 2  # asked again when unanswered
    assert "CAL_MAG1_XOFF" not in asked  # only the enabled slot's fields
    assert (26, 1e4) in intervals  # SCALED_IMU at 100 Hz: the IMU input now
    assert "inputs: IMU now PX4's SCALED_IMU" in err
    c = json.loads(out)["compass"]
    assert c["field"] == "px4-scaled-imu-calibrated"
    assert abs(c["offset_deg"] + 12.0) < 0.7, c  # all of the heading error (HIGHRES_IMU's field shows 4 deg)
