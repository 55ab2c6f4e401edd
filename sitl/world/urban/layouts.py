"""Built-in scenes: the paper's Scenario 4 city block and the validation geometries.

Paper Scenario 4 (urban search, dung-beetle zig-zag). What the paper's text gives: QUIC winds
with a logarithmic profile of 7 m/s at 10 m height from 45 deg, six buildings ("gray patches"
in Figure 19), the vehicle initialized at (340, 30) m. Figure 19 is missing from the text, so
the buildings are NOT known; everything below is an assumption, chosen to be typical of a QUIC
demonstration domain and to make the search meaningful:

* Frame: the project's local NED frame with the grid's south-west corner at the origin,
  x north 0..400 m, y east 0..400 m, top 60 m (3 x the tallest building, QUIC practice), 2 m
  cells (1.2 million). The start (340, 30) is read as NED (north 340, east 30). Reading it as
  QUIC's (east, north) instead mirrors the scene across the wind axis (the line north = east),
  which leaves the search problem unchanged.
* Wind: from 45 deg (air moving south-west), log law with z0 = 0.1 m (not given; QUIC's and the
  project's default) and no displacement height.
* Buildings: six flat-roofed blocks, axis-aligned (QUIC's default building type), in two rows
  of three centred on the diagonal, 36 m north-south by 30 m east-west, heights 10-20 m (H/W of
  the streets 0.3-0.8), streets 24 m (east-west running) and 30 m (north-south running). Rows
  at north 190 and 250 m, columns at east 150, 210 and 270 m.
* Source (for the scenario that uses this field; not part of the field): a ground-level
  release north-east of the block, e.g. NED (300, 300, -2), puts the plume through the streets
  toward the south-west; from the start the vehicle must fly about 220 m south-east to meet it.

Validation geometries (log profile, wind from the north, so the air moves toward -x):
isolated cube (Martinuzzi & Tropea 1993: reattachment 1.6 H behind the cube), a street canyon
of H/W = 1 between two long blocks, and a regular array of cubes.
"""

from __future__ import annotations

from urbanflow.config import BoxBuilding, GridSpec, LogWindProfile, UrbanOptions, UrbanScene

PAPER_S4_START_NED = (340.0, 30.0)
PAPER_S4_SUGGESTED_SOURCE_NED = (300.0, 300.0, -2.0)

# (north centre, east centre, height) of the six assumed blocks; footprint 36 m N-S x 30 m E-W.
_PAPER_S4_BLOCKS = (
    (250.0, 150.0, 12.0),
    (250.0, 210.0, 20.0),
    (250.0, 270.0, 15.0),
    (190.0, 150.0, 18.0),
    (190.0, 210.0, 10.0),
    (190.0, 270.0, 16.0),
)


def paper_s4_scene(spacing_m: float = 2.0, options: UrbanOptions | None = None) -> UrbanScene:
    """The assumed Scenario 4 city block (module docstring) on a 400 x 400 x 60 m grid."""
    buildings = tuple(
        BoxBuilding(x, y, 36.0, 30.0, h, name=f"block-{i + 1}") for i, (x, y, h) in enumerate(_PAPER_S4_BLOCKS)
    )
    return UrbanScene(
        buildings=buildings,
        wind=LogWindProfile(speed_m_s=7.0, from_deg=45.0, reference_height_m=10.0, roughness_length_m=0.1),
        grid=GridSpec(0.0, 0.0, 400.0, 400.0, 60.0, spacing_m),
        options=options or UrbanOptions(),
        name="paper-s4",
    )


def _validation_wind(speed_m_s: float) -> LogWindProfile:
    return LogWindProfile(speed_m_s=speed_m_s, from_deg=0.0, reference_height_m=10.0, roughness_length_m=0.1)


def isolated_cube_scene(
    height_m: float = 10.0, spacing_m: float = 1.0, speed_m_s: float = 7.0, options: UrbanOptions | None = None
) -> UrbanScene:
    """One cube of side H, wind from the north; 3 H of grid upstream, 7 H downstream, 3 H to
    each side, top at 4 H. The cube's lee (south) face is at north 7 H."""
    H = height_m
    cube = BoxBuilding(7.0 * H, 3.0 * H, H, H, H, anchor="corner", name="cube")
    return UrbanScene(
        buildings=(cube,),
        wind=_validation_wind(speed_m_s),
        grid=GridSpec(0.0, 0.0, 11.0 * H, 7.0 * H, 4.0 * H, spacing_m),
        options=options or UrbanOptions(),
        name="isolated-cube",
    )


def street_canyon_scene(
    height_m: float = 10.0, gap_m: float | None = None, span_m: float | None = None,
    spacing_m: float = 1.0, speed_m_s: float = 7.0, options: UrbanOptions | None = None,
) -> UrbanScene:
    """Two blocks H high, H deep (along the wind) and ``span_m`` (default 6 H) long across a wind
    from the north, ``gap_m`` apart (default H: H/W = 1). The canyon runs east-west between
    the upwind block's south face and the downwind block's north face."""
    H = height_m
    gap = H if gap_m is None else gap_m
    span = 6.0 * H if span_m is None else span_m
    x_down = 5.0 * H  # downwind block's south (lee) face
    y0 = 2.0 * H
    down = BoxBuilding(x_down, y0, H, span, H, anchor="corner", name="downwind")
    up = BoxBuilding(x_down + H + gap, y0, H, span, H, anchor="corner", name="upwind")
    length_x = x_down + 2.0 * H + gap + 3.0 * H
    return UrbanScene(
        buildings=(down, up),
        wind=_validation_wind(speed_m_s),
        grid=GridSpec(
            0.0, 0.0, _round_up(length_x, spacing_m), _round_up(span + 4.0 * H, spacing_m), 4.0 * H, spacing_m
        ),
        options=options or UrbanOptions(),
        name="street-canyon",
    )


def cube_array_scene(
    rows: int = 3, cols: int = 3, height_m: float = 10.0, gap_m: float | None = None,
    spacing_m: float = 1.0, speed_m_s: float = 7.0, options: UrbanOptions | None = None,
) -> UrbanScene:
    """A regular ``rows`` x ``cols`` array of cubes of side H, ``gap_m`` apart (default H), wind
    from the north along the rows."""
    H = height_m
    gap = H if gap_m is None else gap_m
    pitch = H + gap
    x0, y0 = 6.0 * H, 3.0 * H
    buildings = tuple(
        BoxBuilding(x0 + r * pitch, y0 + c * pitch, H, H, H, anchor="corner", name=f"cube-{r}-{c}")
        for r in range(rows)
        for c in range(cols)
    )
    return UrbanScene(
        buildings=buildings,
        wind=_validation_wind(speed_m_s),
        grid=GridSpec(
            0.0, 0.0,
            _round_up(x0 + rows * pitch - gap + 3.0 * H, spacing_m),
            _round_up(y0 + cols * pitch - gap + 3.0 * H, spacing_m),
            4.0 * H, spacing_m,
        ),
        options=options or UrbanOptions(),
        name="cube-array",
    )


def _round_up(length_m: float, step_m: float) -> float:
    """``length_m`` rounded up to a whole number of ``step_m`` cells."""
    n = -(-length_m // step_m)
    return float(n * step_m)
