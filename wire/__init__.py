"""What crosses a MAVLink link, shared by every program of the project (no simulator inside).

The SITL, the estimator, the mission runner and the log review all speak the same wire; its
pieces live here so none of them imports another's internals:

- ``dialect``: the windseek MAVLink 2 dialect (common.xml + ESC_INFO/ESC_STATUS), generated module.
- ``names``: the names the mission and the SITL's recorder use on the wire (STATUSTEXT states,
  the declared source as NAMED_VALUE_FLOAT, component ids).
- ``px4_modes``: PX4's custom-mode word (HEARTBEAT.custom_mode, DO_SET_MODE) and mode names.
- ``jsonsafe``: strict-JSON cleaning of result dictionaries (NaN -> null).
- ``param_codec``: PX4's INT32/REAL32 parameter values in PARAM_VALUE/PARAM_SET (bytewise INT32).
- ``signing``: the MAVLink 2 signing key (``--signing-key`` / ``WINDSEEK_SIGNING_KEY``) and verification.
- ``signing_bridge``: signing for MAVSDK, which has none (its ``raw://`` connection through pymavlink).
- ``urls``: MAVSDK-style connection URLs to pymavlink's.
- ``resync``: a parser that re-scans a corrupt frame's bytes (a stray start marker swallowed good frames).
- ``proxy``: a seeded link-fault proxy between two MAVLink endpoints (``windseek link-proxy``).
"""
