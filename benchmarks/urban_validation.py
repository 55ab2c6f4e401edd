"""Urban wind field validation: mass consistency, isolated cube, street canyon, cube array, paper.

Prints, for fields solved in this run (SI units, NED; the validation scenes blow from the north,
so "along" = -north; heights above ground):

* mass consistency: the largest |divergence| over air cells in units of U_ref / dx, before
  (initial field) and after the adjustment (goal: < 1e-3 after);
* isolated cube of side H in a log profile: where the lee recirculation reattaches at ground
  level (reference: Martinuzzi & Tropea 1993, 1.61 H behind the cube; goal 1.0-2.0 H), at three
  grid resolutions; the reversed-flow region upwind of the windward face; the speed-up over the
  roof against the upstream profile at the same height;
* street canyon H/W = 1: street-level reversed flow and the vertical flow along both walls
  (a recirculating vortex);
* the paper's Scenario 4 block (six buildings, 2 m cells) and a 3 x 3 cube array: divergence.

Run: .venv/bin/python benchmarks/urban_validation.py [--quick]   (--quick: skip the 0.5 m cube)
"""

from __future__ import annotations

import sys

import numpy as np

from sitl.world.urban import (
    UrbanWindField,
    cube_array_scene,
    isolated_cube_scene,
    paper_s4_scene,
    solve_urban_wind,
    street_canyon_scene,
)
from urbanflow.geometry import BuildingArrays, voxelize
from urbanflow.initial_field import initial_field
from urbanflow.solver import divergence, zero_solid_faces

MT93_REATTACHMENT_H = 1.61  # Martinuzzi & Tropea (1993), cube in a channel, Re_H = 40,000


def initial_divergence_ratio(field: UrbanWindField) -> float:
    """Largest |div| of the initial (parameterized) field over air cells, in U_ref / dx."""
    scene = field.scene
    g = scene.grid
    nx, ny, nz = g.shape
    geom = BuildingArrays.from_buildings(scene.buildings)
    solid = voxelize(g.x_min_m, g.y_min_m, g.spacing_m, g.spacing_m, g.dz, nx, ny, nz, *geom.args()) >= 0
    u, v, w = initial_field(scene, geom)
    zero_solid_faces(u, v, w, solid)
    div = np.abs(divergence(u, v, w, g.spacing_m, g.spacing_m, g.dz))[~solid]
    return float(div.max() * g.spacing_m / scene.wind.speed_m_s)


def along_profile(field: UrbanWindField, x0: float, x1: float, y: float, h: float) -> tuple[np.ndarray, np.ndarray]:
    """(north positions, along-wind speed) on a line from x0 down to x1 at east y, height h."""
    xs = np.arange(x0, x1, -0.02)
    pts = np.column_stack([xs, np.full_like(xs, y), np.full_like(xs, -h)])
    return xs, -field.mean(pts)[:, 0]


def cube_figures(spacing: float, H: float = 10.0) -> tuple[UrbanWindField, dict[str, float]]:
    field = solve_urban_wind(isolated_cube_scene(height_m=H, spacing_m=spacing))
    lee, front, yc = 7.0 * H, 8.0 * H, 3.5 * H
    out: dict[str, float] = {}
    for h in (0.5 * spacing, 0.25 * H):
        xs, along = along_profile(field, lee - 1e-3, 0.0, yc, h)
        first = int(np.argmax(along > 0.0)) if along[0] < 0.0 else 0
        out[f"reattach@{h:g}"] = (lee - xs[first]) / H
    xs, along = along_profile(field, front + 2.0 * H, front + 1e-3, yc, 0.5 * spacing)
    rev = xs[along < 0.0]
    out["upwind_rev_H"] = float((rev.max() - front) / H) if rev.size else 0.0
    out["upwind_min_UH"] = float(along.min() / field.scene.wind.speed_at(H))
    for h in (1.25 * H, 1.5 * H):
        p = np.array([7.5 * H, yc, -h])
        out[f"speedup@{h / H:g}H"] = float(np.linalg.norm(field.mean(p)) / field.scene.wind.speed_at(h))
    xs, along = along_profile(field, front - 1e-3, lee, yc, H + 0.5 * spacing)
    out["roof_rev_len_H"] = float((along < 0.0).sum() * 0.02 / H)
    return field, out


def print_cube() -> list[UrbanWindField]:
    print("\nIsolated cube, H = 10 m, 7 m/s at 10 m, z0 = 0.1 m, wind normal to a face")
    print("| cells per H | reattachment at ground (H) | at 0.25 H | vs MT93 1.61 H | upwind reversed to (H) |"
          " min upwind along / U_H | roof speed-up 1.25 H / 1.5 H | rooftop reversed length (H) |")
    print("|---|---|---|---|---|---|---|---|")
    fields = []
    spacings = (2.0, 1.0) if "--quick" in sys.argv else (2.0, 1.0, 0.5)
    for sp in spacings:
        field, f = cube_figures(sp)
        fields.append(field)
        r0 = f[f"reattach@{0.5 * sp:g}"]
        print(f"| {10.0 / sp:g} | {r0:.2f} | {f['reattach@2.5']:.2f} | {r0 / MT93_REATTACHMENT_H:.2f} |"
              f" {f['upwind_rev_H']:.2f} | {f['upwind_min_UH']:.2f} | {f['speedup@1.25H']:.2f} /"
              f" {f['speedup@1.5H']:.2f} | {f['roof_rev_len_H']:.2f} |")
    return fields


def print_canyon() -> UrbanWindField:
    H = 10.0
    field = solve_urban_wind(street_canyon_scene(height_m=H, spacing_m=1.0))
    u_h = float(field.scene.wind.speed_at(H))
    x_down, y = 6.0 * H, 5.0 * H  # downwind block's windward face; the canyon spans x_down .. x_down + H
    print("\nStreet canyon H/W = 1 (H = 10 m, blocks 6 H long), 1 m cells; velocities / U_H")
    print("| height (H) | along at mid-street | w at downwind wall (0.1 W) | w at upwind wall (0.9 W) |")
    print("|---|---|---|---|")
    for hh in (0.05, 0.25, 0.5, 0.75, 1.25):
        mid = field.mean(np.array([x_down + 0.5 * H, y, -hh * H]))
        dn = field.mean(np.array([x_down + 0.1 * H, y, -hh * H]))
        up = field.mean(np.array([x_down + 0.9 * H, y, -hh * H]))
        print(f"| {hh:g} | {-mid[0] / u_h:+.2f} | {-dn[2] / u_h:+.2f} | {-up[2] / u_h:+.2f} |")
    return field


def main() -> None:
    fields = print_cube()
    fields.append(print_canyon())
    fields.append(solve_urban_wind(cube_array_scene(3, 3, height_m=10.0, spacing_m=1.0)))
    fields.append(solve_urban_wind(paper_s4_scene()))
    print("\nMass consistency: max |div| over air cells in U_ref / dx (goal < 1e-3)")
    print("| scene | cells | initial field | adjusted field | CG iterations | relative residual |")
    print("|---|---|---|---|---|---|")
    for f in fields:
        g = f.scene.grid
        assert f.stats is not None
        print(f"| {f.scene.name} ({g.spacing_m:g} m) | {g.n_cells:,} | {initial_divergence_ratio(f):.2f} |"
              f" {f.max_divergence_ratio():.1e} | {f.stats.iterations} | {f.stats.relative_residual:.1e} |")


if __name__ == "__main__":
    main()
