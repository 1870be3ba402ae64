"""Results to take away: the fitted scene as TOML and as a Mitsuba dict, errors and correlations as JSON."""

from __future__ import annotations

import dataclasses
import json
import math

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


def same_result(read: sf.FitResult, result: sf.FitResult) -> None:
    """Every saved field of ``result`` equal in ``read`` (NaN where NaN)."""
    assert read.names == result.names and read.status is result.status and read.success == result.success
    assert read.values == result.values and read.start == result.start
    assert np.array_equal(np.fromiter(read.stderr.values(), float), np.fromiter(result.stderr.values(), float), equal_nan=True)
    assert list(read.stderr) == list(result.names)
    assert np.array_equal(read.correlation, np.asarray(result.correlation, float), equal_nan=True)
    assert read.warnings == result.warnings and read.units == result.units and read.entries == result.entries
    assert read.goodness == result.goodness and read.observation_goodness == result.observation_goodness
    assert read.loss == result.loss and read.steps == result.steps and read.solver == result.solver
    assert [h["loss"] for h in read.history] == [h["loss"] for h in result.history]
    assert sf.format_result(read) == sf.format_result(dataclasses.replace(result, observations=()))


def test_a_fit_folder_reads_back_into_its_result(fitted):
    case, result, out = fitted
    for path in (out, out / "fit.json"):
        read = sf.read_fit(path)
        same_result(read, result)
        covariance = [r.correlation * np.outer(*[list(r.stderr.values())] * 2) for r in (read, result)]
        assert np.array_equal(*covariance) and np.all(np.isfinite(covariance[0]))
        assert read.scene == result.scene and read.renders == [] and read.observations == ()
        assert len(read.residuals) == 1 and read.residuals[0].dtype == np.float32
        assert np.allclose(read.residuals[0], result.residuals[0], equal_nan=True, rtol=1e-6, atol=1e-6 * np.nanmax(np.abs(result.residuals[0])))


def test_a_table_fit_reads_back_with_undetermined_and_missing_errors_apart(tmp_path):
    """A standard error not determined (inf) and one not estimated (NaN) are both null in strict JSON;
    they read back apart, and so do the verdict and a history loss that was NaN."""
    names = ("parts.body.kd", "parts.body.alpha")
    history = [{"step": 1, "loss": 2.0, "accepted": True, "loss_noise": float("nan"), "values": {"parts.body.kd": 0.3, "parts.body.alpha": 0.2}}]
    result = sf.FitResult(names, {"parts.body.kd": 0.4, "parts.body.alpha": 0.25}, {"parts.body.kd": float("inf"), "parts.body.alpha": float("nan")},
                          np.array([[1.0, np.nan], [np.nan, 1.0]]), False, sf.Status.AT_BOUND, ["kd at a bound"], history, [], 1.5, "lm",
                          "pixel", 3, 0.2, start={"parts.body.kd": 0.3, "parts.body.alpha": 0.2}, units=["sr^-1"], entries=((0,),))
    sf.write_table_fit(tmp_path / "table", result)
    read = sf.read_fit(tmp_path / "table")
    same_result(read, result)
    assert math.isinf(read.stderr["parts.body.kd"]) and math.isnan(read.stderr["parts.body.alpha"])
    assert math.isnan(read.history[0]["loss_noise"]) and read.status is sf.Status.AT_BOUND and read.scene is None


def test_reading_what_is_not_a_fit_is_one_line(tmp_path):
    with pytest.raises(sf.InputError, match="no fit.json there"):
        sf.read_fit(tmp_path)
    (tmp_path / "fit.json").write_text('{"names": ["parts.body.kd"]}')
    with pytest.raises(sf.InputError, match="has no 'values': it is not a fit's summary"):
        sf.read_fit(tmp_path)
    (tmp_path / "fit.json").write_text('{"names": [], "values": {}, "stderr": {}, "correlation": [], "success": false, "status": "x", "warnings": [], "history": [], "loss": 1, "solver": "lm", "loss_name": "pixel", "steps": 1, "wall_time_s": 1, "status_name": "GUESSED"}')
    with pytest.raises(sf.InputError, match="'GUESSED' is none of sf.Status's"):
        sf.read_fit(tmp_path / "fit.json")
    (tmp_path / "fit.json").write_text("not json")
    with pytest.raises(sf.InputError, match="is not JSON"):
        sf.read_fit(tmp_path)
