"""windseek as ArduPilot's JSON physics, without ArduPilot: the packet layout, the reply as ArduPilot's own
parser reads it, the motor mapping and thrust curve, and the lockstep rules over a real UDP socket."""

from __future__ import annotations

import json
import re
import socket
import threading
import time
from collections.abc import Iterator

import pytest

from sitl.ardupilot import json_protocol as jp
from sitl.ardupilot.bridge import ArduPilotBridge
from sitl.ardupilot.motors import SPIN_MAX, SPIN_MIN, ardupilot_figures, pwm_to_speeds
from sitl.ardupilot.params import PARAMS_FILE, parm_text
from sitl.ardupilot.runner import JsonOptions, JsonRunner
from sitl.scenario import load_scenario
from vehicle.vehicle_file import load_vehicle

# ArduPilot's keytable (SIM_JSON.h): section, key, kind; required ones are the first, quaternion or attitude.
KEYTABLE = [("", "timestamp", "d"), ("imu", "gyro", "v3"), ("imu", "accel_body", "v3"), ("", "position", "v3"),
            ("", "velocity", "v3"), ("", "quaternion", "q")]  # fmt: skip
_FLOAT = r"\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)"


def ardupilot_parse(line: str) -> dict[str, object]:
    """What SIM_JSON::parse_sensors reads from ``line``: strstr for the section, then for the key after it,
    skip the key and two characters, then atof or sscanf("[%f, %f, %f]") right there."""
    out: dict[str, object] = {}
    for section, key, kind in KEYTABLE:
        p = line.find(section)
        assert p >= 0, section
        p = line.find(key, p + len(section) + 1)
        assert p >= 0, key
        p += len(key) + 2
        if kind == "d":
            m = re.match(_FLOAT, line[p:])
            assert m, f"{key}: atof reads nothing at {line[p:p + 20]!r}"
            out[key] = float(m.group(1))
        else:
            n = 3 if kind == "v3" else 4
            m = re.match(r"\[" + r",\s*".join([_FLOAT] * n) + r"\]", line[p:])  # sscanf's literal '[' and ', '
            assert m, f"{key}: sscanf reads nothing at {line[p:p + 30]!r}"
            out[key] = [float(x) for x in m.groups()]
    return out


def test_servo_packets_16_and_32_channels_and_what_is_not_one() -> None:
    pwm = list(range(1000, 1016))
    p = jp.parse_servo_packet(jp.servo_packet(7, pwm, 1200))
    assert (p.frame_rate, p.frame_count, p.pwm) == (1200, 7, tuple(pwm))
    raw = jp.servo_packet(8, pwm)
    assert len(raw) == jp.SIZE_16 and int.from_bytes(raw[:2], "little") == jp.MAGIC_16
    p32 = jp.parse_servo_packet(jp.servo_packet(9, list(range(32))))
    assert len(p32.pwm) == 32 and p32.frame_count == 9
    assert len(jp.servo_packet(9, list(range(32)))) == jp.SIZE_32
    with pytest.raises(jp.PacketError) as e:
        jp.parse_servo_packet(raw[:-2])
    assert e.value.kind == "bad_size"
    with pytest.raises(jp.PacketError) as e:
        jp.parse_servo_packet(b"\x00\x00" + raw[2:])
    assert e.value.kind == "bad_magic" and "18458" in str(e.value)
    with pytest.raises(jp.PacketError) as e:  # a 16-channel magic on a 32-channel packet
        jp.parse_servo_packet(raw[:2] + jp.servo_packet(1, [0] * 32)[2:])
    assert e.value.kind == "bad_magic"


def test_the_reply_is_read_by_ardupilots_parser_and_is_json() -> None:
    r = jp.state_reply(12.5, [0.1, -0.2, 3e-7], [0.01, 0.02, -9.81], [1.5, -2.0, -10.25], [0.5, 0.0, -1.0],
                    [0.9, 0.1, -0.2, 0.3])  # fmt: skip
    assert r.startswith(b"\n") and r.endswith(b"\n") and r.count(b"\n") == 2
    line = r.decode().strip()
    got = ardupilot_parse(line)
    assert got["timestamp"] == 12.5
    assert got["gyro"] == [0.1, -0.2, 3e-7] and got["accel_body"] == [0.01, 0.02, -9.81]
    assert got["position"] == [1.5, -2.0, -10.25] and got["velocity"] == [0.5, 0.0, -1.0]
    assert got["quaternion"] == [0.9, 0.1, -0.2, 0.3]
    assert json.loads(line)["imu"]["accel_body"][2] == -9.81
    with pytest.raises(ValueError):
        jp.state_reply(float("nan"), [0] * 3, [0] * 3, [0] * 3, [0] * 3, [1, 0, 0, 0])


def test_pwm_maps_to_rotor_speeds_in_the_motor_order_and_out_of_range_is_refused() -> None:
    order = [0, 2, 3, 1]
    r = pwm_to_speeds(tuple([1500, 1000, 2000, 1250] + [1500] * 12), order, 600.0)
    assert not isinstance(r, str)
    speeds, armed = r
    assert speeds == [300.0, 150.0, 0.0, 600.0] and armed  # rotor order: outputs 1, 4, 2, 3
    assert pwm_to_speeds(tuple([1000] * 4 + [1500] * 12), order, 600.0) == ([0.0] * 4, False)  # disarmed
    assert pwm_to_speeds(tuple([0] * 16), order, 600.0) == ([0.0] * 4, False)  # not started yet
    assert pwm_to_speeds(tuple([2050, 950, 1000, 1000] + [0] * 12), order, 600.0)[0] == [600.0, 0, 0, 0]  # clipped
    bad = pwm_to_speeds(tuple([1500, 2500, 1500, 700] + [0] * 12), order, 600.0)
    assert isinstance(bad, str) and "[2, 4]" in bad
    # ArduCopter's motor 1 (front right) drives windseek's rotor 1, 2 (rear left) rotor 3, 3 (front left) rotor 4,
    # 4 (rear right) rotor 2.
    b = ArduPilotBridge(load_scenario("calm"), say=lambda s: None)
    for motor, rotor in ((0, 0), (1, 2), (2, 3), (3, 1)):
        pwm = [1100] * 16
        pwm[motor] = 1900
        b.on_servos(jp.parse_servo_packet(jp.servo_packet(1, pwm)))
        sp = b.guard.command.speeds
        assert max(range(4), key=lambda i: sp[i]) == rotor


def test_thrust_curve_is_arducopters_model_of_the_rotor() -> None:
    v = load_vehicle("nasa-quad")
    f = ardupilot_figures(v)
    c, wm = v.control, v.rotor_speed_max_rad_s

    def thrust(u: float) -> float:  # the truth's static thrust at ESC command u
        return c["kt2"] * (wm * u) ** 2 + c["kt1"] * wm * u

    t0, t1 = thrust(SPIN_MIN), thrust(SPIN_MAX)
    e = f.thst_expo
    for r in (0.1, 0.3, 0.5, 0.8):  # ArduCopter's thrust model over its spin range, against the rotor's
        model = (1 - e) * r + e * r * r
        assert model == pytest.approx((thrust(SPIN_MIN + (SPIN_MAX - SPIN_MIN) * r) - t0) / (t1 - t0), abs=1e-9)
    # ArduCopter's actuator for its hover throttle (thrust_to_actuator) is the ESC command that hovers.
    h = f.thst_hover
    ratio = ((e - 1) + ((1 - e) ** 2 + 4 * e * h) ** 0.5) / (2 * e)
    assert SPIN_MIN + (SPIN_MAX - SPIN_MIN) * ratio == pytest.approx(f.hover_esc, abs=1e-9)
    assert thrust(f.hover_esc) * 4 == pytest.approx(v.mass_kg * v.gravity_m_s2, rel=1e-9)
    assert PARAMS_FILE.read_text() == parm_text(v), "regenerate: python -m sitl.ardupilot.params > " + str(PARAMS_FILE)
    with pytest.raises(ValueError, match="quad X"):
        parm_text(load_vehicle("hexa-550"))


class FakeArduPilot:
    """ArduPilot's side of the JSON interface on a real UDP socket: servo packets out, replies in."""

    def __init__(self, port: int) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.settimeout(2.0)
        self.target = ("127.0.0.1", port)

    def frame(self, count: int, pwm: list[int]) -> dict:
        self.sock.sendto(jp.servo_packet(count, pwm, 1200), self.target)
        return json.loads(self.sock.recv(4096))

    def silent_after(self, data: bytes, wait_s: float = 0.15) -> bool:
        """Send ``data``; True if nothing came back within ``wait_s``."""
        self.sock.sendto(data, self.target)
        self.sock.settimeout(wait_s)
        try:
            self.sock.recv(4096)
            return False
        except TimeoutError:
            return True
        finally:
            self.sock.settimeout(2.0)


@pytest.fixture
def served() -> Iterator[tuple[JsonRunner, list[str]]]:
    said: list[str] = []
    r = JsonRunner(ArduPilotBridge(load_scenario("calm"), say=said.append), JsonOptions(port=0, stall_s=0.5),
                   None, said.append)  # fmt: skip
    th = threading.Thread(target=r.serve, kwargs={"wall_limit_s": 60.0}, daemon=True)
    th.start()
    try:
        yield r, said
    finally:
        r.stop()
        th.join(5.0)
        r.close()
    assert not th.is_alive()


def test_lockstep_one_reply_per_frame_resends_restarts_and_junk(served: tuple[JsonRunner, list[str]]) -> None:
    r, said = served
    ap = FakeArduPilot(r.port)
    dt = r.bridge.tick_s
    ts = [ap.frame(i, [1000] * 16)["timestamp"] for i in range(50)]
    assert all(b - a == pytest.approx(dt) for a, b in zip(ts, ts[1:], strict=False)) and ts[0] > 0
    again = ap.frame(49, [1000] * 16)  # a resend: the same state, the world does not move
    assert again["timestamp"] == ts[-1] and r.counters["resends"] == 1
    assert ap.frame(50, [1000] * 16)["timestamp"] == pytest.approx(ts[-1] + dt)
    # Junk is never answered, and counted by kind.
    assert ap.silent_after(b"\x01\x02\x03")
    assert ap.silent_after(b"\x00\x00" + jp.servo_packet(51, [1000] * 16)[2:])
    assert r.counters["rx_bad_size"] == 1 and r.counters["rx_bad_magic"] == 1
    assert sum("not a servo packet" in s for s in said) == 2
    # Climb at full power, then ArduPilot restarts (frame 0) disarmed: the safety pilot lands the vehicle.
    n = 51
    for _ in range(1500):
        ap.frame(n, [1950] * 4 + [0] * 12)
        n += 1
    w = r.bridge.world
    assert -w.position[2] > 3.0
    before = r.counters["frames"]
    ap.frame(0, [1000] * 4 + [0] * 12)
    assert r.counters["restarts"] == 1 and r.bridge.guard.counters["safety_landings"] == 1
    assert any("restarted" in s for s in said) and any("lands the vehicle" in s for s in said)
    for i in range(1, 50000):
        ap.frame(i, [1000] * 4 + [0] * 12)
        if r.bridge.guard.safety is None:
            break
    assert w.on_ground and not w.crashed and r.counters["frames"] > before
    assert any("safety landing done" in s for s in said)
    # Out-of-range outputs: refused, counted, said once.
    ap.frame(5000, [3000] * 4 + [0] * 12)
    ap.frame(5001, [3000] * 4 + [0] * 12)
    assert r.bridge.guard.counters["controls_out_of_range"] == 2
    assert sum("refused (out_of_range)" in s for s in said) == 1
    # Silence is reported once as a stall, and the return said.
    time.sleep(0.9)
    ap.frame(5002, [1000] * 4 + [0] * 12)
    assert r.counters["stalls"] == 1 and any("frozen" in s for s in said) and any("again" in s for s in said)
    s = r.summary()
    assert s["frames"] == r.counters["frames"] and s["lockstep_speed"] > 0
