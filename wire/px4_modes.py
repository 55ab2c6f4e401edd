"""PX4's custom flight modes on the wire: HEARTBEAT ``custom_mode`` and DO_SET_MODE main/sub modes.

PX4 packs its mode into one 32-bit word (``px4_custom_mode.h``): the main mode in bits 16-23,
the auto sub mode in bits 24-31. Names here are PX4's own (QGroundControl and MAVSDK show the
same): ``AUTO.LOITER`` is Hold, ``AUTO.MISSION`` Mission, ``OFFBOARD`` Offboard, and so on.
"""

from __future__ import annotations

# Main modes (PX4_CUSTOM_MAIN_MODE_*).
MAIN_MANUAL, MAIN_ALTCTL, MAIN_POSCTL, MAIN_AUTO, MAIN_ACRO, MAIN_OFFBOARD, MAIN_STABILIZED = 1, 2, 3, 4, 5, 6, 7
# Auto sub modes (PX4_CUSTOM_SUB_MODE_AUTO_*).
AUTO_READY, AUTO_TAKEOFF, AUTO_LOITER, AUTO_MISSION, AUTO_RTL, AUTO_LAND = 1, 2, 3, 4, 5, 6
AUTO_PRECLAND = 9

MAIN_NAMES = {MAIN_MANUAL: "MANUAL", MAIN_ALTCTL: "ALTCTL", MAIN_POSCTL: "POSCTL", MAIN_ACRO: "ACRO",
              MAIN_OFFBOARD: "OFFBOARD", MAIN_STABILIZED: "STABILIZED"}  # fmt: skip
AUTO_NAMES = {AUTO_READY: "AUTO.READY", AUTO_TAKEOFF: "AUTO.TAKEOFF", AUTO_LOITER: "AUTO.LOITER",
              AUTO_MISSION: "AUTO.MISSION", AUTO_RTL: "AUTO.RTL", AUTO_LAND: "AUTO.LAND",
              AUTO_PRECLAND: "AUTO.PRECLAND"}  # fmt: skip

#: MAV_MODE_FLAG_SAFETY_ARMED in HEARTBEAT.base_mode.
SAFETY_ARMED = 128
#: MAV_MODE_FLAG_CUSTOM_MODE_ENABLED in HEARTBEAT.base_mode.
CUSTOM_MODE_ENABLED = 1


def encode(main: int, sub: int = 0) -> int:
    """The custom_mode word of a main / sub mode pair."""
    return ((main & 0xFF) << 16) | ((sub & 0xFF) << 24)


def decode(custom_mode: int) -> tuple[int, int]:
    """(main, sub) of a custom_mode word."""
    return (custom_mode >> 16) & 0xFF, (custom_mode >> 24) & 0xFF


def name(custom_mode: int) -> str:
    """PX4's name of a HEARTBEAT custom_mode word (``MODE<n>`` / ``AUTO.<n>`` when unknown)."""
    main, sub = decode(custom_mode)
    if main == MAIN_AUTO:
        return AUTO_NAMES.get(sub, f"AUTO.{sub}")
    return MAIN_NAMES.get(main, f"MODE{main}")


def from_name(mode_name: str) -> tuple[int, int]:
    """(main, sub) of a PX4 mode name; KeyError if unknown."""
    for sub, n in AUTO_NAMES.items():
        if n == mode_name:
            return MAIN_AUTO, sub
    for main, n in MAIN_NAMES.items():
        if n == mode_name:
            return main, 0
    raise KeyError(mode_name)
