"""The seam between JAX and Dr.Jit: the renderer as a JAX function of Mitsuba scene values.

What crosses the seam is a flat mapping from Mitsuba traverse keys (``'panels.bsdf.alpha_u.value'``,
``'body.vertex_positions'``) to arrays, and seeds; nothing else. ``dr.wrap`` only converts
Dr.Jit -> JAX, so this module owns both directions:

* :func:`render_values` is a ``jax.custom_vjp`` function of the scene values: its reverse rule is
  one Dr.Jit backward pass, whatever the number of parameters (``jax.grad`` of a scalar loss).
* :func:`render_params` is a ``jax.custom_jvp`` function of a small vector of free parameters ``x``
  with scene values ``values_of(x)`` computed in JAX (e.g. W-M vertex positions from D and G). Its
  JVP rule builds the Jacobian J (pixels x parameters) one column per parameter, by a Dr.Jit
  forward-mode render of the tangent ``d values / d x_j`` or by central finite differences with
  common random numbers, and returns ``J @ t``: plain JAX that JAX can linearize and transpose, so
  optimistix least squares, ``jax.jacfwd`` and ``jax.grad`` all work.

Both are built on a loaded scene by :func:`spacefit.rendering.derivatives.render_chain`, the one
place that wires Renderer -> :class:`DrJitScene` -> scene values -> these functions.

Renders are deterministic for a seed (JAX treats callbacks as pure). The primal image and finite
differences use ``seed``; derivative renders use ``seed_grad``, a different seed, so that an L2
loss's gradient is not biased by noise shared with its residual. Inputs are validated before any
callback runs: callbacks never raise. XLA calls a program's callbacks from any thread of its pool;
every render of :class:`DrJitScene` runs on the process's one Dr.Jit thread
(:func:`~spacefit.rendering.backend.on_drjit_thread`), whose AD state is per thread.
"""

from __future__ import annotations

import hashlib
from collections.abc import Callable, Collection, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from spacefit.precision import on_device
from spacefit.programs import operand_jit
from spacefit.rendering.backend import dr, in_variant, mi, on_drjit_thread
from spacefit.rendering.frozen import splat
from spacefit.rendering.drjit_values import differentiable, to_value
from spacefit.rendering.logs import errors_only
from spacefit.rendering.renderer import Renderer
from spacefit.rendering.sample_passes import pass_seed, render_threads
from spacefit.scene.sampling import split_sample_count

SceneValues = Mapping[str, Array]


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
    """A loaded Mitsuba scene whose values are set by traverse key from JAX, rendered with an AD integrator.

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
        The last one is kept: a Jacobian (:func:`render_params`) renders its point's image first, and the
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


def _flat(values: Mapping[str, Array]) -> dict[str, Array]:
    return {k: jnp.ravel(jnp.asarray(v, dtype=jnp.float32)) for k, v in values.items()}


def render_values(scene: DrJitScene, seed: int, seed_grad: int) -> Callable[[SceneValues], Float[Array, "h w 3"]]:
    """The image as a JAX function of scene values, differentiable in reverse mode (one backward pass)."""
    shape = jax.ShapeDtypeStruct(scene.shape, jnp.float32)

    def primal_cb(values: dict[str, np.ndarray]) -> np.ndarray:
        return scene.primal(values, seed)

    @jax.custom_vjp
    def render(flat: dict[str, Array]) -> Array:
        return jax.pure_callback(primal_cb, shape, flat, vmap_method="sequential")

    def fwd(flat: dict[str, Array]) -> tuple[Array, dict[str, Array]]:
        return render(flat), flat

    def bwd(flat: dict[str, Array], cotangent: Array) -> tuple[dict[str, Array]]:
        out = {k: jax.ShapeDtypeStruct(v.shape, jnp.float32) for k, v in flat.items()}
        return (jax.pure_callback(lambda v, c: scene.backward(v, c, seed_grad), out, flat, cotangent, vmap_method="sequential"),)

    render.defvjp(fwd, bwd)

    def call(values: SceneValues) -> Array:
        return render(_flat(values))  # JAX's own chain rule undoes the flattening

    return call


def seeds_array(seed: int, seed_grad: int) -> Array:
    """A (seed, seed_grad) pair as the operand :func:`seeded_render_params` takes (uint32: Mitsuba's seeds)."""
    return on_device([seed, seed_grad], np.uint32)


def render_params(
    scene: DrJitScene,
    values_of: Callable[[Array], dict[str, Array]],
    fd_steps: Float[np.ndarray, " n"],
    seed: int,
    seed_grad: int,
) -> Callable[[Float[Array, " n"]], Float[Array, "h w 3"]]:
    """The image as a JAX function of free parameters ``x`` (n,), with a materialised Jacobian:
    :func:`seeded_render_params` at the seeds ``seed`` (primal and finite differences) and
    ``seed_grad`` (forward-mode renders)."""
    render = seeded_render_params(scene, values_of, fd_steps)
    seeds = seeds_array(seed, seed_grad)
    return lambda x: render(x, seeds)


def seeded_render_params(
    scene: DrJitScene,
    values_of: Callable[..., dict[str, Array]],
    fd_steps: Float[np.ndarray, " n"],
) -> Callable[..., Float[Array, "h w 3"]]:
    """The image as a JAX function ``(x, seeds, *view) -> image`` of free parameters ``x`` (n,), the
    seeds (:func:`seeds_array`) and any further operands ``view`` of ``values_of`` (a pass's frame
    geometry, :func:`~spacefit.rendering.values.scene_view`; not differentiated), with a materialised
    Jacobian. The seeds and the view are operands, not constants, so that one compiled program
    serves every seed (a fit's own and the independent ones of its standard errors) and every frame.

    Args:
        scene: the Dr.Jit side.
        values_of: JAX function (x, *view) -> scene values (traverse key -> array).
        fd_steps: (n,) step of a central finite difference for each parameter, or 0 to take the
            column from a Dr.Jit forward-mode render (the integrator's derivative).
    """
    renders = _Renders(scene, fd_steps)
    image = jax.ShapeDtypeStruct(scene.shape, jnp.float32)
    jac = jax.ShapeDtypeStruct((*scene.shape, renders.n), jnp.float32)
    inputs = _jacobian_inputs(values_of, renders.steps)

    @jax.custom_jvp
    def render(x: Array, seeds: Array, *view: object) -> Array:
        return jax.pure_callback(renders.primal, image, _flat(values_of(x, *view)), seeds, vmap_method="sequential")

    @render.defjvp
    def render_jvp(primals: tuple[Array, ...], tangents: tuple[Array, ...]) -> tuple[Array, Array]:
        (x, seeds, *view), t = primals, tangents[0]
        img, J = jax.pure_callback(renders.jacobian, (image, jac), *inputs(x, *view), seeds, vmap_method="sequential")
        return img, J @ t.astype(jnp.float32)

    return render


def scene_values_program(values_of: Callable[..., dict[str, Array]]) -> Callable[..., dict[str, Array]]:
    """``values_of`` ((x, *view) -> scene values) as one program (:func:`~spacefit.programs.operand_jit`: the arrays it
    closes over, the parts' vertices, its operands), its values flat float32 arrays, as the renders set them."""
    return operand_jit(lambda x, *view: _flat(values_of(x, *view)))


def outside_render_params(
    scene: DrJitScene,
    values_of: Callable[..., dict[str, Array]],
    fd_steps: Float[np.ndarray, " n"],
    values: Callable[..., dict[str, Array]] | None = None,
) -> tuple[Callable[..., np.ndarray], Callable[..., tuple[np.ndarray, np.ndarray]]]:
    """:func:`seeded_render_params`'s image, and its image with its Jacobian (h, w, 3, n), as Python
    functions ``(x, seeds, *view)`` that render outside JAX: the scene values (and their derivatives,
    the finite differences' points) come from compiled programs that call nothing back, so JAX's
    cache keeps them, and the renders run after them. The same images and columns as
    :func:`seeded_render_params`'s and its Jacobian's, from the same values. The Jacobian's ``image=``: the
    image at x for these seeds, rendered before (the first function's): the columns alone are rendered. ``values``:
    :func:`scene_values_program` of ``values_of`` where the caller holds it already (None: one of its own)."""
    renders = _Renders(scene, fd_steps)
    # the arrays the scene values close over (the parts' vertices, a wrinkled part's refinement) the programs' operands
    values = scene_values_program(values_of) if values is None else values
    inputs = operand_jit(_jacobian_inputs(values_of, renders.steps))

    def image(x: Array, seeds: Array, *view: object) -> np.ndarray:
        return renders.primal(values(x, *view), seeds)

    def jacobian(x: Array, seeds: Array, *view: object, image: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        return renders.jacobian(*inputs(x, *view), seeds, image)

    return image, jacobian


class _Renders:
    """A scene's image and its Jacobian columns from scene values: the Dr.Jit renders that
    :func:`seeded_render_params` calls back into and :func:`outside_render_params` calls."""

    def __init__(self, scene: DrJitScene, fd_steps: Float[np.ndarray, " n"]) -> None:
        self.scene, self.steps = scene, np.asarray(fd_steps, dtype=float)
        self.n = len(self.steps)

    # A callback may be handed JAX arrays: it indexes them as NumPy's (an index of a JAX array
    # compiles an XLA program, per shape and per calling thread's settings).
    def primal(self, values: dict[str, np.ndarray], seeds: np.ndarray) -> np.ndarray:
        """The image for the seeds' first."""
        return self.scene.primal(values, int(np.asarray(seeds)[0]))

    def jacobian(self, values: dict[str, np.ndarray], tangents: dict[str, np.ndarray], plus: dict[int, dict[str, np.ndarray]],
                 minus: dict[int, dict[str, np.ndarray]], seeds: np.ndarray, image: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """The image and its Jacobian: column j a central difference of the renders at ``plus[j]`` and
        ``minus[j]`` (the seeds' first), or a forward-mode render along ``tangents``' j-th (the second).
        ``image``: the image at ``values`` for the seeds' first, rendered before (:meth:`primal`'s), not rendered again."""
        seed, seed_grad = (int(s) for s in np.asarray(seeds))
        tangents = {k: np.asarray(t) for k, t in tangents.items()}
        img = self.scene.primal(values, seed) if image is None else image
        ad = [j for j in range(self.n) if j not in plus]  # the forward-mode columns, from one primal pass
        forward = dict(zip(ad, self.scene.forward_columns(values, [{k: t[..., j] for k, t in tangents.items()} for j in ad], seed_grad)))
        cols = []
        for j in range(self.n):
            if j in plus:
                up, down = self.scene.render_primal(plus[j], seed), self.scene.render_primal(minus[j], seed)
                cols.append((up - down) / (2.0 * self.steps[j]))
            else:
                cols.append(forward[j])
        return img, np.stack(cols, axis=-1).astype(np.float32)


def _jacobian_inputs(values_of: Callable[..., dict[str, Array]], steps: np.ndarray) -> Callable[..., tuple[Any, ...]]:
    """``(x, *view) ->`` what :meth:`_Renders.jacobian` takes but the seeds: the scene values at x, their
    derivatives in x (a column per free value), and the values a step up and down each finite
    difference's value."""
    n, fd = len(steps), [j for j in range(len(steps)) if steps[j] > 0]

    def inputs(x: Array, *view: object) -> tuple[Any, ...]:
        def values_at(y: Array) -> dict[str, Array]:
            return values_of(y, *view)

        tangent_cols = {k: jnp.reshape(v, (-1, n)).astype(jnp.float32) for k, v in jax.jacfwd(values_at)(x).items()}
        eye = jnp.eye(n, dtype=x.dtype) * jnp.asarray(steps, dtype=x.dtype)
        plus = {j: _flat(values_at(x + eye[j])) for j in fd}
        minus = {j: _flat(values_at(x - eye[j])) for j in fd}
        return _flat(values_at(x)), tangent_cols, plus, minus

    return inputs
