"""The sensors' sample logs (sitl/world/sensors.py, sensor_kernel.py): samples are kept as rows and made into objects
when drained. Draining rarely, with a bound that drops the oldest, must give the newest samples of draining often,
exactly; GNSS fixes come out only once their latency has elapsed. (world_digest checks odd step groupings against
the previous implementation.)"""

from __future__ import annotations

import numpy as np

from sitl.scenario import load_scenario
from sitl.simulation import Simulation


def _flat(samples: list) -> list[tuple]:
    """A sample as a tuple of its values (arrays as bytes), so two drains compare exactly."""
    out = []
    for s in samples:
        vals = s if isinstance(s, tuple) else tuple(vars(s).values())
        out.append(tuple(v.tobytes() if isinstance(v, np.ndarray) else v for v in vals))
    return out


def test_rare_bounded_drains_keep_the_newest_samples_of_frequent_drains() -> None:
    sc = load_scenario("paper-s1").with_duration(10.0)
    often = Simulation(sc, seed=4)
    rare = Simulation(sc, seed=4)
    bound = 40  # below the IMU, ESC, baro and magnetometer samples of a drain: those logs are trimmed in flight
    rare.world.sensors.maxlen = bound
    for _ in range(3):
        block: dict[str, list] = {}
        # Whole control periods (the IMU's bias walk is summed per batch, so its bits follow the batches).
        for _ in range(59):
            often.step(10)
            for name, samples in often.drain().items():
                block.setdefault(name, []).extend(_flat(samples))
        rare.step(59 * 10)
        for name, samples in rare.drain().items():
            want = block.get(name, [])
            assert _flat(samples) == want[-bound:], name
            assert len(samples) == min(bound, len(want)) and (name == "chem" or len(want) > 0)
    latency = sc.sensors.gnss.latency_s
    for s in rare.drain()["gnss"] + often.drain()["gnss"]:
        assert s.t + latency <= rare.t + 1e-9
