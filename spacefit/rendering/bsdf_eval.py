"""Mitsuba's own evaluation of a material's BSDF: the reference that :mod:`spacefit.materials.brdf` follows.

The material is loaded as the renderer loads it (:func:`spacefit.rendering.materials.bsdf_dict`,
``twosided`` included) and evaluated by ``BSDF.eval`` at a surface interaction whose shading frame
is the local frame (z the normal, x the tangent of ``alpha_x``). ``eval`` returns f_r cos(theta_o);
this returns f_r (sr^-1), the mean of the RGB channels.
"""

from __future__ import annotations

import numpy as np

from spacefit.materials import Material
from spacefit.rendering.backend import mi, variant_scope
from spacefit.rendering.materials import bsdf_dict


@variant_scope("auto")
def mitsuba_brdf(material: Material, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
    """f_r (sr^-1) of ``material`` by Mitsuba for local unit directions ``wi`` (towards the light) and
    ``wo`` (towards the observer), arrays (n, 3), with cos(theta_o) != 0."""
    wi, wo = np.atleast_2d(np.asarray(wi, dtype=float)), np.atleast_2d(np.asarray(wo, dtype=float))
    bsdf = mi.load_dict(bsdf_dict(material))
    si = mi.SurfaceInteraction3f()
    si.wi = mi.Vector3f(*(wi[:, i].astype(np.float32) for i in range(3)))
    si.sh_frame = mi.Frame3f(mi.Vector3f(0.0, 0.0, 1.0))
    si.n = mi.Normal3f(0.0, 0.0, 1.0)
    value = bsdf.eval(mi.BSDFContext(), si, mi.Vector3f(*(wo[:, i].astype(np.float32) for i in range(3))))
    rgb = np.stack([np.asarray(value[c], dtype=float) for c in range(3)], axis=-1)
    return rgb.mean(axis=-1) / np.abs(wo[:, 2])
