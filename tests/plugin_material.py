"""A material model defined outside spacefit, as a user's own module would: a grey diffuse reflector
of albedo ``albedo`` (f_r = albedo / pi), its Mitsuba entry, and the calls that add both.
Only :mod:`tests.test_material_plugin` imports it."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import jax.numpy as jnp

from spacefit.materials import Field, MaterialModel, register_material
from spacefit.rendering.materials import MitsubaMaterial, register_mitsuba, rgb

ALBEDO = Field("albedo", "1", 0.0, 1.0, 0.3, "the toy's diffuse albedo", "toy albedo")


@dataclass(frozen=True)
class ToyDiffuse(MaterialModel):
    """f_r = albedo / pi, drawn by Mitsuba's ``diffuse``."""

    name: ClassVar[str] = "toy_diffuse"
    fields: ClassVar[tuple[Field, ...]] = (ALBEDO,)

    albedo: float

    def f_r(self, wi, wo, **values):
        return jnp.zeros(jnp.shape(wi)[:-1]) + values["albedo"] / jnp.pi


MITSUBA = MitsubaMaterial(lambda m: {"type": "diffuse", "reflectance": {"type": "rgb", "value": [m.albedo] * 3}},
                          {"albedo": (("reflectance.value", rgb),)})


def register() -> None:
    """Add the toy model and its Mitsuba entry (one call each)."""
    register_material(ToyDiffuse)
    register_mitsuba(ToyDiffuse, MITSUBA)
