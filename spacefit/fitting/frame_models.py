"""A fit's image models and residuals: each image's own, and one program for the images alike.

An image's model is its render with its image nuisances applied (:mod:`spacefit.fitting.nuisance`), in
its data's unit (a sensor's expected DN), and its residuals against its reference, those judged and
those a solver descends (:mod:`spacefit.fitting.observations.image`): a :data:`FrameModel` of the
render and the nuisances' values. Traced image by image into a solver's compiled step, a pass of F
frames put F copies of that model in the step's program (its normal equations apply each one
linearised and transposed), and XLA's compilation of the step held about 100 MiB a frame
(docs/measurements/performance-history.md, "A pass's memory"). The frames whose models are one program holding
other arrays (their reference, mask, a sensor's per-pixel factors: a pass's frames) are evaluated as
one :class:`Batch`: the program traced once (:func:`jax.make_jaxpr`, two frames' programs equal where
their printed forms are, literals included), its arrays stacked over the frames and run frame after
frame by :func:`jax.lax.map`, so that the step holds one frame's program, and one frame's temporaries,
whatever the count. Images of another size, other free nuisances or other sensor settings (or the
``stats`` loss's lit pixels) make batches of their own; an image alone is a batch of one.

*A program's arrays are its operands* (:mod:`spacefit.programs`). Every array a model holds (a reference, a mask, a
sensor's per-pixel factors) is taken out of its traced program (:func:`~spacefit.programs.operand_program`) and handed
to every program that evaluates it as an operand (:meth:`FrameModels.operands`): closed over, JAX embedded each as a
constant in every program's module (the 8-parameter observation fit's step 5.6 MB, issue 33).
In a joint fit each model is recomputed where linearised (:func:`jax.checkpoint`): a linearisation
kept every intermediate of the image model and the sensor's (76 image-sized float64 arrays a frame,
26 MiB at 128 x 128 px) in each of the solver's two copies of it, where it keeps the render, the
values and the frame's arrays; an image fitted alone is not recomputed (its CPU time is the concern,
not its memory).
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import TypeVar

import jax
import jax.numpy as jnp
import numpy as np
from jax.extend.core import ClosedJaxpr
from jaxtyping import Array, Float

from spacefit.fitting.nuisance import nuisance_indices, with_nuisances
from spacefit.precision import on_device
from spacefit.programs import operand_program, traced_alike

T = TypeVar("T")
# (render (h, w, 3) float32, the image's nuisance values (p,)) -> (model, residuals, descended residuals)
FrameModel = Callable[[Float[Array, "h w 3"], Float[Array, " p"]], tuple[Array, Array, Array]]


def frame_model(names: Sequence[str], k: int, to_unit: Callable[[Array], Array], residual: Callable[[Array], Array],
                descent: Callable[[Array], Array]) -> tuple[FrameModel, np.ndarray]:
    """Image k's :data:`FrameModel`, from its render in its data's unit (``to_unit``) and its residual
    functions (judged and descended), and where its nuisance values are in the free ``names``."""
    index = nuisance_indices(names, k)

    def model(render: Array, values: Array) -> tuple[Array, Array, Array]:
        image = to_unit(with_nuisances(render, dict(zip(index, values))))
        return image, residual(image), descent(image)

    return model, np.fromiter(index.values(), dtype=int, count=len(index))


@dataclass(frozen=True)
class Batch:
    """Consecutive images evaluated as one.

    Attributes:
        frames: the images, in the fit's order.
        run: the render run they are in (:func:`~spacefit.fitting.render_batches.render_runs`), from ``offset``.
        values: (images, p) where each one's nuisance values are in the free values.
        program: the first image's model traced, its arrays its first operands (:func:`~spacefit.programs.operand_program`).
        own: the program's arrays that differ between the images, each stacked (images, ...), once, on the device.
        common: those every image shares (all of an image alone's), on the device.
        consts: per array of ``program``, where it is: (True, i) ``own[i]``, (False, i) ``common[i]``.
    """

    frames: range
    run: int
    offset: int
    values: np.ndarray
    program: Callable[..., list[Array]]
    own: tuple[Array, ...] = ()
    common: tuple[Array, ...] = ()
    consts: tuple[tuple[bool, int], ...] = ()


def batches(models: Sequence[FrameModel], values: Sequence[np.ndarray], runs: Sequence[range],
            shapes: Sequence[tuple[int, int, int]], dtype: np.dtype) -> list[Batch]:
    """The images in :class:`Batch` es: within each render run, the consecutive images whose models traced
    (a render of its ``shapes`` and values of ``dtype``) are one program with arrays of the same shapes."""
    out = []
    for r, run in enumerate(runs):
        traced = [jax.make_jaxpr(models[k])(jax.ShapeDtypeStruct(shapes[k], jnp.float32),
                                            jax.ShapeDtypeStruct(values[k].shape, dtype)) for k in run]
        keys = [traced_alike(t) for t in traced] if len(run) > 1 else [None]  # an image alone: not printed
        start = 0
        for end in range(1, len(run) + 1):
            if end < len(run) and keys[end] == keys[start]:
                continue
            frames, alike = run[start:end], traced[start:end]
            own, common, consts = _arrays(alike)
            # on the device once: handed to each call of a program as its operands (FrameModels.operands), not copied each time
            out.append(Batch(frames, r, start, np.stack([values[k] for k in frames]), operand_program(alike[0], "model"),
                             *(tuple(on_device(a, a.dtype) for a in arrays) for arrays in (own, common)), consts))
            start = end
    return out


# How many programs :func:`concurrently` runs at once: XLA runs the programs that one thread dispatches one after another,
# each mostly on one core (its FFTs partly on a second), so that a pass's frames' models at 4x the resolution (the pixel
# grid's fixed point), dispatched from one thread, left the second core idle. Each running program holds its own
# temporaries: two at once, not one a core, however many cores.
PROGRAM_THREADS = 2


def concurrently(calls: Sequence[Callable[[], T]]) -> list[T]:
    """``[call() for call in calls]``, each an image's program (:class:`~spacefit.programs.AlikePrograms`): the first in this thread (it
    traces and compiles what the others share), the others :data:`PROGRAM_THREADS` at a time on threads of their own,
    in this thread's 64-bit mode (a thread's own: ``jax.enable_x64``); the same results, in order."""
    if len(calls) < 3:
        return [call() for call in calls]
    first = calls[0]()
    with ThreadPoolExecutor(PROGRAM_THREADS, thread_name_prefix="spacefit-programs") as pool:
        others = [pool.submit(_in_this_mode(call)) for call in calls[1:]]
        return [first, *(other.result() for other in others)]


@contextlib.contextmanager
def meanwhile(call: Callable[[], object] | None) -> Iterator[None]:
    """Run ``call`` (None: nothing) on a thread of its own, in this thread's 64-bit mode, while the ``with`` block runs;
    the block's end waits for it, and its error is raised there (the block's own, if the block raised)."""
    if call is None:
        yield
        return
    with ThreadPoolExecutor(1, thread_name_prefix="spacefit-ahead") as pool:
        done = pool.submit(_in_this_mode(call))
        yield
        done.result()


def _in_this_mode(call: Callable[[], T]) -> Callable[[], T]:
    """``call``, to run on another thread in this thread's 64-bit mode (each thread has its own: ``jax.enable_x64``)."""
    x64 = bool(jax.config.jax_enable_x64)

    def run() -> T:
        with jax.enable_x64(x64):
            return call()

    return run


def _arrays(alike: Sequence[ClosedJaxpr]) -> tuple[tuple[np.ndarray, ...], tuple[np.ndarray, ...], tuple[tuple[bool, int], ...]]:
    """The arrays of one program traced for several images (:attr:`Batch.own`, :attr:`Batch.common`,
    :attr:`Batch.consts`): those equal in every image kept once (a padded frequency grid), those that
    differ stacked, and a stack equal to another (a reference that both residual functions hold) kept once."""
    own: list[np.ndarray] = []
    common: list[np.ndarray] = []
    where = []
    for i, var in enumerate(alike[0].jaxpr.constvars):
        each = [np.asarray(t.consts[i], dtype=var.aval.dtype) for t in alike]
        if all(np.array_equal(a, each[0]) for a in each[1:]):
            where.append((False, len(common)))
            common.append(each[0])
            continue
        stacked = np.stack(each)
        same = next((j for j, o in enumerate(own) if o.dtype == stacked.dtype and np.array_equal(o, stacked)), len(own))
        if same == len(own):
            own.append(stacked)
        where.append((True, same))
    return tuple(own), tuple(common), tuple(where)


class FrameModels:
    """The images' :data:`FrameModel` s of a fit, evaluated by :class:`Batch` es on stacked renders.

    Args:
        models, values: each image's model and where its nuisance values are in x (:func:`frame_model`).
        runs, shapes: the render runs (:func:`~spacefit.fitting.render_batches.render_runs`) and each image's render shape.
        recompute: recompute each model where linearised (a joint fit: the module's docstring).
    """

    def __init__(self, models: Sequence[FrameModel], values: Sequence[np.ndarray], runs: Sequence[range],
                 shapes: Sequence[tuple[int, int, int]], recompute: bool) -> None:
        self.models, self.values, self.runs, self.shapes, self.recompute = list(models), list(values), list(runs), list(shapes), recompute
        self._batches: dict[np.dtype, list[Batch]] = {}

    def batches(self, dtype: np.dtype) -> list[Batch]:
        """The batches of models traced with values of ``dtype`` (the fit's: float64), traced on first use."""
        if dtype not in self._batches:
            self._batches[dtype] = batches(self.models, self.values, self.runs, self.shapes, dtype)
        return self._batches[dtype]

    def operands(self, dtype: np.dtype) -> tuple[tuple[tuple[Array, ...], tuple[Array, ...]], ...]:
        """Each batch's arrays (:attr:`Batch.own`, :attr:`Batch.common`) for values of ``dtype``, for a caller that hands
        them to :meth:`__call__` as operands of its program."""
        return tuple((batch.own, batch.common) for batch in self.batches(np.dtype(dtype)))

    def __call__(self, rendered: Sequence[Array], x: Array, operands: Sequence[tuple[tuple[Array, ...], tuple[Array, ...]]] | None = None) -> tuple[
            list[Array], Array, Array]:
        """Each batch's model images stacked, (images, h, w, c), and every image's residuals in order, those
        judged and those descended, from ``rendered`` (each run's renders stacked) and the free values ``x``;
        ``operands``: :meth:`operands`, arguments of the caller's program (None: from the host by a callback)."""
        out = []
        for b, batch in enumerate(self.batches(np.dtype(x.dtype))):
            renders, values = rendered[batch.run], x[batch.values]
            if len(batch.frames) < renders.shape[0]:
                renders = renders[batch.offset:batch.offset + len(batch.frames)]
            # the batch's arrays as operands where the caller hands them in: held as constants, each compiled program of the
            # fit (the step, the residuals, the covariance's products) would hold a copy of them, more while compiling, and
            # its persistent cache's entry would be the observation's alone. A program without them calls back for its renders
            # (Adam's, BFGS's steps, a residual function traced whole), which JAX's cache refuses anyway: there they are its
            # constants. Not fetched by a callback: a callback run on one of XLA's threads, where the caller's 64-bit mode
            # is off, returns its float64 arrays as float32 (JAX canonicalises a callback's outputs in the thread's mode)
            own, common = operands[b] if operands is not None else (batch.own, batch.common)

            def each(args: tuple[Array, Array, tuple[Array, ...]], batch: Batch = batch, common: tuple[Array, ...] = common) -> list[Array]:
                render, value, own = args
                return batch.program([own[i] if is_own else common[i] for is_own, i in batch.consts], render, value)

            one = jax.checkpoint(each) if self.recompute else each
            if len(batch.frames) == 1:  # not mapped: its arrays are its own as they are
                out.append([o[None] for o in one((renders[0], values[0], ()))])
                continue
            out.append(jax.lax.map(one, (renders, values, own)))
        if not out:
            return [], jnp.zeros(0), jnp.zeros(0)
        return [o[0] for o in out], jnp.concatenate([o[1].reshape(-1) for o in out]), jnp.concatenate([o[2].reshape(-1) for o in out])

    @staticmethod
    def each(stacked: Sequence[Array]) -> list[Array]:
        """The batches' stacked model images as one per image."""
        return [image for batch in stacked for image in batch]
