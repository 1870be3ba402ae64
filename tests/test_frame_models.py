"""A fit's image models by batches (spacefit.fitting.frame_models): the frames alike are one program whatever
their count, each batch's models, residuals and derivatives equal its frames' own, and frames that differ
(another size, other free nuisances) are batched apart."""

from __future__ import annotations

import threading

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import spacefit as sf
from spacefit.fitting import problem
from spacefit.fitting.frame_models import FrameModels, concurrently, frame_model, meanwhile
from spacefit.fitting.render_batches import render_runs
from spacefit.fitting.losses import AffineVariance, residual_fn
from spacefit.precision import float64

NAMES = ("parts.legs.kd", "image.blur_sigma_px", "image.scale@0", "image.scale@1", "image.scale@2", "image.scale@3",
         "image.scale@4", "image.offset_w_m2_sr@5")


def made(k: int, shape: tuple[int, int, int], rng: np.random.Generator) -> tuple:
    """Frame k's model against its own reference, mask and per-pixel factor (a sensor's DN)."""
    reference = rng.uniform(100.0, 200.0, shape).astype(np.float32)
    mask = rng.uniform(size=shape) > 0.1
    factor = rng.uniform(50.0, 150.0, shape)
    noise = AffineVariance(3.0, 0.5, 100.0)
    return frame_model(NAMES, k, lambda image: 100.0 + factor * image, residual_fn(reference, "pixel", noise, mask),
                       residual_fn(reference, "pixel", noise, mask, descent=True))


@float64
def test_each_batch_equals_its_frames_own_models_and_derivatives():
    """Three 8 x 8 frames alike, one 6 x 6, then two 8 x 8 whose free nuisances differ: batched as [0, 1, 2], [3],
    [4], [5]; the models, both residuals and their derivatives in the free values and the renders equal each
    frame's own function evaluated alone, to float64 rounding."""
    rng = np.random.default_rng(0)
    shapes = [(8, 8, 3)] * 3 + [(6, 6, 3)] + [(8, 8, 3)] * 2
    frames = [made(k, shape, rng) for k, shape in enumerate(shapes)]
    runs = render_runs(shapes, [np.arange(1)] * len(shapes))
    assert runs == [range(0, 3), range(3, 4), range(4, 6)]
    models = FrameModels([m for m, _ in frames], [v for _, v in frames], runs, shapes, recompute=True)
    batches = models.batches(np.dtype(np.float64))
    assert [b.frames for b in batches] == [range(0, 3), range(3, 4), range(4, 5), range(5, 6)]
    # the batch of three stacks the arrays that differ (references, masks, factors); an image alone holds its own, every
    # array of each an operand of the programs that evaluate it (FrameModels.operands)
    assert [len(b.own) > 0 for b in batches] == [True, False, False, False] and all(b.common for b in batches[1:])
    assert [len(own) + len(common) for own, common in models.operands(np.dtype(np.float64))] == [
        len(b.own) + len(b.common) for b in batches]
    renders = [rng.uniform(0.0, 1.0, shapes[k]).astype(np.float32) for k in range(len(shapes))]
    stacked = [jnp.stack([renders[k] for k in run]) for run in runs]
    x = jnp.asarray([0.4, 0.7, 1.1, 0.9, 1.2, 1.0, 0.8, 0.05])

    def batched(x: jax.Array, stacked: list[jax.Array]) -> tuple[list[jax.Array], jax.Array, jax.Array]:
        return models(stacked, x)

    def alone(x: jax.Array, stacked: list[jax.Array]) -> tuple[list[jax.Array], jax.Array, jax.Array]:
        out = [frames[k][0](stacked[r][k - run.start], x[frames[k][1]]) for r, run in enumerate(runs) for k in run]
        return [o[0] for o in out], jnp.concatenate([o[1] for o in out]), jnp.concatenate([o[2] for o in out])

    tangents = (jnp.asarray(rng.normal(size=x.shape)), [jnp.asarray(rng.normal(size=s.shape), dtype=jnp.float32) for s in stacked])
    (got, got_t), (want, want_t) = (jax.jvp(jax.jit(fn), (x, stacked), tangents) for fn in (batched, alone))
    np.testing.assert_allclose(np.concatenate([np.ravel(m) for m in got[0]]), np.concatenate([np.ravel(m) for m in want[0]]), rtol=1e-12)
    for i in (1, 2):
        np.testing.assert_allclose(got[i], want[i], rtol=1e-12, atol=1e-12 * np.abs(want[i]).max())
        np.testing.assert_allclose(got_t[i], want_t[i], rtol=1e-9, atol=1e-9 * np.abs(want_t[i]).max())
    assert [m.shape[0] for m in got[0]] == [3, 1, 1, 1]


def equations(jaxpr: jax.extend.core.Jaxpr) -> int:
    """How many equations a program holds, those of the programs inside it included."""
    return len(jaxpr.eqns) + sum(equations(sub) for sub in jax.extend.core.subjaxprs(jaxpr))


@pytest.mark.parametrize("loss", ["pixel", "pyramid"])
@float64
def test_a_joint_fit_s_step_holds_one_frames_model_whatever_the_frames(loss):
    """A pass of 2 and of 5 frames (the blur shared, each frame's attitude, shift and scale its own): its
    residuals and their linearisation trace to programs of the same size, one frame's model in each, those
    that call back for the renders and those that take them made first (spacefit.fitting.outside), stacked."""
    sizes = []
    for n in (2, 5):
        base = sf.load_scene("spacefit/synthetic/panels.toml", {"render.resolution": [12, 12], "camera.pixel_pitch_mm": 200.0})
        columns = {"file": [f"f{k}.exr" for k in range(n)], "time": list(range(n))}
        frames = sf.Pass.from_columns({**columns, **{key: [f[key] for f in sf.arc_pass(n)] for key in sf.arc_pass(n)[0]}})
        obs = [sf.Observation(scene, np.full((12, 12, 3), 0.1), sigma=0.02) for scene in frames.scenes(base)]
        free = ["parts.legs.kd", "image.blur_sigma_px", *frames.per_frame(["target.attitude_x_deg", "image.shift_x_px", "image.scale"])]
        s = problem.setup(obs, free, loss=loss, render=sf.FitRender(spp=2))
        x = jnp.asarray(s.x0)
        images, jacobians = s.problem.outside.render(np.asarray(x), 0, True)
        assert [i.shape for i in images] == [(n, 12, 12, 3)]  # one run, the frames stacked
        evaluate, operands = s.problem.outside.evaluate, s.problem.outside.operands(x.dtype)
        # the frames' own arrays are the program's operands: it calls nothing back, so JAX's persistent cache keeps it
        assert "callback" not in str(jax.make_jaxpr(evaluate)(x, images, jacobians, operands))
        sizes.append((equations(jax.make_jaxpr(s.problem.residual_x)(x).jaxpr),
                      equations(jax.make_jaxpr(lambda v, s=s, x=x: jax.linearize(s.problem.residual_x, x)[1](v))(x).jaxpr),
                      equations(jax.make_jaxpr(lambda y, i, J, o, f=evaluate: jax.linearize(lambda z: f(z, i, J, o)[1], y)[1](y))(
                          x, images, jacobians, operands).jaxpr)))
    assert sizes[0] == sizes[1]


@float64
def test_the_images_programs_run_on_threads_in_order_in_the_callers_64_bit_mode():
    """concurrently: the first call here, the others on threads of their own, their results in the calls' order, each
    in the caller's 64-bit mode (a thread's own: float32 there would run other programs)."""
    calls = [lambda k=k: (threading.current_thread().name, jnp.asarray(np.float64(k) / 3).dtype, k) for k in range(5)]
    out = concurrently(calls)
    assert [k for *_, k in out] == list(range(5)) and all(dtype == jnp.float64 for _, dtype, _ in out)
    assert out[0][0] == threading.current_thread().name and all(name.startswith("spacefit-programs") for name, *_ in out[1:])


@float64
def test_meanwhile_runs_its_call_beside_the_block_in_the_callers_mode_and_raises_its_error_at_the_end():
    """meanwhile: the call on a thread of its own, in the caller's 64-bit mode, done by the block's end; its error raised
    there; the block's own error raised in its place where the block raised; None runs nothing."""
    seen = []
    with meanwhile(lambda: seen.append((threading.current_thread().name, jnp.asarray(np.float64(1) / 3).dtype))):
        pass
    assert seen == [(seen[0][0], jnp.float64)] and seen[0][0].startswith("spacefit-ahead")

    def fails() -> None:
        raise ValueError("from the thread")

    with pytest.raises(ValueError, match="from the thread"):
        with meanwhile(fails):
            pass
    with pytest.raises(KeyError, match="the block's"):
        with meanwhile(fails):
            raise KeyError("the block's")
    with meanwhile(None):
        seen.append("block")
    assert seen[-1] == "block"
