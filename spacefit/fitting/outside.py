"""A problem's residuals from renders made before JAX's programs run, so that no program calls back.

A fit's images are Dr.Jit renders, which a JAX program can only reach by calling back into Python
(``jax.pure_callback``, :func:`~spacefit.fitting.render_batches.batched_renders`), and JAX's persistent cache
keeps no program that calls back: every process compiled the solver's step, the residuals and their
tangents anew (about 2.5 s of the 8-parameter observation fit's process, issue 33). Every point a
least-squares step, the noise floor or the standard errors evaluate is known before its program runs
(optimistix's Gauss-Newton family evaluates its function at the trial point ``y_eval`` of its state
only), so the renders are made first, at that point (:attr:`Outside.render`), and handed to a program
that holds no callback (:attr:`Outside.evaluate`, through :func:`~spacefit.fitting.render_batches.given_renders`):
the same images and the same Jacobian columns times the tangent, and a program JAX's cache keeps. The arrays the
images' models hold (their references, masks: :meth:`~spacefit.fitting.frame_models.FrameModels.operands`) are its
operands too (:attr:`Outside.operands`), neither fetched by a callback nor embedded as constants.
The solver's renders of its best point are kept (:meth:`Outside.keep`): the standard errors linearise
there again with the fit's seeds, the same renders (a fit that ends on rejected trial steps rendered
others since). Renders a caller will ask for next may begin on a thread of their own while it works
(:meth:`Outside.render_ahead`, :meth:`Outside.render_images_ahead`): the same renders, made while the Dr.Jit
thread would idle. The images its own methods render last with each seed index are kept (:attr:`Outside.last_images`),
and the images of the point kept: a point's images are rendered once per seed index, not again by the standard errors'
Jacobian (its columns alone) or the goodness of fit (the noise floor's record rendered the best point's with the independent
seeds, the solver's Jacobian there its images with the fit's; issue 33's fit: 3 primal renders).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import Any

import jax
import numpy as np

# A frame's images and, where linearised, its Jacobian columns (None: not rendered), as NumPy arrays.
Rendered = tuple[tuple[np.ndarray, ...], tuple[np.ndarray, ...] | None]
# (x, images, jacobians, operands) -> the observations' models (as :attr:`Outside.each` splits them), the stacked residuals
# and those a solver descends.
Evaluate = Callable[[jax.Array, Sequence[np.ndarray], Sequence[np.ndarray] | None, Any], tuple[list[jax.Array], jax.Array, jax.Array]]

RESIDUALS, DESCENT = 1, 2  # which residuals of :attr:`Outside.evaluate`'s output


def _key(x: np.ndarray, j: int) -> tuple[bytes, int]:
    """The key of the renders at ``x`` with the j-th seeds: x's float64 bytes and j."""
    return np.asarray(x, dtype=np.float64).tobytes(), j


def _started(fn: Callable[..., Any], *args: Any) -> Future:
    """``fn(*args)`` begun on a thread of its own, which ends with it: renders made while the calling thread traces JAX's
    programs (the renders run on the Dr.Jit thread, :func:`~spacefit.rendering.backend.on_drjit_thread`).
    Nothing run so may import or parse code: CPython 3.11's parse trees are not safe across threads (performance.md)."""
    pool = ThreadPoolExecutor(1, "spacefit-render-ahead")
    try:
        return pool.submit(fn, *args)
    finally:
        pool.shutdown(wait=False)


@dataclass(frozen=True)
class Outside:
    """A problem's renders at a point and its models and residuals from them.

    Attributes:
        render: (physical x, seed index j, with the Jacobian[, the images at x made before]) -> the frames' renders at x
            with the j-th seeds (0 the fit's, 1 the independent ones; :mod:`spacefit.fitting.problem`), outside JAX; given
            the images (its own without the Jacobian), the Jacobian columns alone are rendered, beside them.
        evaluate: (x, images, jacobians, operands) -> the observations' models, the stacked residuals and those a
            solver descends, a compiled program with no callback, differentiable in x where ``jacobians`` are given.
        each: evaluate's models, on the host, -> each observation's, split outside the program (a pass's frames' models come
            stacked, :mod:`spacefit.fitting.frame_models`: split inside, the program grew by each frame).
        operands: the dtype of x -> evaluate's ``operands`` (the same arrays at every call, on the device): a program that
            calls evaluate takes them as its own operands (a solver's step: beside the renders), not as constants.
    """

    render: Callable[..., Rendered]
    evaluate: Evaluate
    each: Callable[[list[np.ndarray]], list[np.ndarray]] = list
    operands: Callable[[np.dtype], Any] = lambda dtype: None
    kept: dict[tuple[bytes, int], Rendered] = field(default_factory=dict)  # one point's renders with their Jacobian (keep)
    ahead: dict[tuple[bytes, int], Future] = field(default_factory=dict)  # renders with their Jacobian being made (render_ahead)
    images_ahead: dict[tuple[bytes, int], Future] = field(default_factory=dict)  # one point's images being made (render_images_ahead)
    last_images: dict[int, tuple[bytes, tuple[np.ndarray, ...]]] = field(default_factory=dict)  # per j: x's bytes, its images

    def keep(self, x: np.ndarray, j: int, rendered: Rendered) -> None:
        """Keep ``rendered``, the renders with their Jacobian at ``x`` with the j-th seeds, in place of those kept before."""
        self.kept.clear()
        self.kept[_key(x, j)] = rendered

    def render_ahead(self, x: np.ndarray, j: int) -> None:
        """Begin the renders with their Jacobian at ``x`` with the j-th seeds on a thread of their own (:func:`_started`),
        for :meth:`linearisable` to take, unless kept."""
        key = _key(x, j)
        if key not in self.kept and key not in self.ahead:
            self.ahead[key] = _started(self._rendered, np.array(x), j, True)

    def linearisable(self, x: np.ndarray, j: int) -> Rendered:
        """The renders with their Jacobian at ``x`` with the j-th seeds: those kept where they are ``x``'s, or begun
        (:meth:`render_ahead`), else made."""
        key = _key(x, j)
        kept, pending = self.kept.get(key), self.ahead.pop(key, None)
        if kept is not None:
            return kept
        return pending.result() if pending is not None else self._rendered(np.asarray(x), j, True)

    def render_images_ahead(self, x: np.ndarray, j: int) -> None:
        """Begin the images (no Jacobian) at ``x`` with the j-th seeds on a thread of their own (:func:`_started`), for
        :meth:`models` and :meth:`residuals` to take, in place of any begun before and not taken."""
        key = _key(x, j)
        if key not in self.images_ahead:
            self.images_ahead.clear()
            self.images_ahead[key] = _started(self._rendered, np.array(x), j, False)

    def images(self, x: np.ndarray, j: int) -> Rendered:
        """The images (no Jacobian) at ``x`` with the j-th seeds: those begun (:meth:`render_images_ahead`), or those of the
        renders kept (:meth:`keep`), else :meth:`_rendered`'s."""
        key = _key(x, j)
        pending, kept = self.images_ahead.pop(key, None), self.kept.get(key)
        if pending is not None:
            return pending.result()
        return (kept[0], None) if kept is not None else self._rendered(np.asarray(x), j, False)

    def _rendered(self, x: np.ndarray, j: int, jacobian: bool) -> Rendered:
        """The renders at ``x`` with the j-th seeds (:attr:`render`), beside the images this object's renders with those
        seeds made last where they are x's (:attr:`last_images`): the Jacobian's columns alone rendered, the images not
        rendered again. Renders are deterministic for a point and seed: the same images."""
        point = _key(x, j)[0]
        last = self.last_images.get(j)
        images = last[1] if last is not None and last[0] == point else None
        if images is not None and not jacobian:
            return images, None
        made = self.render(x, j, jacobian) if images is None else self.render(x, j, jacobian, images)
        self.last_images[j] = (point, made[0])
        return made

    def models(self, x: jax.Array, j: int) -> list[np.ndarray]:
        """Each observation's model at ``x`` (concrete) with the j-th seeds, split on the host (JAX's split of a stacked
        batch is a program of its own)."""
        return self.each([np.asarray(m) for m in self.evaluate(x, *self.images(np.asarray(x), j), self.operands(x.dtype))[0]])

    def residuals(self, x: jax.Array, j: int, kind: int = RESIDUALS) -> jax.Array:
        """The stacked residuals (``kind`` :data:`RESIDUALS`; :data:`DESCENT`: those a solver descends) at ``x`` (concrete) with the j-th seeds."""
        return self.evaluate(x, *self.images(np.asarray(x), j), self.operands(x.dtype))[kind]

    def linearised(self, x: jax.Array, j: int) -> tuple[jax.Array, Callable[[jax.Array], jax.Array]]:
        """``jax.linearize`` of the stacked residuals at ``x`` (concrete) with the j-th seeds: their value and tangent map."""
        images, jacobians = self.linearisable(np.asarray(x), j)
        operands = self.operands(x.dtype)
        return jax.linearize(lambda y: self.evaluate(y, images, jacobians, operands)[RESIDUALS], x)
