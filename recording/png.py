"""Lossless PNG images for the recording: a one-colour image with per-pixel opacity as an indexed PNG.

A strategy's posterior is drawn in one colour whose opacity varies (:func:`recording.style.posterior_alpha`):
sent as raw RGBA it cost ~9 kB a posterior on disk after rerun's LZ4 (4 bytes a pixel, mostly
transparent), the largest part of an infotaxis trial's recording. The same pixels as an indexed
PNG (colour type 3: a palette of 256 entries, entry ``i`` the colour with opacity ``i``, its ``tRNS``
chunk the opacities; one byte a pixel, deflated) are ~4 kB; the viewer decodes a PNG to the same RGBA
(``rr.EncodedImage``). The urban layers' static images go as plain RGBA PNGs (:func:`rgba_png`).
:func:`decode_png` reads any PNG back as RGBA (tests, :mod:`recording.read`).
"""

from __future__ import annotations

import io
import struct
import zlib

import numpy as np
import rerun as rr

from recording.style import C_POSTERIOR, posterior_alpha, posterior_image

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
#: zlib's level: 6 (its default) gives 14 % less than 1 for ~0.35 ms more on a ~230 x 190 posterior.
DEFLATE_LEVEL = 6


def _chunk(tag: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + tag + data + struct.pack(">I", zlib.crc32(tag + data) & 0xFFFFFFFF)


def alpha_png(alpha: np.ndarray, rgb: tuple[int, int, int], level: int = DEFLATE_LEVEL) -> bytes:
    """An indexed PNG of an image of colour ``rgb`` everywhere with opacity ``alpha[row, col]``
    (uint8, H x W): decoded, pixel (row, col) is ``(*rgb, alpha[row, col])``, losslessly."""
    a = np.ascontiguousarray(alpha, dtype=np.uint8)
    if a.ndim != 2 or not a.size:
        raise ValueError(f"alpha_png: expected a non-empty 2D opacity grid, got shape {a.shape}")
    h, w = a.shape
    rows = np.zeros((h, w + 1), dtype=np.uint8)  # each row: filter type 0 (none), then its pixels
    rows[:, 1:] = a
    palette = np.tile(np.asarray(rgb, dtype=np.uint8), 256)
    return b"".join((PNG_SIGNATURE, _chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 3, 0, 0, 0)),
                     _chunk(b"PLTE", palette.tobytes()), _chunk(b"tRNS", bytes(range(256))),
                     _chunk(b"IDAT", zlib.compress(rows.tobytes(), level)), _chunk(b"IEND", b"")))  # fmt: skip


def rgba_png(rgba: np.ndarray, level: int = DEFLATE_LEVEL) -> bytes:
    """A PNG (colour type 6, 8 bits a channel, no filter) of an RGBA image (uint8, H x W x 4): for the
    urban layers' static images, mostly transparent or in a few colours (the wind speed's image 17 -> 8 kB
    on disk, the buildings' footprints 4.7 -> 1.5 kB; the row filters PNG offers only made them larger)."""
    a = np.ascontiguousarray(rgba, dtype=np.uint8)
    if a.ndim != 3 or a.shape[2] != 4 or not a.size:
        raise ValueError(f"rgba_png: expected a non-empty H x W x 4 image, got shape {a.shape}")
    h, w, _ = a.shape
    rows = np.zeros((h, 4 * w + 1), dtype=np.uint8)
    rows[:, 1:] = a.reshape(h, 4 * w)
    return b"".join((PNG_SIGNATURE, _chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 6, 0, 0, 0)),
                     _chunk(b"IDAT", zlib.compress(rows.tobytes(), level)), _chunk(b"IEND", b"")))  # fmt: skip


def decode_png(data: bytes) -> np.ndarray:
    """A PNG's pixels as RGBA (H x W x 4, uint8) (Pillow, which matplotlib already needs)."""
    from PIL import Image

    with Image.open(io.BytesIO(data)) as im:
        return np.asarray(im.convert("RGBA"))


def image_archetype(rgba: np.ndarray, png: bool, opacity: float, draw_order: float) -> rr.AsComponents:
    """An RGBA image as a PNG (``rr.EncodedImage``: :func:`rgba_png`) or raw (``rr.Image``): the same pixels."""
    if png:
        return rr.EncodedImage(contents=rgba_png(rgba), media_type="image/png", opacity=opacity,
                               draw_order=draw_order)  # fmt: skip
    return rr.Image(rgba, opacity=opacity, draw_order=draw_order)


def posterior_archetype(p_ne: np.ndarray, png: bool) -> rr.AsComponents:
    """A posterior grid's image (:func:`recording.style.posterior_image`), as an indexed PNG
    (:func:`alpha_png`) or raw RGBA; drawn under the path, slightly translucent."""
    if png:
        return rr.EncodedImage(contents=alpha_png(posterior_alpha(p_ne), C_POSTERIOR), media_type="image/png",
                               opacity=0.99, draw_order=-5.0)  # fmt: skip
    return rr.Image(posterior_image(p_ne), opacity=0.99, draw_order=-5.0)


__all__ = ["DEFLATE_LEVEL", "PNG_SIGNATURE", "alpha_png", "decode_png", "image_archetype", "posterior_archetype",
           "rgba_png"]
