"""Goodness of fit and the fit's verdicts: chi^2 / dof against its expected range, misfit, no progress, at bound."""

from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace

import jax.numpy as jnp
import numpy as np
import pytest
from astropy.io import fits
from helpers import small_scene, write_sphere_obj

import spacefit as sf
from spacefit.cli import exit_code
from spacefit.formation import expected_dn, noise_variance_dn
from spacefit.fitting.goodness import MAX_JUDGED_RENDER_NOISE, REFERENCE_RENDER_NOISE, RESIDUALS, MAX_VERDICT_FACTOR, MISFIT_FLOOR, MISFIT_SIGMAS, VERDICT_RENDER_NOISE, goodness, part_chi2, verdict_factor
from spacefit.fitting.goodness import _neighbours
from spacefit.fitting.judging import _mean_and_noise, affordable, judged_goodness, per_observation
from spacefit.fitting.status import verdict
from spacefit.fitting.problem import setup
from spacefit.fitting.stopping import REJECTED_PATIENCE
from spacefit.scene.sections import MAX_SPP
from spacefit.rendering.parts import PartImage
from spacefit.scene.assembly import assemble

N = 40_000
RENDER_SIGMA = 0.5  # the fit's own render noise, in units of the observation's noise


def residuals(misfit: float = 0.0, zeros: int = 0, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Residuals of one point rendered with two seeds, as the first render's and a draw of its render
    noise: the observation's unit noise (shared), each render's own noise (independent), a model error
    ``misfit`` (shared), and ``zeros`` values left out."""
    rng = np.random.default_rng(seed)
    shared = rng.normal(0.0, 1.0, N) + misfit
    r, r_alt = (np.concatenate([shared + rng.normal(0.0, RENDER_SIGMA, N), np.zeros(zeros)]) for _ in range(2))
    return r, (r - r_alt) / np.sqrt(2.0)


def test_chi2_of_a_correct_model_is_one_plus_its_render_noise_and_no_misfit():
    g = goodness(*residuals(zeros=500), n_free=3, noise_known=True)
    assert g.values == N and g.dof == N - 3  # the values left out count for nothing
    # normal render noise: the squares' variance 2 v^2, chi^2's spread and the measured v's error
    assert g.expected_spread == pytest.approx(np.sqrt((2.0 + 4.0 * g.render_noise + 4.0 * g.render_noise**2) / (N - 3)), rel=0.03)
    assert g.render_noise == pytest.approx(RENDER_SIGMA**2, rel=0.03)
    assert g.chi2_dof == pytest.approx(1.0 + RENDER_SIGMA**2, abs=4 * g.expected_spread)
    assert g.limit == pytest.approx(1.0 + g.render_noise + max(MISFIT_SIGMAS * g.expected_spread, MISFIT_FLOOR))
    assert not g.misfit and "within the expected range" in g.line()


def test_with_the_noise_known_every_fitted_value_counts_a_zero_residual_too():
    """A sensor's integer sky DN equal to the model's bias gives r = 0: a value, not a masked one."""
    r, noise = residuals(zeros=500)
    fitted = np.ones(r.size, dtype=bool)
    fitted[-100:] = False  # masked out
    assert goodness(r, noise, n_free=3, noise_known=True, fitted=fitted).values == N + 400
    assert goodness(r, noise, n_free=3, noise_known=False, fitted=fitted).values == N  # no noise: black sky is nothing


def test_a_model_error_beyond_the_margin_is_a_misfit():
    # a shared error of 0.45 sigma adds 0.2 to chi^2 / dof: twice the floor
    g = goodness(*residuals(misfit=0.45), n_free=3, noise_known=True)
    assert g.chi2_dof == pytest.approx(1.0 + RENDER_SIGMA**2 + 0.45**2, abs=0.03)
    assert g.misfit and "MISFIT" in g.line()
    # dof counts: a few values with 3 free parameters leave 2 degrees of freedom
    few = goodness(np.array([1.0, -1.0, 0.5, 0.5, 0.0]), np.array([1.0, -1.0, 0.5, 0.5, 0.0]), n_free=2, noise_known=True)
    assert few.values == 4 and few.dof == 2 and few.chi2_dof == pytest.approx(2.5 / 2)


def test_a_model_whose_render_noise_exceeds_the_datas_is_not_judged():
    """Planted: 8 values whose model misses the data by 60 of their sigmas, judged on a model whose own
    render noise has a variance of 1771 data variances (the light curve of issue 34 called chi^2/dof
    5691 "within the expected range" of 1 + 1771). It is not judged, and says so; the same misfit
    judged on a model with a tenth of the data's noise is a misfit."""
    rng = np.random.default_rng(3)
    data = rng.normal(0.0, 1.0, 8) + 60.0
    for render_sigma, judged in ((np.sqrt(1771.0), False), (np.sqrt(0.1), True)):
        r_one, r_two = (data + rng.normal(0.0, render_sigma, 8) for _ in range(2))
        g = goodness((r_one + r_two) / 2, (r_one - r_two) / 2, n_free=3, noise_known=True)
        assert g.judged is judged and (g.render_noise > MAX_JUDGED_RENDER_NOISE) is not judged
        assert g.misfit is judged  # a misfit only where it could be judged
        assert ("CANNOT JUDGE" in g.line()) is not judged and ("within the expected range" not in g.line())
    assert verdict(sf.Status.CONVERGED, True, False, False, True) is sf.Status.UNJUDGED
    assert verdict(sf.Status.CONVERGED, True, True, False, True) is sf.Status.AT_BOUND
    assert not sf.Status.UNJUDGED.success and exit_code(sf.Status.UNJUDGED) == 9


@pytest.mark.parametrize("misfit", [0.0, 0.8])
def test_without_a_stated_noise_a_rendered_references_own_render_noise_is_the_noise_judged(misfit):
    """Radiance residuals (W m^-2 sr^-1, no sensor): a reference rendered at half the fit's samples has
    twice its render noise, the data's noise of the verdict. A correct model's chi^2 / dof in its units
    is 1 + v / v_ref = 1.5 and within range; a planted model error of 0.8 of the reference's noise
    sigma (chi^2 + 0.64) is a misfit. A real observation (no render samples) has its noise from the
    residuals, s over n - p, and no chi^2."""
    rng, model_sigma = np.random.default_rng(5), 0.004
    reference = rng.normal(0.0, model_sigma * np.sqrt(2.0), N) + misfit * model_sigma * np.sqrt(2.0)
    r_one, r_two = (reference + rng.normal(0.0, model_sigma, N) for _ in range(2))
    g = goodness(r_one, (r_one - r_two) / np.sqrt(2.0), n_free=3, noise_known=False, reference_ratio=2.0)
    assert g.basis == REFERENCE_RENDER_NOISE and not g.noise_known and g.judged
    assert g.noise_sigma == pytest.approx(model_sigma * np.sqrt(2.0), rel=0.02)
    assert g.chi2_dof == pytest.approx(1.5 + misfit**2, abs=0.05) and g.misfit is (misfit > 0)
    assert "estimated as the references' render noise" in g.line() and ("MISFIT" in g.line()) is (misfit > 0)
    real = goodness(r_one, (r_one - r_two) / np.sqrt(2.0), n_free=3, noise_known=False)
    assert real.basis == RESIDUALS and np.isnan(real.chi2_dof) and not real.misfit
    assert real.noise_sigma == pytest.approx(np.sqrt(np.sum(r_one**2) / (N - 3)), rel=1e-12)
    assert "estimated from the residuals (s^2 over n - p)" in real.line()


def test_without_a_known_noise_the_spread_and_correlation_are_reported_against_the_render_noise():
    rng = np.random.default_rng(1)
    shape = (60, 60, 3)
    white = rng.normal(0.0, 1.0, shape)
    smooth = np.repeat(np.repeat(rng.normal(0.0, 1.0, (6, 6, 1)), 10, axis=0), 10, axis=1) * np.ones(shape)
    for structure, correlated in ((0.0, False), (3.0, True)):
        r = (white + structure * smooth).ravel()
        r_alt = (white + structure * smooth + rng.normal(0.0, 1.0, shape)).ravel()
        g = goodness(r, (r - r_alt) / np.sqrt(2.0), n_free=1, noise_known=False, shapes=[shape])
        assert np.isnan(g.chi2_dof) and not g.misfit and "no verdict" in g.line()
        assert g.spread == pytest.approx((1.0 + structure**2) / 0.5, rel=0.15)
        assert abs(g.render_correlation) < 0.1
        assert (g.correlation > 0.8) if correlated else (abs(g.correlation) < 0.1), g.correlation


def test_part_chi2_is_the_mean_square_of_each_parts_values():
    parts = PartImage(np.array([[0, 0], [1, -1]], dtype=np.int16), ("a", "b"))
    r = np.array([[1.0, 3.0], [2.0, 5.0]])[..., None]
    used = np.array([[True, False], [True, True]])
    rows = part_chi2(r, r, parts, used, scale=1.0)
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


def test_a_status_in_a_few_words_says_its_verdict_first():
    """Status.headline, a panel's title: the description's first clause, and the name in words where it says more."""
    assert {s: s.headline for s in sf.Status} == {
        sf.Status.CONVERGED: "converged", sf.Status.NOISE_FLOOR: "converged: noise floor",
        sf.Status.NO_BETTER_POINT: "converged: no better point", sf.Status.MAX_STEPS: "stopped: max steps",
        sf.Status.NO_PROGRESS: "failed: no progress", sf.Status.AT_BOUND: "failed: at bound", sf.Status.MISFIT: "misfit",
        sf.Status.UNJUDGED: "not judged", sf.Status.UNSETTLED: "not settled", sf.Status.UNSTEPPED: "not stepped",
        sf.Status.DIVERGED: "failed: diverged", sf.Status.NONFINITE: "failed: nonfinite", sf.Status.FAILED: "failed",
        sf.Status.INTERRUPTED: "stopped: interrupted", sf.Status.TERMINATED: "stopped: terminated"}


# The panels case at 32 x 32 px (same field of view), fitted at 16 spp, observed by a bright calibrated
# sensor (its noise below the fit's render noise: v about 0.9), the references rendered at 1024 spp.
FIT_SPP = 16
TINY = {"render.resolution": [32, 32], "camera.pixel_pitch_mm": 75.0, "render.spp": FIT_SPP}
SENSOR = sf.Sensor(radiometric_scale_dn_per_w_m2_sr=10000.0, gain_dn_per_electron=0.5, bias_dn=100.0, read_noise_electrons=5.0,
                   bit_depth=16, full_well_electrons=None, diffraction=False, psf_sigma_px=1.0)
REFERENCE_SPP = 1024


@pytest.fixture(scope="module")
def sensor_fits(tmp_path_factory):
    """Materials-only fits of the observation of the truth, and of the target turned 1 deg (a pose the
    model does not have), each observation a FITS file that says its render's samples (RENDSPP)."""
    case = sf.load_case("panels").with_values(TINY)
    intrinsics = assemble(case.scene()).intrinsics
    folder = tmp_path_factory.mktemp("observations")
    out, observations = {}, {}
    for turn in (0.0, 1.0):
        truth = case.truth_scene.with_values({"render.spp": REFERENCE_SPP, "target.attitude_deg": [turn, 0.0, 0.0]})
        path = folder / f"turned{turn:g}.fits"
        sf.write_observation(path, sf.observe(np.asarray(sf.render(truth)), SENSOR, intrinsics, seed=3), SENSOR, render_spp=REFERENCE_SPP)
        observations[turn] = sf.Observation.from_file(path, case.scene())
        out[turn] = sf.fit(observations[turn], list(case.free), start=case.start, max_steps=15)
    return case, out, observations


def old_rule(obs, result) -> tuple[float, float]:
    """chi^2 / dof and its limit by the rule before the verdict render: the fit's own render, the noise
    sigma at its DN, the reference taken as real, the spread sqrt(2 / dof)."""
    s = setup(obs, list(result.names), start=result.values)
    x = jnp.asarray(s.x0)
    r, r_alt = np.asarray(s.problem.residual_x(x)), np.asarray(s.problem.residual_x_independent(x))
    g = goodness(r, (r - r_alt) / np.sqrt(2.0), len(x), True)
    return g.chi2_dof, 1.0 + g.render_noise + max(MISFIT_SIGMAS * np.sqrt(2.0 / g.dof), MISFIT_FLOOR)


def test_a_correct_model_at_few_samples_is_within_the_expected_range(sensor_fits):
    _, results, observations = sensor_fits
    result = results[0.0]
    g = result.goodness
    chi2_dof, limit = old_rule(observations[0.0], result)
    assert chi2_dof > limit  # the old rule: the fit's own render condemns the correct model
    assert g.noise_known and g.dof == g.values - 3 and not g.misfit
    assert g.samples_factor >= 8 and g.verdict_spp == (FIT_SPP * g.samples_factor,) and g.render_noise < 2 * VERDICT_RENDER_NOISE
    assert abs(g.chi2_dof - (1.0 + g.render_noise + g.reference_noise)) < 5 * g.expected_spread, g
    assert result.success and sf.format_result(result).startswith("converged")
    assert result.uncertainty()["stderr_valid"] and not result.stderr_note
    target = result.parts[0]["target"]["chi2_per_value"]
    assert abs(target - (1.0 + g.render_noise + g.reference_noise)) < 0.5, result.parts
    # what it could hide, beside the verdict: the rule's fraction of the signal, from the model's DN above the bias
    model = np.asarray(result.renders[0], dtype=float)
    snr = (model - SENSOR.bias_dn) / np.sqrt(np.asarray(noise_variance_dn(model, SENSOR)))
    assert g.detectable == pytest.approx(np.sqrt(g.margin * g.dof / np.sum(snr**2)), rel=0.05)
    assert f"below {100 * g.detectable:.2g} % of the signal" in sf.format_result(result).splitlines()[1]
    assert result.to_dict()["goodness"]["detectable"] == g.detectable and result.observation_goodness[0].detectable == pytest.approx(g.detectable)


def test_the_reference_render_noise_is_read_from_the_file_and_counted(sensor_fits):
    _, results, _ = sensor_fits
    g = results[0.0].goodness
    assert g.reference_spp == (REFERENCE_SPP,)
    assert g.reference_noise == pytest.approx(g.render_noise * g.verdict_spp[0] / REFERENCE_SPP) and g.reference_noise > 0
    assert f"references rendered at {REFERENCE_SPP} spp" in g.line() and f"render noise at {g.verdict_spp[0]} spp" in g.line()
    assert json.loads(json.dumps(results[0.0].to_dict()["goodness"]))["verdict_spp"] == [FIT_SPP * g.samples_factor]


def test_a_missing_nuisance_is_a_misfit_and_says_so_first(sensor_fits):
    """The target turned 1 deg, only the materials free: the solver converges, the verdict is a misfit."""
    case, results, _ = sensor_fits
    result = results[1.0]
    assert result.status is sf.Status.MISFIT and not result.success
    assert result.goodness.chi2_dof > 1.5 * result.goodness.limit, result.goodness
    assert sf.format_result(result).splitlines()[0].startswith("misfit:")
    assert "[misfit: the errors assume a correct model" in sf.format_result(result)
    data = result.uncertainty()
    assert data["stderr_valid"] is False and data["stderr_note"].startswith("misfit")
    # the misfit's errors are too small indeed: some value lies more than 3 of them off the truth
    assert max(abs(result.values[n] - v) / result.stderr[n] for n, v in case.truth.items()) > 3.0


def test_a_file_without_the_render_keyword_is_a_real_observation(tmp_path):
    """A FITS file of another writer (no RENDSPP) has no render noise; spacefit's says its own; a bad one is refused."""
    dn = np.full((32, 32), 400, dtype=np.uint16)
    fits.PrimaryHDU(dn, header=fits.Header({"BUNIT": "adu", "ROWORDER": "TOP-DOWN"})).writeto(tmp_path / "other.fits")
    scene = sf.load_case("panels").with_values(TINY).scene()
    other = sf.Observation.from_file(tmp_path / "other.fits", scene, sensor=SENSOR)
    assert other.render_spp is None
    assert setup(other, ["parts.panels.alpha_x"]).problem.reference_spp == (None,)
    sf.write_observation(tmp_path / "ours.fits", dn[..., None], SENSOR, render_spp=64)
    assert sf.Observation.from_file(tmp_path / "ours.fits", scene).render_spp == 64
    fits.PrimaryHDU(dn, header=fits.Header({"BUNIT": "adu", "ROWORDER": "TOP-DOWN", "RENDSPP": 0})).writeto(tmp_path / "bad.fits")
    with pytest.raises(sf.InputError, match="RENDSPP"):
        sf.read_image(tmp_path / "bad.fits")
    real = goodness(*residuals(), n_free=3, noise_known=True, reference_spp=[None])
    assert real.reference_noise == 0 and "references taken as real observations" in real.line()


def test_an_exr_reference_says_its_render_samples_in_its_header(tmp_path):
    """An EXR of spacefit's simulated references carries RENDSPP in its header (the committed synthetic references
    too); an EXR of another writer (no such attribute) is a real observation; a bad count is refused naming the file."""
    radiance = np.full((8, 8, 3), 0.25, dtype=np.float32)
    sf.write_exr(tmp_path / "ours.exr", radiance, header={"RENDSPP": 64})
    sf.write_exr(tmp_path / "other.exr", radiance)
    sf.write_exr(tmp_path / "bad.exr", radiance, header={"RENDSPP": "many"})
    scene = sf.load_case("panels").with_values({"render.resolution": [8, 8]}).scene()
    assert sf.Observation.from_file(tmp_path / "ours.exr", scene).render_spp == 64
    assert sf.read_image(tmp_path / "other.exr").metadata["render_spp"] is None
    with pytest.raises(sf.InputError, match="bad.exr.*RENDSPP"):
        sf.read_image(tmp_path / "bad.exr")
    np.testing.assert_array_equal(sf.read_exr(tmp_path / "ours.exr"), radiance)
    committed = Path(__file__).resolve().parents[1] / "data" / "synthetic" / "panels" / "reference_noise2.exr"
    assert sf.read_image(committed, sigma=1.0).metadata["render_spp"] == sf.load_case("panels").truth_scene.render.spp


def test_the_render_samples_travel_in_a_png_sidecar_and_a_bad_count_is_refused_before_writing(tmp_path):
    dn = np.full((4, 4, 1), 400, dtype=np.uint16)
    sf.write_observation(tmp_path / "o.png", dn, SENSOR, render_spp=32)
    assert sf.read_image(tmp_path / "o.png").metadata["render_spp"] == 32
    with pytest.raises(sf.InputError, match="`render_spp` must be an integer >= 1, got 0"):
        sf.write_observation(tmp_path / "bad.fits", dn, SENSOR, render_spp=0)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["o.png", "o.png.json"]
    with pytest.raises(sf.InputError, match="render_spp"):
        sf.Observation(sf.load_case("panels").scene(), dn.astype(float), sensor=SENSOR, render_spp=0)


def test_the_models_dn_is_the_observations_mean_never_below_the_bias():
    """A glint next to black sky: the PSF's ringing dips below zero electrons, which observe's Poisson
    mean does not; the fit's model takes 0 there too (else a correct fit is judged a misfit)."""
    radiance = np.zeros((32, 32, 1))
    radiance[10:20, 10:20] = 5.0
    intrinsics = assemble(sf.load_case("panels").with_values(TINY).scene()).intrinsics
    model = np.asarray(expected_dn(radiance, SENSOR, intrinsics))
    assert model.min() == SENSOR.bias_dn and model.max() > 1e4
    simulated = np.mean([sf.observe(radiance, SENSOR, intrinsics, seed=k).astype(float) for k in range(50)], axis=0)
    dark = model < SENSOR.bias_dn + 1  # the sky and the ringing round the glint
    assert abs(float(np.mean((simulated - model)[dark]))) < 0.05


def test_a_verdict_render_the_machine_cannot_hold_takes_fewer_samples(monkeypatch):
    """The fit's result must not be lost to its verdict: a render the memory cannot hold is not asked for."""
    monkeypatch.setattr("spacefit.rendering.memory.available_memory_bytes", lambda: 2**30)  # 1 GiB
    film = SimpleNamespace(references=[np.zeros((256, 256, 3))], spp=(64,))  # 4.2e6 samples, 0.26 GiB at 64 bytes each
    assert affordable(film, 2) and not affordable(film, 4)


def test_a_simulated_references_render_noise_raises_the_expectation():
    r, noise = residuals()
    real = goodness(r, noise, n_free=3, noise_known=True)
    rendered = goodness(r, noise, n_free=3, noise_known=True, reference_ratio=0.5, reference_spp=[64])
    assert rendered.reference_noise == pytest.approx(0.5 * real.render_noise)
    assert rendered.limit - real.limit == pytest.approx(rendered.reference_noise) and "references rendered at 64 spp" in rendered.line()


@pytest.mark.parametrize(("v", "spp", "k"), [(0.2, 8, 1), (0.3, 8, 2), (2.9, 32, 16), (100.0, 8, MAX_VERDICT_FACTOR),
                                             (100.0, MAX_SPP // 4, 4), (float("nan"), 8, 1)])
def test_the_verdict_render_takes_enough_samples_for_its_noise_to_be_small(v, spp, k):
    assert verdict_factor(v, spp) == k
    assert v / (2 * k) <= VERDICT_RENDER_NOISE or k == min(MAX_VERDICT_FACTOR, MAX_SPP // spp) or np.isnan(v)


def test_a_fit_where_every_step_is_rejected_makes_no_progress(tmp_path):
    """The sun behind the target: kd changes no pixel, every trial step leaves the loss where it was."""
    mesh = write_sphere_obj(tmp_path / "sphere.obj", subdivisions=2)
    lit = small_scene(mesh, {"material": "white_paint", "kd": 0.5}, camera={"pixel_pitch_mm": 0.5}, render={"spp": 4})
    behind = lit.with_values({"sun.direction": [0.0, 0.0, 1.0]})
    result = sf.fit(sf.Observation(behind, np.asarray(sf.render(lit)), sigma=0.01), ["parts.sphere.kd"], max_steps=20)
    assert not any(h["accepted"] for h in result.history[1:])
    assert result.status is sf.Status.NO_PROGRESS and not result.success
    assert result.values == result.start
    assert "converged" not in sf.format_result(result).splitlines()[0]
    # it stops at once (the solver's own tolerance, or at most REJECTED_PATIENCE re-evaluations of the start: issue 34)
    # and says why, with how far the start is from the data
    assert len(result.history) <= 1 + REJECTED_PATIENCE
    assert result.warnings[0].startswith(f"the fit did not succeed ({sf.Status.NO_PROGRESS})") and "goodness of fit" in result.warnings[0]


def test_the_neighbour_correlation_is_taken_over_each_pixels_channel_mean():
    """Channels (1, 2, 3) x a checkerboard of +-1: the channels' mean is the checkerboard, whose
    horizontal and vertical neighbours are perfectly anti-correlated (over rows instead, the mean is 0)."""
    board = np.where(np.add.outer(np.arange(4), np.arange(6)) % 2 == 0, 1.0, -1.0)
    image = board[..., None] * np.array([1.0, 2.0, 3.0])
    assert _neighbours(image.ravel(), [image.shape]) == pytest.approx(-1.0)


def test_the_misfit_margin_is_five_standard_deviations():
    """103 equal residuals, 3 free, no render noise: chi^2 / dof's spread is sqrt(2 / 100); at 4
    spreads above 1 (past the 10 % floor) it is within range, at 6 a misfit."""
    spread = np.sqrt(2.0 / 100.0)
    for sigmas, misfit in ((4.0, False), (6.0, True)):
        r = np.full(103, np.sqrt((1.0 + sigmas * spread) * 100.0 / 103.0))
        g = goodness(r, np.zeros(103), n_free=3, noise_known=True)
        assert g.expected_spread == pytest.approx(spread) and g.misfit is misfit


def test_the_render_noise_of_the_mean_of_two_renders_is_half_their_difference():
    """The mean of renders a and b is judged; a draw of its noise is (a - b) / 2, the residuals' unit."""
    problem = SimpleNamespace(residual_of=lambda models: jnp.concatenate(models) / 2.0)
    a, b = jnp.asarray([1.0, 4.0]), jnp.asarray([3.0, 0.0])
    r, noise = _mean_and_noise(problem, [[a], [b]])
    np.testing.assert_allclose(r, [1.0, 1.0])
    np.testing.assert_allclose(noise, [-0.5, 1.0])


def value_setup(render_sigma: float, names: tuple[str, ...] = ("parts.a.kd",)) -> SimpleNamespace:
    """A fit of 4000 values with unit noise and no image, whose model is rendered: at samples factor f
    each of its renders has noise ``render_sigma`` / sqrt(f) (seeded by the seed index j and f)."""
    data = np.random.default_rng(0).normal(0.0, 1.0, 4000)

    def problem(factor: int) -> SimpleNamespace:
        def model(x: jnp.ndarray, j: int) -> jnp.ndarray:
            return jnp.asarray(np.random.default_rng(100 * factor + j).normal(0.0, render_sigma / np.sqrt(factor), data.size))

        block = SimpleNamespace(resampled=True, spp=8, data=SimpleNamespace(value=data), known=names, noise_known=True)
        return SimpleNamespace(models_seeded=lambda x, j: [model(x, j)], residual_of=lambda models: models[0] - jnp.asarray(data),
                               spp=(), blocks=(block,), resampled=problem, references=[], used=[], reference_spp=(), pixels=0,
                               part_images=[], dark=())

    return SimpleNamespace(problem=problem(1), noise_given=True, x0=np.zeros(len(names)), user=SimpleNamespace(names=names))


def test_the_verdict_renders_twice_at_the_factor_a_single_renders_noise_asks():
    """A rendered value model with v = 0.6 per render at the fit's samples: the verdict's two renders
    take k = 4 times the samples (0.6 / 8 <= 0.1, 0.6 / 4 is not), the mean of two: 8 times a render's,
    its noise v / 8."""
    s = value_setup(np.sqrt(0.6))
    quality = judged_goodness(s, jnp.zeros(1), "pixel")[0]
    assert quality.samples_factor == 8 and quality.render_noise == pytest.approx(0.6 / 8, rel=0.1)


def test_each_observations_goodness_counts_the_shared_and_its_own_free_parameters():
    """An image of 4 values with a shared parameter and its own scale (of 3 free names, one another
    image's): its goodness has 4 - 2 degrees of freedom; a value observation of 4000 with 1 known: 3999."""
    image = SimpleNamespace(problem=SimpleNamespace(references=[np.zeros((2, 2, 1))], spp=(4,), reference_spp=(None,),
                                                    used=[np.ones((2, 2), bool)], blocks=()),
                            user=SimpleNamespace(names=("parts.a.kd", "image.scale@0", "image.scale@1")), noise_given=True)
    r = np.array([1.0, -1.0, 0.5, 0.5])
    assert per_observation(r, r, image, 1)[0].dof == 2
    s = value_setup(0.1)
    data = s.problem.blocks[0].data.value
    assert per_observation(data, data, s, 1)[0].dof == data.size - 1


def test_the_verdict_states_the_smallest_effect_it_could_see_and_one_just_above_it_is_a_misfit():
    """Planted: an unmodelled effect proportional to the signal, a checkerboard of +- epsilon of it (no
    free parameter absorbs it), on 40k unit-noise values at 5 to 40 noise sigmas of signal each. The stated
    fraction is the rule's sqrt(margin x dof / sum (s / sigma)^2): 1.05 times it is a misfit, 0.95 times it passes."""
    rng = np.random.default_rng(7)
    snr = rng.uniform(5.0, 40.0, N)
    effect = snr * np.where(np.arange(N) % 2 == 0, 1.0, -1.0)
    noise = rng.normal(0.0, 1.0, N)
    noise -= effect * (noise @ effect) / (effect @ effect)  # no cross term: chi^2 rises by the effect's own share
    noise *= np.sqrt((N - 3) / np.sum(noise**2))  # chi^2 / dof 1 without it
    clean = goodness(noise, np.zeros(N), n_free=3, noise_known=True, signal=snr)
    assert clean.margin == pytest.approx(MISFIT_FLOOR) and not clean.misfit
    assert clean.detectable == pytest.approx(np.sqrt(MISFIT_FLOOR * (N - 3) / np.sum(snr**2)))
    for factor, misfit in ((1.05, True), (0.95, False)):
        assert goodness(noise + factor * clean.detectable * effect, np.zeros(N), n_free=3, noise_known=True, signal=snr).misfit is misfit
    assert f"cannot see an unmodelled effect below {100 * clean.detectable:.2g} % of the signal" in clean.line()
    assert json.loads(json.dumps(clean.to_dict()))["detectable"] == clean.detectable
    unjudged = goodness(noise, np.full(N, 2.0), n_free=3, noise_known=True, signal=snr)  # render noise 4 x the data's
    assert not unjudged.judged and np.isnan(unjudged.detectable) and "cannot see" not in unjudged.line()


def test_a_frame_that_misfits_on_its_own_is_named_by_frame():
    """A pooled verdict within range can hold a frame that is not: each observation's own misfit is a warning
    naming it, by its frame in a pass."""
    from spacefit.fitting.conclusion import _own_misfits

    passed, failed = (goodness(*residuals(misfit=m), n_free=1, noise_known=True) for m in (0.0, 0.6))
    frames = SimpleNamespace(images=[None] * 3, names=lambda first: [], report=lambda *a: [], plot=lambda *a, **k: None)
    s = SimpleNamespace(layout=((frames, (0, 1, 2)), (SimpleNamespace(), (3,))))
    warnings = _own_misfits(s, [passed, failed, passed, failed])
    assert warnings == [f"frame 1 of the pass (observation 1) is a misfit on its own: chi^2/dof {failed.chi2_dof:.3f} above its "
                        f"limit {failed.limit:.3f}.",
                        f"observation 3 is a misfit on its own: chi^2/dof {failed.chi2_dof:.3f} above its limit {failed.limit:.3f}."]


def test_without_a_known_noise_an_observation_whose_residuals_stand_out_is_named():
    """Residuals against render noise per observation, the noise unknown: a view whose residuals' mean
    square over its render noise's is 4 times the others' is named, with its ratio; a few fireflies
    (0.3 % of the values, 100 times the noise) that hold most of the sum do not make a view stand out;
    with the noise known none is compared."""
    from spacefit.fitting.goodness import STANDS_OUT, standing_out

    rng = np.random.default_rng(3)

    def view(excess: float, fireflies: int = 0) -> sf.Goodness:
        noise = rng.normal(0.0, 1.0, N)
        r = rng.normal(0.0, np.sqrt(1.0 + excess), N)
        r[:fireflies] *= 100.0
        return goodness(r, noise, n_free=1, noise_known=False)

    views = [view(0.0), view(0.0, fireflies=N * 3 // 1000), view(3.0), view(0.0)]
    assert views[1].spread > 10.0 and views[1].robust_spread == pytest.approx(1.0, abs=0.1)  # the fireflies trimmed
    apart = standing_out(views)
    assert list(apart) == [2] and apart[2] == pytest.approx(4.0, rel=0.1) and apart[2] > STANDS_OUT
    known = [goodness(np.asarray(v.robust_spread) * rng.normal(0.0, 1.0, N), rng.normal(0.0, 1.0, N), 1, True) for v in views]
    assert standing_out(known) == {}


def test_a_view_with_a_model_error_of_its_own_is_named_when_the_noise_is_unknown():
    """Two views of the panels case at 48 x 48 px, references rendered at 16 spp without a sensor (noise
    unknown), the second's target turned 3 deg more than its scene says (a pose the fit does not free):
    the fit of the legs' albedo warns that observation 1's residuals stand out and its errors may be
    understated, and says nothing of observation 0."""
    case = sf.load_case("panels").with_values({"render.resolution": [48, 48], "camera.pixel_pitch_mm": 50.0, "render.spp": 4})
    views = [case.truth_scene, case.truth_scene.with_values({"target.attitude_deg": [90.0, 0.0, 25.0]})]
    truths = [views[0], views[1].with_values({"target.attitude_deg": [90.0, 0.0, 28.0]})]
    observations = [sf.Observation(v, np.asarray(sf.render(t.with_values({"render.spp": 16, "render.seed": 7})), float))
                    for v, t in zip(views, truths)]
    result = sf.fit(observations, ["parts.legs.kd"], start={"parts.legs.kd": 0.4})
    assert [g.basis for g in result.observation_goodness] == [RESIDUALS, RESIDUALS]
    standing = [w for w in result.warnings if "stand out" in w]
    assert len(standing) == 1 and standing[0].startswith("observation 1's residuals stand out"), result.warnings
    assert "may be understated" in standing[0]
    # the render-seed check ran (spacefit.fitting.render_seeds) and, the model error common to every render, names nothing
    assert set(result.extras["render_seed_widened"]) == {"parts.legs.kd"}
    assert not [w for w in result.warnings if "render seed" in w], result.warnings
