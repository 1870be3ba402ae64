"""BRDF values of spacefit's material models as JAX functions, evaluated the way the renderer does.

Each model's BRDF lives in its own module (:mod:`spacefit.materials.conductor`,
:mod:`~spacefit.materials.lambert`, :mod:`~spacefit.materials.oren_nayar`, ...) as its
:meth:`~spacefit.materials.model.MaterialModel.f_r`; :func:`brdf` evaluates any material the way
the renderer draws it: Mitsuba's ``twosided`` wrapper (both directions on the back are mirrored to
the front, opposite sides give 0), the RGB channels' mean (the renderer's light curve is the
channels' mean radiance). The test ``tests/test_brdf_tables.py`` holds them to Mitsuba's
``BSDF.eval`` within 1e-5 relative.
"""

from __future__ import annotations

from collections.abc import Mapping

from jaxtyping import Array

from spacefit.materials.model import Material


def brdf(material: Material, wi: Array, wo: Array, values: Mapping[str, Array] | None = None) -> Array:
    """f_r (sr^-1) of ``material`` for local unit directions ``wi`` (towards the light) and ``wo``
    (towards the observer), arrays (..., 3); ``values`` replace its fields by name with grey values
    (JAX-traceable). A mirror's BRDF is a delta function: refused (TypeError)."""
    return material.evaluate(wi, wo, values)
