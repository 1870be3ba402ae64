"""A rough conductor plus a diffuse term: f_r = kd / pi + the rough conductor's BRDF."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar, TYPE_CHECKING


from spacefit.errors import check_choice
from spacefit.materials.conductor import ALPHA_X, ALPHA_Y, DISTRIBUTIONS, ETA, K, ROUGHNESS_TIE, conductor_brdf
from spacefit.materials.lambert import KD
from spacefit.materials.model import Field, MaterialModel, Spectrum

if TYPE_CHECKING:
    from jaxtyping import Array


@dataclass(frozen=True)
class DiffuseConductor(MaterialModel):
    """A rough conductor plus a diffuse term: f_r = kd / pi + the :class:`Conductor`'s
    BRDF (the sum a measured table of a painted or coated surface often needs: a specular peak over a
    diffuse floor). The renderer draws it as Mitsuba's ``blendbsdf`` of the two, each doubled, at weight 0.5.

    Args:
        kd: albedo of the diffuse term, one value or RGB, in [0, 1].
        eta, k: the conductor's complex refractive index (one value or RGB; eta > 0, k >= 0).
        alpha_x, alpha_y: the conductor's roughness along and across the tangent, in [1e-4, 1].
        distribution: ``"ggx"`` or ``"beckmann"``.

    Raises:
        InputError: a value outside its range.

    Example:
        >>> import spacefit as sf
        >>> sf.DiffuseConductor(kd=0.1, eta=1.5, k=3.0, alpha_x=0.2, alpha_y=0.2)
        DiffuseConductor(kd=0.1, eta=1.5, k=3.0, alpha_x=0.2, alpha_y=0.2, distribution='ggx')
    """

    name: ClassVar[str] = "diffuse_conductor"
    fields: ClassVar[tuple[Field, ...]] = (KD, ETA, K, ALPHA_X, ALPHA_Y)
    ties: ClassVar = ROUGHNESS_TIE

    kd: Spectrum
    eta: Spectrum
    k: Spectrum
    alpha_x: float
    alpha_y: float
    distribution: str = "ggx"

    def __post_init__(self) -> None:
        super().__post_init__()
        check_choice("distribution", self.distribution, DISTRIBUTIONS)

    def f_r(self, wi: Array, wo: Array, **values: Array) -> Array:
        """kd / pi + D G F / (4 cos_i cos_o)."""
        import jax.numpy as jnp  # deferred: a model's fields are read without JAX (the parameter table, a scene file)
        specular = conductor_brdf(wi, wo, values["eta"], values["k"], values["alpha_x"], values["alpha_y"], self.distribution)
        return values["kd"] / jnp.pi + specular
