"""Renders made before JAX's programs run (spacefit.fitting.outside): the same residuals, tangents and solver steps as
the programs that call back into Python for them."""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import spacefit as sf
from spacefit.fitting import drivers, frames, render_batches
from spacefit.fitting.loop import _rendered_first
from spacefit.fitting.drivers import RenderedFirst, Step, drive
from spacefit.fitting.solvers import make_solver
from spacefit.precision import float64
from spacefit.fitting.problem import setup

# the panels case at 32 x 32 px, 8 spp: a material (forward-mode column), an attitude (finite differences) and the
# PSF width and a shift (image nuisances) free
SMALL = {"render.resolution": [32, 32], "camera.pixel_pitch_mm": 75.0, "render.spp": 8}
FREE = ["parts.panels.alpha_x", "parts.legs.kd", "target.attitude_x_deg", "image.blur_sigma_px", "image.shift_x_px"]
START = {"parts.panels.alpha_x": 0.18, "parts.legs.kd": 0.6, "target.attitude_x_deg": 0.4, "image.blur_sigma_px": 0.6,
         "image.shift_x_px": 0.2}


@pytest.fixture(scope="module")
def small():
    case = sf.load_case("panels").with_values(SMALL)
    reference = np.asarray(sf.render(case.truth_scene.with_values({"render.spp": 64})))
    return float64(lambda: setup(sf.Observation(case.scene(), reference, sigma=0.01), FREE, start=START))()


def close(a, b) -> None:
    """Equal but for the rounding of the image model compiled in another program."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    np.testing.assert_allclose(a, b, rtol=1e-5, atol=1e-5 * np.abs(b).max())


@pytest.mark.slow  # 4 Jacobian renders and 2 primal renders at 32 x 32 px, programs compiled: about 15 s at load 10
@float64
def test_renders_made_first_give_the_callbacks_residuals_and_tangents(small):
    problem, x = small.problem, jnp.asarray(small.x0)
    assert problem.outside is not None
    for j, residuals in enumerate((problem.residual_x, problem.residual_x_independent)):
        r, J = problem.linearised(x, j)
        r_cb, J_cb = jax.linearize(residuals, x)
        close(r, r_cb)
        for e in np.eye(len(x)):
            close(J(jnp.asarray(e)), J_cb(jnp.asarray(e)))
    close(problem.descent_at(x, 1), problem.descent_x_independent(x))


@pytest.mark.slow  # two solves of 4 steps at 32 x 32 px, their steps compiled: about 30 s at load 10
@float64
def test_the_solver_steps_the_same_on_renders_made_first(small):
    """Levenberg-Marquardt from the start, 4 steps: stepped on renders made before each step, it evaluates the
    same trial points with the same losses as stepped on the renders its compiled step calls back for."""
    fp, problem = small.solver_params, small.problem
    u = jnp.asarray(fp.to_unconstrained(jnp.asarray(small.x0)))

    def residual_u(y: jax.Array) -> jax.Array:
        return problem.descent_x(fp.to_physical(y)).astype(y.dtype)

    assert _rendered_first(small).columns_held  # an image fitted alone: its Jacobian's columns held in the solver's state
    solves = [list(drive(make_solver("lm"), residual_u, u, 4, None, rendered_first)) for rendered_first in (None, _rendered_first(small))]
    assert [len(s) for s in solves] == [4, 4]
    for called_back, first in zip(*solves):
        np.testing.assert_allclose(first.u, called_back.u, rtol=1e-5, atol=1e-7)  # the rounding of two programs
        assert first.loss == pytest.approx(called_back.loss, rel=1e-6)
    assert solves[1][-1].loss < 0.5 * solves[1][0].loss  # the solve moved: the comparison is of steps taken


@pytest.mark.slow  # two Jacobian renders at 32 x 32 px
@float64
def test_renders_begun_ahead_are_the_renders_made_in_turn(small):
    """``render_ahead``'s renders, made on a thread while the caller works, are those ``linearisable`` makes in turn, bit
    for bit, and are taken once."""
    outside, x = small.problem.outside, np.asarray(small.x0)
    outside.render_ahead(x, 1)
    assert len(outside.ahead) == 1
    ahead = outside.linearisable(x, 1)
    assert not outside.ahead
    outside.linearisable(1.01 * x, 1)  # another point: the frames' last Jacobian (frames.frame_jacobian) no longer x's
    in_turn = outside.linearisable(x, 1)
    for a, b in zip(jax.tree.leaves(ahead), jax.tree.leaves(in_turn), strict=True):
        assert a is not b
        np.testing.assert_array_equal(a, b)


def _stepped(small, solver: str, max_steps: int, rendered_first: RenderedFirst) -> list[Step]:
    """The steps of ``solver`` from the start of ``small`` on ``rendered_first``'s renders."""
    u = jnp.asarray(small.solver_params.to_unconstrained(jnp.asarray(small.x0)))
    return list(drive(make_solver(solver), None, u, max_steps, None, rendered_first))


def _every_trial_linearised(given: RenderedFirst) -> RenderedFirst:
    """``given`` rendering every trial point's Jacobian with its images (the driver's renders before rejected trials
    were stepped on their images alone)."""
    return dataclasses.replace(given, render=lambda u, jacobian: given.render(u, True), linearised=lambda u, operands: operands)


def _assert_same_steps(steps: list[Step], reference: list[Step]) -> None:
    assert len(steps) == len(reference)
    for a, b in zip(steps, reference):
        for got, expected in [(a.u, b.u), (a.residuals, b.residuals), (a.iterate, b.iterate), (a.next_u, b.next_u)]:
            np.testing.assert_array_equal(np.asarray(got), np.asarray(expected))
        assert a.loss == b.loss


@pytest.fixture
def jacobian_renders(monkeypatch):
    """Per Jacobian render of a frame (frames.frame_jacobian, as frames.frame_columns and render_batches call it),
    whether its image was given (rendered before)."""
    calls: list[bool] = []
    render = frames.frame_jacobian

    def counted(spec, key, x, seed, seed_grad, loaded=None, image=None):
        calls.append(image is not None)
        return render(spec, key, x, seed, seed_grad, loaded, image)

    monkeypatch.setattr(frames, "frame_jacobian", counted)
    monkeypatch.setattr(render_batches, "frame_jacobian", counted)
    return calls


@pytest.mark.slow  # two solves of 7 steps at 32 x 32 px: about 20 s at load 7
@float64
def test_a_trial_rejected_on_its_loss_renders_no_jacobian_and_steps_the_same_bits(small, jacobian_renders):
    """Levenberg-Marquardt from the start, 7 steps, the last two rejected (their losses above the best): stepped on their
    images alone, zeros in their Jacobian's place, the solver's states are those stepped on their Jacobians, bit for
    bit, and no Jacobian is rendered for them; an accepted trial's columns are rendered beside its images."""
    reference = _stepped(small, "lm", 7, _every_trial_linearised(_rendered_first(small)))
    assert len(jacobian_renders) == 7
    jacobian_renders.clear()
    steps = _stepped(small, "lm", 7, _rendered_first(small))
    _assert_same_steps(steps, reference)
    rejected = [k for k in range(1, 7) if steps[k].loss > min(s.loss for s in steps[:k])]
    assert rejected == [5, 6]
    assert jacobian_renders == [False, True, True, True, True]  # the start's with its image, then the accepted trials'


@pytest.mark.slow  # two solves of 6 steps at 32 x 32 px: about 15 s at load 7
@float64
def test_a_trial_stepped_on_its_images_alone_and_accepted_is_stepped_again_on_its_jacobian(small, jacobian_renders, monkeypatch):
    """Gauss-Newton accepts every step, a rise of the loss too: told that it rejects on the loss as a trust region does,
    the driver steps its rising trial on its images alone, sees the step accept it, and steps it again on its Jacobian:
    the same states bit for bit as stepped on every trial's Jacobian."""
    reference = _stepped(small, "gn", 6, _every_trial_linearised(_rendered_first(small)))
    assert reference[-1].loss > reference[-2].loss  # the last trial's loss rose: the driver steps it without its Jacobian first
    jacobian_renders.clear()
    monkeypatch.setattr(drivers, "_rejects_above", lambda solver: True)
    _assert_same_steps(_stepped(small, "gn", 6, _rendered_first(small)), reference)
    assert jacobian_renders == [False, True, True, True, True, True]


@pytest.mark.slow  # three primal renders at 32 x 32 px
@float64
def test_images_begun_ahead_are_the_images_made_in_turn(small):
    """``render_images_ahead``'s images, made on a thread while the caller works, are those ``residuals`` renders in turn,
    bit for bit, and are taken once; a point begun after another replaces it."""
    outside, x = small.problem.outside, np.asarray(small.x0)
    outside.render_images_ahead(1.01 * x, 1)
    outside.render_images_ahead(x, 1)
    assert len(outside.images_ahead) == 1
    ahead = outside.residuals(jnp.asarray(x), 1)
    assert not outside.images_ahead
    np.testing.assert_array_equal(ahead, outside.residuals(jnp.asarray(x), 1))


@pytest.mark.slow  # a primal render and three Jacobian renders at 32 x 32 px
@float64
def test_a_point_s_images_are_rendered_once_per_seed_index(small, jacobian_renders, monkeypatch):
    """The images rendered at a point with seed index j are those asked there again, and beside them the point's Jacobian
    renders its columns alone; the images of the renders kept are not rendered again either: the renders made from nothing,
    bit for bit."""
    primals: list[int] = []
    render = render_batches.frame_primal

    def counted(spec, key, x, seed, loaded=None):
        primals.append(seed)
        return render(spec, key, x, seed, loaded)

    monkeypatch.setattr(render_batches, "frame_primal", counted)
    outside, x = small.problem.outside, 1.02 * np.asarray(small.x0)  # a point no test rendered before
    residuals = outside.residuals(jnp.asarray(x), 1)
    linearisable = outside.linearisable(x, 1)
    np.testing.assert_array_equal(outside.residuals(jnp.asarray(x), 1), residuals)
    assert len(primals) == 1 and jacobian_renders == [True]  # the Jacobian's columns beside the images
    outside.keep(x, 0, outside.render(x, 0, True))
    assert outside.images(x, 0)[0] is outside.kept[next(iter(outside.kept))][0] and len(primals) == 1
    outside.render(1.01 * x, 1, True)  # another point: the frames' last Jacobian (frames.frame_jacobian) no longer x's
    jacobian_renders.clear()
    from_nothing = outside.render(x, 1, True)
    assert jacobian_renders == [False]
    for a, b in zip(jax.tree.leaves(linearisable), jax.tree.leaves(from_nothing), strict=True):
        np.testing.assert_array_equal(a, b)
    y = 1.03 * x  # another point, the same seed index: its own images, not the last ones (x's)
    for a, b, at_x in zip(jax.tree.leaves(outside.images(y, 1)[0]), jax.tree.leaves(outside.render(y, 1, False)[0]),
                          jax.tree.leaves(from_nothing[0]), strict=True):
        np.testing.assert_array_equal(a, b)
        assert not np.array_equal(a, at_x)
