"""BRDF values of spacefit's material models as JAX functions, evaluated the way the renderer does.

Each function takes unit directions in the surface's local frame (z the normal, x the tangent along
which a conductor's ``alpha_x`` lies), ``wi`` towards the light and ``wo`` towards the observer,
and returns the BRDF f_r in sr^-1 (radiance out per irradiance in). They follow Mitsuba 3's own
evaluation of the BSDFs the renderer loads (:func:`spacefit.rendering.renderer.bsdf_dict`), term for
term, so that a fit to a measured table or to a flat plate's light curve uses the material the
renderer draws: Mitsuba's ``twosided`` wrapper (both directions on the back are mirrored to the
front, opposite sides give 0), ``diffuse`` kd / pi (thesis eq. 2-10) and ``roughconductor``
D G F / (4 cos_i cos_o) with the anisotropic GGX (Trowbridge & Reitz 1975) or Beckmann distribution,
Smith's separable masking (Walter et al. 2007; Beckmann's G1 by its rational approximation) and
the conductor Fresnel factor of the complex index eta + i k (thesis eq. 2-8). The test
``tests/test_brdf_tables.py`` holds them to Mitsuba's ``BSDF.eval`` within 1e-5 relative.
A scalar ``eta`` / ``k`` is grey; RGB values give the mean of the three channels' BRDFs (the
renderer's light curve is the channels' mean radiance).

A :class:`DiffuseConductor` (the sum kd / pi + the rough conductor) is evaluated as that sum.
"""

from __future__ import annotations

import jax.numpy as jnp
from jaxtyping import Array

from spacefit.materials.models import DiffuseConductor, Lambert, Material, Mirror


def _channels(value: object) -> Array:
    return jnp.asarray(value if isinstance(value, (tuple, list)) else (value,), dtype=float)


def _safe_sqrt(x: Array) -> Array:
    """sqrt(max(x, 0)) (Mitsuba's ``safe_sqrt``) with a zero derivative where x <= 0, not NaN."""
    positive = x > 0
    return jnp.where(positive, jnp.sqrt(jnp.where(positive, x, 1.0)), 0.0)


def fresnel_conductor(cos_i: Array, eta: Array, k: Array) -> Array:
    """Unpolarised reflectance of a conductor of complex index eta + i k at cos_i (Mitsuba's
    ``fresnel_conductor``, the exact form for an absorbing medium)."""
    c2 = cos_i**2
    s2 = 1.0 - c2
    t1 = eta**2 - k**2 - s2
    a2pb2 = _safe_sqrt(t1**2 + 4.0 * k**2 * eta**2)
    a = _safe_sqrt(0.5 * (a2pb2 + t1))
    term1 = a2pb2 + c2
    term2 = 2.0 * cos_i * a
    r_s = (term1 - term2) / (term1 + term2)
    term3 = a2pb2 * c2 + s2**2
    term4 = term2 * s2
    r_p = r_s * (term3 - term4) / (term3 + term4)
    return 0.5 * (r_s + r_p)


def microfacet_d(m: Array, alpha_x: Array, alpha_y: Array, distribution: str) -> Array:
    """The microfacet distribution D(m) (sr^-1) of unit half vectors ``m`` (..., 3)."""
    mx, my, mz = m[..., 0], m[..., 1], m[..., 2]
    if distribution == "ggx":
        d = 1.0 / (jnp.pi * alpha_x * alpha_y * ((mx / alpha_x) ** 2 + (my / alpha_y) ** 2 + mz**2) ** 2)
    else:
        c2 = mz**2
        d = jnp.exp(-((mx / alpha_x) ** 2 + (my / alpha_y) ** 2) / jnp.where(c2 > 0, c2, 1.0)) / (jnp.pi * alpha_x * alpha_y * c2**2)
    return jnp.where(d * mz > 1e-20, d, 0.0)


def smith_g1(v: Array, m: Array, alpha_x: Array, alpha_y: Array, distribution: str) -> Array:
    """Smith's masking of direction ``v`` for microfacet normal ``m`` (Mitsuba's ``smith_g1``)."""
    xy = (alpha_x * v[..., 0]) ** 2 + (alpha_y * v[..., 1]) ** 2
    tan2 = xy / v[..., 2] ** 2
    if distribution == "ggx":
        g = 2.0 / (1.0 + jnp.sqrt(1.0 + tan2))
    else:
        a = 1.0 / jnp.sqrt(jnp.where(tan2 > 0, tan2, 1.0))
        g = jnp.where(a >= 1.6, 1.0, (3.535 * a + 2.181 * a**2) / (1.0 + 2.276 * a + 2.577 * a**2))
    g = jnp.where(xy == 0, 1.0, g)
    return jnp.where(jnp.sum(v * m, axis=-1) * v[..., 2] <= 0, 0.0, g)


def conductor_brdf(wi: Array, wo: Array, eta: Array, k: Array, alpha_x: Array, alpha_y: Array, distribution: str) -> Array:
    """The rough conductor's BRDF (sr^-1) for front-side ``wi``, ``wo``; grey ``eta``, ``k``."""
    h = wi + wo
    h = h / jnp.linalg.norm(h, axis=-1, keepdims=True)
    d = microfacet_d(h, alpha_x, alpha_y, distribution)
    g = smith_g1(wi, h, alpha_x, alpha_y, distribution) * smith_g1(wo, h, alpha_x, alpha_y, distribution)
    f = fresnel_conductor(jnp.sum(wi * h, axis=-1), eta, k)
    return d * g * f / (4.0 * wi[..., 2] * wo[..., 2])


def brdf_value(wi: Array, wo: Array, *, kd: Array | None = None, eta: Array | None = None, k: Array | None = None,
               alpha_x: Array | None = None, alpha_y: Array | None = None, distribution: str = "ggx") -> Array:
    """f_r (sr^-1) for local unit directions ``wi`` (towards the light) and ``wo`` (towards the
    observer), arrays (..., 3): kd / pi where ``kd`` is given, plus the rough conductor where ``eta``
    is (grey values, JAX-traceable: what a fit varies); 0 where the directions lie on opposite sides
    of the surface (Mitsuba's ``twosided``: the back shades as the front)."""
    wi, wo = jnp.asarray(wi, dtype=float), jnp.asarray(wo, dtype=float)
    back = (wi[..., 2] < 0)[..., None]
    flip = jnp.array([1.0, 1.0, -1.0])
    wi, wo = jnp.where(back, wi * flip, wi), jnp.where(back, wo * flip, wo)
    front = (wi[..., 2] > 0) & (wo[..., 2] > 0)
    up = jnp.array([0.0, 0.0, 1.0])
    safe_i, safe_o = jnp.where(front[..., None], wi, up), jnp.where(front[..., None], wo, up)
    value = jnp.zeros(jnp.shape(wi)[:-1])
    if kd is not None:
        value = value + kd / jnp.pi
    if eta is not None:
        value = value + conductor_brdf(safe_i, safe_o, eta, k, alpha_x, alpha_y, distribution)
    return jnp.where(front, value, 0.0)


def brdf(material: Material, wi: Array, wo: Array) -> Array:
    """f_r (sr^-1) of ``material`` (:func:`brdf_value`); RGB values give the channels' mean. A
    mirror's BRDF is a delta function: refused."""
    if isinstance(material, Mirror):
        raise TypeError("a Mirror's BRDF is a delta function: it has no finite value to evaluate")
    if isinstance(material, Lambert):
        return brdf_value(wi, wo, kd=jnp.mean(_channels(material.kd)))
    eta, k = jnp.broadcast_arrays(_channels(material.eta), _channels(material.k))
    kd = jnp.mean(_channels(material.kd)) if isinstance(material, DiffuseConductor) else None
    channels = [brdf_value(wi, wo, kd=kd, eta=eta[c], k=k[c], alpha_x=material.alpha_x, alpha_y=material.alpha_y,
                           distribution=material.distribution) for c in range(len(eta))]
    return sum(channels) / len(channels)
