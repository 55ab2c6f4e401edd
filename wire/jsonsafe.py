"""Strict JSON for result dictionaries: every ``--json`` output and summary file goes through here."""

from __future__ import annotations

import math
from typing import Any


def json_safe(o: Any) -> Any:
    """``o`` with non-finite floats replaced by None (strict JSON has no NaN), numpy scalars and
    arrays turned into Python numbers and lists, recursively."""
    if hasattr(o, "tolist") and not isinstance(o, str | bytes):  # numpy scalar or array
        o = o.tolist()
    if isinstance(o, float):
        return o if math.isfinite(o) else None
    if isinstance(o, dict):
        return {k: json_safe(v) for k, v in o.items()}
    if isinstance(o, list | tuple):
        return [json_safe(v) for v in o]
    return o
