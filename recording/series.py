"""Where a scalar series is stored: its own entity, or rows shared with other series (issue 30).

A scalar row costs ~22 bytes on disk whatever it holds: 8 the value, and 14 that two series with the
same times can share (its time 6, row id 4, list offset 4). Series logged together at the same times
therefore share rows, in two ways that keep every plot as it was without anything in the layout:

- :data:`ROWS`: series drawn in the same plot are the instances of one ``rr.Scalars`` row (the rotor
  speeds: ``rotors`` holds 4 values a row; one static ``rr.SeriesLines`` names and colours each);
- :data:`CARRIED`: a series no plot shows rides in the rows of the one it goes with, as a component of
  its own beside ``Scalars:scalars`` (the chemical reading in mg/m³ beside its log10, which the
  plot shows). The plot's visualizer reads ``Scalars:scalars`` only.

Every other series is an entity of its own (``Scalars:scalars``, one value a row). The series keep
their names (``rotors/2``, ``chem/value``): :func:`storage` says where each is, the recorder's range
fit and :class:`recording.read.RrdLog` read them by name, in recordings of either layout.
A value that is not finite where a row holds several (a rotor speed) is stored as NaN (a gap in the
plot) and read back as no value, as a series of its own leaves it out.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import rerun as rr

from recording.style import C_ROTORS, C_THRESH, C_TRUTH, Rgb

#: Entity -> the series that are its rows' instances (in order), each with its name and colour in the legend.
ROWS: dict[str, tuple[tuple[str, str, Rgb], ...]] = {
    "rotors": tuple((f"rotors/{i}", f"rotor {i}", c) for i, c in enumerate(C_ROTORS, start=1)),
}
#: The custom archetype of the carried components (their column is ``Chem:mg_m3``).
CARRIED_ARCHETYPE = "Chem"
#: Series -> (the entity whose rows carry it, its component there).
CARRIED: dict[str, tuple[str, str]] = {
    "chem/value": ("chem/log10", f"{CARRIED_ARCHETYPE}:mg_m3"),
    "chem/threshold": ("chem/threshold_log10", f"{CARRIED_ARCHETYPE}:mg_m3"),
}
SCALARS = "Scalars:scalars"


class Storage(NamedTuple):
    """Where a series' values are: the entity, the component and the instance in each row (None: the
    row's only value)."""

    entity: str
    component: str
    instance: int | None


_IN_ROWS = {name: Storage(entity, SCALARS, i) for entity, cols in ROWS.items() for i, (name, _, _) in enumerate(cols)}


def storage(series: str) -> Storage:
    """Where ``series`` is stored in a recording of this layout (its own entity unless grouped above)."""
    got = _IN_ROWS.get(series)
    if got is not None:
        return got
    carried = CARRIED.get(series)
    if carried is not None:
        return Storage(carried[0], carried[1], None)
    return Storage(series, SCALARS, None)


def row_series(entity: str) -> tuple[str, ...]:
    """The series of an entity's ``Scalars:scalars`` instances (its own name when it holds one)."""
    cols = ROWS.get(entity)
    return tuple(name for name, _, _ in cols) if cols is not None else (entity,)


def carried_by(entity: str) -> dict[str, str]:
    """Component -> series carried in the rows of ``entity``."""
    return {comp: series for series, (e, comp) in CARRIED.items() if e == entity}


def row_styles(shared_rows: bool = True) -> list[tuple[str, Any]]:
    """(entity, ``rr.SeriesLines``) of the series above: one per entity of :data:`ROWS` (a name and a
    colour per instance), none for a carried series (no plot shows it); ``shared_rows=False``, as each
    was styled when it had an entity of its own."""
    if shared_rows:
        return [(e, rr.SeriesLines(names=[n for _, n, _ in cols], colors=[c for _, _, c in cols],
                                   widths=[1.5] * len(cols))) for e, cols in ROWS.items()]  # fmt: skip
    rows = [(name, rr.SeriesLines(names=n, colors=[c], widths=1.5)) for cols in ROWS.values() for name, n, c in cols]
    return [*rows, ("chem/value", rr.SeriesLines(names="reading", colors=[C_TRUTH], widths=1.5)),
            ("chem/threshold", rr.SeriesLines(names="threshold", colors=[C_THRESH], widths=1.0))]


__all__ = ["CARRIED", "CARRIED_ARCHETYPE", "ROWS", "SCALARS", "Storage", "carried_by", "row_series", "row_styles",
           "storage"]
