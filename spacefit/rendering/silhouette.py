"""The pixels a render must trace: those whose samples can reach a lit pixel through the pixel filter.

In black space a camera ray is lit only where it hits the target, and a pinhole camera's ray through
film point x hits it only where x lies inside the target's projected silhouette. A pixel's value is
its filter-weighted mean of the samples that land within the filter's reach, so the pixels that can be
non-zero are the silhouette's pixels dilated by that reach, and their weights need the samples of one
reach further: a render tracing the silhouette dilated twice gives every pixel the distribution of
samples a whole-film render gives it, and is unbiased. Numpy only; the renderer traces the mask.
"""

from __future__ import annotations

import math

import numpy as np

# Rounding allowance (px) of the conservative rasterisation: the mask's vertices are projected in
# float64, Mitsuba's rays in float32 (about 1e-7 relative).
EPS_PX = 1e-3
# Triangles whose pixel box is at most this wide and high are marked whole (conservative, and fast for
# the many sub-pixel triangles of a wrinkled mesh); larger ones are tested pixel by pixel.
SMALL_BOX_PX = 3


def filter_reach_px(radius_px: float) -> int:
    """How many pixels away a sample can land in a pixel's filter of ``radius_px``: a sample at x in
    pixel q reaches pixel p when |x - (p + 1/2)| < radius, so |p - q| < radius + 1/2 (tent: 1, box: 0)."""
    return max(0, math.ceil(radius_px + 0.5) - 1)


def _mark(mask: np.ndarray, x0: np.ndarray, y0: np.ndarray, x1: np.ndarray, y1: np.ndarray) -> None:
    """Set every pixel of the boxes [x0, x1] x [y0, y1] (inclusive; each overlaps ``mask``, clipped to it): a
    2-D difference array, +1 at each box's first corner and -1 past its edges, summed over the image (exact;
    16 bytes a pixel at its peak)."""
    h, w = mask.shape
    x0, y0, x1, y1 = np.maximum(x0, 0), np.maximum(y0, 0), np.minimum(x1, w - 1) + 1, np.minimum(y1, h - 1) + 1
    size = (h + 1) * (w + 1)
    diff = np.bincount(y0 * (w + 1) + x0, minlength=size)
    diff -= np.bincount(y0 * (w + 1) + x1, minlength=size)
    diff -= np.bincount(y1 * (w + 1) + x0, minlength=size)
    diff += np.bincount(y1 * (w + 1) + x1, minlength=size)
    grid = diff.reshape(h + 1, w + 1)
    np.cumsum(grid, axis=0, out=grid)
    np.cumsum(grid, axis=1, out=grid)
    mask |= grid[:h, :w] > 0


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The z component of the cross product of 2-vectors (..., 2)."""
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


# Pixel squares tested at once for the triangles larger than SMALL_BOX_PX (bounds the temporaries: about
# 100 bytes a square).
SQUARES_PER_BATCH = 1 << 20


def _mark_covered(mask: np.ndarray, tris: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> None:
    """Set the pixels of ``mask`` whose square [x, x + 1) x [y, y + 1) may overlap a triangle of ``tris``
    (n, 3, 2) px, within its pixel box [lo, hi] (n, 2), conservatively: no edge's outward half-plane
    holds the whole square (a corner pixel may pass); a degenerate triangle marks its whole box. The
    boxes' squares are tested together, in batches of about :data:`SQUARES_PER_BATCH`."""
    h, w = mask.shape
    x0, y0 = np.maximum(lo[:, 0], 0), np.maximum(lo[:, 1], 0)
    bw, bh = np.minimum(hi[:, 0], w - 1) - x0 + 1, np.minimum(hi[:, 1], h - 1) - y0 + 1
    area = _cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
    # each edge's outward normal (a -> b turned by the winding) and its slack: half the square's extent
    # along it, plus the rounding allowance
    a, b = tris, np.roll(tris, -1, axis=1)
    sign = np.where(area > 0, 1.0, -1.0)[:, None]
    nx, ny = sign * (b[..., 1] - a[..., 1]), sign * (a[..., 0] - b[..., 0])
    slack = 0.5 * (np.abs(nx) + np.abs(ny)) + EPS_PX * np.hypot(nx, ny)
    degenerate = np.abs(area) < 1e-9
    squares = bw * bh
    ends = np.cumsum(squares)
    first = 0
    while first < len(tris):
        last = max(first + 1, int(np.searchsorted(ends, ends[first] - squares[first] + SQUARES_PER_BATCH, side="right")))
        k = np.repeat(np.arange(first, last), squares[first:last])
        offset = np.arange(k.size) - np.repeat(ends[first:last] - squares[first:last] - (ends[first] - squares[first]), squares[first:last])
        x, y = x0[k] + offset % bw[k], y0[k] + offset // bw[k]
        covered = degenerate[k]
        inside = np.ones(k.size, dtype=bool)
        for e in range(3):
            inside &= nx[k, e] * (x + 0.5 - a[k, e, 0]) + ny[k, e] * (y + 0.5 - a[k, e, 1]) <= slack[k, e]
        covered |= inside
        mask[y[covered], x[covered]] = True
        first = last


def silhouette(uv: np.ndarray, faces: np.ndarray, width: int, height: int) -> np.ndarray:
    """(height, width) bool: the pixels whose square [x, x + 1) x [y, y + 1) (px, u right, v down) a
    projected triangle may overlap, conservatively (never misses one). ``uv``: (m, 2) the vertices'
    projections, px; ``faces``: (n, 3) vertex indices."""
    mask = np.zeros((height, width), dtype=bool)
    # each triangle's pixel box from its corners' pixels: floor is monotonic, so the box of the corners'
    # floors is that of their extremes, and 3 gathers of integers cost less than one of the corners
    lo_v, hi_v = np.floor(uv - EPS_PX).astype(np.int64), np.floor(uv + EPS_PX).astype(np.int64)
    f0, f1, f2 = (np.ascontiguousarray(faces[:, i]) for i in range(3))
    lo = np.minimum(np.minimum(np.take(lo_v, f0, axis=0), np.take(lo_v, f1, axis=0)), np.take(lo_v, f2, axis=0))
    hi = np.maximum(np.maximum(np.take(hi_v, f0, axis=0), np.take(hi_v, f1, axis=0)), np.take(hi_v, f2, axis=0))
    size = hi - lo
    visible = (hi[:, 0] >= 0) & (hi[:, 1] >= 0) & (lo[:, 0] < width) & (lo[:, 1] < height)
    small = visible & (size[:, 0] < SMALL_BOX_PX) & (size[:, 1] < SMALL_BOX_PX)
    _mark(mask, lo[small, 0], lo[small, 1], hi[small, 0], hi[small, 1])
    large = np.flatnonzero(visible & ~small)
    if large.size:
        _mark_covered(mask, np.take(uv, faces[large], axis=0), lo[large], hi[large])
    return mask


def dilate(mask: np.ndarray, reach: int) -> np.ndarray:
    """``mask`` (h, w) bool dilated by a square of side 2 reach + 1 (NumPy only: a plain render never imports SciPy)."""
    out = mask
    for axis in (0, 1):
        n = out.shape[axis]
        padded = np.pad(out, [(reach, reach) if a == axis else (0, 0) for a in (0, 1)])
        out = np.zeros_like(mask)
        for k in range(2 * reach + 1):
            out |= padded[k:k + n] if axis == 0 else padded[:, k:k + n]
    return out


def traced_pixels(uv: np.ndarray, faces: np.ndarray, width: int, height: int, radius_px: float) -> tuple[np.ndarray, np.ndarray]:
    """The pixels a render traces and those it may light, both (height, width) bool: the silhouette of
    the mesh (:func:`silhouette`) dilated by twice and by once the filter's reach (:func:`filter_reach_px`)."""
    reach = filter_reach_px(radius_px)
    inside = silhouette(uv, faces, width, height)
    lit = dilate(inside, reach)
    return dilate(lit, reach), lit
