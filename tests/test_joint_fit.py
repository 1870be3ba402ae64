"""One fit of several kinds of observation: an image of a plate and a flat-plate light curve of the
same plate share its registered albedo ``parts.plate.kd``; the joint fit recovers it within its
error, and its error is smaller than either observation's alone (their information adds)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import small_scene, write_plate_obj

import spacefit as sf
from spacefit.fitting.observations.base import Block, MeasuredValues, ValueObservation
from spacefit.studies.lightcurve_observations import LightCurveObservations

TRUE_KD, START_KD = 0.3, 0.2


def unit(elevation_deg: np.ndarray, azimuth_deg: np.ndarray) -> np.ndarray:
    """Unit vectors above the plate (its normal +z) at these elevations and azimuths."""
    e, a = np.radians(elevation_deg), np.radians(azimuth_deg)
    return np.stack([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)], axis=1)


@pytest.fixture(scope="module")
def observations(tmp_path_factory: pytest.TempPathFactory) -> tuple[sf.Observation, sf.PlateLightCurve]:
    """The plate's image (16 x 16 px, radiance with a stated noise of 0.1 W m^-2 sr^-1) and its light
    curve (30 magnitudes, 0.05 mag), both simulated at kd 0.3 and started at kd 0.2."""
    mesh = write_plate_obj(tmp_path_factory.mktemp("joint") / "plate.obj")
    material = {"material": "white_paint"}
    sections = {"render": {"resolution": [16, 16], "spp": 8, "seed": 7}}
    truth = small_scene(mesh, {**material, "kd": TRUE_KD}, **sections)
    rng = np.random.default_rng(5)
    reference = np.asarray(sf.render(truth)) + 0.1 * rng.standard_normal((16, 16, 3))
    image = sf.Observation(small_scene(mesh, {**material, "kd": START_KD}, **sections), reference, sigma=0.1)
    n = 30
    sun, observer = unit(rng.uniform(20, 70, n), rng.uniform(0, 360, n)), unit(rng.uniform(20, 70, n), rng.uniform(0, 360, n))

    def curve(magnitude: np.ndarray, kd: float) -> sf.PlateLightCurve:
        data = LightCurveObservations(magnitude, np.full(n, 0.05), "AB532", sun, observer, np.full(n, 6e5), np.zeros(n, bool), None,
                                      "simulated")
        return sf.PlateLightCurve([sf.Plate("plate", 4.0, (0, 0, 1), sf.Lambert(kd))], data)

    exact = sf.predict_magnitudes(curve(np.zeros(n), TRUE_KD).plates, curve(np.zeros(n), TRUE_KD).observations)
    return image, curve(exact + 0.05 * rng.standard_normal(n), START_KD)


@pytest.fixture(scope="module")
def joint(observations: tuple[sf.Observation, sf.PlateLightCurve]) -> sf.FitResult:
    """The image and the light curve fitted together (kd free), once for the tests that read it."""
    return sf.fit(list(observations), ["parts.plate.kd"], max_steps=20)


def test_an_image_and_a_light_curve_share_a_part_and_their_information_adds(observations, joint):
    alone = [sf.fit(obs, ["parts.plate.kd"], max_steps=20) for obs in observations]
    for result in (*alone, joint):
        assert result.success and not result.goodness.misfit, sf.format_result(result)
        kd, error = result.values["parts.plate.kd"], result.stderr["parts.plate.kd"]
        assert abs(kd - TRUE_KD) < 3 * error, sf.format_result(result)
    errors = [result.stderr["parts.plate.kd"] for result in alone]
    # independent observations: 1 / sigma^2 adds, so the joint error is below each and near the combination
    assert joint.stderr["parts.plate.kd"] < min(errors)
    assert joint.stderr["parts.plate.kd"] == pytest.approx(1.0 / np.sqrt(sum(1.0 / e**2 for e in errors)), rel=0.2)
    # one result for both kinds: per observation, its goodness and its residuals (pixels, then irradiances)
    assert len(joint.observation_goodness) == 2 and joint.residuals[0].shape == (16, 16, 3) and joint.residuals[1].shape == (30,)
    assert joint.units[1] == "W m^-2" and joint.scene.parts["plate"].material.kd == pytest.approx(joint.values["parts.plate.kd"])
    assert "observation 1 (W m^-2 values): goodness of fit: chi^2/dof" in sf.format_result(joint)


class Line(ValueObservation):
    """A test-only kind: y = a + b t at times t, a and b the albedos of parts ``a`` and ``b``."""

    def __init__(self, t: np.ndarray, y: np.ndarray, sigma: float | None) -> None:
        self.t, self.y, self.sigma = t, y, sigma

    def parameters(self) -> tuple[str, ...]:
        return ("parts.a.kd", "parts.b.kd")

    def start(self, name: str) -> float:
        return 0.5

    def block(self, free: tuple[str, ...]) -> Block:
        def model(x: jax.Array, j: int) -> jax.Array:
            v = self.values_of(free, x)
            return v["parts.a.kd"] + v["parts.b.kd"] * jnp.asarray(self.t)

        sigma = None if self.sigma is None else np.full(self.t.size, self.sigma)
        return Block(MeasuredValues(self.y, sigma, False, "1", "a line"), model, free)


@pytest.mark.parametrize("sigma", [0.02, None])
def test_a_new_kind_is_fitted_with_the_closed_form_least_squares_errors(sigma):
    """A kind defined here, outside the package, is fitted by sf.fit: the estimates are ordinary least
    squares', and the errors (X^T X)^-1 sigma^2 with sigma stated, s^2 (X^T X)^-1 without (s^2 the
    residuals' mean square over n - 2), from the image fits' covariance code; chi^2 judged only with sigma."""
    rng = np.random.default_rng(2)
    t = np.linspace(0.0, 1.0, 40)
    y = 0.2 + 0.5 * t + 0.02 * rng.standard_normal(t.size)
    result = sf.fit(Line(t, y, sigma), ["parts.a.kd", "parts.b.kd"], max_steps=30)
    X = np.stack([np.ones_like(t), t], axis=1)
    beta = np.linalg.lstsq(X, y, rcond=None)[0]
    r = y - X @ beta
    scale = sigma**2 if sigma is not None else float(r @ r) / (t.size - 2)
    expected = np.sqrt(np.diag(scale * np.linalg.inv(X.T @ X)))
    np.testing.assert_allclose([result.values["parts.a.kd"], result.values["parts.b.kd"]], beta, atol=1e-6)
    np.testing.assert_allclose([result.stderr["parts.a.kd"], result.stderr["parts.b.kd"]], expected, rtol=1e-4)
    assert result.goodness.noise_known == (sigma is not None) and result.success, sf.format_result(result)


def test_a_joint_fit_writes_its_folder_with_each_kind_in_its_own_figure(observations, joint, tmp_path):
    """The report of an image and a light curve: the image's residuals in residuals.fits (one extension, the
    image's) and comparison.png, the light curve's observed and predicted magnitudes in observation1.png."""
    from astropy.io import fits

    out = sf.write_fit_report(tmp_path / "fit", joint, [observations[0].reference])
    assert {"fit.json", "uncertainty.json", "residuals.fits", "comparison.png", "observation1.png"} <= {
        p.name for p in out.iterdir()}
    with fits.open(out / "residuals.fits") as hdus:
        assert [h.name for h in hdus[1:]] == ["OBS0"]
        np.testing.assert_array_equal(np.moveaxis(hdus[1].data, 0, -1), joint.residuals[0].astype(np.float32))
