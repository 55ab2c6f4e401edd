"""World digest: one SHA-256 over everything a flight of the built-in autopilot produces, to show a speed change
kept the numbers bit for bit (issue 30).

Flies ``open-field`` 40 s, ``paper-s1`` 30 s, ``paper-s4`` 20 s and ``modes`` 120 s (paper-s1 from the ground through
take-off, waypoints, land, take-off and RTL) with fixed seeds and hashes, after every slow tick (50 Hz): the world's
state vector, flags and tick, the autopilot's setpoint and controller memory, the run's statistics, the plume's live
puffs (position, r^2, mass, meander cache, release time and serial), its mass budget and meander frame, the chemical
sensor's element, and every sensor sample drained since the previous slow tick (IMU, ESC, GNSS, baro, magnetometer,
chemical), each value exactly (floats by their bits, not a rounded repr). Prints a 16-hex digest per scenario. Usage:

    python benchmarks/world_digest.py [--scenario open-field:40:7[:vehicle] ...]
"""

from __future__ import annotations

import argparse
import dataclasses
import hashlib
import sys
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from toolchain import numba_cache  # before any kernel module

numba_cache.configure()
from sitl.scenario import Route, Scenario, Waypoint, load_scenario  # noqa: E402
from sitl.simulation import Simulation  # noqa: E402

#: (scenario, simulated seconds, seed) flown by default; "modes" is paper-s1 flown from the ground through every mode.
CASES = (("open-field", 40.0, 7), ("paper-s1", 30.0, 3), ("paper-s4", 20.0, 5), ("modes", 120.0, 9))


def modes_scenario() -> Scenario:
    """paper-s1's wind from the ground: take-off, two waypoints (one far: the setpoint leads), land; the digest then
    arms, takes off and returns to launch (climb, return, descent) with the commands of the MAVLink link."""
    sc = load_scenario("paper-s1")
    route = Route(takeoff_altitude_m=8.0, cruise_speed_m_s=4.0, land=True,
                  waypoints=(Waypoint((15.0, 0.0, -8.0), hold_s=2.0), Waypoint((40.0, 30.0, -12.0), speed_m_s=6.0)))
    return replace(sc, start=replace(sc.start, position_ned=(0.0, 0.0, 0.0), airborne=False), route=route)


def canonical(value: Any, h: Any) -> None:
    """Feed ``value`` to hash ``h`` exactly: arrays and floats by their float64 bytes, numbers, strings and booleans
    by their repr, sequences and dataclasses element by element (field names included), rows of an array-valued
    sample run one by one, so a sample kept as a tuple or as a row of arrays hashes the same."""
    if isinstance(value, np.ndarray):
        h.update(np.ascontiguousarray(value, dtype=np.float64).tobytes())
    elif isinstance(value, (float, np.floating)):
        h.update(np.float64(value).tobytes())
    elif isinstance(value, (bool, int, str, np.integer, np.bool_)) or value is None:
        h.update(repr(value if not isinstance(value, (np.integer, np.bool_)) else value.item()).encode())
    elif dataclasses.is_dataclass(value) and not isinstance(value, type):
        for f in dataclasses.fields(value):
            h.update(f.name.encode())
            canonical(getattr(value, f.name), h)
    elif isinstance(value, (tuple, list)):
        for v in value:
            canonical(v, h)
    else:
        raise TypeError(f"world_digest: cannot hash a {type(value).__name__}")


def samples(drained: dict[str, Any]) -> list[tuple[str, Any]]:
    """The drained samples as (sensor, sample) pairs, one per sample, oldest first per sensor."""
    out: list[tuple[str, Any]] = []
    for name in sorted(drained):
        out.extend((name, s) for s in drained[name])
    return out


def digest(scenario: str, seconds: float, seed: int, vehicle: str | None = None) -> tuple[str, int, int]:
    """(16-hex digest, slow ticks hashed, samples hashed) of ``scenario`` flown ``seconds`` s with ``seed`` (and the
    vehicle file ``vehicle`` instead of the scenario's)."""
    sc = modes_scenario() if scenario == "modes" else load_scenario(scenario)
    if vehicle:
        sc = replace(sc, vehicle=vehicle)
    sim = Simulation(sc.with_duration(seconds + 1.0), seed=seed)
    h = hashlib.sha256()
    counts = [0, 0]

    def hook(s: Simulation) -> None:
        w = s.world
        st = s.stats
        canonical((w.tick, w.phys.x, w.phys.flags, w.phys.fb, s.autopilot.fc.sp, s.autopilot.cs, st.pos_err_sq_sum,
                   st.pos_err_n, st.airborne_s, st.max_tilt_rad), h)
        plume = s.plume
        store = getattr(plume, "_store", None)
        if store is not None:
            canonical((plume.t, store.pos, store.r2, store.mass, store.unit, store.t_rel, store.serial.astype(float),
                       plume.released_mass_g, plume.removed_domain_mass_g, plume.removed_cap_mass_g, plume.reflected,
                       plume._meander.offset, plume._meander.phase, s.chem.sensor.state_mg_m3), h)
        got = samples(s.drain())
        for name, sample in got:
            h.update(name.encode())
            canonical(sample, h)
        counts[0] += 1
        counts[1] += len(got)

    sim.step_hooks.append(hook)
    if scenario == "modes":
        sim.run_until(70.0)  # landed and disarmed by then
        fc = sim.fc
        canonical((fc.arm()[0], fc.takeoff(6.0)[0]), h)
        sim.run_until(85.0)
        canonical(fc.rtl()[0], h)
    sim.run_until(seconds)
    hook(sim)
    return h.hexdigest()[:16], counts[0], counts[1]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", action="append", default=None,
                    help="name:seconds:seed[:vehicle] (repeatable); default: "
                    + " ".join(f"{a}:{b:g}:{c}" for a, b, c in CASES))  # fmt: skip
    args = ap.parse_args()
    cases = [tuple(s.split(":")) for s in args.scenario] if args.scenario else [tuple(map(str, c)) for c in CASES]
    for name, seconds, seed, *vehicle in cases:
        d, ticks, n = digest(name, float(seconds), int(seed), vehicle[0] if vehicle else None)
        label = name + (f" ({vehicle[0]})" if vehicle else "")
        print(f"{label:12s} {float(seconds):5.0f} s seed {seed}: {d}  ({ticks} slow ticks, {n} samples)", flush=True)


if __name__ == "__main__":
    main()
