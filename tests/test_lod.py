"""Level of detail: the effective-roughness model of sub-pixel wrinkles and the automatic choice."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from spacefit.errors import InputError
from spacefit import Observation, fit
from spacefit.fitting.problem import fit_scene as _fit_scene
from spacefit.materials import Conductor, Lambert
from spacefit.render_job import render_to_folder
from spacefit.rendering.renderer import Renderer
from spacefit.scene.assembly import assemble
from spacefit.scene.toml import load_scene
from spacefit.scene.lod import effective_alpha, effective_material

from scripts import read_csv, run_script

LITERAL = Path(__file__).resolve().parents[1] / "data" / "scenes" / "thesis-literal.toml"
GENTLE = Path(__file__).resolve().parents[1] / "data" / "scenes" / "gentle-wrinkles.toml"
SMALL = ["render.resolution=[48, 48]", "camera.pixel_pitch_mm=50", "render.spp=16"]


def test_effective_roughness_adds_slope_variance():
    assert effective_alpha(0.1, 0.0) == pytest.approx(0.1)
    assert effective_alpha(0.0, 0.2) == pytest.approx(np.sqrt(2) * 0.2)
    widened = effective_material(Conductor(2.0, 0.1, 0.1, 0.05), 0.2)
    assert widened.alpha_x == pytest.approx(np.sqrt(0.01 + 0.08)) and widened.alpha_y == pytest.approx(np.sqrt(0.0025 + 0.08))
    assert effective_material(Conductor(2.0, 0.1, 0.1, 0.1), 1.0) is None  # alpha would exceed 1
    assert effective_material(Lambert(0.2), 0.1) is None


@pytest.mark.parametrize(("distance", "model"), [(15.0, "geometry"), (800.0, "effective")])
def test_auto_model_follows_the_pixel_footprint(distance, model):
    a = assemble(load_scene(GENTLE, [f"camera.position_m=[0, 0, {distance}]", "wrinkles.model='auto'"]))
    assert a.lod["body"].model == model
    assert (len(a.faces("body")) == 12) == (model == "effective")


def test_thesis_literal_wrinkles_are_too_steep_for_an_effective_roughness():
    far = SMALL + ["camera.position_m=[0, 0, 2000]", "camera.pixel_pitch_mm=1", "wrinkles.model='auto'"]
    with pytest.warns(UserWarning, match="fold over"):
        a = assemble(load_scene(LITERAL, far))
    assert a.lod["body"].model == "geometry" and "steep" in a.lod["body"].reason
    with pytest.raises(InputError, match="wrinkles.model"):
        assemble(load_scene(LITERAL, SMALL + ["wrinkles.model='effective'"]))
    farther = SMALL + ["camera.position_m=[0, 0, 4000]", "camera.pixel_pitch_mm=1"]  # a pixel 5.7 L
    assert assemble(load_scene(None, farther)).lod["body"].model == "effective"  # the default's crumpled foil


def test_sidecar_records_the_choice(tmp_path):
    scene = load_scene(GENTLE, SMALL + ["camera.position_m=[0, 0, 400]", "wrinkles.model='auto'"])
    render_to_folder(scene, tmp_path / "run", quiet=True)
    sidecar = json.loads((tmp_path / "run" / "render.json").read_text())
    choice = sidecar["wrinkle_model"]["body"]
    assert choice["model"] == "effective" and choice["footprint_over_L"] >= 1.0 and choice["effective_alpha"] > 0.14


def test_lod_study_shape(tmp_path):
    """The study at its reduced size: the automatic choice switches with range, errors and costs recorded."""
    run_script("lod_study", "--out", str(tmp_path), "--quick", "--ranges", "15", "800", "--spp", "8")
    rows = [{k: v if k in ("auto_model", "model") else float(v) for k, v in row.items()} for row in read_csv(tmp_path / "lod.csv")]
    assert [r["auto_model"] for r in rows] == ["geometry", "effective"]
    assert all(r["error_effective"] > 0 and r["noise_geometry"] > 0 and r["noise_effective"] > 0 for r in rows)
    assert all(0 <= r["bias_effective"] <= min(r["error_effective"], r["bias_upper"]) for r in rows)
    assert (tmp_path / "lod.csv").exists() and (tmp_path / "lod.png").stat().st_size > 0


def test_effective_model_keeps_the_geometry_flux():
    """Beckmann with alpha^2 = alpha0^2 + 2 s^2 reflects the wrinkled body's total radiance (a GGX of
    the same alpha rendered 27-33 % darker); the lander at 64 x 64 px from 40 m, 512 spp (flux noise about 1 %)."""
    base = ["camera.position_m=[0, 0, 40]", "render.resolution=[64, 64]", "camera.pixel_pitch_mm=37.5",
                     "render.spp=512"]
    flux = {m: Renderer(assemble(load_scene(GENTLE, base + [f"wrinkles.model='{m}'"]))).render(seed=1).sum()
            for m in ("geometry", "effective")}
    assert flux["effective"] == pytest.approx(flux["geometry"], rel=0.05)


def test_fits_render_the_geometry_and_refuse_merged_parameters():
    scene = load_scene(GENTLE, SMALL + ["wrinkles.model='auto'", "camera.position_m=[0, 0, 400]"])
    assert _fit_scene(scene, ["parts.body.alpha"]).wrinkles.model == "geometry"
    effective = scene.replace(wrinkles=dataclasses.replace(scene.wrinkles, model="effective"))
    reference = np.zeros((48, 48, 3))
    for free in (["wrinkles.D"], ["parts.body.alpha"]):
        with pytest.raises(InputError, match="effective"):
            fit(Observation(effective, reference), free)
    assert _fit_scene(effective, ["parts.legs.kd"]) is effective
