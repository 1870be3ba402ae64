"""Sensitivities: derivative images against central finite differences of plain renders (cosine and
relative error per parameter), standard errors, normalisation, and the flag on a derivative that is
only noise."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from helpers import small_scene, write_sphere_obj

import spacefit as sf
from spacefit.scene.parameters import scene_with_values


def sphere_scene(tmp_path: Path, spp: int = 4) -> sf.Scene:
    return small_scene(write_sphere_obj(tmp_path / "sphere.obj", subdivisions=3), {"material": "white_paint", "kd": 0.4},
                       render={"spp": spp}, camera={"focal_length_mm": 5.0}, sun={"direction": [-0.5, 0.0, -0.75**0.5]})


def central_difference(scene: sf.Scene, name: str, step: float) -> np.ndarray:
    """(image(p + step) - image(p - step)) / (2 step), both renders with the same seed (common random numbers)."""
    from spacefit.scene.parameters import scene_value

    p = scene_value(scene, name)
    return (sf.render(scene_with_values(scene, {name: p + step})) - sf.render(scene_with_values(scene, {name: p - step}))) / (2 * step)


@pytest.fixture(scope="module")
def result(tmp_path_factory):
    scene = sphere_scene(tmp_path_factory.mktemp("sens"), spp=16)
    names = ["parts.sphere.kd", "sun.elevation_deg", "target.position_x_m", "target.attitude_x_deg"]
    return scene, sf.sensitivity(scene, names, seeds=4, quiet=True)


# (parameter, step of the reference difference, least cosine, largest relative error): a translation's
# derivative lives on the limb's pixels only, where 16 spp leave more noise (measured 0.988, 0.17).
CASES = [("parts.sphere.kd", 0.05, 0.99, 0.1), ("sun.elevation_deg", 2.0, 0.99, 0.1), ("target.position_x_m", 0.05, 0.97, 0.3)]


@pytest.mark.parametrize(("name", "step", "cosine_min", "error_max"), CASES)
def test_derivative_images_match_central_differences(result, name, step, cosine_min, error_max):
    """AD (albedo) and finite differences with common random numbers (sun, position) against plain renders."""
    scene, sens = result
    reference = central_difference(scene.with_values({"render.spp": 32}), name, step).mean(axis=-1)
    d = sens.derivative[sens.names.index(name)].mean(axis=-1)
    cosine = float((d * reference).sum() / np.linalg.norm(d) / np.linalg.norm(reference))
    relative_error = float(np.linalg.norm(d - reference) / np.linalg.norm(reference))
    assert cosine > cosine_min and relative_error < error_max, (cosine, relative_error)
    assert sens.resolved[sens.names.index(name)].all()


def test_normalised_sensitivities_and_errors(result):
    _, sens = result
    kd, el = sens.names.index("parts.sphere.kd"), sens.names.index("sun.elevation_deg")
    target = sens.regions.index("target")
    # the image is linear in the albedo: (kd / L) dL/dkd = 1
    assert sens.sensitivity[kd, target] == pytest.approx(1.0, abs=5 * sens.sensitivity_se[kd, target] + 0.005)
    assert sens.normalised_units == {"parts.sphere.kd": "1", "sun.elevation_deg": "rad^-1", "target.position_x_m": "m^-1",
                                     "target.attitude_x_deg": "rad^-1"}
    # per radian is 180 / pi times per degree
    per_degree = sens.d_mean_radiance[el, target] / sens.mean_radiance[target]
    assert sens.sensitivity[el, target] == pytest.approx(per_degree * 180 / np.pi, rel=0.01)
    assert np.all(sens.d_mean_radiance_se > 0) and np.all(np.isfinite(sens.sensitivity_se))
    ds = sens.to_dataset()
    assert ds.d_mean_radiance.dims == ("parameter", "region") and ds.derivative.dims == ("parameter", "y", "x", "channel")


def test_a_derivative_made_of_noise_is_flagged(result):
    """A sphere turned about its centre looks the same: d(mean radiance)/d(attitude) is only noise
    (Monte Carlo and the facets), and must be flagged, in the arrays and in the table."""
    _, sens = result
    i = sens.names.index("target.attitude_x_deg")
    assert not sens.resolved[i].any()
    assert np.all(np.abs(sens.d_mean_radiance[i]) < sens.t * sens.d_mean_radiance_se[i])
    rows = [line for line in sens.table().splitlines() if line.startswith("target.attitude_x_deg")]
    assert rows and all("UNRESOLVED" in row and "+-" in row for row in rows)
    assert not any("UNRESOLVED" in line for line in sens.table().splitlines() if line.startswith("parts.sphere.kd"))
    assert len(sens.figure()) == len(sens.names) + 1


def test_bad_input_names_the_argument(tmp_path):
    scene = sphere_scene(tmp_path)
    with pytest.raises(sf.InputError, match="names"):
        sf.sensitivity(scene, ["parts.sphere.alpha_x"], quiet=True)
    with pytest.raises(sf.InputError, match="seeds"):
        sf.sensitivity(scene, ["parts.sphere.kd"], seeds=1, quiet=True)


def test_seeds_past_mitsubas_range_are_refused_before_their_pairs_are_made(tmp_path):
    """2**70 estimates (a fuzz test's) filled the memory making their seed pairs; the last pair's seeds, render.seed + 2 k
    and + 2 k + 1, must be Mitsuba's (below 2^31): refused by name, with the largest count allowed."""
    scene = sphere_scene(tmp_path)
    high = scene.with_values({"render.seed": 2**31 - 5})
    with pytest.raises(sf.InputError, match=r"`seeds` must be an integer in \[2, 2\].*got 3"):
        sf.sensitivity(high, ["parts.sphere.kd"], seeds=3, quiet=True)
    with pytest.raises(sf.InputError, match=r"`seeds` must be an integer in \[2, 1073741823\].*got 1180591620717411303424"):
        sf.sensitivity(scene, ["parts.sphere.kd"], seeds=2**70, quiet=True)


def test_a_sweep_stores_derivatives_per_point(tmp_path):
    scene = sphere_scene(tmp_path)
    ds = sf.sweep(scene, {"sun.elevation_deg": [40.0, 80.0]}, derivatives=["parts.sphere.kd", "target.attitude_x_deg"],
                  quiet=True).load()
    assert ds.sensitivity.dims == ("sun.elevation_deg", "parameter", "region")
    assert list(ds.normalised_unit.values) == ["1", "rad^-1"] and list(ds.parameter_unit.values) == ["1", "deg"]
    np.testing.assert_allclose(ds.sensitivity.sel(parameter="parts.sphere.kd").values, 1.0, atol=0.01)
    assert ds.resolved.sel(parameter="parts.sphere.kd").all() and not ds.resolved.sel(parameter="target.attitude_x_deg").any()
