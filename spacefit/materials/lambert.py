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
    """Lambertian reflector, f_r = kd / pi (thesis eq. 2-10); kd in [0, 1].

    A diffuse surface that reflects alike in every direction: paint, a matte coating, the default
    lander's legs.

    Args:
        kd: the albedo (diffuse reflectance), one value or RGB (3 values), in [0, 1].

    Raises:
        InputError: ``kd`` outside [0, 1].

    Example:
        >>> import numpy as np, spacefit as sf
        >>> paint = sf.Lambert(kd=0.5)
        >>> up = np.array([0.0, 0.0, 1.0])
        >>> round(float(paint.evaluate(up, up)), 4)  # kd / pi, sr^-1
        0.1592
    """

    name: ClassVar[str] = "lambert"
    fields: ClassVar[tuple[Field, ...]] = (KD,)

    kd: Spectrum

    def f_r(self, wi: Array, wo: Array, **values: Array) -> Array:
        """kd / pi."""
        import jax.numpy as jnp  # deferred: a model's fields are read without JAX (the parameter table, a scene file)
        return jnp.zeros(jnp.shape(wi)[:-1]) + values["kd"] / jnp.pi
