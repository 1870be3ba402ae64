"""Level of detail for wrinkles: displaced geometry, or an effective roughness on the flat part.

When wrinkles are much smaller than a pixel, the image only sees their slope statistics: a flat
part whose microfacet distribution is widened by the wrinkles' slopes renders nearly the same image
for a fraction of the triangles. Eq. 2-1 sums many ridges with random phases, so its slopes are
close to Gaussian; Beckmann's distribution of roughness alpha has Gaussian slopes of per-axis
variance alpha^2 / 2 (Walter et al. 2007), so wrinkle slopes of per-axis standard deviation s add
``2 s^2`` to alpha^2 and the effective material is a Beckmann conductor. The facets' own GGX
roughness alpha0 enters the sum as if it were Beckmann's; it is small beside the wrinkles'. A GGX
of the same effective alpha would be wrong in shape: its core is narrower and its tail heavier
than Gaussian slopes', and it rendered the study's body 27-33 % darker than the geometry.
The slopes are those of eq. 2-1 down to Ls (:func:`spacefit.geometry.wm.wm_rms_slope`): the
wrinkles as specified, not as a mesh of some spacing would sample them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from spacefit.errors import InputError
from spacefit.geometry.frames import CameraFrame, Intrinsics
from spacefit.geometry.wm import wm_rms_slope
from spacefit.materials import Material
from spacefit.materials.conductor import effective_alpha
from spacefit.scene.sections import WrinkleSettings


# The effective model's stated accuracy: relative RMSE against the displaced geometry over the lit
# pixels, Monte Carlo noise taken out (experiments/lod_study.py). The default
# ``wrinkles.lod_footprint`` (3) is the smallest pixel footprint / L from which the study met it.
LOD_TOLERANCE = 0.15


@dataclass(frozen=True)
class LodChoice:
    """Which wrinkle model a part is rendered with, and why (recorded in the render sidecar)."""

    part: str
    model: str
    footprint_m: float
    footprint_over_L: float
    slope_rms: float
    effective_alpha: float | None
    reason: str


def effective_material(material: Material, slope_rms: float) -> Material | None:
    """The part's material widened by the wrinkles' slopes (its model's rule,
    :meth:`~spacefit.materials.model.MaterialModel.effective`); None where it has none (a conductor's
    alpha would exceed 1, or a model without one)."""
    return material.effective(slope_rms)


def choose_model(
    part: str, material: Material, centroid: np.ndarray, camera: CameraFrame, intrinsics: Intrinsics, w: WrinkleSettings
) -> tuple[LodChoice, Material | None]:
    """Pick geometry or effective roughness for one wrinkled part (world ``centroid``, metres)."""
    distance = float(np.linalg.norm(centroid - camera.position))
    footprint = distance * intrinsics.pixel_pitch / intrinsics.focal_length
    slope = float(wm_rms_slope(w.D, w.G, gamma=w.gamma, M=w.M, L=w.L, Ls=w.Ls))
    effective = effective_material(material, slope)
    alpha = getattr(effective, "alpha_x", None)  # a conductor's widened roughness; None for another model
    ratio = footprint / w.L
    if w.model == "geometry":
        model, reason = "geometry", "forced by wrinkles.model"
    elif w.model == "effective":
        if effective is None:
            raise InputError(
                f"`wrinkles.model` = 'effective' needs a conductor part and an effective roughness <= 1; part {part!r} "
                f"has rms slope {slope:.3g}, which would need alpha {effective_alpha(0.0, slope):.3g}."
            )
        model, reason = "effective", "forced by wrinkles.model"
    elif effective is None:
        model, reason = "geometry", f"wrinkles too steep for an effective roughness (rms slope {slope:.3g})"
    elif ratio >= w.lod_footprint:
        model, reason = "effective", f"a pixel spans {ratio:.3g} L >= wrinkles.lod_footprint = {w.lod_footprint:g}"
    else:
        model, reason = "geometry", f"a pixel spans {ratio:.3g} L < wrinkles.lod_footprint = {w.lod_footprint:g}"
    choice = LodChoice(part, model, footprint, ratio, slope, alpha, reason)
    return choice, (effective if model == "effective" else None)
