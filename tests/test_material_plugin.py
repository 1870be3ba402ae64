"""A material model added from a test-only module (``plugin_material.py``), with no other file
touched: a scene names it, the renderer draws it, an image fit frees its field by
``parts.<part>.<field>``, a BRDF table is fitted with it; and the registry refuses a field name
that another model's field has with another meaning."""

from __future__ import annotations

import dataclasses
from typing import ClassVar

import numpy as np
import plugin_material
import pytest
from helpers import small_scene, write_plate_obj

import spacefit as sf
from spacefit.fitting.brdf_table import BRDF_MODELS, simulate_brdf_table
from spacefit.fitting.observations.brdf import fit_brdf_table
from spacefit.materials import MODELS, Field, MaterialModel
from spacefit.rendering.materials import MITSUBA
from spacefit.rendering.renderer import render
from spacefit.scene.parameters import PARAMETERS, available

E = 5.0


@pytest.fixture
def toy():
    plugin_material.register()
    yield plugin_material.ToyDiffuse
    MODELS.pop("toy_diffuse")
    MITSUBA.pop(plugin_material.ToyDiffuse)


def scene(tmp_path, albedo, **render_):
    return small_scene(write_plate_obj(tmp_path / "plate.obj", size=4.0), {"material": "toy_diffuse", "albedo": albedo},
                       sun={"irradiance_w_m2": E}, render={"resolution": [16, 16], **render_})


def test_a_plugin_model_is_rendered_and_fitted_by_name(tmp_path, toy):
    assert "parts.P.albedo" in PARAMETERS and "parts.plate.albedo" in available(scene(tmp_path, 0.4))
    img = render(scene(tmp_path, 0.4))
    assert np.mean(img) == pytest.approx(0.4 * E / np.pi, rel=0.01)  # facing the sun: albedo E / pi
    reference = render(scene(tmp_path, 0.4, seed=7))
    result = sf.fit(sf.Observation(scene(tmp_path, 0.15), reference), ["parts.plate.albedo"], max_steps=20)
    assert result.values["parts.plate.albedo"] == pytest.approx(0.4, rel=0.01)


def test_a_plugin_model_fits_a_brdf_table(toy):
    assert "toy_diffuse" in BRDF_MODELS
    table = simulate_brdf_table(toy(0.27), [0.0, 30.0, 60.0], [10.0, 40.0, 70.0], (0.0, 90.0), relative_error=0.01, seed=2)
    fit = fit_brdf_table(table, "toy_diffuse", part="sample")
    assert fit.values["parts.sample.albedo"] == pytest.approx(0.27, rel=0.01)


def test_unregistered_after_the_test():
    assert "toy_diffuse" not in MODELS and "parts.P.albedo" not in PARAMETERS and "toy_diffuse" not in BRDF_MODELS


def test_a_field_name_has_one_meaning():
    @dataclasses.dataclass(frozen=True)
    class Clash(MaterialModel):
        name: ClassVar[str] = "clash"
        fields: ClassVar[tuple[Field, ...]] = (Field("kd", "1", 0.0, 2.0, 0.5, "an albedo on another range", "kd"),)
        kd: float

    with pytest.raises(ValueError, match="one field name is one parameter"):
        sf.register_material(Clash)
    assert "clash" not in MODELS
