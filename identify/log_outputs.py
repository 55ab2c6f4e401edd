"""A logged vehicle's motors: which output drives which rotor, what an output value commands, and the
actuator outputs of a log whose reader kept only its ESC telemetry.

The motor map is an :class:`estimator.motor_output.OutputMap` (output number -> rotor, raw value ->
normalized command u in [0, 1] -> rotor speed in rad/s): PWM 1000-2000 us, the vehicle file's idle
(``rotor_speed_min_rad_s``) to maximum speed, linear in u unless PX4's ``THR_MDL_FAC`` is given.
Which output drives which rotor (``motor_order``):

- ``"vehicle"``: the vehicle file's ``[frame] px4_outputs`` (the PX4 output of each rotor);
- ``"quad-x"``: PX4 / ArduPilot quad-X (1 front-right, 2 rear-left, 3 front-left, 4 rear-right);
- ``"windseek"``: output / ESC k drives rotor k (the project SITL's numbering).

ESC k is taken to report the motor of output k (PX4's ``esc_status``, MAVLink ESC_STATUS, DataFlash ESC).

The review's readers (:mod:`review`) keep the actuator outputs only when a log has no ESC telemetry;
the identification wants both (the outputs say when a motor saturates, and the commands sharpen the
rotor speeds: :func:`identify.measure.rotor_speeds`), so :func:`actuator_outputs` reads them again
through the review's own decoders (pyulog topics, the tlog collector, the DataFlash tables).
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
from pymavlink.dialects.v20 import ardupilotmega

from estimator.motor_output import PX4_QUAD_X, SITL_ORDER, OutputMap
from review import tlog_columns, ulog_topics
from review.df_tables import DataFlashTables
from review.flight import FlightData, Series, outputs_to_rotors
from review.tlog_collect import collect
from review.tlog_scan import survey
from review.ulog import open_ulog
from vehicle.params import VehicleParams
from wire.dialect import mavlink

MOTOR_ORDERS = ("vehicle", "quad-x", "windseek")
OUTPUT_PROFILES = ("px4", "sitl")
#: Output order of the review's decoding here: output / ESC k stays in column k.
AS_LOGGED = (0, 1, 2, 3)


def motor_map(vehicle: VehicleParams, motor_order: str = "vehicle", profile: str = "px4",
              thr_mdl_fac: float | None = None) -> OutputMap:  # fmt: skip
    """The vehicle's :class:`OutputMap` with the output -> rotor order ``motor_order`` (module docstring);
    ``profile`` ``px4``: idle..max speed of the vehicle file over PWM 1000-2000 us; ``sitl``: 0..max."""
    if motor_order not in MOTOR_ORDERS:
        raise ValueError(f"motor order {motor_order!r}: choose one of {', '.join(MOTOR_ORDERS)}")
    if profile not in OUTPUT_PROFILES:
        raise ValueError(f"output profile {profile!r}: choose one of {', '.join(OUTPUT_PROFILES)}")
    n = vehicle.n_rotors
    if motor_order == "vehicle":
        outs = vehicle.px4_outputs or tuple(range(n))
        order = [0] * n
        for rotor, out in enumerate(outs):
            order[out] = rotor
        order_t = tuple(order)
    else:
        order_t = PX4_QUAD_X if motor_order == "quad-x" else SITL_ORDER
    if len(order_t) != n:
        raise ValueError(f"motor order {motor_order!r} numbers {len(order_t)} motors; vehicle {vehicle.name} has {n}")
    return replace(OutputMap.for_vehicle(vehicle, profile, thr_mdl_fac), order=order_t)


def to_rotor_order(values: np.ndarray, omap: OutputMap) -> np.ndarray:
    """Columns of outputs / ESCs 1..N (n, >= N) -> the vehicle's rotor order (n, N)."""
    out = np.empty((values.shape[0], len(omap.order)))
    for k, rotor in enumerate(omap.order):
        out[:, rotor] = values[:, k]
    return out


def commanded_speeds(u: np.ndarray, omap: OutputMap) -> np.ndarray:
    """Normalized commands u in [0, 1] (any shape) -> commanded rotor speeds (rad/s) by the map."""
    return np.vectorize(omap.speed, otypes=[float])(np.clip(u, 0.0, 1.0)) if u.size else u.astype(float)


def actuator_outputs(path: Path, fd: FlightData) -> tuple[Series, str]:
    """The normalized outputs (n, 4) of motors 1-4 (u in [0, 1], PWM 1000-2000 us as the review maps it)
    of the log ``fd`` was read from, and where they came from: ``fd.rotor_cmd`` when the reader kept
    them, else read again; an empty series when the log has none."""
    if len(fd.rotor_cmd):
        return fd.rotor_cmd, fd.sources.get("rotor_cmd", "")
    out = FlightData(path=path, kind=fd.kind)
    src = ""
    if fd.kind == "ulog" and fd.counts.get("actuator_outputs"):
        ulog, _ = open_ulog(path)
        d = next((ds.data for ds in ulog.data_list if ds.name == "actuator_outputs" and ds.multi_id == 0), None)
        if d is not None:
            ulog_topics.outputs_topic(out, d, AS_LOGGED, 1.0)
    elif fd.kind == "tlog":
        src = next((m for m in tlog_columns.OUTPUT_TYPES if fd.counts.get(m)), "")
        if src:
            sv = survey(path)
            dialect = ardupilotmega if fd.family == "ArduPilot" else mavlink
            tlog_columns.output_columns(out, collect(path, dialect, sv.vehicle, {src}), src, AS_LOGGED, 1.0)
    elif fd.kind == "dataflash" and fd.counts.get("RCOU"):
        tables = DataFlashTables(path)
        rc = tables.get("RCOU")
        if rc is not None and all(f"C{i}" in rc for i in range(1, 5)):
            raw = np.column_stack([rc[f"C{i}"] for i in range(1, 5)])
            out.rotor_cmd = Series.of(tables.time_s(rc), outputs_to_rotors(raw, AS_LOGGED, 1.0), "rotor_cmd")
            out.sources["rotor_cmd"] = "RCOU"
    return out.rotor_cmd, out.sources.get("rotor_cmd", src)
