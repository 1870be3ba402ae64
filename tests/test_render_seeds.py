"""The render-seed check (spacefit.fitting.render_seeds): a render of the fit's own whose noise moved the estimate
beyond what a fresh render's does is measured and named; a clean fit, or a firefly in a fresh render, is not."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

import spacefit as sf
from spacefit.fitting import uncertainty
from spacefit.fitting.render_seeds import FRESH, seed_excess, seed_notes, seed_shift

ROWS, NAMES = 400, ("a", "b")


def linear_case(rng: np.random.Generator, noise: float = 1.0, planted: dict[int, np.ndarray] | None = None):
    """A linear model's residuals at its root: per seed index j a render with noise ``noise`` per residual, plus
    ``planted[j]``; the fit's own two (j = 0, 1), the problem the check renders the fresh ones of, the Gauss-Newton
    step and the standard errors of an estimate from two such renders whose residuals' noise is the renders' alone."""
    J = rng.normal(size=(ROWS, len(NAMES)))
    draws = {j: rng.normal(0.0, noise, ROWS) + (planted or {}).get(j, 0.0) for j in (0, 1, *FRESH)}
    problem = SimpleNamespace(models_seeded=lambda x, j: [draws[j]], residual_of=lambda models: models[0])
    bread = np.linalg.inv(J.T @ J)
    step = lambda d: -bread @ (J.T @ d)  # noqa: E731
    stderr = np.sqrt(np.diag(bread) * noise**2 / 2)  # the mean of two renders' noise
    return (draws[0], draws[1]), problem, step, J, stderr


def widened(shift: np.ndarray, stderr: np.ndarray) -> dict[str, float]:
    """By name, the factor the check widens each standard error by, the error carrying its render noise as modelled."""
    return dict(zip(NAMES, np.sqrt(1.0 + seed_excess(shift, stderr**2) / stderr**2)))


def test_a_planted_firefly_in_the_fits_render_is_measured_carried_and_named():
    """A firefly in the fit's first render, on a row that pulls parameter a: the check's shift is the move it gave the
    estimate (half its step, undone by the fresh renders) within the check's noise; the widened error carries it (the
    estimate's error from the firefly within 1.5 of the new standard errors) and a is named; b, which the row hardly
    moves, is not."""
    J = linear_case(np.random.default_rng(1))[3]
    row = int(np.argmax(np.abs(J[:, 0]) - np.abs(J[:, 1])))
    firefly = np.zeros(ROWS)
    firefly[row] = 60.0
    own, problem, step, J, stderr = linear_case(np.random.default_rng(1), planted={0: firefly})
    shift = seed_shift(problem, np.zeros(2), own, step)
    moved = step(firefly) / 2  # what the firefly moved the two renders' estimate by
    assert abs(moved[0]) > 5 * stderr[0] and abs(moved[1]) < 2 * stderr[1]
    assert shift[0] == pytest.approx(-moved[0], abs=3 * np.sqrt(1.0 + 2.0 / len(FRESH)) * stderr[0])
    factors = widened(shift, stderr)
    assert abs(moved[0]) < 1.5 * factors["a"] * stderr[0]
    notes = seed_notes(dict(zip(NAMES, shift)), factors, dict(zip(NAMES, stderr)))
    assert len(notes) == 1 and notes[0].startswith("a depends on the fit's render seed"), notes


def test_clean_renders_and_a_firefly_in_a_fresh_render_are_not_named():
    """Over 2000 linear fits with normal render noise (all of the estimate's error), the shift has the spread the module
    states, sqrt(1 + 2 / len(FRESH)) standard errors, the widened variance is the error's only where the draw exceeds it,
    and an error is widened more than SEED_WIDENED_WARN times in
    under 2 % of them; a firefly in a fresh render moves the shift 2 / len(FRESH) as far as in the fit's own, and the
    other way (diluted among the fresh renders; in the fit's own it is half its estimate's render noise)."""
    rng = np.random.default_rng(0)
    z, named, variance = [], 0, []
    for _ in range(2000):
        own, problem, step, _, stderr = linear_case(rng)
        shift = seed_shift(problem, np.zeros(2), own, step)
        z.append(shift / stderr)
        factors = widened(shift, stderr)
        variance += [f**2 for f in factors.values()]
        named += bool(seed_notes(dict(zip(NAMES, shift)), factors, dict(zip(NAMES, stderr))))
    assert np.std(z) == pytest.approx(np.sqrt(1.0 + 2.0 / len(FRESH)), rel=0.05)
    # the error as modelled is the render noise's own: the widened variance is E[max(1, chi^2_1)] = 1 + 2 phi(1) of it
    assert np.mean(variance) == pytest.approx(1.0 + 2.0 * np.exp(-0.5) / np.sqrt(2.0 * np.pi), abs=0.1)
    assert named < 0.02 * 2000
    J = linear_case(np.random.default_rng(1))[3]
    firefly = np.zeros(ROWS)
    firefly[int(np.argmax(np.abs(J[:, 0])))] = 40.0
    clean = seed_shift(*_check(linear_case(np.random.default_rng(1))))[0]
    own, fresh = (seed_shift(*_check(linear_case(np.random.default_rng(1), planted={j: firefly})))[0] - clean for j in (0, FRESH[0]))
    assert fresh == pytest.approx(-own * 2 / len(FRESH), rel=1e-6)  # a fresh render's weight 1 / len(FRESH), the fit's own 1/2


def _check(case: tuple) -> tuple:
    """:func:`seed_shift`'s arguments for a :func:`linear_case`."""
    own, problem, step, _, _ = case
    return problem, np.zeros(2), own, step


def test_a_fit_whose_own_render_is_far_noisier_than_fresh_ones_says_so(monkeypatch):
    """A fit of the panels case's legs' albedo at 48 x 48 px with the noise unknown, its own first render's noise planted
    30 times over where the check reads it: the check's shift and widening are in its extras, and the warning names the
    albedo, in the result and in fit.json's warnings (a clean fit names nothing: tests/test_goodness.py)."""
    case = sf.load_case("panels").with_values({"render.resolution": [48, 48], "camera.pixel_pitch_mm": 50.0, "render.spp": 4})
    observation = sf.Observation(case.truth_scene, np.asarray(sf.render(case.truth_scene.with_values({"render.spp": 16, "render.seed": 7})), float))
    real = uncertainty.seed_shift

    def planted(problem, x, own, step):
        r, r_alt = own
        return real(problem, x, (r + 30.0 * (r - r_alt), r_alt), step)

    monkeypatch.setattr(uncertainty, "seed_shift", planted)
    result = sf.fit(observation, ["parts.legs.kd"], start={"parts.legs.kd": 0.4})
    assert set(result.extras["render_seed_shift"]) == {"parts.legs.kd"} and result.extras["render_seed_widened"]["parts.legs.kd"] > 3
    named = [w for w in result.to_dict()["warnings"] if "render seed" in w]
    assert len(named) == 1 and named[0].startswith("parts.legs.kd depends on the fit's render seed"), result.warnings
