"""The world stepped with rotor commands from outside the built-in autopilot (sitl.world.world).

SI units, NED world, FRD body; rotors 1 front-right, 2 rear-right, 3 rear-left, 4 front-left.
"""

from __future__ import annotations

import numpy as np
import pytest

from sitl.scenario import parse_scenario
from sitl.simulation import T_POS, T_ROTOR_CMD, Simulation
from sitl.world.world import RotorCommand, World
from vehicle.frames import quat_to_euler
from vehicle.rotor_model import hover_rotor_speed

AIRBORNE = {"name": "hover-test", "start": {"position_ned": [0.0, 0.0, -5.0], "airborne": True},
            "wind": {"speed_m_s": 3.0, "from_deg": 30.0}, "turbulence": {"level": "low"}}  # fmt: skip


class OutsideHover:
    """A plain Python hover controller (not the built-in autopilot): position PI-D to tilt, tilt
    PD to rotor-speed differences, altitude PID to the collective, run at 250 Hz like PX4's
    lockstep. Reads the world's truth as an autopilot would read its estimator."""

    def __init__(self, world: World, target_ned: np.ndarray) -> None:
        self.w_hover = float(np.mean(hover_rotor_speed(world.vehicle)))
        self.target = np.asarray(target_ned, dtype=float)
        self.int = np.zeros(3)

    def command(self, x: np.ndarray, dt: float) -> np.ndarray:
        pos, vel = x[0:3], x[3:6]
        roll, pitch, _ = quat_to_euler(x[6:10])
        p, q, r = x[10:13]
        err = self.target - pos
        self.int += err * dt
        a_n = 0.8 * err[0] - 1.2 * vel[0] + 0.15 * self.int[0]
        a_e = 0.8 * err[1] - 1.2 * vel[1] + 0.15 * self.int[1]
        pitch_d = -np.clip(a_n / 9.81, -0.5, 0.5)  # nose down to accelerate north
        roll_d = np.clip(a_e / 9.81, -0.5, 0.5)  # right wing down to accelerate east
        climb = -(2.0 * err[2] - 2.5 * vel[2] + 0.5 * self.int[2])
        du = 40.0 * climb
        dr = 60.0 * (roll_d - roll) - 12.0 * p
        dp = 60.0 * (pitch_d - pitch) - 12.0 * q
        dy = -10.0 * r
        w = self.w_hover + du + np.array([-dr + dp + dy, -dr - dp - dy, dr - dp + dy, dr + dp - dy])
        return np.clip(w, 0.0, 600.0)


def test_an_outside_controller_hovers_the_world() -> None:
    world = World(parse_scenario(AIRBORNE).world_spec(), seed=4)
    cmd = RotorCommand()
    ctrl = OutsideHover(world, np.array([0.0, 0.0, -3.0]))
    heights, offsets, tilts = [], [], []
    for _ in range(250 * 25):  # 25 s at 250 Hz: two physics ticks per command, as PX4 lockstep
        cmd.set(ctrl.command(world.x, 0.004))
        world.step(2, cmd)
        if world.t > 15.0:
            heights.append(-world.position[2])
            offsets.append(float(np.hypot(*world.position[0:2])))
            tilts.append(world.tilt_rad)
    assert not world.crashed and not world.on_ground
    assert abs(np.mean(heights) - 3.0) < 0.2 and np.ptp(heights) < 1.0
    assert max(offsets) < 2.0  # the integrator holds the point against 3 m/s of wind
    assert np.degrees(max(tilts)) < 25.0
    samples = world.drain()
    assert len(samples["imu"]) == pytest.approx(250 * 25, abs=2) and samples["gnss"] and samples["esc"]


def test_rotor_commands_replayed_from_outside_give_the_builtin_flight_bit_for_bit() -> None:
    """The built-in autopilot's rotor commands, replayed tick by tick through RotorCommand,
    reproduce its trajectory exactly: both paths run the same physics tick."""
    scenario = parse_scenario({**AIRBORNE, "sensors": {"imu": {"rate_hz": 500.0}, "esc": {"rate_hz": 50.0}}})
    sim = Simulation(scenario, seed=2, record_truth=True)
    sim.fc.reposition(np.array([4.0, -3.0, -6.0]))
    sim.run(6.0)
    truth = sim.truth_array()
    world = World(scenario.world_spec(), seed=2)
    world.phys.x[:] = sim_start_state(scenario)
    cmd = RotorCommand(world.n_rotors)
    for row in truth:
        cmd.set(row[T_ROTOR_CMD][: world.n_rotors])
        world.step(1, cmd)
    assert np.array_equal(world.position, sim.position)
    assert np.array_equal(world.x, sim.x)
    assert np.allclose(truth[-1, T_POS], sim.position, atol=0.1)


def sim_start_state(scenario: object) -> np.ndarray:
    """The built-in autopilot's trimmed airborne start (its captive trim settles the rotors)."""
    return Simulation(scenario, seed=2).x.copy()  # type: ignore[arg-type]


def test_bad_rotor_commands_are_refused() -> None:
    cmd = RotorCommand()
    for bad in ([1.0, 2.0, 3.0], [np.nan, 0, 0, 0], [-1.0, 0, 0, 0]):
        with pytest.raises(ValueError, match="rotor command"):
            cmd.set(np.array(bad, dtype=float))
