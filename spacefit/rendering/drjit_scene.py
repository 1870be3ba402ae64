"""A loaded Mitsuba scene rendered from scene values by traverse key: its image, forward-mode derivative images and
backward pass, NumPy arrays in and out, every render on the process's Dr.Jit thread.

:class:`DrJitScene` is the Dr.Jit side of the seam between JAX and Dr.Jit (:mod:`spacefit.rendering.bridge`, which
calls it back from JAX's programs and from a fit's renders made outside them); it imports no JAX.
"""

from __future__ import annotations

import hashlib
from collections.abc import Callable, Collection, Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from spacefit.rendering.backend import dr, in_variant, mi, on_drjit_thread
from spacefit.rendering.drjit_values import differentiable, to_value
from spacefit.rendering.frozen import splat
from spacefit.rendering.logs import errors_only
from spacefit.rendering.renderer import Renderer
from spacefit.rendering.sample_passes import pass_seed, render_threads
from spacefit.scene.sampling import split_sample_count


def _flat_grad(value: object) -> np.ndarray:
    return np.asarray(dr.grad(value), dtype=np.float32).ravel()


# Dr.Jit's refusal to forward-propagate across an edge made before the current isolation scope, and how
# many times a forward-mode render is tried when it meets it (:meth:`DrJitScene.forward`).
OUTSIDE_SCOPE = "outside of the current dr.isolate_grad() scope"
FORWARD_ATTEMPTS = 2


def _outside_scope(err: BaseException | None) -> bool:
    """Whether ``err``, or an exception it was raised from (PRB's loop wraps it), is that refusal."""
    while err is not None:
        if OUTSIDE_SCOPE in str(err):
            return True
        err = err.__cause__ or err.__context__
    return False


@dataclass
class DrJitScene:
    """A loaded Mitsuba scene whose values are set by traverse key (the bridge's JAX functions call it back), rendered with
    an AD integrator.

    Args:
        renderer: the loaded scene (its film, camera and parts).
        spp: samples per pixel of primal renders.
        spp_grad: samples per pixel of derivative renders.
        integrator: Mitsuba AD integrator (``prb``, ``direct_projective``, ``prb_projective``).
    """

    renderer: Renderer
    spp: int
    spp_grad: int
    integrator: str = "prb"

    @property
    def variant(self) -> str:
        """The Mitsuba variant of the loaded scene, set around each of the methods below."""
        return self.renderer.variant

    @in_variant
    def __post_init__(self) -> None:
        depth = self.renderer.assembly.scene.render.depth + 1
        props = {"type": self.integrator, "max_depth": depth, "rr_depth": depth + 1}
        self._integrator = mi.load_dict(props)
        self.params = self.renderer.params
        intr = self.renderer.assembly.intrinsics
        self.shape = (intr.height, intr.width, 3)
        self._last: tuple[tuple[int, bytes], np.ndarray] | None = None  # the last primal image, by seed and values

    @staticmethod
    def _key(values: Mapping[str, np.ndarray], seed: int) -> tuple[int, bytes]:
        digest = hashlib.blake2b(digest_size=16)
        for name in sorted(values):
            digest.update(name.encode())
            digest.update(np.ascontiguousarray(values[name], dtype=np.float32).tobytes())
        return seed, digest.digest()

    def _set(self, values: Mapping[str, np.ndarray], grad: Collection[str] = ()) -> None:
        """Set scene values by traverse key: those named in ``grad`` attached to Dr.Jit's AD graph, the others detached."""
        self.renderer.set_params(values, grad)

    def _passes(self, spp: int, seed: int) -> list[tuple[int, int, float]]:
        """(seed, spp, weight) of each pass of a render: the counts the sampler takes (``multijitter``
        splits one it would round, :func:`~spacefit.scene.schema.split_sample_count`), weighted by their share."""
        counts = split_sample_count(self.renderer.assembly.scene.render.sampler, spp)
        return [(pass_seed(seed, i), count, count / spp) for i, count in enumerate(counts)]

    def _render_ad(self, seed_grad: int) -> object:
        """The image attached to the AD graph, for :meth:`backward` (Mitsuba's ``mi.render``). Its own primal
        is not used: its seed only has to differ from ``seed_grad``."""
        return sum(mi.render(self.renderer.scene, self.params, integrator=self._integrator, seed=seed + 1, seed_grad=seed, spp=count) * weight
                   for seed, count, weight in self._passes(self.spp_grad, seed_grad))

    # Each render logs errors only (errors_only): projective integrators warn about film borders per call.
    @on_drjit_thread
    @in_variant
    def primal(self, values: Mapping[str, np.ndarray], seed: int) -> np.ndarray:
        """Radiance image (h, w, 3) float32 at ``values``; bitwise reproducible if the scene is deterministic.
        The last one is kept: a Jacobian (:func:`~spacefit.rendering.bridge.render_params`) renders its point's image first, and the
        residuals asked next at that point and seed (a fit's standard errors) are that image."""
        key = self._key(values, seed)
        if self._last is None or self._last[0] != key:
            self._last = (key, self.render_primal(values, seed))
        return self._last[1].copy()

    @on_drjit_thread
    @in_variant
    def render_primal(self, values: Mapping[str, np.ndarray], seed: int) -> np.ndarray:
        """:meth:`primal` rendered, not kept (a finite difference's renders are used once)."""
        self._set(values)
        return self.renderer.radiance(self.spp, seed)  # the scene's path tracer: a seed gives the image Renderer.render gives

    @on_drjit_thread
    @in_variant
    def forward(self, values: Mapping[str, np.ndarray], tangent: Mapping[str, np.ndarray], seed_grad: int) -> np.ndarray:
        """Directional derivative of the image along ``tangent`` (same keys as ``values``), one render
        (:meth:`forward_columns` of one column)."""
        return self.forward_columns(values, [tangent], seed_grad)[0]

    @on_drjit_thread
    @in_variant
    def forward_columns(self, values: Mapping[str, np.ndarray], tangents: Sequence[Mapping[str, np.ndarray]],
                        seed_grad: int) -> list[np.ndarray]:
        """Directional derivatives of the image along each of ``tangents`` (same keys as ``values``): one forward
        pass each, from one primal pass that they share (:func:`~spacefit.rendering.frozen.primal_state`, made at the
        first column's render, the gradients suspended; made again for a column whose values rebuilt the geometry: a
        pose or wrinkles differentiated by forward mode). A column's forward-mode
        render was its own primal pass and forward pass; the primal pass took 0.55 to 0.6 of its CPU (the panels case,
        128 x 128 px, 32 spp, frozen), and the 8-parameter fit's Jacobian (3 such columns and 2 finite differences) now
        takes 0.92 of the CPU it took.

        Only the values a tangent moves are attached to the AD graph: a material's column leaves the
        meshes detached. Dr.Jit's forward mode follows every AD edge out of an attached value and
        refuses one to a variable made before its isolation scope; a stack-sampling profiler (dask's
        worker profiler, every 10 ms) that holds a frame of PRB's first trace of a symbolic branch as
        it returns keeps such variables alive (made from the vertex positions there). A column that
        moves vertices must attach them: its render is tried again on that refusal, from freshly set
        values (the same seed, so the same image). The values are detached again after an error too.
        """
        states: dict[tuple[int, int], tuple[object]] = {}  # per pass and geometry, its primal pass's state
        columns = []
        for tangent in tangents:
            moved = [key for key, t in tangent.items() if np.any(np.asarray(t) != 0) and differentiable(self.params[key])]
            if not moved:  # nothing the render differentiates moves (Dr.Jit would refuse an image attached to nothing)
                columns.append(np.zeros(self.shape, np.float32))
                continue
            attempt = 1
            while True:
                try:
                    columns.append(self._forward_once(values, {key: tangent[key] for key in moved}, seed_grad, states))
                    break
                except RuntimeError as err:
                    if attempt == FORWARD_ATTEMPTS or not _outside_scope(err):
                        raise
                    attempt += 1
        return columns

    def _primal_states(self, state: Callable[..., tuple[object]], seed_grad: int, states: dict[tuple[int, int], tuple[object]]) -> None:
        """Each pass's primal state by ``state`` (:func:`~spacefit.rendering.frozen.primal_state`, frozen or not) in the
        scene's present geometry, into ``states``, unless there; those of an earlier geometry dropped (a vertex-moving
        column rebuilds it: its columns' states would otherwise all be held until the last column)."""
        for key in [key for key in states if key[1] != self.renderer.geometry]:
            del states[key]
        for i, (seed, count, _) in enumerate(self._passes(self.spp_grad, seed_grad)):
            key = (i, self.renderer.geometry)
            if key not in states:
                states[key] = state(self.renderer.scene, self._integrator, dr.opaque(mi.UInt32, seed), count)
                dr.eval(states[key])

    def _forward_once(self, values: Mapping[str, np.ndarray], tangent: Mapping[str, np.ndarray], seed_grad: int,
                      states: dict[tuple[int, int], tuple[object]]) -> np.ndarray:
        """One forward-mode render of :meth:`forward_columns`, with AD on the keys of ``tangent`` only."""
        self._set(values, grad=tangent)
        try:
            for key, t in tangent.items():
                dr.set_grad(self.params[key], to_value(self.params[key], t))
            return self.renderer.to_film(np.asarray(self._render_forward(seed_grad, states), dtype=np.float32))
        finally:
            self._set(values)

    def _render_forward(self, seed_grad: int, states: dict[tuple[int, int], tuple[object]]) -> "mi.TensorXf":
        """The window's forward-mode derivative image along the gradients set on the scene's values, from each pass's
        primal state in ``states`` (made where missing): each pass's samples on all threads
        (:func:`~spacefit.rendering.frozen.derivative_samples`, replayed after its first call), splatted on one thread
        when the render is deterministic, in the samples' order, as Mitsuba's ``render_forward`` splats them (the image
        it gives wholly on one thread, bit for bit), the passes weighted by their shares of the samples."""
        film = self.renderer.scene.sensors()[0].film()
        _, state, derivative = self.renderer.frozen.functions(self.renderer.geometry)  # once: a new geometry's first render is unfrozen
        self._primal_states(state, seed_grad, states)
        image = None
        with errors_only():  # projective integrators warn about film borders per call
            for i, (seed, count, weight) in enumerate(self._passes(self.spp_grad, seed_grad)):
                position, value = derivative(self.renderer.scene, self._integrator, dr.opaque(mi.UInt32, seed), count,
                                             *states[(i, self.renderer.geometry)])
                dr.eval(position, value)
                with render_threads(self.renderer.assembly.scene.render.deterministic):
                    block = film.create_block()
                    block.set_coalesce(block.coalesce() and count >= 4)  # as render_forward sets it
                    splat(block, position, value)
                    film.put_block(block)
                    developed = film.develop() * weight
                    image = developed if image is None else image + developed
                    dr.eval(image)
        return image

    @on_drjit_thread
    @in_variant
    def backward(self, values: Mapping[str, np.ndarray], cotangent: np.ndarray, seed_grad: int) -> dict[str, np.ndarray]:
        """Gradient of sum(cotangent * image) with respect to every key of ``values``, one backward pass
        (the values detached again after it, and after an error)."""
        self._set(values, grad=values)
        try:
            with render_threads(self.renderer.assembly.scene.render.deterministic), errors_only():
                image = self._render_ad(seed_grad)
                dr.backward_from(image * mi.TensorXf(self.renderer.to_window(np.asarray(cotangent, dtype=np.float32))))
                return {key: _flat_grad(self.params[key]) if differentiable(self.params[key]) else np.zeros(np.size(values[key]), np.float32)
                        for key in values}
        finally:
            self._set(values)
