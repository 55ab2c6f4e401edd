"""Who wrote a log and what flew: autopilot versions, vehicle types, and what the force model means.

- :func:`sw_version`: a flight software version word (MAVLink AUTOPILOT_VERSION.flight_sw_version,
  PX4 ULog ``ver_sw_release``) as text. Both PX4 and ArduPilot pack it as major << 24 | minor << 16
  | patch << 8 | type, type being MAVLink's FIRMWARE_VERSION_TYPE (0 dev, 64 alpha, 128 beta,
  192 rc, 255 official); QGroundControl shows it the same way.
- :func:`mav_type_name`: a MAVLink MAV_TYPE as words (``"quadrotor"``, ``"fixed wing"``, ...).
- :func:`model_caveat`: what the estimator's force model (a quadrotor's rotor forces, paper
  Eq. 40-46, with the coefficients of the ``--vehicle`` file) means for the vehicle in the log.
"""

from __future__ import annotations

from wire.dialect import mavlink

#: FIRMWARE_VERSION_TYPE thresholds (MAVLink common.xml) -> label.
_VERSION_TYPES = ((255, ""), (192, "rc"), (128, "beta"), (64, "alpha"), (0, "dev"))
#: MAV_TYPE values of multirotors with four rotors (the paper's model has four).
QUADROTOR_TYPES = frozenset({mavlink.MAV_TYPE_QUADROTOR})
#: Vehicle types (the words of :func:`mav_type_name`, PX4's and the DataFlash reader's) that never fly.
NON_FLYING_TYPES = frozenset({"submarine", "ground rover", "surface boat", "rover", "antenna tracker"})
#: PX4 vehicle_status.vehicle_type (VEHICLE_TYPE_*) -> words.
PX4_VEHICLE_TYPES = {0: "unknown", 1: "multicopter", 2: "fixed wing", 3: "rover", 4: "airship"}


def sw_version(word: int) -> str:
    """``0x01060000`` -> ``"v1.6.0 (dev)"``; ``0x040500FF`` -> ``"v4.5.0"`` (official release)."""
    word = int(word) & 0xFFFFFFFF
    major, minor, patch, kind = (word >> 24) & 0xFF, (word >> 16) & 0xFF, (word >> 8) & 0xFF, word & 0xFF
    label = next(name for lo, name in _VERSION_TYPES if kind >= lo)
    return f"v{major}.{minor}.{patch}" + (f" ({label})" if label else "")


#: MAV_TYPE names of current MAVLink where pymavlink's common.xml still has older or reserved names.
MAV_TYPE_NAMES = {19: "VTOL tailsitter duorotor", 20: "VTOL tailsitter quadrotor", 22: "VTOL fixedrotor",
                  23: "VTOL tailsitter", 24: "VTOL tiltwing"}  # fmt: skip


def mav_type_name(mav_type: int) -> str:
    """MAV_TYPE value -> words, e.g. 2 -> ``"quadrotor"``, 22 -> ``"VTOL fixedrotor"`` (hover rotors + pusher)."""
    if int(mav_type) in MAV_TYPE_NAMES:
        return MAV_TYPE_NAMES[int(mav_type)]
    entry = mavlink.enums["MAV_TYPE"].get(int(mav_type))
    if entry is None or entry.name.startswith("MAV_TYPE_ENUM_END"):
        return f"MAV_TYPE {mav_type}"
    words = entry.name.removeprefix("MAV_TYPE_").lower().replace("_", " ")
    return words.replace("vtol", "VTOL")


#: (word in the vehicle type, what the vehicle is, what the quadrotor force model leaves out for it); the
#: first match counts, so "VTOL (fixed wing)" and "VTOL QuadPlane (fixed wing with lift motors)" are VTOLs.
_NOT_MODELLED = (
    ("vtol", "VTOL", "its wing lift and drag in forward flight, its transitions and its tilt or pusher motors"),
    ("submarine", "submarine", "buoyancy, water drag and thrusters pushing in every direction"),
    ("boat", "surface boat", "buoyancy, hull drag and a water propeller"),
    ("rover", "ground rover", "wheels on the ground carrying its weight"),
    ("coaxial", "coaxial helicopter", "two counter-rotating main rotors with collective and cyclic pitch"),
    ("helicopter", "helicopter", "one main rotor with collective and cyclic pitch, and a tail rotor"),
    ("wing", "fixed wing", "its wing lift and drag, control surfaces and forward motor"),
    ("airship", "airship", "buoyancy carrying its weight, and its hull drag"),
    ("balloon", "balloon", "buoyancy carrying its weight"),
)  # fmt: skip
#: Words of multirotors that do not have the model's four rotors (hexa-, octo-, tri-, Y6, octa-quad, ...).
_MULTIROTOR_WORDS = ("rotor", "copter", "y6", "octa", "hexa")


def _article(noun: str) -> str:
    return ("an " if noun[:1].lower() in "aeiou" else "a ") + noun


def _what_it_is(vehicle_type: str) -> tuple[str, str]:
    """(what the vehicle is, in words with its type, what the quadrotor model lacks for it) for a vehicle
    that is not a quadrotor: ``"submarine"`` -> ``("a submarine, which does not fly", "buoyancy, ...")``."""
    kind = vehicle_type.lower()
    noun, missing = vehicle_type, "its own means of lift"
    for word, n, m in _NOT_MODELLED:
        if word in kind:
            noun, missing = n, m
            break
    else:
        if any(w in kind for w in _MULTIROTOR_WORDS):
            noun, missing = "multirotor", "its rotors beyond the four of a quad-X, its mass and its drag"
    what = _article(vehicle_type if noun.lower() in kind else f"{noun} ({vehicle_type})")
    return what + (", which does not fly" if kind in NON_FLYING_TYPES else ""), missing


def model_caveat(vehicle_type: str, vehicle_file: str, simulated: bool = False) -> str:
    """One sentence: what the re-run's wind means for this vehicle, given the force model's vehicle file.

    The vehicle is named from its type (MAV_TYPE words, PX4's vehicle type or the DataFlash firmware):
    a fixed wing, a submarine, a rover, a boat, a helicopter, a hexa- or octorotor, a VTOL, ..."""
    if simulated:
        return f"model: the log is from windseek's own SITL; the force model is the vehicle file's ({vehicle_file})"
    kind = vehicle_type.lower()
    base = (f"model: the estimator's force model is a quadrotor's rotor thrust and drag (paper Eq. 40-46) with "
            f"the coefficients of '{vehicle_file}'")  # fmt: skip
    if kind in ("quadrotor", "multicopter"):
        return (base + f"; this log's vehicle is a {kind} but not that airframe: its rotors, mass and drag differ, "
                "so the wind figure is biased by the model error (use --vehicle with this airframe's model)")
    if kind == "unknown":
        return base + "; the log does not say what the vehicle is: the figure holds only if it is that airframe"
    what, missing = _what_it_is(vehicle_type)
    return (base + f"; this log's vehicle is {what}, not a quadrotor: the model has none of {missing}, and the "
            "actuator outputs may not be lift motors, so the figure is not a wind measurement (only the "
            "autopilot's own estimate, where logged, is)")


__all__ = ["NON_FLYING_TYPES", "PX4_VEHICLE_TYPES", "QUADROTOR_TYPES", "mav_type_name", "model_caveat", "sw_version"]
