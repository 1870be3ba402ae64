"""The bias of a sensor's noise weight taken at the fit's noisy render (spacefit.fitting.noise_weight)."""

from types import SimpleNamespace

import numpy as np

from spacefit.fitting.noise_weight import WEIGHT_BIAS_WARN, expected_residuals, weight_bias, weight_bias_notes

FLOOR, GAIN, BIAS = 6.25 + 1.0 / 12.0, 0.5, 100.0  # read noise 5 e- at 0.5 DN per electron, rounding; 100 DN of bias


def problem(y: np.ndarray, terms=(FLOOR, GAIN, BIAS), blocks=()) -> SimpleNamespace:
    return SimpleNamespace(pixels=y.size, blocks=blocks, references=[y.reshape(-1, 1, 1)], noise_terms=(terms,))


def weighted(mu: np.ndarray, y: np.ndarray) -> np.ndarray:
    """The fit's residual: the difference over the noise the model predicts."""
    return (mu - y) / np.sqrt(FLOOR + GAIN * np.maximum(mu - BIAS, 0.0))


def test_the_expected_residual_of_a_noisy_model_matches_its_expectation_and_vanishes_below_the_bias():
    """A model equal to the data (1100 DN: 1000 above the bias) with Gaussian render noise of 50 DN: the weighted
    residual's expectation (Gauss-Hermite quadrature, 60 nodes) is -0.5 * 50^2 / (2 * 506.33^1.5) = -0.05485 to second
    order (within 3 %), and the estimate of it from the difference of two draws (200000 pixels) agrees within 3 %; at
    or below the bias (no shot noise) it is 0."""
    y0 = 1100.0
    nodes, weights = np.polynomial.hermite_e.hermegauss(60)
    exact = float(weights @ weighted(y0 + 50.0 * nodes, y0) / weights.sum())
    assert abs(exact / -0.05485 - 1.0) < 0.03
    rng = np.random.default_rng(1)
    y = np.full(200000, y0)
    e1, e2 = rng.normal(0.0, 50.0, (2, y.size))
    expected = expected_residuals(problem(y), weighted(y + e1, y), weighted(y + e2, y))
    assert abs(expected.mean() / exact - 1.0) < 0.03
    dark = np.full(1000, BIAS)
    assert not np.any(expected_residuals(problem(dark), rng.normal(size=1000), rng.normal(size=1000)))


def test_no_expected_residuals_without_a_sensor_or_pixel_residuals_and_the_bias_goes_through_the_step():
    """None without a sensor's noise or where the residuals are not the pixels (a pyramid loss); the bias is the
    linearisation's step of the expected residuals."""
    y = np.full(4, 1100.0)
    r, r_alt = np.array([1.0, -1.0, 2.0, 0.0]), np.zeros(4)
    assert expected_residuals(problem(y, None), r, r_alt) is None
    assert expected_residuals(problem(y), np.ones(6), np.zeros(6)) is None
    sigma = np.sqrt(FLOOR + GAIN * 1000.0)
    np.testing.assert_allclose(weight_bias(problem(y), r, r_alt, lambda d: np.array([d.sum()])),
                               [-GAIN * 0.5 * (r @ r) / (2.0 * sigma)])


def test_a_weight_bias_over_half_a_standard_error_is_warned():
    """kd's bias 0.003 on an error of 0.0046 (0.65 of it) is warned of, alpha_x's 0.0001 on 0.0005 is not."""
    notes = weight_bias_notes({"parts.legs.kd": 0.003, "parts.panels.alpha_x": 0.0001}, {"parts.legs.kd": 0.0046,
                                                                                         "parts.panels.alpha_x": 0.0005})
    assert WEIGHT_BIAS_WARN == 0.5
    assert notes == ["parts.legs.kd: the noise weights taken at the fit's noisy renders bias it by about +0.003 (+0.65 of its "
                     "standard error; not subtracted): the render noise is large where parts cover pixels partly; more samples "
                     "per pixel (FitRender) shrink it as 1/spp."]
