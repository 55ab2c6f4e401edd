"""The wind modes a mission can fly with, written once.

- ``estimated``: the paper's UKF on the vehicle's own sensors (what a real vehicle has);
- ``oracle``: the simulator's true mean wind (in-process only; for comparison, no vehicle has it);
- ``mavlink``: WIND_COV from the network (the autopilot's own estimate, a relayed ``windseek estimator``);
- ``none``: no wind information (pure chemotaxis).
"""

from __future__ import annotations

#: In-process (lockstep) trials: ``windseek search``, batch evaluation.
INPROCESS_WIND_MODES: tuple[str, ...] = ("estimated", "oracle", "none")
#: Missions flown over MAVLink: ``windseek mission``.
LIVE_WIND_MODES: tuple[str, ...] = ("estimated", "mavlink", "none")
