"""The rough conductor (thesis eqs. 2-8, 2-9): anisotropic microfacets with conductor Fresnel.

f_r = D G F / (4 cos_i cos_o) with the anisotropic GGX (Trowbridge & Reitz 1975) or Beckmann
distribution D, Smith's separable masking G (Walter, Marschner, Li & Torrance 2007, "Microfacet
models for refraction through rough surfaces", EGSR; Beckmann's G1 by its rational approximation)
and the Fresnel factor F of the complex index eta + i k (thesis eq. 2-8), evaluated as Mitsuba 3's
``roughconductor`` does, term for term (``tests/test_brdf_tables.py`` holds it to ``BSDF.eval``
within 1e-5 relative). Its level-of-detail rule widens the roughness by the wrinkles' slopes
(:meth:`Conductor.effective`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar, TYPE_CHECKING


from spacefit.errors import check_choice
from spacefit.materials.model import Field, MaterialModel, Spectrum

if TYPE_CHECKING:
    from jaxtyping import Array

DISTRIBUTIONS = ("ggx", "beckmann")
# The smallest microfacet roughness: below it GGX is a mirror in float32 and Mitsuba's GGX evaluates to NaN.
MIN_ALPHA = 1e-4
# Beyond 100 no conductor of the solar spectrum lies (metals' eta and k are below 10 there).
MAX_INDEX = 100.0

ETA = Field("eta", "1", 0.0, MAX_INDEX, 1.5, "real part of the conductor's refractive index", "refractive index eta",
            spectral=True, lo_open=True)
K = Field("k", "1", 0.0, MAX_INDEX, 1.0, "imaginary part of the conductor's refractive index", "extinction coefficient k",
          spectral=True)
ALPHA_X = Field("alpha_x", "1", MIN_ALPHA, 1.0, 0.1, "GGX roughness along the part's tangent axis", "roughness alpha_x")
ALPHA_Y = Field("alpha_y", "1", MIN_ALPHA, 1.0, 0.1, "GGX roughness across the part's tangent axis", "roughness alpha_y")
# ``alpha`` sets both roughnesses (an isotropic conductor).
ROUGHNESS_TIE = {"alpha": (("alpha_x", "alpha_y"), "both roughnesses, tied (isotropic)", "roughness alpha")}


def _safe_sqrt(x: Array) -> Array:
    """sqrt(max(x, 0)) (Mitsuba's ``safe_sqrt``) with a zero derivative where x <= 0, not NaN."""
    import jax.numpy as jnp  # deferred: a model's fields are read without JAX (the parameter table, a scene file)
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
    import jax.numpy as jnp  # deferred: a model's fields are read without JAX (the parameter table, a scene file)
    mx, my, mz = m[..., 0], m[..., 1], m[..., 2]
    if distribution == "ggx":
        d = 1.0 / (jnp.pi * alpha_x * alpha_y * ((mx / alpha_x) ** 2 + (my / alpha_y) ** 2 + mz**2) ** 2)
    else:
        c2 = mz**2
        d = jnp.exp(-((mx / alpha_x) ** 2 + (my / alpha_y) ** 2) / jnp.where(c2 > 0, c2, 1.0)) / (jnp.pi * alpha_x * alpha_y * c2**2)
    return jnp.where(d * mz > 1e-20, d, 0.0)


def smith_g1(v: Array, m: Array, alpha_x: Array, alpha_y: Array, distribution: str) -> Array:
    """Smith's masking of direction ``v`` for microfacet normal ``m`` (Mitsuba's ``smith_g1``)."""
    import jax.numpy as jnp  # deferred: a model's fields are read without JAX (the parameter table, a scene file)
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
    import jax.numpy as jnp  # deferred: a model's fields are read without JAX (the parameter table, a scene file)
    h = wi + wo
    h = h / jnp.linalg.norm(h, axis=-1, keepdims=True)
    d = microfacet_d(h, alpha_x, alpha_y, distribution)
    g = smith_g1(wi, h, alpha_x, alpha_y, distribution) * smith_g1(wo, h, alpha_x, alpha_y, distribution)
    f = fresnel_conductor(jnp.sum(wi * h, axis=-1), eta, k)
    return d * g * f / (4.0 * wi[..., 2] * wo[..., 2])


def effective_alpha(alpha0: float, slope_rms: float) -> float:
    """Roughness of a flat surface whose microfacets are tilted by wrinkles of rms slope ``slope_rms``
    (Beckmann's slopes have per-axis variance alpha^2 / 2, Walter et al. 2007; :mod:`spacefit.scene.lod`)."""
    return math.sqrt(alpha0**2 + 2.0 * slope_rms**2)


@dataclass(frozen=True)
class Conductor(MaterialModel):
    """Rough conductor: anisotropic microfacets, conductor Fresnel.

    ``alpha_x`` is the roughness along the part's stated tangent axis (for the built-in panels,
    the span), ``alpha_y`` across it. Both in [:data:`MIN_ALPHA`, 1]. ``distribution`` is "ggx" (Trowbridge-Reitz,
    thesis eq. 2-9) or "beckmann" (Gaussian slopes of per-axis variance alpha^2 / 2, which the
    level of detail uses for wrinkles' slopes). Masking is Smith's separable form, as in Walter et
    al. 2007 and Mitsuba 3.

    Args:
        eta: real part of the complex refractive index, one value or RGB (3 values), > 0.
        k: imaginary part (extinction coefficient), one value or RGB, >= 0.
        alpha_x: roughness along the tangent (dimensionless microfacet alpha), in [1e-4, 1].
        alpha_y: roughness across the tangent, in [1e-4, 1].
        distribution: ``"ggx"`` or ``"beckmann"``.

    Raises:
        InputError: a value outside its range or an unknown distribution, naming the field.

    Example:
        >>> import spacefit as sf
        >>> sf.Conductor(eta=0.18, k=0.01, alpha_x=0.14, alpha_y=0.14)  # the thesis's MLI
        Conductor(eta=0.18, k=0.01, alpha_x=0.14, alpha_y=0.14, distribution='ggx')
        >>> try:
        ...     sf.Conductor(eta=0.18, k=0.01, alpha_x=2.0, alpha_y=0.1)
        ... except sf.InputError as err:
        ...     print(err)
        `alpha_x` must be in [0.0001, 1], got 2.
    """

    name: ClassVar[str] = "conductor"
    fields: ClassVar[tuple[Field, ...]] = (ETA, K, ALPHA_X, ALPHA_Y)
    ties: ClassVar = ROUGHNESS_TIE

    eta: Spectrum
    k: Spectrum
    alpha_x: float
    alpha_y: float
    distribution: str = "ggx"

    def __post_init__(self) -> None:
        super().__post_init__()
        check_choice("distribution", self.distribution, DISTRIBUTIONS)

    def f_r(self, wi: Array, wo: Array, **values: Array) -> Array:
        """D G F / (4 cos_i cos_o) (:func:`conductor_brdf`) of the values eta, k, alpha_x, alpha_y."""
        return conductor_brdf(wi, wo, values["eta"], values["k"], values["alpha_x"], values["alpha_y"], self.distribution)

    def effective(self, slope_rms: float) -> Conductor | None:
        """A Beckmann conductor whose roughnesses are widened by the wrinkles' slopes (:func:`effective_alpha`);
        None if that exceeds alpha <= 1."""
        ax, ay = effective_alpha(self.alpha_x, slope_rms), effective_alpha(self.alpha_y, slope_rms)
        if max(ax, ay) > 1.0:
            return None
        return Conductor(self.eta, self.k, ax, ay, "beckmann")
