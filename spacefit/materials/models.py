"""BRDF models of thesis section 2.3 as small value objects holding the paper's parameters.

The renderer maps each to a Mitsuba 3 BSDF; the values are physical (dimensionless) and validated
on construction. A scalar ``eta`` / ``k`` / ``kd`` is grey; a 3-tuple is per RGB channel.

References:
    Walter, Marschner, Li, Torrance (2007), "Microfacet models for refraction through rough
    surfaces", EGSR. Trowbridge & Reitz (1975) distribution (GGX), anisotropic form of thesis
    eq. 2-9; conductor Fresnel with complex index eta + i k, thesis eq. 2-8.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Union

from spacefit.errors import InputError, check_choice, check_range

Spectrum = Union[float, tuple[float, float, float]]
DISTRIBUTIONS = ("ggx", "beckmann")
# The smallest microfacet roughness: below it GGX is a mirror in float32 and Mitsuba's GGX evaluates to NaN.
MIN_ALPHA = 1e-4


def _check_spectrum(name: str, value: Spectrum, lo: float, hi: float, lo_open: bool) -> Spectrum:
    values = value if isinstance(value, (tuple, list)) else (value,)
    if len(values) not in (1, 3):
        raise InputError(f"`{name}` must be one number or 3 (RGB), got {value!r}.")
    checked = tuple(check_range(name, v, lo, hi, lo_open=lo_open) for v in values)
    return checked[0] if len(checked) == 1 else checked  # type: ignore[return-value]


@dataclass(frozen=True)
class Conductor:
    """Rough conductor: anisotropic microfacets, conductor Fresnel.

    ``alpha_x`` is the roughness along the part's stated tangent axis (for the built-in panels,
    the span), ``alpha_y`` across it. Both in [:data:`MIN_ALPHA`, 1]. ``distribution`` is "ggx" (Trowbridge-Reitz,
    thesis eq. 2-9) or "beckmann" (Gaussian slopes of per-axis variance alpha^2 / 2, which the
    level of detail uses for wrinkles' slopes). Masking is Smith's separable form, as in Walter et
    al. 2007 and Mitsuba 3.
    """

    eta: Spectrum
    k: Spectrum
    alpha_x: float
    alpha_y: float
    distribution: str = "ggx"

    def __post_init__(self) -> None:
        object.__setattr__(self, "eta", _check_spectrum("eta", self.eta, 0.0, 100.0, True))
        object.__setattr__(self, "k", _check_spectrum("k", self.k, 0.0, 100.0, False))
        object.__setattr__(self, "alpha_x", check_range("alpha_x", self.alpha_x, MIN_ALPHA, 1.0))
        object.__setattr__(self, "alpha_y", check_range("alpha_y", self.alpha_y, MIN_ALPHA, 1.0))
        check_choice("distribution", self.distribution, DISTRIBUTIONS)


@dataclass(frozen=True)
class Mirror:
    """Smooth conductor (thesis eq. 2-5): a delta reflection weighted by conductor Fresnel.

    Under a single distant sun a mirror is never seen lit directly (delta BRDF times delta light);
    it only shows what it reflects.
    """

    eta: Spectrum
    k: Spectrum

    def __post_init__(self) -> None:
        object.__setattr__(self, "eta", _check_spectrum("eta", self.eta, 0.0, 100.0, True))
        object.__setattr__(self, "k", _check_spectrum("k", self.k, 0.0, 100.0, False))


@dataclass(frozen=True)
class Lambert:
    """Lambertian reflector, f_r = kd / pi (thesis eq. 2-10); kd in [0, 1]."""

    kd: Spectrum

    def __post_init__(self) -> None:
        object.__setattr__(self, "kd", _check_spectrum("kd", self.kd, 0.0, 1.0, False))


@dataclass(frozen=True)
class DiffuseConductor:
    """A rough conductor plus a diffuse term: f_r = kd / pi + the :class:`Conductor`'s BRDF (the sum a
    measured table of a painted or coated surface often needs: a specular peak over a diffuse floor).
    The renderer draws it as Mitsuba's ``blendbsdf`` of the two, each doubled, at weight 0.5.
    Image fits cannot free its parameters (only its light-curve and BRDF-table fits do)."""

    kd: Spectrum
    eta: Spectrum
    k: Spectrum
    alpha_x: float
    alpha_y: float
    distribution: str = "ggx"

    def __post_init__(self) -> None:
        object.__setattr__(self, "kd", _check_spectrum("kd", self.kd, 0.0, 1.0, False))
        Conductor.__post_init__(self)  # type: ignore[arg-type]


Material = Union[Conductor, Mirror, Lambert, DiffuseConductor]
