"""The Lambertian reflector, f_r = kd / pi (thesis eq. 2-10)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar, TYPE_CHECKING


from spacefit.materials.model import Field, MaterialModel, Spectrum

if TYPE_CHECKING:
    from jaxtyping import Array

KD = Field("kd", "1", 0.0, 1.0, 0.1, "diffuse albedo", "albedo kd", spectral=True)


@dataclass(frozen=True)
class Lambert(MaterialModel):
    """Lambertian reflector, f_r = kd / pi (thesis eq. 2-10); kd in [0, 1]."""

    name: ClassVar[str] = "lambert"
    fields: ClassVar[tuple[Field, ...]] = (KD,)

    kd: Spectrum

    def f_r(self, wi: Array, wo: Array, **values: Array) -> Array:
        """kd / pi."""
        import jax.numpy as jnp  # deferred: a model's fields are read without JAX (the parameter table, a scene file)
        return jnp.zeros(jnp.shape(wi)[:-1]) + values["kd"] / jnp.pi
