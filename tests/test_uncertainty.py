"""Standard errors against closed forms, in both directions: an error too large fails as surely as one
too small (the fit tests only ask that the truth lies within k standard errors).

The covariance code reads residuals and Jacobians from a problem's two residual functions only, so a
linear residual r(x) = A x - b stands in for the renderer and every quantity has a closed form.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from types import SimpleNamespace

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import spacefit as sf
from spacefit.fitting.losses import residual_fn
from spacefit.fitting.params import free_parameters
from spacefit.fitting.uncertainty import covariance, linearise, map_covariance
from spacefit.fitting.value_warnings import warnings_for
from spacefit.geometry.wm import wm_G_from_rms

N, P = 12, 3  # few rows, so that the small-sample factor n / (n - p) = 4/3 is far from 1


@dataclass
class LinearProblem:
    """The two residual functions the covariance reads: r(x) = A x - b and r2(x) = A2 x - b2, and
    whether the residuals are divided by a known noise."""

    residual_x: object
    residual_x_independent: object
    noise_known: bool = False
    references: tuple = ()  # no image layout: each residual its own block
    noise_spread_px: tuple = ()  # per reference: (pixel filter radius, PSF rms width), px
    free: object = field(default_factory=lambda: SimpleNamespace(names=()))  # no image nuisance is free
    blocks: tuple = ()  # no value observation's block

    @property
    def pixels(self) -> int:
        """The residuals laid out as the references' pixels (Problem.pixels)."""
        return sum(int(np.size(ref)) for ref in self.references)

    def render_ahead(self, x, j):
        """Nothing rendered (Problem.render_ahead without renders made first)."""

    def linearised(self, x, j):
        """The j-th residual function's value and tangent map at x (Problem.linearised)."""
        return jax.linearize((self.residual_x, self.residual_x_independent)[j], x)


def linear(A, b, A2=None, b2=None, noise_known=False) -> LinearProblem:
    A2, b2 = (A, b) if A2 is None else (A2, b2)
    return LinearProblem(lambda x: jnp.asarray(A) @ x - jnp.asarray(b), lambda x: jnp.asarray(A2) @ x - jnp.asarray(b2), noise_known)


@pytest.fixture
def heteroscedastic():
    """A, the estimate x_hat, and residuals at x_hat whose size varies 30-fold from row to row
    (glints), orthogonal to A's columns as at a least-squares solution."""
    rng = np.random.default_rng(4)
    A = rng.normal(size=(N, P))
    x_hat = np.array([0.4, -1.2, 2.5])
    e = rng.normal(size=N) * np.geomspace(0.1, 3.0, N)
    r = e - A @ np.linalg.solve(A.T @ A, A.T @ e)
    return A, x_hat, r


def sandwich(A, r):
    """White's HC1 covariance, written out: (A^T A)^-1 A^T diag(r^2) A (A^T A)^-1 n / (n - p)."""
    bread = np.linalg.inv(A.T @ A)
    n, p = A.shape
    return bread @ A.T @ np.diag(r**2) @ A @ bread * n / (n - p)


def test_covariance_is_the_hc1_sandwich(heteroscedastic):
    A, x_hat, r = heteroscedastic
    with jax.enable_x64(True):
        cov, loss, fisher, _ = covariance(linear(A, A @ x_hat - r), x_hat)
    expected = sandwich(A, r)
    np.testing.assert_allclose(cov, expected, rtol=1e-9)
    # with these residuals the uniform-noise form s^2 (A^T A)^-1 is another matrix: the test can tell
    assert not np.allclose(np.linalg.inv(A.T @ A) * (r @ r) / (N - P), expected, rtol=0.1)
    assert loss == pytest.approx(0.5 * r @ r, rel=1e-12)
    # the Fisher information under uniform noise: eigenvalues of A^T A / s^2
    np.testing.assert_allclose(np.sort(fisher), np.linalg.eigvalsh(A.T @ A) / ((r @ r) / (N - P)), rtol=1e-9)


def test_with_the_noise_known_the_covariance_is_the_inverse_information(heteroscedastic):
    """Residuals divided by their predicted noise: (A^T A)^-1, no scale taken from the residuals."""
    A, x_hat, r = heteroscedastic
    with jax.enable_x64(True):
        cov, _, fisher, correction = covariance(linear(A, A @ x_hat - r, noise_known=True), x_hat)
    np.testing.assert_allclose(cov, np.linalg.inv(A.T @ A), rtol=1e-9)
    np.testing.assert_allclose(np.sort(fisher), np.linalg.eigvalsh(A.T @ A), rtol=1e-9)
    np.testing.assert_allclose(correction, 0.0, atol=1e-12)  # x_hat is the least-squares root already


def test_with_the_noise_known_a_noisy_jacobian_adds_its_own_term(heteroscedastic):
    """Two Jacobians from independent seeds, A and A + E, with the same residuals: a fit that stops
    where A^T r = 0 for its noisy A is off by (A^T A)^-1 E^T r, whose covariance is
    B sum_i r_i^2 e_i e_i^T / 2 B, with e_i the rows of the difference; the estimate averages the
    two seeds' equations, so half of that adds to the inverse information."""
    A, x_hat, r = heteroscedastic
    E = np.random.default_rng(5).normal(size=A.shape)
    A2 = A + E
    with jax.enable_x64(True):
        cov, *_ = covariance(linear(A, A @ x_hat - r, A2, A2 @ x_hat - r, noise_known=True), x_hat)
    bread = np.linalg.inv(0.5 * (A.T @ A2 + A2.T @ A))
    expected = bread + 0.5 * bread @ (0.5 * E.T @ np.diag(r**2) @ E) @ bread
    np.testing.assert_allclose(cov, expected, rtol=1e-9)
    assert np.all(np.diag(cov) > 1.05 * np.diag(bread))  # the term matters here: the test can tell


@pytest.mark.parametrize(("spread", "reach"), [((0.5, 0.0), 0), ((1.0, 0.0), 1), ((1.0, 1.0), 4)])
def test_render_noise_shared_by_neighbouring_pixels_is_counted(spread, reach):
    """With the noise known, the fit's render noise d = (r - r_alt) / sqrt(2) enters as the spatial
    HAC meat sum_i s_i sum_{j near i} s_j^T, s_i = sum of A_i d_i over pixel i's channels, j within
    the reach, at half weight (the estimate averages the two seeds' renders): the box filter's samples stay in their pixel (0), the tent's reach the next pixel
    (1), a PSF of rms width 1 px spreads them 2 sqrt(2) px further (4). Written out pair by pair
    here on an 8 x 5 px RGB image."""
    from spacefit.fitting.uncertainty import noise_reach_px

    rng = np.random.default_rng(6)
    h, w = 8, 5
    A = rng.normal(size=(h * w * 3, P))
    x_hat = np.array([0.4, -1.2, 2.5])
    r = rng.normal(size=len(A))
    d = rng.normal(size=len(A))
    problem = LinearProblem(lambda x: jnp.asarray(A) @ x - jnp.asarray(A @ x_hat - r),
                            lambda x: jnp.asarray(A) @ x - jnp.asarray(A @ x_hat - r + np.sqrt(2.0) * d),
                            noise_known=True, references=(np.zeros((h, w, 3)),), noise_spread_px=(spread,))
    assert noise_reach_px(problem, x_hat, 0) == reach
    with jax.enable_x64(True):
        cov, *_ = covariance(problem, x_hat)
    s = (A * d[:, None]).reshape(h, w, 3, P).sum(axis=2)
    meat = sum(np.outer(s[i, j], s[k, m]) for i in range(h) for j in range(w) for k in range(h) for m in range(w)
               if max(abs(i - k), abs(j - m)) <= reach)
    eigval, eigvec = np.linalg.eigh(meat)
    meat = (eigvec * np.clip(eigval, 0.0, None)) @ eigvec.T
    bread = np.linalg.inv(A.T @ A)
    np.testing.assert_allclose(cov, bread + 0.5 * bread @ meat @ bread, rtol=1e-9)
    per_residual = bread + bread @ (A.T @ np.diag(d**2) @ A) @ bread
    assert not np.allclose(cov, per_residual, rtol=0.1)  # channels and neighbours matter: the test can tell


def test_with_the_noise_known_the_estimate_solves_the_two_seed_equation():
    """The fit's minimum of |r1|^2 is biased when the render noise is in the Jacobian too: here a
    gain x of a template t, the render t + d1, r1 = x (t + d1) - y; the minimum x (t + d1).y /
    |t + d1|^2 is low by the factor |t|^2 / (|t|^2 + n s^2) = 1/2 on average (n = 40 pixels of render
    noise s = |t| / sqrt(n)). The correction takes it to the root of 0.5 (J1^T r2 + J2^T r1) = 0,
    (2 t + d1 + d2).y / (2 (t + d1).(t + d2)), whose mean over 100 draws is the truth within its
    Monte Carlo error, and the uncorrected minimum's is half of it."""
    rng = np.random.default_rng(8)
    n, truth = 40, 2.0
    t = rng.uniform(0.5, 1.5, size=n)
    s = np.linalg.norm(t) / np.sqrt(n)
    fitted, corrected = [], []
    with jax.enable_x64(True):
        for _ in range(100):
            d1, d2, e = rng.normal(0.0, s, size=n), rng.normal(0.0, s, size=n), rng.normal(0.0, 0.1, size=n)
            y = truth * t + e
            x_hat = np.array([(t + d1) @ y / ((t + d1) @ (t + d1))])  # the minimum of |r1|^2
            problem = LinearProblem(lambda x, m=t + d1, y=y: x[0] * m - y, lambda x, m=t + d2, y=y: x[0] * m - y, noise_known=True)
            *_, correction = covariance(problem, x_hat)
            expected = (2 * t + d1 + d2) @ y / (2 * (t + d1) @ (t + d2))
            np.testing.assert_allclose(x_hat + correction, [expected], rtol=1e-9)
            fitted.append(x_hat[0])
            corrected.append(x_hat[0] + correction[0])
    assert np.mean(fitted) == pytest.approx(truth / 2, rel=0.05)
    assert np.mean(corrected) == pytest.approx(truth, abs=4 * np.std(corrected) / np.sqrt(len(corrected)))


def test_a_free_psf_widens_the_reach_of_the_render_noise():
    """A free ``image.blur_sigma_px`` (its value at x) adds to the sensor's PSF in quadrature."""
    from spacefit.fitting.uncertainty import noise_reach_px

    problem = LinearProblem(None, None, noise_spread_px=((1.0, 0.0), (1.0, 0.0)),
                            free=SimpleNamespace(names=("parts.legs.kd", "image.blur_sigma_px@1")))
    assert noise_reach_px(problem, np.array([0.5, 2.0]), 0) == 1  # observation 0 has no PSF of its own
    assert noise_reach_px(problem, np.array([0.5, 2.0]), 1) == 7  # ceil(1 + 2 sqrt(2) 2)


def test_covariance_does_not_depend_on_the_noise_scale_or_the_units(heteroscedastic):
    """Dividing every residual by c (a sigma c times larger) leaves the errors unchanged: the
    sandwich takes the noise level from the residuals, the stated sigma only weighs pixels. Stating
    x in other units (x = K y, metres to millimetres, say) scales the errors by the same units."""
    A, x_hat, r = heteroscedastic
    c = 7.0
    K = np.diag([1e-2, 1.0, 5.0])
    with jax.enable_x64(True):
        base, *_ = covariance(linear(A, A @ x_hat - r), x_hat)
        scaled, *_ = covariance(linear(A / c, (A @ x_hat - r) / c), x_hat)
        units, *_ = covariance(linear(A @ K, A @ x_hat - r), np.linalg.solve(K, x_hat))
    np.testing.assert_allclose(scaled, base, rtol=1e-9)
    np.testing.assert_allclose(K @ units @ K.T, base, rtol=1e-9)


def test_rows_with_nothing_in_them_do_not_count(heteroscedastic):
    """Black sky (residual and Jacobian row both 0) adds no degrees of freedom: n counts only the
    informative rows, and the covariance is the same with 30 such rows appended."""
    A, x_hat, r = heteroscedastic
    A_sky = np.vstack([A, np.zeros((30, P))])
    r_sky = np.concatenate([r, np.zeros(30)])
    with jax.enable_x64(True):
        cov, *_ = covariance(linear(A_sky, A_sky @ x_hat - r_sky), x_hat)
    np.testing.assert_allclose(cov, sandwich(A, r), rtol=1e-9)


def test_two_jacobians_enter_as_their_symmetrised_cross_product(heteroscedastic):
    """Monte Carlo noise in a Jacobian would add to J^T J as if it were information; the covariance
    uses sym(J1^T W J2) of two independently seeded Jacobians, whose noise does not correlate. Without a
    known noise too the estimate is the two-seed equation's root, one step c from x_hat, its meat the
    mean residual there, r + (A + A2) c / 2, and the Jacobians' difference E adds B E^T diag(r^2) E B / 4."""
    A, x_hat, r = heteroscedastic
    A2 = A + 0.1 * np.random.default_rng(5).normal(size=A.shape)
    n, p = A.shape

    def sym(W):
        return 0.5 * (A.T @ W @ A2 + A2.T @ W @ A)

    bread = np.linalg.inv(sym(np.eye(n)))
    step = -bread @ (0.5 * (A.T @ r + A2.T @ r))
    mean = r + 0.5 * (A + A2) @ step
    meat = sym(np.diag(mean**2 * n / (n - p)))
    assert np.all(np.linalg.eigvalsh(meat) > 0)  # so no clipping of the meat's eigenvalues applies
    E = A - A2
    with jax.enable_x64(True):
        cov, _, _, correction = covariance(linear(A, A @ x_hat - r, A2, A2 @ x_hat - r), x_hat)
    np.testing.assert_allclose(correction, step, rtol=1e-9)
    assert np.abs(step).max() > 1e-3 * np.abs(x_hat).max()  # the step is not 0: the test can tell
    expected = bread @ (meat + 0.25 * E.T @ np.diag(r**2) @ E) @ bread
    np.testing.assert_allclose(cov, expected, rtol=1e-9)
    # the mean residual at the root, not the fit's own: another matrix
    assert not np.allclose(bread @ (sym(np.diag(r**2 * n / (n - p))) + 0.25 * E.T @ np.diag(r**2) @ E) @ bread, expected, rtol=1e-3)


def test_linearise_begins_the_independent_seeds_renders_before_it_traces_the_fit_s():
    """The independent seeds' renders are asked for first (Problem.render_ahead: they run while the fit's seeds'
    tangents are traced), then each seed's linearisation, the fit's first."""
    asked = []

    class Recording(LinearProblem):
        def render_ahead(self, x, j):
            asked.append(("render_ahead", j))

        def linearised(self, x, j):
            asked.append(("linearised", j))
            return super().linearised(x, j)

    with jax.enable_x64(True):
        lin = linearise(Recording(lambda x: 2.0 * x, lambda x: 3.0 * x), np.ones(2))
    assert asked == [("render_ahead", 1), ("linearised", 0), ("linearised", 1)]
    np.testing.assert_array_equal(lin.r, [2.0, 2.0])
    np.testing.assert_array_equal(lin.r_alt, [3.0, 3.0])


def test_a_parameter_nothing_constrains_gets_infinite_error_and_leaves_the_others(heteroscedastic):
    A, x_hat, r = heteroscedastic
    A_blind = A.copy()
    A_blind[:, 2] = 0.0  # the images do not depend on x_2
    with jax.enable_x64(True):
        cov, *_ = covariance(linear(A_blind, A_blind @ x_hat - r), x_hat)
    assert np.all(np.isinf(cov[2, :])) and np.all(np.isinf(cov[:, 2]))
    # the others: the sandwich of the two columns that matter, with the blind one still counted in
    # the small-sample factor (n / (n - 3), not n / (n - 2))
    two = sandwich(A[:, :2], r) * (N - 2) / (N - P)
    np.testing.assert_allclose(cov[:2, :2], two, rtol=1e-9)


def test_map_covariance_is_T_C_T_transposed():
    C = np.array([[0.04, 0.01], [0.01, 0.09]])
    T = np.array([[1.0, 0.0], [0.7, 2.5]])  # not symmetric: T C T^T differs from T^T C T
    expected = np.array(
        [
            [0.04, 0.7 * 0.04 + 2.5 * 0.01],
            [0.7 * 0.04 + 2.5 * 0.01, 0.7**2 * 0.04 + 2 * 0.7 * 2.5 * 0.01 + 2.5**2 * 0.09],
        ]
    )
    np.testing.assert_allclose(map_covariance(T, C), expected, rtol=1e-12)


def test_map_covariance_keeps_undetermined_undetermined():
    C = np.array([[0.04, np.inf], [np.inf, np.inf]])
    T = np.array([[2.0, 0.0], [0.7, 2.5]])  # y_0 = 2 x_0 is determined; y_1 mixes in x_1
    out = map_covariance(T, C)
    assert out[0, 0] == pytest.approx(4 * 0.04)
    assert np.all(np.isinf(out[1, :])) and np.all(np.isinf(out[:, 1]))


def test_D_rms_to_D_G_covariance_matches_the_scatter_of_mapped_samples():
    """The (D, rms) -> (D, G) map of a fit, by the delta method with T = d(D, G) / d(D, rms) from
    JAX, against the covariance of Gaussian samples pushed through G(D, rms) itself."""
    w = {"gamma": 1.5, "M": 5, "L": 0.1, "Ls": 5e-3}
    x = np.array([2.4, 2e-3])  # D, rms height (m)
    C = np.array([[1e-4, 2e-9], [2e-9, 1e-10]])  # small, so the map is close to linear over the spread
    with jax.enable_x64(True):
        def to_user(v):
            return jnp.stack([v[0], wm_G_from_rms(v[0], v[1], **w)])

        T = np.asarray(jax.jacfwd(to_user)(jnp.asarray(x)))
        samples = np.random.default_rng(6).multivariate_normal(x, C, size=200_000)
        mapped = np.asarray(jax.vmap(to_user)(jnp.asarray(samples)))
    assert abs(T[1, 0]) * np.sqrt(C[0, 0]) > 0.1 * abs(T[1, 1]) * np.sqrt(C[1, 1])  # T is far from diagonal
    np.testing.assert_allclose(map_covariance(T, C), np.cov(mapped.T), rtol=0.03)


def test_per_pixel_sigma_makes_residuals_standard_normal():
    """Noise drawn with a per-pixel sigma map comes back as the standard normal draws themselves."""
    rng = np.random.default_rng(7)
    h, w = 6, 5
    ref = rng.uniform(0.5, 2.0, size=(h, w, 3))
    z = rng.normal(size=(h, w, 3))
    for sigma in (rng.uniform(0.02, 0.5, size=(h, w)), rng.uniform(0.02, 0.5, size=(h, w, 3))):
        noise = (sigma[..., None] if sigma.ndim == 2 else sigma) * z
        r = np.asarray(residual_fn(ref, "pixel", sigma)(jnp.asarray(ref + noise, dtype=jnp.float32)))
        # float32 images: the difference is exact to ~1e-7 of the radiance, i.e. 2e-7 / 0.02 in z
        np.testing.assert_allclose(r, z.ravel(), atol=1e-4)


def test_poorly_determined_is_judged_against_the_parameters_own_scale():
    """A standard error is compared with 0.2 of the larger of the value and the parameter's own scale
    (0.1 px for a shift, 0.1 deg for an attitude angle): a shift of 0.001 px determined to 0.004 px
    and an angle of 0 deg determined to 0.008 deg are well determined; a roughness of 0.1 determined
    to 0.2 is not, and neither is a shift known only to 0.021 px (0.2 x 0.1 px is the line)."""
    names = ["image.shift_x_px", "target.attitude_x_deg", "parts.panels.alpha_x"]
    params = free_parameters(sf.load_case("panels").scene(), names, 1)
    values = np.array([0.001, 0.0, 0.1])

    def poorly(stderr):
        return [m.split()[0] for m in warnings_for(params, values, np.array(stderr), np.eye(3)) if "poorly determined" in m]

    assert poorly([0.004, 0.008, 0.2]) == ["parts.panels.alpha_x"]
    assert poorly([0.021, 0.021, 0.019]) == ["image.shift_x_px", "target.attitude_x_deg"]
    assert poorly([0.019, 0.019, 0.021]) == ["parts.panels.alpha_x"]


def test_a_value_observation_without_errors_has_its_noise_from_s2_over_n_minus_p():
    """A table of 10 values without errors, 2 parameters known: each value's noise draw in the sandwich is
    the root of sum r^2 / (10 - 2); with errors stated, 1."""
    from spacefit.fitting.uncertainty import _unknown_noise_draw

    r = np.arange(1.0, 11.0)
    for known, expected in ((False, np.full(10, np.sqrt(r @ r / 8.0))), (True, np.ones(10))):
        block = SimpleNamespace(data=SimpleNamespace(value=r), known=("a", "b"), noise_known=known)
        problem = SimpleNamespace(pixels=0, blocks=(block,))
        np.testing.assert_allclose(_unknown_noise_draw(problem, np.zeros(10), r, 10, 8), expected)


def test_a_value_within_two_standard_errors_of_a_bound_is_flagged_with_its_correlated_parameters():
    """A blur of 0.03 +- 0.04 px (its range (0, 4) px) reaches out of its range at 2 sigma: the warning names the lower
    bound and the parameters correlated with it at |rho| >= 0.3 (kd at -0.5, not alpha_x at 0.1), beside "poorly
    determined"; kd at 0.97 +- 0.02 is flagged at its upper bound 1; 0.05 +- 0.02 px and kd 0.95 +- 0.02 are not."""
    names = ["image.blur_sigma_px", "parts.legs.kd", "parts.panels.alpha_x"]
    params = free_parameters(sf.load_case("panels").scene(), names, 1)
    corr = np.array([[1.0, -0.5, 0.1], [-0.5, 1.0, 0.0], [0.1, 0.0, 1.0]])

    def near(values, stderr):
        return [m for m in warnings_for(params, np.array(values), np.array(stderr), corr) if "standard errors of the" in m]

    assert near([0.03, 0.5, 0.15], [0.04, 0.005, 0.001]) == [
        "image.blur_sigma_px = 0.03 +- 0.04 lies within 2 standard errors of the lower bound 0 of its range: its interval "
        "is cut there, so it is not a normal error (the estimate cannot fall beyond the bound, so it is biased away from it); "
        "the errors of the parameters correlated with it, parts.legs.kd (-0.50), take it as normal and may be understated."]
    assert [m.split(" lies")[0] + m[m.index("bound 1"):][:7] for m in near([1.0, 0.97, 0.15], [0.01, 0.02, 0.001])] == [
        "parts.legs.kd = 0.97 +- 0.02bound 1"]
    assert near([0.05, 0.95, 0.15], [0.02, 0.02, 0.001]) == []
