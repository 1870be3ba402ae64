"""Oren-Nayar rough diffuse reflection (Oren & Nayar 1994), the qualitative model.

Oren & Nayar, "Generalization of Lambert's reflectance model", SIGGRAPH 94, pp. 239-246: a surface
of long symmetric V-cavities, each side a Lambertian facet, with facet slopes of Gaussian
distribution of standard deviation ``sigma`` (rad). This is the paper's qualitative model (its
eq. 30, the form Mitsuba 0.6's ``roughdiffuse`` evaluates with ``useFastApprox``), which leaves out
the interreflection term of the full model:

    f_r = kd / pi (A + B max(0, cos(phi_i - phi_o)) sin(alpha) tan(beta)),
    A = 1 - 0.5 sigma^2 / (sigma^2 + 0.33),   B = 0.45 sigma^2 / (sigma^2 + 0.09),

alpha = max(theta_i, theta_o), beta = min(theta_i, theta_o). sigma = 0 is Lambert's kd / pi
exactly. With sin(alpha) sin(beta) = sin(theta_i) sin(theta_o) and cos(beta) = max(cos theta_i,
cos theta_o), the B term is max(0, wi_xy . wo_xy) / max(cos theta_i, cos theta_o): no angle is
taken, and the BRDF is smooth in sigma and kd (what a fit differentiates).

``sigma`` lies in [0, pi/2): it is the standard deviation of the facets' slope angle, and a
facet's slope angle lies in [0, pi/2); at pi/2 the Gaussian no longer describes a surface (A and
B have long saturated by then: A = 0.56, B = 0.43). Isotropic: the part's tangent does not matter.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar, TYPE_CHECKING


from spacefit.materials.lambert import KD
from spacefit.materials.model import Field, MaterialModel, Spectrum

if TYPE_CHECKING:
    from jaxtyping import Array

SIGMA = Field("sigma", "rad", 0.0, math.pi / 2, 0.3, "Oren-Nayar roughness: standard deviation of the facets' slope angle",
              "roughness sigma", hi_open=True)


def oren_nayar_ab(sigma: Array) -> tuple[Array, Array]:
    """The qualitative model's A and B (Oren & Nayar 1994, eq. 30) of the slope deviation ``sigma`` (rad)."""
    s2 = sigma**2
    return 1.0 - 0.5 * s2 / (s2 + 0.33), 0.45 * s2 / (s2 + 0.09)


def oren_nayar_brdf(wi: Array, wo: Array, kd: Array, sigma: Array) -> Array:
    """f_r (sr^-1) of the qualitative model (module docstring) for front-side local unit directions (..., 3)."""
    import jax.numpy as jnp  # deferred: a model's fields are read without JAX (the parameter table, a scene file)
    a, b = oren_nayar_ab(sigma)
    azimuthal = jnp.maximum(0.0, wi[..., 0] * wo[..., 0] + wi[..., 1] * wo[..., 1])
    return kd / jnp.pi * (a + b * azimuthal / jnp.maximum(wi[..., 2], wo[..., 2]))


@dataclass(frozen=True)
class OrenNayar(MaterialModel):
    """Oren-Nayar rough diffuse reflector (Oren & Nayar 1994, qualitative model, eq. 30): albedo ``kd``
    in [0, 1] and facet-slope deviation ``sigma`` in [0, pi/2) rad (Oren & Nayar 1994).
    sigma = 0 is :class:`Lambert`.

    Args:
        kd: albedo, one value or RGB, in [0, 1].
        sigma: standard deviation of the facets' slope angle (rad), in [0, pi/2).

    Raises:
        InputError: a value outside its range.

    Example:
        >>> import spacefit as sf
        >>> sf.OrenNayar(kd=0.5, sigma=0.3)
        OrenNayar(kd=0.5, sigma=0.3)
        >>> try:
        ...     sf.OrenNayar(kd=0.5, sigma=2.0)
        ... except sf.InputError as err:
        ...     print(err)
        `sigma` must be in [0, 1.5708) rad, got 2.
    """

    name: ClassVar[str] = "oren_nayar"
    fields: ClassVar[tuple[Field, ...]] = (KD, SIGMA)

    kd: Spectrum
    sigma: float

    def f_r(self, wi: Array, wo: Array, **values: Array) -> Array:
        """kd / pi (A + B max(0, cos dphi) sin(alpha) tan(beta)) (:func:`oren_nayar_brdf`)."""
        return oren_nayar_brdf(wi, wo, values["kd"], values["sigma"])
