"""A strategy's posterior on the recording's map: only the visible part of the grid is drawn (a particle
posterior fills a few hundred cells of a ~430 x 430 grid), at the same place on the map."""

from __future__ import annotations

import numpy as np

from recording.read import RrdLog
from recording.recorder import RunRecorder


def test_posterior_image_is_cropped_to_its_visible_cells_at_the_same_place(tmp_path):
    n, cell = 430, 1.0
    extent = (-200.0, -200.0 + n * cell, -215.0, -215.0 + n * cell)  # north_min, north_max, east_min, east_max
    p = np.zeros((n, n))
    # A blob around (north 60.5, east -3.5): row 260 -> north -200 + 260.5; col 211 -> east -215 + 211.5.
    p[255:266, 206:217] = 1e-3
    p[260, 211] = 1.0
    p[0, 0] = 1e-9  # below what the image can show: not drawn, so not in the crop
    path = tmp_path / "post.rrd"
    with RunRecorder(path, scenario="open-field", strategy="infotaxis") as rec:
        rec.posterior(10.0, p, extent, ((60.5, -3.5), 3.0))
    log = RrdLog(path)
    _, imgs = log.images("map/posterior/image")
    img = imgs[-1]
    h, w = img.shape[:2]
    assert (h, w) == (11, 11), (h, w)
    _, tr = log.vectors("map/posterior/image", "Transform3D:translation")
    _, sc = log.vectors("map/posterior/image", "Transform3D:scale")
    row, col = np.unravel_index(np.argmax(img[..., 3]), (h, w))
    east, north = tr[-1][0] + (col + 0.5) * sc[-1][0], -(tr[-1][1] + (row + 0.5) * sc[-1][1])
    assert (north, east) == (60.5, -3.5)
    assert tuple(sc[-1][:2]) == (cell, cell)
