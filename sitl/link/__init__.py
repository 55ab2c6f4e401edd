"""MAVLink 2 endpoint around the lockstep simulation: the simulator speaks MAVLink like PX4.

Modules, one job each:

- ``dialect``: the windseek MAVLink dialect (common.xml + ESC_INFO/ESC_STATUS), generated module.
- ``transports``: UDP, TCP server and serial byte pipes (non-blocking).
- ``endpoint``: per-link parsing, dispatch to handlers, routing, counters of bad input.
- ``telemetry``: builders of the outgoing messages from the simulation state and samples.
- ``streams``: stream rates, SET_MESSAGE_INTERVAL / GET_MESSAGE_INTERVAL / REQUEST_MESSAGE.
- ``commands``: COMMAND_LONG / COMMAND_INT with COMMAND_ACK.
- ``mission_protocol``: mission and geofence transfers; ``geofence``: the fence check.
- ``offboard``: SET_POSITION_TARGET_* and SET_ATTITUDE_TARGET.
- ``params``: the parameter protocol over gains, limits and simulation knobs (PX4's INT32/REAL32).
- ``ftp``: MAVLink FTP answered as PX4 (read-only in-memory tree).
- ``runner``: :class:`SitlLink`, the pacing loop (lockstep simulation paced to wall clock * speed).

Identity: system 1, component 1, MAV_TYPE_QUADROTOR, MAV_AUTOPILOT_PX4, PX4 custom modes.
All MAVLink time stamps are simulation time.
"""

from sitl.link.runner import SitlLink
from sitl.link.transports import SerialTransport, TcpServerTransport, UdpTransport

__all__ = ["SerialTransport", "SitlLink", "TcpServerTransport", "UdpTransport"]
