"""ArduPilot SITL's JSON physics interface on the wire: servo packets in, one JSON state line out.

The reference is ArduPilot's ``libraries/SITL/SIM_JSON.cpp`` / ``SIM_JSON.h`` and
``libraries/SITL/examples/JSON/readme.md`` (upstream master of 2025-07, 265753db8b):

- **Servo packet** (ArduPilot -> physics, UDP, little-endian): ``uint16 magic, uint16 frame_rate,
  uint32 frame_count, uint16 pwm[16]`` with magic 18458 (40 bytes), or ``pwm[32]`` with magic 29569
  (72 bytes, ``SERVO_32_ENABLE 1``). ``frame_rate`` is ArduPilot's physics rate [Hz]; ``frame_count``
  increments by one for each JSON reply ArduPilot has taken, and is resent unchanged when no reply
  came within 1 s; it starts again from 0 when ArduPilot restarts. ``pwm`` in microseconds.
- **State reply** (physics -> ArduPilot, to the address the packet came from): one JSON object
  between newlines. ArduPilot's parser (``parse_sensors``) is not a JSON parser: it finds each key
  with ``strstr`` in a fixed order and reads vectors with ``sscanf("[%f, %f, %f]")``. So the reply
  is written without a space after ``:`` and with the required keys before anything whose name
  contains one of them. Required: ``timestamp`` (s, the physics time, absolute: ArduPilot's clock
  advances by its differences, and only steps of 0-0.1 s pace it), ``imu.gyro`` (rad/s, body FRD),
  ``imu.accel_body`` (specific force, m/s^2, body FRD: -9.8 on z at rest), ``position`` (m, NED from
  ArduPilot's origin, its ``--home``), ``velocity`` (m/s, NED); and ``quaternion`` (``[w, x, y, z]``,
  body to NED) or ``attitude`` (roll, pitch, yaw, rad).

Pure functions on bytes and numbers, no I/O. Units SI, NED world, FRD body.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass
from typing import Any

#: Magic of a 16-channel servo packet, and of a 32-channel one (``SIM_JSON.h`` servo_packet_16/32).
MAGIC_16 = 18458
MAGIC_32 = 29569
_HEAD = struct.Struct("<HHI")
_PWM16 = struct.Struct("<16H")
_PWM32 = struct.Struct("<32H")
SIZE_16 = _HEAD.size + _PWM16.size  # 40 bytes
SIZE_32 = _HEAD.size + _PWM32.size  # 72 bytes


@dataclass(frozen=True)
class ServoPacket:
    """One servo packet: ``frame_rate`` [Hz], ``frame_count``, ``pwm`` (us, one per channel)."""

    frame_rate: int
    frame_count: int
    pwm: tuple[int, ...]


class PacketError(ValueError):
    """A datagram that is not a servo packet; ``kind`` names the counter it goes to."""

    def __init__(self, kind: str, why: str) -> None:
        super().__init__(why)
        self.kind = kind


def parse_servo_packet(data: bytes) -> ServoPacket:
    """Decode a servo packet; :class:`PacketError` (``bad_size`` / ``bad_magic``) for anything else."""
    n = len(data)
    if n not in (SIZE_16, SIZE_32):
        raise PacketError("bad_size", f"{n} bytes: a servo packet is {SIZE_16} (16 channels) or {SIZE_32} (32)")
    magic, rate, count = _HEAD.unpack_from(data)
    want = MAGIC_16 if n == SIZE_16 else MAGIC_32
    if magic != want:
        raise PacketError("bad_magic", f"magic {magic}: a {n}-byte servo packet has magic {want}")
    pwm = (_PWM16 if n == SIZE_16 else _PWM32).unpack_from(data, _HEAD.size)
    return ServoPacket(int(rate), int(count), pwm)


def servo_packet(frame_count: int, pwm: list[int] | tuple[int, ...], frame_rate: int = 500) -> bytes:
    """A servo packet as ArduPilot sends it (16 or 32 channels by ``len(pwm)``): for tests and probes."""
    if len(pwm) == 16:
        return _HEAD.pack(MAGIC_16, frame_rate, frame_count) + _PWM16.pack(*pwm)
    if len(pwm) == 32:
        return _HEAD.pack(MAGIC_32, frame_rate, frame_count) + _PWM32.pack(*pwm)
    raise ValueError(f"{len(pwm)} channels: a servo packet has 16 or 32")


#: The state line: timestamp and position as doubles (ArduPilot reads them with strtod / ``%lf``), the
#: rest as float32 (``%f``): 17 and 9 significant digits read back exactly. One format call: this runs
#: once per ArduPilot frame (800 a simulated second).
_STATE = ('\n{"timestamp":%.17g,"imu":{"gyro":[%.9g,%.9g,%.9g],"accel_body":[%.9g,%.9g,%.9g]},'
          '"position":[%.17g,%.17g,%.17g],"velocity":[%.9g,%.9g,%.9g],"quaternion":[%.9g,%.9g,%.9g,%.9g]}\n')


def state_reply(t: float, gyro_frd: Any, accel_frd: Any, pos_ned: Any, vel_ned: Any, quat: Any) -> bytes:
    """The JSON state line for simulation time ``t`` [s]: rates [rad/s] and specific force [m/s^2] in
    body FRD (the IMU sample), position [m] and velocity [m/s] NED, attitude quaternion ``[w, x, y, z]``
    (body -> NED); numpy arrays or sequences. Newline before and after, as ``recv_fdm`` splits on them."""
    if not math.isfinite(t):
        raise ValueError(f"timestamp {t}: not finite")
    g, a, p, v, q = gyro_frd, accel_frd, pos_ned, vel_ned, quat
    return (_STATE % (t, g[0], g[1], g[2], a[0], a[1], a[2], p[0], p[1], p[2], v[0], v[1], v[2],
                      q[0], q[1], q[2], q[3])).encode()  # fmt: skip
