"""The pixel grid's model error of a fitted blur (spacefit.fitting.pixel_grid): the pixel's
response, the fine and grid models made from one render, the step it moves the estimate by."""

import dataclasses
import threading
from types import SimpleNamespace

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from spacefit.cli import NOT_CONVERGED, exit_code
from spacefit.fitting.nuisance import PAD_PX, image_model
from spacefit.fitting.fine_models import (COARSER, MOVES, RESPONSE_REACH_PX, RESPONSES, STEPS_PER_FINE_PX, SUPERSAMPLE, binned,
                                          fine_and_grid_models, response_matrix)
from spacefit.fitting.pixel_grid import (FIXED_POINT_STEPS, FIXED_POINT_TOLERANCE, REMAINDER_RATIO, GridChanges, ImageColumns, PastBlackSky,
                                         black_sky_notes, grid_step, past_black_sky, unsettled_notes)
from spacefit.formation import fast_pad
from spacefit.fitting.status import Status, verdict
from spacefit.fitting.uncertainty import linearise

FACTOR = 4
NAMES = [*MOVES, "image.scale"]
X = np.array([0.8, 0.3, -0.2, 1.5])  # blur (px), shift x and y (px), scale


def test_a_box_pixel_averages_its_own_fine_pixels_and_a_tent_weighs_its_neighbours_by_their_overlap():
    box = response_matrix(5, FACTOR, "box")
    np.testing.assert_array_equal(box, np.kron(np.eye(5), np.full(FACTOR, 1.0 / FACTOR)))
    tent = response_matrix(5, 2, "tent")  # fine px centred at +-0.25 and +-0.75 px: the tent's integrals over each, 3/8 and 1/8
    np.testing.assert_allclose(tent[2], [0, 0, 0, 0.125, 0.375, 0.375, 0.125, 0, 0, 0], atol=1e-12)
    np.testing.assert_allclose(tent.sum(axis=1), 1.0)


@pytest.mark.parametrize("pixel_filter", sorted(RESPONSES))
def test_a_response_matrix_is_each_rows_response_integrated_over_the_whole_axis(pixel_filter):
    """One pixel's fine weights placed along the diagonal: the same bits as the midpoint rule over every fine pixel of
    the axis for each row, at the factors the pixel grid uses (and the edges' rows cut and renormalised alike)."""
    beyond = np.linspace(RESPONSE_REACH_PX + 0.5, RESPONSE_REACH_PX + 3.0, 11)
    assert not RESPONSES[pixel_filter](beyond).any() and not RESPONSES[pixel_filter](-beyond).any()
    for size in (1, 2, 5, 129):
        for factor in (COARSER, SUPERSAMPLE):
            t = (np.arange(size * factor * STEPS_PER_FINE_PX) + 0.5) / (factor * STEPS_PER_FINE_PX)
            fine = RESPONSES[pixel_filter](t[None, :] - (np.arange(size)[:, None] + 0.5)).reshape(size, size * factor, -1).sum(axis=-1)
            np.testing.assert_array_equal(response_matrix(size, factor, pixel_filter), fine / fine.sum(axis=1, keepdims=True))


def _models(fine: np.ndarray, pixel_filter: str = "box") -> tuple[np.ndarray, np.ndarray]:
    same = lambda image: image  # noqa: E731
    truth, grid = fine_and_grid_models(jnp.asarray(fine), pixel_filter, X, 0, image_model(NAMES), same, same, same,
                                       [NAMES.index(n) for n in MOVES], FACTOR)
    return np.asarray(truth), np.asarray(grid)


def test_a_resolved_image_has_no_pixel_grid_error_and_a_point_has_one():
    """A blob of 2 px rms is resolved by the grid: blurred, shifted and scaled at the fine scale then
    integrated over each pixel, it is what the fit's model makes of its pixel-integrated render
    (so the blur and shifts scale to the fine pixels right); a point of light within one pixel is not."""
    v, u = (np.mgrid[0 : 16 * FACTOR, 0 : 16 * FACTOR] + 0.5) / FACTOR
    blob = np.exp(-((u - 7.3) ** 2 + (v - 8.6) ** 2) / (2 * 2.0**2))[..., None] * np.ones(3)
    truth, grid = _models(blob)
    assert truth.shape == (16, 16, 3) and np.abs(truth - grid).max() < 1e-4 * truth.max()  # float32's FFT round-off
    point = np.zeros_like(blob)
    point[8 * FACTOR + 1, 7 * FACTOR + 2] = 1.0
    truth, grid = _models(point)
    assert np.abs(truth - grid).max() > 0.05 * truth.max()


def test_the_fine_models_black_sky_covers_its_blur_and_shift_at_the_fine_scale_and_a_reach_past_it_fails():
    """A wide blur of light at the image's edge: with the fit's pad (28 px) taken as fine px, the model made at 4x
    wraps light round to the opposite edge (the FFT is circular); the pad sized at the fine scale for the values is the
    ample pad's model to round-off. A centred target with a 0.8 px blur keeps the fit's pad: its model unchanged."""
    same = lambda image: image  # noqa: E731
    moves = [NAMES.index(n) for n in MOVES]

    def model(fine: np.ndarray, x: np.ndarray, pad: int | None) -> jax.Array:
        """The model made at 4x on ``pad`` fine px of black sky (None: sized for x), its reach checked."""
        return fine_and_grid_models(jnp.asarray(fine), "box", x, 0, image_model(NAMES), same, same, same, moves, FACTOR, NAMES, pad)[0]

    def unchecked(fine: np.ndarray, x: np.ndarray, pad: int) -> jax.Array:
        """The same on ``pad`` as given (names None: the image model's own pad, by the real FFT as the fine models'), as
        before the pad was sized at 4x."""
        return fine_and_grid_models(jnp.asarray(fine), "box", x, 0, image_model(NAMES, pad, real=True), same, same, same, moves, FACTOR)[0]

    with jax.enable_x64(True):  # float64: the wrap against the FFT's round-off
        size = 16
        shape = (size * FACTOR, size * FACTOR)
        v, u = (np.mgrid[0 : shape[0], 0 : shape[1]] + 0.5) / FACTOR
        fits_pad, ample = fast_pad(shape, PAD_PX), fast_pad(shape, FACTOR * PAD_PX)
        edge = np.exp(-((u - size + 0.5) ** 2 + (v - 8.2) ** 2) / (2 * 0.5**2))[..., None] * np.ones(3)
        wide = np.array([3.0, 2.0, -0.2, 1.5])  # blur 3 px, shifted 2 px out of the image: 17 px, 68 fine px, past twice its pad
        truth = model(edge, wide, ample)
        wrapped = unchecked(edge, wide, fits_pad)
        truth, wrapped = np.asarray(truth), np.asarray(wrapped)
        assert np.abs(wrapped - truth)[:, :2].max() > 1e-5 * truth.max()  # at the opposite edge
        np.testing.assert_allclose(model(edge, wide, None), truth, rtol=0, atol=1e-13 * truth.max())
        past = np.asarray(model(edge, wide, fits_pad))
        assert np.isnan(past).all()  # past its pad: refused
        refused = GridChanges(lambda y: np.stack([past.ravel()] * 2), lambda y, columns, last=False: None)
        with pytest.raises(PastBlackSky, match="not finite at the values") as refusal:  # the fixed point's iterations stop there
            grid_step(refused, lambda d: np.zeros(len(wide)), wide, np.ones(len(wide)), [])
        np.testing.assert_array_equal(refusal.value.tried, wide)
        centred = np.exp(-((u - 7.7) ** 2 + (v - 8.6) ** 2) / (2 * 0.5**2))[..., None] * np.ones(3)
        np.testing.assert_array_equal(model(centred, X, None), unchecked(centred, X, fits_pad))


def systematic_step(J1: np.ndarray, J2: np.ndarray, d: np.ndarray) -> np.ndarray:
    """The covariance's step for a change d of residuals whose Jacobians are J1 and J2 (linear residuals)."""
    problem = SimpleNamespace(linearised=lambda x, j: jax.linearize(lambda y: jnp.asarray((J1, J2)[j]) @ y, x),
                              render_ahead=lambda x, j: None, free=SimpleNamespace(names=("a", "b")), blocks=())
    with jax.enable_x64(True):
        return linearise(problem, np.zeros(J1.shape[1])).step(d)


def test_the_systematic_step_is_the_least_squares_step_of_the_residuals_change():
    rng = np.random.default_rng(3)
    J, d = rng.normal(size=(40, 3)), rng.normal(size=40)
    np.testing.assert_allclose(systematic_step(J, J, d), -np.linalg.lstsq(J, d, rcond=None)[0], rtol=1e-9)
    noise = 0.1 * rng.normal(size=J.shape)  # two seeds' Jacobians: J^T J as sym(J1^T J2), J^T as their mean
    J1, J2 = J + noise, J - noise
    expected = -np.linalg.solve(0.5 * (J1.T @ J2 + J2.T @ J1), J.T @ d)
    np.testing.assert_allclose(systematic_step(J1, J2, d), expected, rtol=1e-9)


def linear_changes(A: np.ndarray, a: np.ndarray, c: np.ndarray, calls: list[np.ndarray] | None = None) -> GridChanges:
    """Residual changes linear in the values: each render's d_S(y) = A y + a +- y[0] a / 10 (their mean A y + a),
    d_C(y) = A y + c, the derivatives of d_S the columns of A; ``calls``: the values each is evaluated at."""
    def fine(y: np.ndarray) -> np.ndarray:
        (calls if calls is not None else []).append(y)
        return np.stack([A @ y + a + 0.1 * y[0] * a, A @ y + a - 0.1 * y[0] * a])

    return GridChanges(fine, lambda y, columns, last=False: (fine(y), A @ y + c, A[:, list(columns)].T))


def test_the_grid_step_is_the_fixed_point_of_the_step_and_carries_a_third_of_the_coarser_models_step():
    """Residual changes linear in the values, d_S(y) = A y + a and d_C(y) = A y + c, with a linear
    step S d = -(J^T J)^-1 J^T d: the fixed point delta = S d_S(x + delta) is (I - S A)^-1 S (A x + a),
    the bound what remains is a third of S (a - c), the step from the coarser model to the finer, and the
    render noise's draw the two renders' changes' difference over sqrt 2, all at the fixed point."""
    rng = np.random.default_rng(5)
    J, A = rng.normal(size=(40, 3)), 0.3 * rng.normal(size=(40, 3))
    a, c, x = rng.normal(size=40), rng.normal(size=40), np.array([0.8, 0.1, -0.2])
    S = -np.linalg.solve(J.T @ J, J.T)
    assert np.abs(np.linalg.eigvals(S @ A)).max() < 0.2  # a contraction
    fixed_point = np.linalg.solve(np.eye(3) - S @ A, S @ (A @ x + a))
    calls: list[np.ndarray] = []
    grid = grid_step(linear_changes(A, a, c, calls), lambda d: S @ d, x, np.full(3, 1e-12), [])
    np.testing.assert_allclose(grid.delta, fixed_point, rtol=0, atol=1e-12)
    np.testing.assert_allclose(grid.remainder, REMAINDER_RATIO * S @ (a - c), rtol=1e-9)
    np.testing.assert_allclose(grid.noise, 0.2 * (x + grid.delta)[0] * a / np.sqrt(2.0), rtol=1e-12)  # the draw at the fixed point
    # 3 values, linear: 4 evaluations reach it (GMRES's), the fifth's step within a hundredth of 1e-12
    assert REMAINDER_RATIO == 1.0 / 3.0 and grid.evaluations == 5 and len(calls) == 6 and not grid.feedback.any()
    calls.clear()
    grid = grid_step(linear_changes(A, a, c, calls), lambda d: S @ d, x, np.full(3, 1e3), [])  # within a hundredth of the errors
    assert np.abs(grid.delta - fixed_point).max() < 1e-2 * 1e3 and np.abs(grid.delta - S @ (A @ x + a)).max() > 1e-6
    assert len(calls) == 3  # the one step, the secant step from it within a hundredth of the errors, then its values settled


def contraction(rates: list[float], seed: int) -> tuple[GridChanges, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Changes d_S(y) = A y + a whose step's fixed-point map S A has eigenvalues ``rates`` (A = -J T, T = Q diag(rates) Q^-1,
    Q not orthogonal): the changes, S, x, the fixed point's delta, and the first plain step's largest value (a standard error)."""
    rng = np.random.default_rng(seed)
    n = len(rates)
    J, Q = rng.normal(size=(60, n)), np.eye(n) + 0.3 * rng.normal(size=(n, n))
    T = Q @ np.diag(rates) @ np.linalg.inv(Q)
    A, a, x = -J @ T, rng.normal(size=60), rng.normal(size=n)
    S = -np.linalg.solve(J.T @ J, J.T)
    return linear_changes(A, a, 0.0 * a), S, x, np.linalg.solve(np.eye(n) - T, S @ (A @ x + a)), np.abs(S @ (A @ x + a)).max()


def plain(changes: GridChanges, S: np.ndarray, x: np.ndarray, stderr: np.ndarray, steps: int) -> tuple[np.ndarray, int]:
    """The plain iteration delta = S d_S(x + delta) from 0 until it moves every value by at most a hundredth of ``stderr``
    (the stop rule before the acceleration), or ``steps`` times: delta and the evaluations."""
    delta, evaluations, moved = np.zeros(len(x)), 0, np.inf
    while evaluations < steps and np.any(np.abs(moved) > FIXED_POINT_TOLERANCE * stderr):
        stepped = S @ changes.fine(x + delta).mean(axis=0)
        moved, delta, evaluations = stepped - delta, stepped, evaluations + 1
    return delta, evaluations


def test_the_accelerated_fixed_point_is_the_long_plain_iterations_in_fewer_evaluations():
    """A fixed-point map of six values contracting at rates up to 0.7 (a 12-frame pass's slowest, 0.68): the plain
    iteration stopped at 8 evaluations leaves values more than 0.1 of a standard error short, and stopped where its last
    move is below a hundredth of one (after more than 8) still leaves them beyond that hundredth (short by up to 0.7 / 0.3
    of the move); Anderson's acceleration reaches the 60-step iteration's fixed point within the tolerance in at most
    n + 1 = 7 (GMRES's), and the distance it measures at its end (with D) is the true one."""
    changes, S, x, fixed_point, se = contraction([0.7, 0.6, 0.5, 0.3, 0.1, -0.2], 2)
    stderr = np.full(6, se)
    long, _ = plain(changes, S, x, stderr * 1e-20, 60)
    np.testing.assert_allclose(long, fixed_point, rtol=0, atol=1e-8 * se)
    capped, _ = plain(changes, S, x, stderr, FIXED_POINT_STEPS)
    settled, evaluations = plain(changes, S, x, stderr, 60)
    assert np.abs(capped - long).max() > 10 * FIXED_POINT_TOLERANCE * se
    assert evaluations > FIXED_POINT_STEPS and np.abs(settled - long).max() > FIXED_POINT_TOLERANCE * se
    grid = grid_step(changes, lambda d: S @ d, x, stderr, range(6))
    assert grid.evaluations <= 7 and np.abs(grid.delta - long).max() < FIXED_POINT_TOLERANCE * se
    np.testing.assert_allclose(grid.short, (fixed_point - grid.delta) / se, rtol=0, atol=1e-12)


def test_a_fixed_point_not_reached_in_its_evaluations_is_flagged_with_each_values_distance():
    """Twelve values contracting at rates from -0.9 to 0.95 (the plain iteration needs 45 evaluations): the eight
    accelerated ones leave values short; the distance measured at the end is the true one, each value beyond the
    tolerance is named with it in standard errors, and the fit's verdict is UNSETTLED (not over the solver's own
    MAX_STEPS, under a MISFIT; exit 3, as the solver's shortfalls)."""
    changes, S, x, fixed_point, se = contraction(list(np.linspace(-0.9, 0.95, 12)), 1)
    grid = grid_step(changes, lambda d: S @ d, x, np.full(12, se), range(12))
    np.testing.assert_allclose(grid.short, (fixed_point - grid.delta) / se, rtol=0, atol=1e-9)
    short = dict(zip([f"v{i}" for i in range(12)], grid.short))
    far = [name for name, s in short.items() if abs(s) > FIXED_POINT_TOLERANCE]
    assert grid.evaluations == FIXED_POINT_STEPS and 0 < len(far) <= 12
    notes = unsettled_notes({"image.shift_y_px@10": -0.183, "image.shift_y_px@11": 0.004, **short})
    assert notes[0] == ("image.shift_y_px@10: the pixel grid's step did not settle in 8 evaluations of the model made at 4x: its "
                        "fixed point is -0.18 standard errors from the value (the tolerance 0.01); the value and its error are "
                        "taken where the iterations stopped.")
    assert [n.split(":")[0] for n in notes[1:]] == far
    assert verdict(Status.CONVERGED, True, False, False, False, bool(notes)) is Status.UNSETTLED and not Status.UNSETTLED.success
    assert exit_code(Status.UNSETTLED) == NOT_CONVERGED  # exit 3, docs/reference/fits.md
    assert verdict(Status.MAX_STEPS, True, False, False, False, True) is Status.MAX_STEPS
    assert verdict(Status.CONVERGED, True, False, True, False, True) is Status.MISFIT
    assert verdict(Status.CONVERGED, True, False, False, False, bool(unsettled_notes({"a": 0.0099}))) is Status.CONVERGED


def test_image_columns_read_as_the_matrix_of_their_blocks_with_zeros_elsewhere():
    """Three images of 2, 3 and 4 rows, four columns: image 0 has columns 0 and 2, image 1 none, image 2 columns 2
    and 3; each column read (by index, from the end, in order) is the dense matrix's, and none past the last."""
    rng = np.random.default_rng(2)
    blocks = [([0, 2], rng.normal(size=(2, 2))), ([], np.zeros((0, 3))), ([2, 3], rng.normal(size=(2, 4)))]
    dense = np.zeros((4, 9))
    dense[[0, 2], 0:2] = blocks[0][1]
    dense[[2, 3], 5:9] = blocks[2][1]
    columns = ImageColumns(4, [2, 3, 4], blocks)
    assert len(columns) == 4 and np.array_equal(np.stack(list(columns)), dense) and np.array_equal(columns[-1], dense[3])
    with pytest.raises(IndexError):
        columns[4]


def test_the_fixed_point_moves_with_the_fits_estimate_by_the_inverse_of_one_less_the_steps_feedback():
    """With d_S(y) = A y + a and S d = -(J^T J)^-1 J^T d, the fixed point x* = x + delta(x) moves by
    (I - S A)^-1 per change of x: grid_step's feedback D is S A in the columns it is given (0 in the
    others), so that (I - D)^-1 C (I - D)^-T is the fixed point's covariance where x's is C."""
    rng = np.random.default_rng(7)
    J, A = rng.normal(size=(40, 3)), 0.3 * rng.normal(size=(40, 3))
    a = rng.normal(size=40)
    S = -np.linalg.solve(J.T @ J, J.T)
    changes = linear_changes(A, a, 0.0 * a)
    x, stderr = np.array([0.8, 0.1, -0.2]), np.full(3, 1e-12)
    D = grid_step(changes, lambda d: S @ d, x, stderr, [1, 2]).feedback
    np.testing.assert_allclose(D[:, 1:], (S @ A)[:, 1:], rtol=1e-9, atol=1e-12)
    assert not D[:, 0].any()
    D = grid_step(changes, lambda d: S @ d, x, stderr, [0, 1, 2]).feedback
    fixed_point = lambda y: y + grid_step(changes, lambda d: S @ d, y, stderr, []).delta  # noqa: E731
    moved = np.stack([(fixed_point(x + h) - fixed_point(x - h)) / 2e-3 for h in 1e-3 * np.eye(3)], axis=1)
    np.testing.assert_allclose(np.linalg.inv(np.eye(3) - D), moved, rtol=0, atol=1e-6)
    assert np.abs(moved - np.eye(3)).max() > 0.05  # the feedback is not negligible here: a constant step would be wrong


def test_a_box_render_binned_is_the_box_render_at_the_coarser_resolution():
    fine = np.random.default_rng(2).random((8, 12, 3))
    np.testing.assert_allclose(np.asarray(binned(jnp.asarray(fine), 2))[1, 2], fine[2:4, 4:6].mean(axis=(0, 1)), rtol=1e-6)
    assert binned(jnp.asarray(fine), 4).shape == (2, 3, 3)


def test_a_step_past_the_black_sky_records_each_images_values_and_reach_and_the_fit_is_unstepped():
    """Two frames, the blur shared, frame 1's shift x its own, frame 0's not free: the record holds the blur and the free
    shift at the result and where tried, and each frame's reach (5 sigma and the larger shift); the warning names the
    frame whose reach grew past its black sky (more than 1 px), or, none grown, a render not finite. The verdict is
    UNSTEPPED (exit 3) under a MISFIT, not over the solver's MAX_STEPS, and before UNSETTLED."""
    names = ["parts.legs.kd", "image.blur_sigma_px", "image.shift_x_px@1"]
    x, tried = np.array([0.5, 0.8, 0.3]), np.array([0.49, 0.9, -1.2])
    past = past_black_sky(names, x, tried, 2)
    assert past == {"values": {"image.blur_sigma_px": [0.8, 0.9], "image.shift_x_px@1": [0.3, -1.2]},
                    "reach_px": [[pytest.approx(4.0), pytest.approx(4.5)], [pytest.approx(4.3), pytest.approx(5.7)]]}
    assert black_sky_notes(past) == [
        "the pixel grid's step to the model made at 4x was not taken: its fixed point's iterations tried image.blur_sigma_px 0.9 "
        "(0.8 at the result), image.shift_x_px@1 -1.2 (0.3 at the result); there image 1's reach 5.7 px (4.3 px at the result): "
        "past the black sky its finer models were sized for (the reach at the result and 1 px; the reach is 5 sigma of the blur "
        "and the larger shift). The values and their standard errors are the fit's on the pixel grid, without the step, and carry "
        "neither the grid's model error nor a bound on it; fit at a finer resolution, or with the blur fixed."]
    assert "a render at 4x is not finite" in black_sky_notes(past_black_sky(names, x, x, 2))[0]
    assert black_sky_notes(None) == [] and past_black_sky(["parts.legs.kd"], x[:1], x[:1], 1) == {"values": {}, "reach_px": [None]}
    assert verdict(Status.CONVERGED, True, False, False, False, False, True) is Status.UNSTEPPED and not Status.UNSTEPPED.success
    assert verdict(Status.CONVERGED, True, False, False, False, True, True) is Status.UNSTEPPED
    assert verdict(Status.CONVERGED, True, False, True, False, False, True) is Status.MISFIT
    assert verdict(Status.MAX_STEPS, True, False, False, False, False, True) is Status.MAX_STEPS
    assert exit_code(Status.UNSTEPPED) == NOT_CONVERGED  # exit 3, docs/reference/fits.md


@pytest.mark.slow
def test_a_small_pass_s_accelerated_step_is_its_long_plain_iterations_and_a_cut_budget_is_flagged(tmp_path, monkeypatch):
    """Three frames of the panels case at 32 x 32 px through a sensor, the blur shared and each frame's shifts free:
    the fit's accelerated step is within a hundredth of a standard error of 60 plain iterations' fixed point from the
    same renders, in fewer evaluations than the plain iteration needs to move less than that, and the distance it
    measures at its end is the true one (to first order); with its budget cut to 2 evaluations the fit is UNSETTLED and its warnings
    name each value left short with its distance in standard errors."""
    import spacefit as sf
    from spacefit.fitting import pixel_grid, uncertainty

    base = sf.load_case("panels").truth_scene.with_values({"render.resolution": [32, 32], "camera.pixel_pitch_mm": 150.0})
    sensor = sf.Sensor(radiometric_scale_dn_per_w_m2_sr=500.0, gain_dn_per_electron=0.5, bias_dn=100.0, read_noise_electrons=5.0,
                       bit_depth=16, full_well_electrons=None, diffraction=False, psf_sigma_px=0.0)
    frames = sf.simulate_pass(base, sf.arc_pass(3), tmp_path / "pass", sensor=sensor, spp=64)
    obs = [sf.Observation.from_file(f.file, s) for f, s in zip(frames.frames, frames.scenes(base))]
    free = ["parts.legs.kd", "image.blur_sigma_px", *frames.per_frame(["image.shift_x_px", "image.shift_y_px"])]
    seen: list[tuple] = []
    real = uncertainty.grid_step

    def kept(changes: GridChanges, *args: object) -> object:  # the renders kept for the plain iterations below: no `last`
        held = GridChanges(changes.fine, lambda y, columns, last=False: changes.settled(y, columns))
        seen.append(((held, *args), real(held, *args)))
        return seen[-1][1]

    monkeypatch.setattr(uncertainty, "grid_step", kept)
    monkeypatch.setattr(pixel_grid, "FIXED_POINT_STEPS", 2)
    result = sf.fit(obs, free, start={"parts.legs.kd": 0.45}, render=sf.FitRender(spp=8), max_steps=8)
    (changes, step, x, stderr, columns), cut = seen[-1]
    short = result.extras["pixel_grid_short"]
    far = {name: s for name, s in short.items() if abs(s) > FIXED_POINT_TOLERANCE}
    assert result.status is Status.UNSETTLED and cut.evaluations == 2 and far
    np.testing.assert_allclose(list(short.values()), cut.short, rtol=1e-12)
    assert result.warnings[0] == f"the fit did not succeed ({Status.UNSETTLED})."
    assert [w for w in result.warnings if "did not settle" in w] == [
        f"{name}: the pixel grid's step did not settle in 2 evaluations of the model made at 4x: its fixed point is {s:+.2g} standard "
        "errors from the value (the tolerance 0.01); the value and its error are taken where the iterations stopped."
        for name, s in far.items()]
    monkeypatch.undo()
    with jax.enable_x64(True):  # as the fit's programs were traced
        grid = grid_step(changes, step, x, stderr, columns)
        long, evaluations = np.zeros(len(x)), []
        for _ in range(60):
            moved, long = long, step(changes.fine(x + long).mean(axis=0))
            evaluations.append(np.abs((long - moved) / stderr).max())
    plain_evaluations = next(k for k, m in enumerate(evaluations, 1) if m <= FIXED_POINT_TOLERANCE)
    assert evaluations[-1] < 1e-6 and grid.evaluations < plain_evaluations
    assert np.abs((grid.delta - long) / stderr).max() < FIXED_POINT_TOLERANCE
    np.testing.assert_allclose(grid.short, (long - grid.delta) / stderr, rtol=0, atol=0.1 * FIXED_POINT_TOLERANCE)
    # the cut step's distance, 0.2 of a standard error at most, to first order: measured within 0.3 of it (0.26 the worst)
    np.testing.assert_allclose(cut.short, (long - cut.delta) / stderr, rtol=0.3, atol=0.1 * FIXED_POINT_TOLERANCE)


def test_the_grid_step_compiles_its_last_programs_on_a_thread_beside_the_iterations_and_raises_its_error():
    """grid_step hands ``ahead`` the fit's values and the columns once, on a thread of its own while the fixed point's
    iterations run (in the caller's 64-bit mode), and the same step comes out; an error there is the step's."""
    rng = np.random.default_rng(5)
    J, A = rng.normal(size=(40, 3)), 0.3 * rng.normal(size=(40, 3))
    a, c = rng.normal(size=40), rng.normal(size=40)
    step = lambda d: -np.linalg.lstsq(J, d, rcond=None)[0]  # noqa: E731
    x = np.array([0.1, -0.2, 0.3])
    plain = grid_step(linear_changes(A, a, c), step, x, np.ones(3), [0, 2])
    seen = []
    changes = dataclasses.replace(linear_changes(A, a, c), ahead=lambda y, columns: seen.append(
        (threading.current_thread().name, y.copy(), list(columns), bool(jax.config.jax_enable_x64))))
    with jax.enable_x64(True):
        early = grid_step(changes, step, x, np.ones(3), [0, 2])
    assert len(seen) == 1 and seen[0][0].startswith("spacefit-ahead") and seen[0][2:] == ([0, 2], True)
    np.testing.assert_array_equal(seen[0][1], x)
    np.testing.assert_array_equal(early.delta, plain.delta)

    def fails(y: np.ndarray, columns: list[int]) -> None:
        raise MemoryError("compiling ahead")

    with pytest.raises(MemoryError, match="compiling ahead"):
        grid_step(dataclasses.replace(linear_changes(A, a, c), ahead=fails), step, x, np.ones(3), [0, 2])
