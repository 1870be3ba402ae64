"""A fit step's frames' renders as one JAX function: :func:`batched_renders`, "free values -> every frame's image",
whose single callback hands the batch to an executor (:func:`~spacefit.fitting.frames.run_frames`), its derivative
each frame's Jacobian columns times the tangent; :func:`given_renders`, the same with the renders made beforehand
(:func:`frame_renders`) as operands. The frames stack in runs of one image shape (:func:`render_runs`)."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from spacefit.executors import Executor
from spacefit.fitting.frames import FrameSpec, frame_columns, frame_jacobian, frame_primal, run_frames


def render_runs(shapes: Sequence[tuple[int, int, int]], indices: Sequence[np.ndarray]) -> list[range]:
    """The frames as runs of consecutive frames whose renders stack: one image shape and one count of
    free values seen (Jacobian columns) in each run (a pass's frames: one run)."""
    runs: list[range] = []
    for k, (shape, idx) in enumerate(zip(shapes, indices)):
        if runs and (tuple(shapes[runs[-1].start]), len(indices[runs[-1].start])) == (tuple(shape), len(idx)):
            runs[-1] = range(runs[-1].start, k + 1)
        else:
            runs.append(range(k, k + 1))
    return runs


def _stacked(per_frame: Sequence[np.ndarray], runs: Sequence[range]) -> tuple[np.ndarray, ...]:
    """Per-frame arrays stacked per run, (frames, ...); a run of one frame as a view (no copy)."""
    return tuple(per_frame[run.start][None] if len(run) == 1 else np.stack([per_frame[k] for k in run]) for run in runs)


def frame_renders(executor: Executor, specs: Sequence[FrameSpec], indices: Sequence[np.ndarray], runs: Sequence[range], x: np.ndarray,
                  seeds: np.ndarray, jacobian: bool, images: tuple[np.ndarray, ...] | None = None) -> tuple[
                      tuple[np.ndarray, ...], tuple[np.ndarray, ...] | None]:
    """Every frame's image, frame k's at ``x[indices[k]]``, for the seeds ``seeds``
    (:func:`~spacefit.rendering.bridge.seeds_array`), stacked per run of ``runs`` (:func:`render_runs`;
    (frames, h, w, 3) each), and with ``jacobian`` each run's Jacobian columns (frames, h, w, 3, n)
    (None without): one batch on ``executor``. ``images``: the images at x for these seeds, made before (this
    function's without ``jacobian``): with ``jacobian``, the columns alone are rendered, beside them."""
    x, seeds = np.asarray(x), np.asarray(seeds)  # JAX may hand a callback its own arrays (each index of one compiles)
    if not jacobian:
        return _stacked(run_frames(executor, frame_primal, specs, [x[idx] for idx in indices], [int(seeds[0])] * len(specs)), runs), None
    per_frame = [[x[idx] for idx in indices], [int(seeds[0])] * len(specs), [int(seeds[1])] * len(specs)]
    if images is None:
        out = run_frames(executor, frame_jacobian, specs, *per_frame)
    else:
        out = run_frames(executor, frame_columns, specs, *per_frame, [images[i][k - run.start] for i, run in enumerate(runs) for k in run])
    return _stacked([img for img, _ in out], runs) if images is None else images, _stacked([J for _, J in out], runs)


def _run_indices(indices: Sequence[np.ndarray], runs: Sequence[range]) -> list[np.ndarray]:
    """Per run, where each of its frames' values are in x, (frames, n)."""
    return [np.stack([indices[k] for k in run]) for run in runs]


def _tangents(jacobians: Sequence[jax.Array], t: jax.Array, seen: Sequence[np.ndarray]) -> tuple[jax.Array, ...]:
    """Each run's image change along the free values' change ``t``: each frame's Jacobian columns times its
    share of ``t`` (``seen``: (frames, n) per run, where each frame's values are in x), one product per run."""
    return tuple(jnp.einsum("f...n,fn->f...", J, t[idx].astype(jnp.float32)) for J, idx in zip(jacobians, seen))


def batched_renders(executor: Executor, specs: Sequence[FrameSpec], indices: Sequence[np.ndarray],
                    shapes: Sequence[tuple[int, int, int]]) -> Callable[[jax.Array, jax.Array], tuple[jax.Array, ...]]:
    """Every frame's image as one JAX function of the fit's free values x and the seeds
    (:func:`~spacefit.rendering.bridge.seeds_array`; an operand, so that one compiled program serves
    the fit's seeds and the independent ones): frame k renders ``x[indices[k]]``; the images come
    stacked, one (frames, h, w, 3) array per :func:`render_runs` run. Its derivative is each frame's
    materialised Jacobian times the tangent, as :func:`~spacefit.rendering.bridge.render_params`'s, with
    all frames' Jacobians in one batch and one product per run, whatever its frames. A program that
    calls it calls back into Python (:func:`given_renders` takes the renders as operands)."""
    runs = render_runs(shapes, indices)
    images = tuple(jax.ShapeDtypeStruct((len(run), *shapes[run.start]), jnp.float32) for run in runs)
    columns = tuple(jax.ShapeDtypeStruct((len(run), *shapes[run.start], len(indices[run.start])), jnp.float32) for run in runs)
    seen = _run_indices(indices, runs)

    def primal_cb(x: np.ndarray, seeds: np.ndarray) -> tuple[np.ndarray, ...]:
        return frame_renders(executor, specs, indices, runs, x, seeds, False)[0]

    def jacobian_cb(x: np.ndarray, seeds: np.ndarray) -> tuple[tuple[np.ndarray, ...], tuple[np.ndarray, ...] | None]:
        return frame_renders(executor, specs, indices, runs, x, seeds, True)

    # Evaluated eagerly (not traced: jax.block_until_ready passes tracers through), each callback is waited
    # for before the caller dispatches work on its outputs. The callbacks render through JAX themselves
    # (each frame's bridge function), and XLA's CPU client runs a bounded number of computations at once:
    # the reductions queued on a light curve's 24 images took every slot, the callback's own renders
    # waited for one, and the fit hung in its verdict (issue 34; both threads in xla::Semaphore::Acquire).
    @jax.custom_jvp
    def render(x: jax.Array, seeds: jax.Array) -> tuple[jax.Array, ...]:
        return jax.block_until_ready(jax.pure_callback(primal_cb, images, x, seeds, vmap_method="sequential"))

    @render.defjvp
    def render_jvp(primals: tuple[jax.Array, jax.Array], tangents: tuple[jax.Array, jax.Array]) -> tuple[Any, Any]:
        (x, seeds), (t, _) = primals, tangents
        imgs, Js = jax.block_until_ready(jax.pure_callback(jacobian_cb, (images, columns), x, seeds, vmap_method="sequential"))
        return imgs, _tangents(Js, t, seen)

    return render


def given_renders(indices: Sequence[np.ndarray], runs: Sequence[range]) -> Callable[
        [jax.Array, Sequence[jax.Array], Sequence[jax.Array] | None], tuple[jax.Array, ...]]:
    """``(x, images, jacobians) -> images``: :func:`batched_renders`'s function with its renders made
    beforehand (:func:`frame_renders` at x, stacked per run of ``runs``) and handed in as operands, so that
    a program that calls it calls nothing back and JAX's cache can keep it; its derivative in x is each
    frame's Jacobian times the tangent, as :func:`batched_renders`'s (``jacobians`` None: not differentiable)."""
    seen = _run_indices(indices, runs)

    @jax.custom_jvp
    def given(x: jax.Array, images: Sequence[jax.Array], jacobians: Sequence[jax.Array] | None) -> tuple[jax.Array, ...]:
        return tuple(images)

    @given.defjvp
    def given_jvp(primals: tuple[Any, Any, Any], tangents: tuple[Any, Any, Any]) -> tuple[Any, Any]:
        (_, images, jacobians), (t, _, _) = primals, tangents
        return tuple(images), _tangents(jacobians, t, seen)

    return given
