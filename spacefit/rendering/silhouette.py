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


def _covers(tri: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Whether each pixel square [x, x + 1) x [y, y + 1) may overlap triangle ``tri`` (3, 2): no edge's
    outward half-plane holds the whole square (conservative: a corner pixel may pass)."""
    cx, cy = x + 0.5, y + 0.5
    area = _cross(tri[1] - tri[0], tri[2] - tri[0])
    inside = np.ones(np.broadcast(x, y).shape, dtype=bool)
    for i in range(3):
        a, b = tri[i], tri[(i + 1) % 3]
        nx, ny = (b[1] - a[1], a[0] - b[0]) if area > 0 else (a[1] - b[1], b[0] - a[0])  # outward normal
        inside &= nx * (cx - a[0]) + ny * (cy - a[1]) <= 0.5 * (abs(nx) + abs(ny)) + EPS_PX * math.hypot(nx, ny)
    return inside


def silhouette(triangles: np.ndarray, width: int, height: int) -> np.ndarray:
    """(height, width) bool: the pixels whose square [x, x + 1) x [y, y + 1) (px, u right, v down) a
    projected triangle may overlap, conservatively (never misses one). ``triangles``: (n, 3, 2) px."""
    mask = np.zeros((height, width), dtype=bool)
    a, b, c = triangles[:, 0], triangles[:, 1], triangles[:, 2]  # not min(axis=1): NumPy reduces a short axis 4x slower
    lo = np.floor(np.minimum(np.minimum(a, b), c) - EPS_PX).astype(np.int64)
    hi = np.floor(np.maximum(np.maximum(a, b), c) + EPS_PX).astype(np.int64)
    size = hi - lo
    visible = (hi[:, 0] >= 0) & (hi[:, 1] >= 0) & (lo[:, 0] < width) & (lo[:, 1] < height)
    small = visible & (size[:, 0] < SMALL_BOX_PX) & (size[:, 1] < SMALL_BOX_PX)
    _mark(mask, lo[small, 0], lo[small, 1], hi[small, 0], hi[small, 1])
    for i in np.flatnonzero(visible & ~small):
        x0, y0 = np.maximum(lo[i], 0)
        x1, y1 = np.minimum(hi[i], [width - 1, height - 1])
        y, x = np.ogrid[y0:y1 + 1, x0:x1 + 1]
        area = abs(_cross(triangles[i, 1] - triangles[i, 0], triangles[i, 2] - triangles[i, 0]))
        mask[y0:y1 + 1, x0:x1 + 1] |= True if area < 1e-9 else _covers(triangles[i], x, y)
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


def traced_pixels(triangles: np.ndarray, width: int, height: int, radius_px: float) -> tuple[np.ndarray, np.ndarray]:
    """The pixels a render traces and those it may light, both (height, width) bool: the silhouette
    (:func:`silhouette`) dilated by twice and by once the filter's reach (:func:`filter_reach_px`)."""
    reach = filter_reach_px(radius_px)
    inside = silhouette(triangles, width, height)
    lit = dilate(inside, reach)
    return dilate(lit, reach), lit
