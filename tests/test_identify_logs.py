"""System identification from flight logs (identify/logs.py, ``windseek identify --log``), through real formats.

The identification manoeuvre is flown in-process (``calm``, world seeds 1 and 1001, 40 s + 20 s of
excitation: shortened from the paper's 2 min + 1 min for speed), written as PX4 would log it (a ULog:
IMU 250 Hz, attitude / position / ESC 50 Hz, actuator outputs 250 Hz) and stream it (a tlog: IMU 250 Hz,
the rest 50 Hz; tests/flight_logs.py), read back and identified. The result must be the in-process
identification of the same flight sampled as the log samples it (attitude, velocity, ESC and, for the
tlog, the commands linearly interpolated from 50 Hz), on the log's clock and with its exclusions: same
model structure on every axis, coefficients within 0.02 of their 95 % half-width, R^2 within 0.01 points,
TIC within 0.2 % (measured: 0.003, 0.001 points, 0.03 %; what remains is the integer rpm, float32 values
are 1e-6 away). The log's clock matters: with the flight's own (4 ms steps, not rounded to microseconds)
a sample bordering an exclusion can flip in or out, which moved coefficients by 0.1 half-width. The
exclusions themselves agree within 1 % of the samples (a 50 Hz output log misses a motor at its limit
for less than 20 ms). Against the flight as recorded at 250 Hz the 50 Hz sampling costs up to 2 R^2
points (the tlog's yaw axis: 98.6 -> 97.0 %).

Also: a log without ESC telemetry (rotor speeds from the actuator outputs through the vehicle's motor map
and motor lag), the hold-out of ``--log`` alone, the shared real logs (the PX4 SITL hover identifies the
thrust and nothing else, and no vehicle file is written from it), one-line refusals naming what a log
lacks, and ``windseek identify SCENARIO`` unchanged.
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from flight_logs import write_tlog, write_ulog

from identify.design import ManoeuvreSpec, design
from identify.excitation import WIND_TERMS, not_excited, screen, wind_blind
from identify.flight_data import FlightData
from identify.fly.world import fly
from identify.log_outputs import motor_map
from identify.logs import flight_data_from_log, read_log, split_record
from identify.pipeline import Identification, identify
from sitl.scenario import load_scenario
from vehicle.vehicle_file import load_vehicle
from windseek.cli import main as cli_main

_CANDIDATES = [Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "logs", Path("/work/shared/data/logs")]
SHARED = next((p.resolve() for p in _CANDIDATES if (p / "SOURCES.md").is_file()), None)
needs_shared = pytest.mark.skipif(SHARED is None, reason="third-party logs not found at ../shared/data/logs")


class Flights:
    """The in-process flights, their identification, and the logs written from them."""

    def __init__(self, root: Path) -> None:
        sc = load_scenario("calm")
        self.vehicle = v = load_vehicle(sc.vehicle)
        hd = v.n_rotors * v.control["hover_speed"] ** 2
        self.fit = fly(sc, 1, design(ManoeuvreSpec(duration_s=40.0, seed=0), hd), v)
        self.val = fly(sc, 1001, design(ManoeuvreSpec(duration_s=20.0, seed=1), hd), v)
        self.ident = identify(self.fit, v, self.val)
        omap = motor_map(v)
        self.logs: dict[str, Path] = {}
        for part, data in (("fit", self.fit), ("val", self.val)):
            self.logs[f"{part}.ulg"] = write_ulog(root / f"{part}.ulg", data, omap)
            self.logs[f"{part}.tlog"] = write_tlog(root / f"{part}.tlog", data, omap)
            self.logs[f"{part}_noesc.ulg"] = write_ulog(root / f"{part}_noesc.ulg", data, omap,
                                                        drop=frozenset({"esc_status"}))  # fmt: skip
        self._read: dict[str, FlightData] = {}

    def read(self, name: str) -> FlightData:
        """The identification data of one of the logs (read once)."""
        if name not in self._read:
            self._read[name] = flight_data_from_log(self.logs[name], self.vehicle)
        return self._read[name]


@pytest.fixture(scope="module")
def flights(tmp_path_factory: pytest.TempPathFactory) -> Flights:
    return Flights(tmp_path_factory.mktemp("idlogs"))


def resampled(data: FlightData, every: int, commands_every: int) -> FlightData:
    """``data`` as a log samples it: attitude, velocity and ESC speeds (and the commands) kept every
    ``every``-th (``commands_every``-th) sample and interpolated linearly in between, as the reader does."""

    def back(a: np.ndarray, e: int) -> np.ndarray:
        i = np.arange(0, data.n, e)
        return np.column_stack([np.interp(data.t, data.t[i], a[i, k]) for k in range(a.shape[1])])

    q = back(data.quaternion, every)
    assert data.rotor_commands is not None
    return replace(data, quaternion=q / np.linalg.norm(q, axis=1, keepdims=True),
                   velocity_ned=back(data.velocity_ned, every), rotor_speeds=back(data.rotor_speeds, every),
                   rotor_commands=back(data.rotor_commands, commands_every))  # fmt: skip


def cut(data: FlightData, n: int) -> FlightData:
    """The first ``n`` samples of ``data`` (nothing excluded)."""
    return replace(data, t=data.t[:n], specific_force=data.specific_force[:n], rates=data.rates[:n],
                   rotor_speeds=data.rotor_speeds[:n], velocity_ned=data.velocity_ned[:n],
                   quaternion=data.quaternion[:n], excluded=None,
                   rotor_commands=None if data.rotor_commands is None else data.rotor_commands[:n])  # fmt: skip


def assert_saturation_as_sampled(log: FlightData, flown: FlightData) -> None:
    """The log's exclusions are the flight's (saturation) as its outputs sample it, within 1 % of the samples
    each way: a motor at its limit for less than a period between two logged outputs is missed, and an output
    within half a microsecond of PWM of its limit counts as at it (tested exactly in
    test_saturated_outputs_are_excluded_with_a_margin)."""
    assert log.excluded is not None and flown.excluded is not None
    assert (log.excluded & ~flown.excluded).mean() <= 0.01
    assert (flown.excluded & ~log.excluded).mean() <= 0.01


def assert_same_identification(got: Identification, ref: Identification) -> None:
    for a, r in ref.axes.items():
        g = got.axes[a]
        assert g.names == r.names, (a, g.names, r.names)
        for n, th, ci in zip(r.names, r.theta, r.ci95, strict=True):
            assert abs(got.coefficients[n] - th) <= 0.02 * ci, (n, got.coefficients[n], th, ci)
        assert abs(g.r2_pct - r.r2_pct) <= 0.01, (a, g.r2_pct, r.r2_pct)
        assert g.val_tic is not None and r.val_tic is not None
        for x, y in ((g.fit_tic, r.fit_tic), (g.val_tic, r.val_tic)):
            assert abs(x - y) <= 0.002 * y, (a, x, y)


@pytest.mark.parametrize(("suffix", "commands_every"), [("ulg", 1), ("tlog", 5)])
def test_log_identifies_as_the_flight_sampled_like_it(flights: Flights, suffix: str, commands_every: int) -> None:
    v = flights.vehicle
    fit, val = flights.read(f"fit.{suffix}"), flights.read(f"val.{suffix}")
    refs = []
    for log, flown in ((fit, flights.fit), (val, flights.val)):
        assert_saturation_as_sampled(log, flown)
        # on the log's clock (microsecond stamps: which samples border an exclusion can flip) and exclusions
        refs.append(replace(resampled(flown, 5, commands_every), t=log.t, excluded=log.excluded,
                            exclusions=log.exclusions))  # fmt: skip
    got = identify(fit, v, val)
    ref = identify(refs[0], v, refs[1])
    assert_same_identification(got, ref)
    for a, r in flights.ident.axes.items():  # the flight as recorded in-process, at 250 Hz
        assert abs(got.axes[a].r2_pct - r.r2_pct) < 2.0, (a, got.axes[a].r2_pct, r.r2_pct)
    assert screen(got, v) is got  # the manoeuvre excites every term


def test_ulog_holds_the_flight(flights: Flights) -> None:
    lf = read_log(flights.logs["fit.ulg"], flights.vehicle)
    d, f = lf.data, flights.fit
    assert d.n == f.n and np.allclose(d.t, f.t, atol=1e-6)  # the IMU's clock, from the log's start (100 s)
    assert np.abs(d.specific_force - f.specific_force).max() < 1e-5  # float32
    assert np.abs(d.rates - f.rates).max() < 1e-6
    assert d.rotor_commands is not None and f.rotor_commands is not None
    assert np.abs(d.rotor_commands - f.rotor_commands).max() < 1e-3  # PWM floats through the motor map
    assert np.abs(d.rotor_speeds - resampled(f, 5, 1).rotor_speeds).max() < 0.06  # integer rpm
    assert d.excluded is not None and f.excluded is not None
    assert (d.excluded != f.excluded).sum() <= 5  # saturation: the same spans, +-0.1 s edges to rounding
    assert [e.split("% of samples ")[-1] for e in d.exclusions] == [e.split("% of samples ")[-1] for e in f.exclusions]
    assert not d.wind_ned.any() and "wind assumed zero" in d.source and "fit.ulg" in d.source
    assert any("ground contact not checked" in n for n in lf.notes)  # airborne from the first sample


def test_saturated_outputs_are_excluded_with_a_margin(flights: Flights, tmp_path: Path) -> None:
    v = flights.vehicle
    part = cut(flights.fit, 20 * 250 + 1)
    assert part.rotor_commands is not None
    cmd = part.rotor_commands.copy()
    cmd[(part.t >= 5.0) & (part.t < 5.5), 2] = v.rotor_speed_max_rad_s + 50.0  # the map clips it to 2000 us
    cmd[(part.t >= 8.0) & (part.t < 8.2), 0] = v.rotor_speed_min_rad_s
    path = write_ulog(tmp_path / "sat.ulg", replace(part, rotor_commands=cmd), motor_map(v))
    d = flight_data_from_log(path, v)
    sat = [e for e in d.exclusions if e.startswith("motor output at its minimum or maximum")]
    assert len(sat) == 1 and sat[0].endswith("(4.9-5.6 s, 7.9-8.3 s)"), d.exclusions
    assert d.excluded is not None
    assert d.excluded[(d.t > 4.905) & (d.t < 5.59)].all() and not d.excluded[(d.t > 5.61) & (d.t < 7.89)].any()


def test_log_without_esc_identifies_through_the_motor_map(flights: Flights) -> None:
    v = flights.vehicle
    lf = read_log(flights.logs["fit_noesc.ulg"], v)
    fit, val = lf.data, flights.read("val_noesc.ulg")
    assert "no ESC telemetry" in fit.source and "actuator_outputs" in fit.source
    # the commands through the vehicle's motor lag are the rotors' speeds (the world's motors lag the same way)
    assert float(np.sqrt(np.mean((fit.rotor_speeds - flights.fit.rotor_speeds) ** 2))) < 3.0
    got = identify(fit, v, val)
    for a, r in flights.ident.axes.items():
        g = got.axes[a]
        assert g.r2_pct > r.r2_pct - 1.0, (a, g.r2_pct, r.r2_pct)
        assert g.val_tic is not None and r.val_tic is not None and g.val_tic < 1.25 * r.val_tic, (a, g.val_tic)
    assert not wind_blind(got)


def test_motor_order_maps_esc_and_outputs_to_rotors(flights: Flights) -> None:
    v = flights.vehicle
    as_vehicle = flights.read("fit.ulg")  # nasa-quad: px4_outputs = PX4 quad-X
    as_quad_x = flight_data_from_log(flights.logs["fit.ulg"], v, motor_order="quad-x")
    as_logged = flight_data_from_log(flights.logs["fit.ulg"], v, motor_order="windseek")
    assert np.array_equal(as_vehicle.rotor_speeds, as_quad_x.rotor_speeds)
    order = motor_map(v).order  # output k drives rotor order[k]
    for k, rotor in enumerate(order):
        assert np.array_equal(as_logged.rotor_speeds[:, k], as_vehicle.rotor_speeds[:, rotor])
    assert order != (0, 1, 2, 3)


def test_window_and_a_landing_between_airborne_segments(flights: Flights, tmp_path: Path) -> None:
    """Two airborne segments (the land detector says landed 12-15 s): the record spans both, the time
    between is excluded, and so is everything within 1 m of where the log said the vehicle stood."""
    v = flights.vehicle
    path = write_ulog(tmp_path / "hops.ulg", cut(flights.fit, 30 * 250 + 1), motor_map(v), landed=(12.0, 15.0))
    lf = read_log(path, v)
    d = lf.data
    assert d.t[0] == pytest.approx(0.0) and d.t[-1] == pytest.approx(30.0)
    between = [e for e in d.exclusions if e.startswith("on the ground between airborne segments")]
    assert len(between) == 1 and between[0].endswith("(12.0-15.0 s)"), d.exclusions
    assert d.excluded is not None and d.excluded[(d.t > 12.05) & (d.t < 14.95)].all()
    assert any(e.startswith("ground contact or ground effect (less than 1 m") for e in d.exclusions)
    pos = lf.log.position
    stood = float(np.median(pos.v[(pos.t >= 112.0) & (pos.t < 115.0), 2]))
    height = stood - np.interp(d.t + 100.0, pos.t, pos.v[:, 2])
    assert d.excluded[height < 0.95].all()
    assert flights.fit.excluded is not None  # saturation, if the flight had any
    landed_or_saturated = ((d.t >= 12.0) & (d.t < 15.0)) | flights.fit.excluded[: d.n]
    assert not d.excluded[(height > 1.05) & ~landed_or_saturated].any()
    w = flight_data_from_log(path, v, window=(16.0, 29.0))
    assert w.t[0] >= 16.0 and w.t[-1] <= 29.0 and w.duration_s > 12.9
    assert not any(e.startswith("on the ground") for e in w.exclusions)


def test_cli_holds_out_the_last_30_percent(flights: Flights, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    out = tmp_path / "identified.toml"
    log = flights.logs["fit.ulg"]
    assert cli_main(["identify", "--log", str(log), "--vehicle", "nasa-quad", "-o", str(out), "--json"]) == 0
    res = json.loads(capsys.readouterr().out)
    assert res["written"] and res["refused"] is None and not res["wind_blind"]
    v = load_vehicle(out)
    info = v.model_info
    assert info["source"].endswith(f"windseek identify --log {log} --vehicle nasa-quad")
    assert "[first 70%: 0.0-31.5 s]" in info["data"][0] and "[last 30%, held out: 31.5-45.0 s]" in info["data"][1]
    assert 0.6 < info["samples_validation"] / info["samples_fit"] * 0.7 / 0.3 < 1.1  # less any saturated samples
    assert v.coefficients == pytest.approx(res["coefficients"]) and v.mass_kg == flights.vehicle.mass_kg
    assert all(r["val_tic"] is not None for r in res["axes"].values())


def test_cli_with_a_validation_log(flights: Flights, capsys: pytest.CaptureFixture) -> None:
    args = ["identify", "--log", str(flights.logs["fit.tlog"]), "--validation-log", str(flights.logs["val.tlog"]),
            "--vehicle", "nasa-quad", "--json"]  # fmt: skip
    assert cli_main(args) == 0
    res = json.loads(capsys.readouterr().out)
    v = flights.vehicle
    direct = screen(identify(flights.read("fit.tlog"), v, flights.read("val.tlog")), v)
    for a, m in direct.table().items():
        assert res["axes"][a] == pytest.approx(m), a
    assert res["output"] is None and not res["written"]


def test_split_record(flights: Flights) -> None:
    f = flights.fit
    fit, val, how = split_record(f)
    assert val is not None and fit.n + val.n == f.n and "last 30%" in how
    assert fit.t[-1] < f.t[0] + 0.7 * f.duration_s <= val.t[0]
    assert fit.excluded is not None and val.excluded is not None and f.excluded is not None
    assert fit.excluded.sum() + val.excluded.sum() == f.excluded.sum()
    short = cut(f, 8250)  # 33 s: 30 % of it is under 10 s
    whole, none, why = split_record(short)
    assert whole is short and none is None and why.startswith("no validation: the 33.0 s record is too short")
    fit, val, _ = split_record(cut(f, 8500))  # 34 s: 23.8 + 10.2 s
    assert val is not None and val.duration_s > 10.0


def test_excitation_screen_takes_out_what_a_flight_did_not_excite(flights: Flights) -> None:
    v = flights.vehicle
    assert screen(flights.ident, v) is flights.ident
    noise = np.random.default_rng(7).normal(0.0, 0.02, flights.fit.velocity_ned.shape)  # a hover's velocity in calm
    still = replace(flights.fit, velocity_ned=noise)
    raw = identify(still, v, None)
    assert raw.data is not None
    dull = not_excited(raw.data[0], v)
    assert set(dull) >= set(WIND_TERMS["x"]) | set(WIND_TERMS["y"]) | {"C_Z_Tmu2", "C_Z_Ti"}
    assert "C_Z_Tv" not in dull and "C_l_T0" not in dull  # the rotor speeds still vary
    fitted_noise = set(raw.coefficients) & set(dull)
    assert fitted_noise  # step-wise regression alone takes some of them (C_Z_Tmu2 = -4e4: it fits noise)
    s = screen(raw, v)
    assert not set(s.coefficients) & set(dull)
    for n in fitted_noise:
        a = "xyzlmn"["XYZlmn".index(n[2])]
        assert s.axes[a].not_identified[n].startswith("not excited: "), (n, s.axes[a].not_identified[n])
        assert " spans 0.0" in s.axes[a].not_identified[n] and " m/s (needs " in s.axes[a].not_identified[n]
    assert [w[:4] for w in wind_blind(s)] == ["no X", "no Y"]


@needs_shared
def test_hover_log_identifies_the_thrust_only(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    """The PX4 SITL hover (31 s, 11.4 s airborne, 2 m up): nothing but the thrust is excited, so no model
    that could estimate the wind comes out of it, and no vehicle file is written unless asked."""
    assert SHARED is not None
    log, out = SHARED / "px4-sitl-quad-hover.ulg", tmp_path / "hover.toml"
    args = ["identify", "--log", str(log), "--vehicle", "nasa-quad", "-o", str(out), "--json"]
    assert cli_main(args) == 1
    cap = capsys.readouterr()
    res = json.loads(cap.out)
    assert not out.exists() and not res["written"]
    last = cap.err.strip().splitlines()[-1]
    assert last.startswith("windseek identify: not written: the flight did not identify what a wind estimate needs")
    assert list(res["coefficients"]) == ["C_Z_T0"]
    assert all(why.startswith("not excited: ") for why in res["not_identified"]["x"].values())
    assert res["excitation"]["u"] < 0.1 and res["excitation"]["w"] > 1.0
    assert any(e.startswith("ground contact or ground effect") for e in res["exclusions"])
    assert any(n.endswith("the whole record is fitted") for n in res["notes"])  # 11.4 s: no hold-out
    assert cli_main([*args, "--partial"]) == 0
    capsys.readouterr()
    v = load_vehicle(out)
    assert list(v.coefficients) == ["C_Z_T0"] and v.model_info["warning"].startswith("PARTIAL: this model cannot")
    assert out.read_text().splitlines()[2].startswith("# WARNING: PARTIAL model")


@needs_shared
@pytest.mark.parametrize(("name", "why"), [
    ("ardupilot-quadplane-sitl.tlog", "the log's vehicle is a fixed wing (ArduPilot v3.10.0 (dev)), not a multirotor"),
    ("ardupilot-quadplane-sitl.tlog", "IMU at 3.8 Hz (RAW_IMU): at least 50 Hz is needed"),
    ("ardupilot-dataflash-excerpt.BIN", "no airborne segment (STAT (isFlying))"),
    ("px4-bench-never-armed.ulg", "no 3-D velocity; no airborne segment (vehicle_status (armed))"),
    ("px4-vtol-short-hop.ulg", "VTOL fixedrotor"),
])  # fmt: skip
def test_other_shared_logs_are_refused_in_one_line(name: str, why: str, capsys: pytest.CaptureFixture) -> None:
    assert SHARED is not None
    assert cli_main(["identify", "--log", str(SHARED / name), "--vehicle", "nasa-quad"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith(f"windseek identify: error: {name}: cannot identify") and why in err


@pytest.mark.parametrize(("drop", "seconds", "why"), [
    ({"esc_status", "actuator_outputs"}, 14.0, "no rotor speeds (ESC telemetry) and no actuator outputs"),
    ({"vehicle_attitude"}, 14.0, "no attitude"),
    ({"sensor_combined"}, 14.0, "no IMU (accelerometer and gyroscope)"),
    ({"vehicle_local_position"}, 14.0, "no 3-D velocity"),
    ({"vehicle_land_detected", "vehicle_status"}, 14.0, "no airborne segment (neither a landed state nor arming)"),
    (set(), 8.0, "too short: 8.0 s airborne, at least 10 s of flight is needed"),
])  # fmt: skip
def test_a_log_lacking_an_input_is_refused_naming_it(flights: Flights, tmp_path: Path, drop: set[str],
                                                     seconds: float, why: str) -> None:  # fmt: skip
    part = cut(flights.fit, int(seconds * 250) + 1)
    path = write_ulog(tmp_path / "cut.ulg", part, motor_map(flights.vehicle), drop=frozenset(drop))
    with pytest.raises(ValueError) as e:
        flight_data_from_log(path, flights.vehicle)
    assert why in str(e.value) and "\n" not in str(e.value)


def test_scenario_mode_is_unchanged(flights: Flights, capsys: pytest.CaptureFixture) -> None:
    assert cli_main(["identify", "calm", "--duration", "40", "--validation-duration", "20", "--json"]) == 0
    res = json.loads(capsys.readouterr().out)
    assert res["axes"] == flights.ident.table() and res["coefficients"] == flights.ident.coefficients
