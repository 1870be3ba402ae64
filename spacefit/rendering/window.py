"""The part of the film a render traces: the window around the target's projected box and, within it,
the pixels whose samples can reach the target (NumPy; :mod:`spacefit.rendering.silhouette` rasterises).

In black space nothing but the target is lit, so the pixels away from it are black without a ray.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from spacefit.geometry.frames import project
from spacefit.rendering.silhouette import traced_pixels
from spacefit.scene.assembly import Assembly
from spacefit.scene.sections import FILTER_RADIUS_PX

# Pixels around the target's projected box that its light can still reach: the tent filter's
# radius (1 px) and one for rounding.
CROP_MARGIN_PX = 2


def target_window(assembly: Assembly, vertices: Mapping[str, np.ndarray]) -> tuple[int, int, int, int]:
    """The film window (x0, y0, width, height), px, outside which the image is black: the projected
    box of every vertex of the target (world ``vertices`` per part, m), widened by
    :data:`CROP_MARGIN_PX` and clipped to the film. In black space nothing else is lit. The whole
    film when a vertex lies behind the camera, where the projected box means nothing."""
    intr = assembly.intrinsics
    uv, depth = project(np.concatenate(list(vertices.values())), assembly.camera, intr)
    size = np.array([intr.width, intr.height])
    if not np.all(depth > 0):
        return 0, 0, intr.width, intr.height
    lo = np.clip(np.floor([u.min() for u in uv.T]) - CROP_MARGIN_PX, 0, size - 1).astype(int)  # by column: 50x faster
    hi = np.clip(np.ceil([u.max() for u in uv.T]) + CROP_MARGIN_PX, lo + 1, size).astype(int)
    return int(lo[0]), int(lo[1]), int(hi[0] - lo[0]), int(hi[1] - lo[1])


def target_mask(assembly: Assembly, vertices: Mapping[str, np.ndarray], window: tuple[int, int, int, int]) -> np.ndarray:
    """(height, width) bool over the film ``window``: the pixels a render traces, those whose samples
    can reach a pixel the target lights (:func:`spacefit.rendering.silhouette.traced_pixels`: its
    projected triangles, world ``vertices`` per part, m, dilated twice by the filter's reach). The whole
    window when a vertex lies behind the camera."""
    x0, y0, w, h = window
    uv, depth = project(np.concatenate(list(vertices.values())), assembly.camera, assembly.intrinsics)
    if not np.all(depth > 0):
        return np.ones((h, w), dtype=bool)
    starts = np.cumsum([0, *(len(points) for points in vertices.values())])
    faces = np.concatenate([assembly.faces(name) + start for name, start in zip(vertices, starts)])
    return traced_pixels(uv - [x0, y0], faces, w, h, FILTER_RADIUS_PX[assembly.scene.render.filter])[0]
