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
place that wires Renderer -> :class:`~spacefit.rendering.drjit_scene.DrJitScene` (the Dr.Jit side: its renders, NumPy in
and out, no JAX) -> scene values -> these functions.

Renders are deterministic for a seed (JAX treats callbacks as pure). The primal image and finite
differences use ``seed``; derivative renders use ``seed_grad``, a different seed, so that an L2
loss's gradient is not biased by noise shared with its residual. Inputs are validated before any
callback runs: callbacks never raise. XLA calls a program's callbacks from any thread of its pool;
every render of :class:`~spacefit.rendering.drjit_scene.DrJitScene` runs on the process's one Dr.Jit thread
(:func:`~spacefit.rendering.backend.on_drjit_thread`), whose AD state is per thread.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from spacefit.precision import on_device
from spacefit.programs import operand_jit
from spacefit.rendering.drjit_scene import DrJitScene

SceneValues = Mapping[str, Array]


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
