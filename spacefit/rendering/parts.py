"""Which part of the target each pixel sees (:class:`PartImage`), and each part's share of an image:
plain NumPy, made by :meth:`spacefit.rendering.renderer.Renderer.part_image`."""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from spacefit.errors import InputError, check_array
from spacefit.units import RADIANCE_UNIT


@dataclass(frozen=True)
class PartImage:
    """Which part each pixel sees, and each part's share of a radiance image.

    Attributes:
        ids: (height, width) int16: the index into ``names`` of the part hit by the ray through
            each pixel's centre, -1 where it misses the target (black space).
        names: the parts, in the scene's order.

    Example:
        >>> import spacefit as sf
        >>> renderer = sf.Renderer(sf.default_scene().with_values({"render.resolution": [48, 48], "camera.pixel_pitch_mm": 50, "render.spp": 4}))
        >>> parts = renderer.part_image()
        >>> parts.regions
        ('body', 'panels', 'legs', 'target')
        >>> table = parts.table(renderer.render())  # an xarray Dataset: pixels, mean_radiance per region
        >>> int(table["pixels"].sel(region="target")) == int((parts.ids >= 0).sum())
        True
    """

    ids: np.ndarray
    names: tuple[str, ...]

    @property
    def regions(self) -> tuple[str, ...]:
        """The parts, then ``target``: all of them together."""
        return (*self.names, "target")

    def masks(self) -> np.ndarray:
        """(regions, height, width) bool: the pixels whose centre sees each of :attr:`regions`."""
        return np.stack([*(self.ids == i for i in range(len(self.names))), self.ids >= 0])

    def means(self, image: np.ndarray, used: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Per region (:attr:`regions`): the pixels counted, whose centre sees it (int), and the
        mean of ``image``'s RGB mean over them (in its unit; NaN for a region out of view). Edge
        pixels count for the part at their centre. ``used``: (height, width) bool, the pixels to
        count (default: all)."""
        image = check_array("image", image)
        if image.shape[:2] != self.ids.shape or image.ndim != 3:
            raise InputError(f"`image` must be (height, width, channels) with (height, width) = {self.ids.shape}, got shape {image.shape}.")
        counted = self.ids >= 0 if used is None else (self.ids >= 0) & np.asarray(used, dtype=bool)
        ids = self.ids[counted]  # a target in black space is a few % of the film: only its pixels are summed
        rgb = image[counted][:, :3].astype(float)
        grey = functools.reduce(np.add, rgb.T) / rgb.shape[-1]  # the mean over channels, 10x faster
        parts = len(self.names)
        pixels = np.append(np.bincount(ids, minlength=parts), ids.size)
        sums = np.append(np.bincount(ids, weights=grey, minlength=parts), grey.sum())
        with np.errstate(invalid="ignore", divide="ignore"):
            means = np.where(pixels > 0, sums / pixels, math.nan)
        return pixels, means

    def table(self, radiance: np.ndarray, used: np.ndarray | None = None) -> Any:
        """Per region (each part, then the whole ``target``): ``pixels`` and ``mean_radiance`` (W m^-2 sr^-1)
        of :meth:`means`, as an xarray Dataset with dimension ``region``, each variable with its units
        (``table(r).to_dataframe()`` is a pandas table of it)."""
        import xarray as xr  # here: only a table needs xarray (slow to import)

        pixels, means = self.means(radiance, used)
        return xr.Dataset(
            {"pixels": ("region", pixels, {"description": "pixels whose centre sees the region"}),
             "mean_radiance": ("region", means, {"units": RADIANCE_UNIT,
                                                  "description": "mean of the RGB mean over those pixels (NaN: out of view)"})},
            coords={"region": list(self.regions)})
