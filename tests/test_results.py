"""Results to take away: the fitted scene as TOML and as a Mitsuba dict, errors and correlations as JSON."""

from __future__ import annotations

import json

import numpy as np
import pytest

import spacefit as sf
from spacefit.scene.parameters import scene_value, scene_with_values

TINY = {"render.resolution": [32, 32], "camera.pixel_pitch_mm": 75.0, "render.spp": 8}


@pytest.fixture(scope="module")
def fitted(tmp_path_factory):
    case = sf.load_case("panels").with_values(TINY)
    reference, _ = case.reference()
    free = [*case.free, "image.scale"]
    result = sf.fit(sf.Observation(case.scene(), reference), free, start=case.start)
    out = tmp_path_factory.mktemp("fit")
    sf.write_fit_report(out, result, [reference])
    return case, result, out


def test_fit_toml_renders_the_fit_again(fitted):
    case, result, out = fitted
    scene = sf.load_scene(out / "fit.toml")
    for name, value in result.estimates.items():
        assert scene_value(scene, name) == pytest.approx(value, rel=1e-9)
    assert scene.render == case.scene().render and scene.camera == case.scene().camera
    # the fitted gain is not a scene value: the scene renders the fit divided by it
    again = np.asarray(sf.render(scene), float) * result.values["image.scale"]
    assert again.mean() == pytest.approx(np.asarray(result.renders[0], float).mean(), rel=0.02)


def test_uncertainty_json_holds_errors_and_correlations(fitted):
    _, result, out = fitted
    data = json.loads((out / "uncertainty.json").read_text())  # strict JSON: json.loads would refuse NaN only via parse_constant
    assert data["names"] == list(result.names) and data["nuisances"] == ["image.scale"]
    corr = np.array(data["correlation"])
    assert corr.shape == (4, 4) and np.allclose(corr, corr.T) and np.allclose(np.diag(corr), 1.0)
    assert data["stderr"] == pytest.approx(result.stderr) and data["units"]["image.scale"] == "1"


def test_mitsuba_scene_dict_loads_and_renders_like_the_scene(fitted):
    import mitsuba as mi

    _, result, _ = fitted
    d = result.mitsuba_scene_dict()
    assert {"integrator", "sensor", "sun", "panels", "legs"} <= set(d)
    image = np.asarray(mi.render(mi.load_dict(d), spp=64), float)
    reference = np.asarray(sf.render(result.scene.with_values({"render.spp": 64})), float)
    assert image.mean() == pytest.approx(reference.mean(), rel=0.02)


def test_scene_with_values_refuses_unknown_names():
    with pytest.raises(sf.InputError, match="values"):
        scene_with_values(sf.load_case("panels").scene(), {"parts.panels.shininess": 1.0})


def test_scene_with_values_sets_both_roughnesses_for_alpha(tmp_path):
    """`alpha` sets both roughnesses, whether the scene file spelt them `alpha` (the materials case)
    or apart; the scene it writes reads back to the same materials."""
    for case in ("materials", "panels"):
        fitted = scene_with_values(sf.load_case(case).scene(), {"parts.body.alpha": 0.2})
        body = fitted.parts["body"].material
        assert body.alpha_x == body.alpha_y == 0.2
        (tmp_path / f"{case}.toml").write_text(fitted.to_toml())
        assert sf.load_scene(tmp_path / f"{case}.toml") == fitted
