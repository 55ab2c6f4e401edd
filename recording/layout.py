"""The viewer layout (blueprint) of a recording, built from a few facts about the run.

:class:`Layout` holds what the layout depends on: the map's extent (the search area, not the
plume's), the flight altitude (the 3D camera), the time range the plots open on (the whole flight,
with room on the right for the legends), each plot's value range (fitted to the data, so early
large uncertainties or a touchdown spike do not flatten the rest), which panels have no data and
why (a text panel says so instead of an empty plot), and whether phase markers exist. The recorder
sends :func:`make_blueprint` once at the start (no facts yet: a usable layout if the run is cut
short) and again, with the facts, when it closes; the facts are stored in the recording (property
``layout``) so a rewritten recording gets the same layout.

The layout::

    +--------------------------------+------------------------------------+
    | map (north up)                 | phases: mission / strategy / mode  |
    |                                | altitude (m, up)                   |
    |                                | chemical (log10 mg/m³)             |
    +----------------+---------------+ [wind | flight | battery · GPS |   |
    | 3D             | run summary   |  rotors]: wind speed, wind from,   |
    +----------------+---------------+  wind north, east, down / velocity,|
    | events                         |  attitude / voltage, current, ... |
    +--------------------------------+------------------------------------+

Every plot spans the right column's whole width and opens on the same time range (the flight, with
room on the right for its legend), so a moment lines up across all of them; every plot shows its
legend. A tab holds only the plots with data (a tab without any is left out); a review opens on the
flight tab (:attr:`Layout.first_tab`), a simulated run on the wind.
The plots take the whole height of the right column: at a 1600 x 1000 window a plot needs about
20 pixels per unit of its value axis before the viewer labels the axis (a wind plot spans ~5 m/s).
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field, fields

import rerun as rr
import rerun.blueprint as rrb
from rerun.blueprint.encodings import TextLogColumn, TimelineColumn

from recording.style import SCENE_BACKGROUND, TIMELINE

#: Plots: key -> (title, origin, contents below the origin, legend shown). A legend lists the
#: series by name (the markers' first) in the plot's top right corner, over the room left there.
PLOTS: dict[str, tuple[str, str, tuple[str, ...], bool]] = {
    "altitude": ("altitude, m (up, above the start / the log's local origin)", "/flight/altitude", ("**",), True),
    "chem": ("chemical, log10 mg/m³", "/chem", ("log10", "threshold_log10"), True),
    "speed": ("wind speed, m/s", "/wind/speed", ("**",), True),
    "direction": ("wind from, ° (0 = north; unwrapped: may run past 0 / 360)", "/wind/direction", ("**",), True),
    "north": ("wind north (N), m/s", "/wind/north", ("**",), True),
    "east": ("wind east (E), m/s", "/wind/east", ("**",), True),
    "down": ("wind down (D), m/s", "/wind/down", ("**",), True),
    "velocity": ("ground velocity, m/s (north, east, down)", "/flight/velocity", ("**",), True),
    "attitude": ("attitude, ° (roll, pitch, yaw; yaw unwrapped)", "/flight/attitude", ("**",), True),
    "voltage": ("battery voltage, V", "/flight/battery", ("voltage",), True),
    "current": ("battery current, A", "/flight/battery", ("current",), True),
    "remaining": ("battery remaining, %", "/flight/battery", ("remaining",), True),
    "gps": ("GPS fix type · satellites used", "/flight/gps", ("**",), True),
    "rotors": ("rotor speed, rad/s", "/rotors", ("**",), True),
}
#: Tabs of plots below the chemical one: name -> plot keys (top to bottom).
TABS: dict[str, tuple[str, ...]] = {
    "wind": ("speed", "direction", "north", "east", "down"),
    "flight": ("velocity", "attitude"),
    "battery · GPS": ("voltage", "current", "remaining", "gps"),
    "rotors": ("rotors",),
}
#: Tabs shown only when a plot of theirs has data (the others say why a plot is empty).
OPTIONAL_TABS = ("flight", "battery · GPS")
#: Plots that appear only with data: no "no data" line is written or shown for them.
OPTIONAL_PLOTS = frozenset(k for name in OPTIONAL_TABS for k in TABS[name])
#: Other panels: key -> title.
PANELS = {"map": "map (north up)", "3d": "3D (NED)", "summary": "run summary", "events": "events",
          "phases": "mission phase · strategy state · flight mode"}  # fmt: skip
#: Fraction of the flight's duration added on the right of every plot: the legends sit there (a
#: legend is ~180 px wide: a fifth of a plot half a 1600 px window wide).
LEGEND_PAD = 0.3


@dataclass
class Layout:
    """Facts the layout depends on (see the module docstring); all optional.

    bounds_ne: (north_min, north_max, east_min, east_max) of the map [m].
    altitude_m: flight altitude above the start [m] (aims the 3D camera).
    t_range: (start, end) of the flight [s, vehicle time]: what the plots open on.
    y_ranges: plot key -> (low, high) of its value axis.
    missing: panel or plot key -> one line saying why it has no data.
    markers: phase marker series exist (``markers/...``; they need fixed value axes).
    top_m: the tallest thing in the scene above the ground [m] (buildings; aims the 3D camera).
    first_tab: the tab of plots shown first (:data:`TABS`).
    """

    bounds_ne: tuple[float, float, float, float] | None = None
    altitude_m: float = 5.0
    t_range: tuple[float, float] | None = None
    y_ranges: dict[str, tuple[float, float]] = field(default_factory=dict)
    missing: dict[str, str] = field(default_factory=dict)
    markers: bool = False
    top_m: float = 0.0
    first_tab: str = "wind"

    def to_json(self) -> str:
        return json.dumps(asdict(self))

    @classmethod
    def from_json(cls, text: str) -> Layout:
        d = json.loads(text)
        known = {f.name for f in fields(cls)}
        d = {k: v for k, v in d.items() if k in known}
        for k in ("bounds_ne", "t_range"):
            if d.get(k) is not None:
                d[k] = tuple(d[k])
        d["y_ranges"] = {k: tuple(v) for k, v in d.get("y_ranges", {}).items()}
        return cls(**d)


def _time_axis(lay: Layout) -> rrb.TimeAxis | None:
    if lay.t_range is None:
        return None
    t0, t1 = lay.t_range
    end = t1 + LEGEND_PAD * max(t1 - t0, 1.0)
    return rrb.TimeAxis(view_range=rr.TimeRange(start=rrb.TimeRangeBoundary.absolute(seconds=t0),
                                                end=rrb.TimeRangeBoundary.absolute(seconds=end)),
                        zoom_lock=False)  # fmt: skip


def _missing_view(key: str, title: str) -> rrb.TextDocumentView:
    return rrb.TextDocumentView(origin=f"/missing/{key}", name=f"{title}: no data")


def plot_view(key: str, lay: Layout) -> rrb.View:
    """One time series plot (or the text saying why it is empty)."""
    title, origin, contents, legend = PLOTS[key]
    if key in lay.missing:
        return _missing_view(key, title)
    rng = lay.y_ranges.get(key)
    query = [f"$origin/{c}" for c in contents]
    if rng is None:  # an axis fitted by the viewer: the early, wide uncertainty band would flatten the rest
        query.append("- $origin/band")
    elif lay.markers:  # markers span +-1e4: only on a fixed value axis
        query.append("/markers/**")
    return rrb.TimeSeriesView(
        origin=origin, contents=query, name=title,
        axis_x=_time_axis(lay),
        axis_y=None if rng is None else rrb.ScalarAxis(range=rng, zoom_lock=False),
        plot_legend=rrb.PlotLegend(corner=rrb.Corner2D.RightTop, visible=legend),
    )  # fmt: skip


def _up_to_cursor() -> rrb.VisibleTimeRanges:
    """Every row up to the time cursor: the path and the hits are sent piece by piece."""
    return rrb.VisibleTimeRanges([rrb.VisibleTimeRange(TIMELINE, start=rrb.TimeRangeBoundary.infinite(),
                                                       end=rrb.TimeRangeBoundary.cursor_relative())])  # fmt: skip


def map_view(lay: Layout) -> rrb.View:
    if "map" in lay.missing:
        return _missing_view("map", PANELS["map"])
    bounds = None
    if lay.bounds_ne is not None:
        n0, n1, e0, e1 = lay.bounds_ne
        bounds = rrb.VisualBounds2D(x_range=(e0, e1), y_range=(-n1, -n0))
    # No chemical readings (a flight log): no concentration colour bar, which would suggest a plume.
    contents = ["$origin/**", "- $origin/colorbar/**"] if "chem" in lay.missing else ["$origin/**"]
    return rrb.Spatial2DView(origin="/map", name=PANELS["map"], visual_bounds=bounds, contents=contents,
                             background=rrb.Background(color=SCENE_BACKGROUND),
                             overrides={"/map/path": _up_to_cursor(), "/map/hits": _up_to_cursor()})  # fmt: skip


def view_3d(lay: Layout) -> rrb.View:
    if "map" in lay.missing:
        return _missing_view("3d", PANELS["3d"])
    eye = None
    if lay.bounds_ne is not None:
        n0, n1, e0, e1 = lay.bounds_ne
        cn, ce, cz = 0.5 * (n0 + n1), 0.5 * (e0 + e1), -0.5 * lay.altitude_m
        # From the south-east, above: the search reads left (start) to right (source, upwind).
        d = 0.7 * max(n1 - n0, (e1 - e0) / 1.4)  # the map was widened to 1.4: aim at the search itself
        up = 0.5
        if lay.top_m > lay.altitude_m:  # buildings: farther and higher, aimed at their middle height
            d, up, cz = 1.15 * d, 0.75, -0.3 * lay.top_m
        eye = rrb.EyeControls3D(kind=rrb.Eye3DKind.Orbital, position=(cn - 0.8 * d, ce + 0.6 * d, cz - up * d),
                                look_target=(cn, ce, cz), eye_up=(0.0, 0.0, -1.0))  # fmt: skip
    return rrb.Spatial3DView(origin="/world", name=PANELS["3d"], eye_controls=eye,
                             background=rrb.Background(color=SCENE_BACKGROUND),
                             overrides={"/world/trail": _up_to_cursor()})  # fmt: skip


def _tabs(lay: Layout) -> rrb.Tabs:
    """The tabs of :data:`TABS` that have a plot with data (a tab of one plot is that plot); the wind's
    and rotors' always (their "no data" lines say why), the first tab :attr:`Layout.first_tab` when it is there."""
    tabs: list[tuple[str, rrb.View | rrb.Container]] = []
    for name, keys in TABS.items():
        shown = [k for k in keys if k not in lay.missing] if name in OPTIONAL_TABS else list(keys)
        if not shown:
            continue
        views = [plot_view(k, lay) for k in shown]
        tabs.append((name, views[0] if len(views) == 1 else rrb.Vertical(*views, name=name)))
    names = [n for n, _ in tabs]
    active = names.index(lay.first_tab) if lay.first_tab in names else 0
    return rrb.Tabs(*(c for _, c in tabs), active_tab=active)


def make_blueprint(lay: Layout | None = None) -> rrb.Blueprint:
    """The layout (see the module docstring) for these facts (default: none known yet)."""
    lay = lay or Layout()
    phases = rrb.StateTimelineView(origin="/phases", name=PANELS["phases"], time_view=_time_axis(lay))
    events = rrb.TextLogView(
        origin="/log", name=PANELS["events"],
        columns=rrb.TextLogColumns(timeline_columns=[TimelineColumn(TIMELINE)],
                                   text_log_columns=[TextLogColumn("LogLevel"), TextLogColumn("Body"),
                                                     TextLogColumn("EntityPath", visible=False)]),
    )  # fmt: skip
    summary = rrb.TextDocumentView(origin="/summary", name=PANELS["summary"])
    left = rrb.Vertical(map_view(lay), rrb.Horizontal(view_3d(lay), summary, column_shares=[1, 1]), events,
                        row_shares=[5, 3, 3])  # fmt: skip
    right = rrb.Vertical(
        phases, plot_view("altitude", lay), plot_view("chem", lay), _tabs(lay),
        # The phase view shows its three lanes; every plot gets >= 20 px per unit of its value axis; a
        # "no data" line needs no plot's height.
        row_shares=[1.25, 0.35 if "altitude" in lay.missing else 1.0, 0.35 if "chem" in lay.missing else 1.0, 5.0],
    )  # fmt: skip
    return rrb.Blueprint(
        rrb.Horizontal(left, right, column_shares=[1, 1]),
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
        rrb.TimePanel(timeline=TIMELINE, state="collapsed"),
        collapse_panels=False,
    )


__all__ = ["LEGEND_PAD", "OPTIONAL_PLOTS", "OPTIONAL_TABS", "PANELS", "PLOTS", "TABS", "Layout", "make_blueprint",
           "map_view", "plot_view", "view_3d"]  # fmt: skip
