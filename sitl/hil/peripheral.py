"""windseek's sensors as a MAVLink component of the vehicle: how the chemical reading, the rotor speeds
and the truth reach the companion programs when PX4 flies.

On a real vehicle a chemical sensor or an ESC telemetry board is a MAVLink component of the
vehicle's system, connected to a port of the autopilot; PX4 forwards what it publishes to its
other links when forwarding is on (``MAV_X_FORWARD``; PX4 SITL starts every instance with ``-f``).
windseek does the same: a component with PX4's system id and component id 158
(``MAV_COMP_ID_PERIPHERAL``) that sends

- ESC_STATUS (the ESC sensor model's rotor speeds, rpm, 50 Hz; ESC 1-4 = windseek's rotors 1 front
  right, 2 rear right, 3 rear left, 4 front left),
- NAMED_VALUE_FLOAT ``CHEM`` (mg/m^3, the chemical sensor's rate),
- NAMED_VALUE_FLOAT ``TRUEWN/TRUEWE/TRUEWD`` (simulation-only true wind, m/s, NED, 5 Hz),
- a 1 Hz HEARTBEAT (``MAV_TYPE_GENERIC``, ``MAV_AUTOPILOT_INVALID``: never taken for an autopilot).

PX4 SITL: to PX4's onboard payload link (UDP 14280 + instance; PX4 answers the first sender), so
PX4 forwards these to the API link (MAVSDK, ``windseek mission``, 14540 + instance) and the
ground-station link (18570 + instance, ``windseek estimator``). HITL: on the same serial link as
the HIL messages (set ``MAV_0_FORWARD 1`` on that port). PX4 in turn forwards what the companions
publish (WIND_COV, the mission's declaration) here, where :mod:`sitl.hil.summary` scores it.

PX4's own ESC_STATUS in SITL (component 1) is a placeholder (``simulator_mavlink`` publishes
``rpm = 6000 * output``); a companion takes the rotor speeds from component 158
(``--esc-component 158``).
"""

from __future__ import annotations

import contextlib
import socket
from collections import Counter
from typing import Any

from sitl.hil.frames import FrameEncoder
from sitl.hil.messages import heartbeat_peripheral
from wire.dialect import mavlink

#: MAV_COMP_ID_PERIPHERAL.
PERIPHERAL_COMPONENT = 158
#: PX4 SITL's onboard payload link: PX4 binds UDP 14280 + instance (``px4-rc.mavlink``).
PX4_PAYLOAD_PORT = 14280
PX4_SIM_PORT = 4560


def parse_frames(parser: Any, data: bytes, counters: Counter[str]) -> list[Any]:
    """The messages pymavlink's ``parser`` finds in ``data``; unparsable bytes counted (``rx_bad``), never raised."""
    try:
        msgs = parser.parse_buffer(data) or []
    except Exception:  # noqa: BLE001 - hostile input is counted, never raised
        counters["rx_bad"] += 1
        return []
    good = [m for m in msgs if m.get_type() != "BAD_DATA"]
    counters["rx_bad"] += len(msgs) - len(good)
    return good


class UdpPeripheral:
    """The peripheral component on a UDP link to a PX4 MAVLink instance at ``target`` (host, port)."""

    def __init__(self, target: tuple[str, int], system_id: int) -> None:
        self.target = (socket.gethostbyname(target[0]), int(target[1]))
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1" if self.target[0].startswith("127.") else "0.0.0.0", 0))
        self.sock.setblocking(False)
        self.encoder = FrameEncoder(system_id, PERIPHERAL_COMPONENT)
        self._parser = mavlink.MAVLink(None, 0, 0)
        self._parser.robust_parsing = True
        self.counters: Counter[str] = Counter()
        self.name = f"udp:{self.target[0]}:{self.target[1]}"
        self._last_hb = -1e9

    @property
    def system_id(self) -> int:
        return int(self.encoder.srcSystem)

    def set_system_id(self, system_id: int) -> None:
        """Adopt the autopilot's system id (learned from PX4's messages)."""
        self.encoder.srcSystem = int(system_id)

    def send(self, msgs: list[Any]) -> None:
        """One datagram per message batch (split under 1400 bytes); send errors are counted."""
        if not msgs:
            return
        enc = self.encoder.encode
        chunk = b""
        for m in msgs:
            frame = enc(m)
            if len(chunk) + len(frame) > 1400:
                self._sendto(chunk)
                chunk = b""
            chunk += frame
        self._sendto(chunk)
        self.counters["tx_messages"] += len(msgs)

    def _sendto(self, data: bytes) -> None:
        if not data:
            return
        try:
            self.sock.sendto(data, self.target)
        except OSError:  # PX4 not up yet (ICMP port unreachable) or a full buffer
            self.counters["tx_errors"] += 1

    def heartbeat(self, now_wall_s: float) -> None:
        """A HEARTBEAT once per wall second."""
        if now_wall_s - self._last_hb >= 1.0:
            self._last_hb = now_wall_s
            self.send([heartbeat_peripheral()])

    def poll(self) -> list[Any]:
        """Messages PX4 sent us (its onboard streams and what it forwards); never blocks."""
        out: list[Any] = []
        for _ in range(64):  # bounded: at most 64 datagrams per call
            try:
                data = self.sock.recv(65536)  # a non-blocking socket: no select() needed to learn it is empty
            except (BlockingIOError, InterruptedError):
                break
            except OSError:
                self.counters["rx_errors"] += 1
                break
            out.extend(parse_frames(self._parser, data, self.counters))
            # A datagram holds whole frames: a partial one is bad, and never carried into the next datagram.
            p = self._parser
            if p.buf_len() > 0:
                self.counters["rx_bad"] += 1
            p.buf, p.buf_index, p.have_prefix_error = bytearray(), 0, False
            p.expected_length = mavlink.HEADER_LEN_V1 + 2
        self.counters["rx_messages"] += len(out)
        return out

    def close(self) -> None:
        with contextlib.suppress(OSError):
            self.sock.close()


class SharedPeripheral:
    """The peripheral component on the HIL link itself (HITL over serial: one port to the flight
    controller carries both); what PX4 forwards arrives with the HIL link's input."""

    def __init__(self, link: Any) -> None:
        self.link = link
        self.counters: Counter[str] = Counter()
        self.name = f"{link.name} (shared)"
        self._last_hb = -1e9

    @property
    def system_id(self) -> int:
        return int(self.link.encoder.srcSystem)

    def set_system_id(self, system_id: int) -> None:
        self.link.encoder.srcSystem = int(system_id)

    def send(self, msgs: list[Any]) -> None:
        self.link.send(msgs)
        self.counters["tx_messages"] += len(msgs)

    def heartbeat(self, now_wall_s: float) -> None:
        if now_wall_s - self._last_hb >= 1.0:
            self._last_hb = now_wall_s
            self.send([heartbeat_peripheral()])

    def poll(self) -> list[Any]:
        return []

    def close(self) -> None:
        pass
