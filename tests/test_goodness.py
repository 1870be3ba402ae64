"""Goodness of fit and the fit's verdicts: chi^2 / dof against its expected range, misfit, no progress, at bound."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import small_scene, write_sphere_obj

import spacefit as sf
from spacefit.fitting.goodness import MISFIT_FLOOR, MISFIT_SIGMAS, goodness, part_chi2
from spacefit.fitting.loop import verdict
from spacefit.rendering.renderer import PartImage
from spacefit.scene.assembly import assemble

N = 40_000
RENDER_SIGMA = 0.5  # the fit's own render noise, in units of the observation's noise


def residuals(misfit: float = 0.0, zeros: int = 0, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Residuals of one point rendered with two seeds: the observation's unit noise (shared), each
    render's own noise (independent), a model error ``misfit`` (shared), and ``zeros`` values left out."""
    rng = np.random.default_rng(seed)
    shared = rng.normal(0.0, 1.0, N) + misfit
    r, r_alt = (shared + rng.normal(0.0, RENDER_SIGMA, N) for _ in range(2))
    return np.concatenate([r, np.zeros(zeros)]), np.concatenate([r_alt, np.zeros(zeros)])


def test_chi2_of_a_correct_model_is_one_plus_its_render_noise_and_no_misfit():
    g = goodness(*residuals(zeros=500), n_free=3, noise_known=True)
    assert g.values == N and g.dof == N - 3  # the values left out count for nothing
    assert g.expected_spread == pytest.approx(np.sqrt(2.0 / (N - 3)))
    assert g.render_noise == pytest.approx(RENDER_SIGMA**2, rel=0.03)
    assert g.chi2_dof == pytest.approx(1.0 + RENDER_SIGMA**2, abs=4 * g.expected_spread)
    assert g.limit == pytest.approx(1.0 + g.render_noise + max(MISFIT_SIGMAS * g.expected_spread, MISFIT_FLOOR))
    assert not g.misfit and "within the expected range" in g.line()


def test_a_model_error_beyond_the_margin_is_a_misfit():
    # a shared error of 0.45 sigma adds 0.2 to chi^2 / dof: twice the floor
    g = goodness(*residuals(misfit=0.45), n_free=3, noise_known=True)
    assert g.chi2_dof == pytest.approx(1.0 + RENDER_SIGMA**2 + 0.45**2, abs=0.03)
    assert g.misfit and "MISFIT" in g.line()
    # dof counts: a few values with 3 free parameters leave 2 degrees of freedom
    few = goodness(np.array([1.0, -1.0, 0.5, 0.5, 0.0]), np.array([1.0, -1.0, 0.5, 0.5, 0.0]), n_free=2, noise_known=True)
    assert few.values == 4 and few.dof == 2 and few.chi2_dof == pytest.approx(2.5 / 2)


def test_without_a_known_noise_the_spread_and_correlation_are_reported_against_the_render_noise():
    rng = np.random.default_rng(1)
    shape = (60, 60, 3)
    white = rng.normal(0.0, 1.0, shape)
    smooth = np.repeat(np.repeat(rng.normal(0.0, 1.0, (6, 6, 1)), 10, axis=0), 10, axis=1) * np.ones(shape)
    for structure, correlated in ((0.0, False), (3.0, True)):
        r = (white + structure * smooth).ravel()
        r_alt = (white + structure * smooth + rng.normal(0.0, 1.0, shape)).ravel()
        g = goodness(r, r_alt, n_free=1, noise_known=False, shapes=[shape])
        assert np.isnan(g.chi2_dof) and not g.misfit and "no verdict" in g.line()
        assert g.spread == pytest.approx((1.0 + structure**2) / 0.5, rel=0.15)
        assert abs(g.render_correlation) < 0.1
        assert (g.correlation > 0.8) if correlated else (abs(g.correlation) < 0.1), g.correlation


def test_part_chi2_is_the_mean_square_of_each_parts_values():
    parts = PartImage(np.array([[0, 0], [1, -1]], dtype=np.int16), ("a", "b"))
    r = np.array([[1.0, 3.0], [2.0, 5.0]])[..., None]
    used = np.array([[True, False], [True, True]])
    rows = part_chi2(r, r, parts, used, noise=1.0)
    assert rows == {"a": 1.0, "b": 4.0, "target": 2.5}


@pytest.mark.parametrize(
    ("solver_status", "moved", "at_bound", "misfit", "expected"),
    [
        (sf.Status.CONVERGED, True, False, False, sf.Status.CONVERGED),
        (sf.Status.NOISE_FLOOR, False, False, False, sf.Status.NO_PROGRESS),  # never "converged" without a step
        (sf.Status.CONVERGED, False, True, True, sf.Status.NO_PROGRESS),
        (sf.Status.MAX_STEPS, True, True, True, sf.Status.AT_BOUND),
        (sf.Status.NOISE_FLOOR, True, False, True, sf.Status.MISFIT),
        # stopped because no trial step lowered the loss: a success only with the residuals at the noise
        (sf.Status.NO_BETTER_POINT, True, False, True, sf.Status.MISFIT),
        (sf.Status.NO_BETTER_POINT, True, False, False, sf.Status.NO_BETTER_POINT),
        (sf.Status.NO_BETTER_POINT, True, True, False, sf.Status.AT_BOUND),
        (sf.Status.NONFINITE, False, True, True, sf.Status.NONFINITE),
    ],
)
def test_verdicts_and_their_precedence(solver_status, moved, at_bound, misfit, expected):
    status = verdict(solver_status, moved, at_bound, misfit)
    assert status is expected
    assert status.success == (expected in (sf.Status.CONVERGED, sf.Status.NOISE_FLOOR, sf.Status.NO_BETTER_POINT))


# The panels case at 32 x 32 px (same field of view), 4 spp (the truth at 64), observed by a sensor (the noise known).
TINY = {"render.resolution": [32, 32], "camera.pixel_pitch_mm": 75.0, "render.spp": 4}
SENSOR = sf.Sensor(exposure_time_s=1e-8, psf_sigma_px=1.0, full_well_electrons=None, bit_depth=16)


@pytest.fixture(scope="module")
def sensor_fits():
    """Materials-only fits of the observation of the truth, and of the target turned 1 deg (a pose the
    model does not have)."""
    case = sf.load_case("panels").with_values(TINY)
    intrinsics = assemble(case.scene()).intrinsics
    out = {}
    for turn in (0.0, 1.0):
        truth = np.asarray(sf.render(case.truth_scene.with_values({"render.spp": 64, "target.attitude_deg": [turn, 0.0, 0.0]})))
        dn = sf.observe(truth, SENSOR, intrinsics, seed=3).astype(float)
        out[turn] = sf.fit(sf.Observation(case.scene(), dn, sensor=SENSOR), list(case.free), start=case.start, max_steps=15)
    return case, out


def test_a_correct_model_is_within_the_expected_range(sensor_fits):
    _, fits = sensor_fits
    result = fits[0.0]
    g = result.goodness
    assert g.noise_known and g.dof == g.values - 3 and not g.misfit
    assert abs(g.chi2_dof - (1.0 + g.render_noise)) < 5 * g.expected_spread, g
    assert result.success and sf.format_result(result).startswith("converged")
    assert result.uncertainty()["stderr_valid"] and not result.stderr_note
    target = result.parts[0]["target"]["chi2_per_value"]
    assert abs(target - (1.0 + g.render_noise)) < 0.5, result.parts


def test_a_missing_nuisance_is_a_misfit_and_says_so_first(sensor_fits):
    """The target turned 1 deg, only the materials free: the solver converges, the verdict is a misfit."""
    case, fits = sensor_fits
    result = fits[1.0]
    assert result.status is sf.Status.MISFIT and not result.success
    assert result.goodness.chi2_dof > 1.5 * result.goodness.limit, result.goodness
    assert sf.format_result(result).splitlines()[0].startswith("misfit:")
    assert "[misfit: the errors assume a correct model" in sf.format_result(result)
    data = result.uncertainty()
    assert data["stderr_valid"] is False and data["stderr_note"].startswith("misfit")
    # the misfit's errors are too small indeed: some value lies more than 3 of them off the truth
    assert max(abs(result.values[n] - v) / result.stderr[n] for n, v in case.truth.items()) > 3.0


def test_a_fit_where_every_step_is_rejected_makes_no_progress(tmp_path):
    """The sun behind the target: kd changes no pixel, every trial step leaves the loss where it was."""
    mesh = write_sphere_obj(tmp_path / "sphere.obj", subdivisions=2)
    lit = small_scene(mesh, {"material": "white_paint", "kd": 0.5}, camera={"pixel_pitch_mm": 0.5}, render={"spp": 4})
    behind = lit.with_values({"sun.direction": [0.0, 0.0, 1.0]})
    result = sf.fit(sf.Observation(behind, np.asarray(sf.render(lit)), sigma=0.01), ["parts.sphere.kd"], max_steps=5)
    assert not any(h["accepted"] for h in result.history[1:])
    assert result.status is sf.Status.NO_PROGRESS and not result.success
    assert result.values == result.start
    assert "converged" not in sf.format_result(result).splitlines()[0]
