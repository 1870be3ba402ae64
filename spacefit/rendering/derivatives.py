"""Derivatives of the image with respect to registered parameters, for notebooks and solvers.

:func:`render_chain` is the one constructor of the chain "loaded scene -> JAX image function":
Renderer (the scene loaded into Mitsuba) -> :class:`~spacefit.rendering.drjit_scene.DrJitScene` ->
scene values (:func:`~spacefit.rendering.values.scene_values_fn`) -> the bridge's forward
(:func:`~spacefit.rendering.bridge.render_params`) or reverse
(:func:`~spacefit.rendering.bridge.render_values`) function; the fit, the sensitivities, the
experiments and the tests all build it here. :func:`render_function` is the image as a JAX function of the parameters' physical values, with the
bridge's materialised Jacobian (forward-mode AD for materials and the sun's irradiance, central
finite differences with common random numbers for geometry and the sun's angles), so that
``jax.jacfwd``, ``jax.jvp`` and optimistix least squares work on it unchanged. :func:`jacobian`
evaluates it once: the image and d(image)/d(parameter) for each parameter.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from spacefit.errors import InputError, check_count, check_type
from spacefit.precision import float64
from spacefit.rendering.bridge import render_params, render_values
from spacefit.rendering.drjit_scene import DrJitScene
from spacefit.rendering.renderer import Renderer
from spacefit.rendering.memory import check_memory
from spacefit.rendering.values import SceneValuesFn, ad_names, scene_values_fn
from spacefit.scene.assembly import Assembly, assemble
from spacefit.scene.schema import Scene
from spacefit.scene.sections import MAX_SEED, MAX_SPP, check_scene
from spacefit.scene.sampling import check_sample_count
from spacefit.scene.parameters import MOVES_VERTICES, check_names, fd_step, scene_value, scene_with_values


ImageFn = Callable[[Float[Array, " n"]], Float[Array, "h w 3"]]


@dataclass(frozen=True)
class RenderChain:
    """A loaded scene's radiance image (W m^-2 sr^-1, float32) as JAX functions of the physical
    values x of the parameters ``names``; built by :func:`render_chain`.

    Attributes:
        names: the parameters, in the order of x (registry names).
        renderer: the loaded scene (its assembly, part image, film window).
        drjit: its Dr.Jit side, rendered by traverse key.
        values_of: JAX function x -> the Mitsuba scene values it sets.
        fd_steps: (n,) central finite-difference step of each parameter, 0 where its Jacobian
            column comes from a forward-mode AD render.
    """

    names: tuple[str, ...]
    renderer: Renderer
    drjit: DrJitScene
    values_of: SceneValuesFn
    fd_steps: np.ndarray

    def forward(self, seed: int, seed_grad: int) -> ImageFn:
        """The image with a materialised Jacobian (:func:`~spacefit.rendering.bridge.render_params`):
        ``jax.jacfwd``, ``jax.jvp``, ``jax.grad`` and optimistix least squares work on it."""
        return render_params(self.drjit, self.values_of, self.fd_steps, seed, seed_grad)

    def reverse(self, seed: int, seed_grad: int) -> ImageFn:
        """The image differentiable in reverse mode, one Dr.Jit backward pass whatever the number of
        parameters (:func:`~spacefit.rendering.bridge.render_values`); it carries AD derivatives only
        (a frame's, the sun's or the camera's, is zero, and so is the pose's where the camera and the sun
        move for it: :func:`~spacefit.rendering.values.pose_by_view`)."""
        image = render_values(self.drjit, seed, seed_grad)
        return lambda x: image(self.values_of(x))

    def primal(self, x: Float[np.ndarray, " n"], seed: int) -> np.ndarray:
        """The image (h, w, 3) at x for ``seed``, rendered directly (no JAX transformation)."""
        return self.drjit.primal(self.values_of(jnp.asarray(x)), seed)


def render_chain(
    scene: Scene | Assembly, names: Sequence[str], *, spp: int | None = None, spp_grad: int | None = None,
    integrator: str = "prb", fd_steps: Float[np.ndarray, " n"] | None = None, crop: bool | None = None,
) -> RenderChain:
    """Load ``scene`` (or its assembly) once and chain it to JAX for the parameters ``names``.

    ``spp`` / ``spp_grad``: samples per pixel of the primal and derivative renders (default: the
    scene's, and ``spp``); ``integrator``: Mitsuba's AD integrator (``prb``, ``direct_projective``,
    ``prb_projective``); ``fd_steps``: each parameter's finite-difference step, 0 for an AD column
    (default: the registry's). Only the film window around the target is rendered unless a
    parameter moves vertices (D, G, the pose), which the window would not hold, or ``crop`` is
    False (the whole film, for a scene whose camera will move). A pose whose columns are finite
    differences moves the camera and the sun the other way, not the vertices, so that its renders replay
    (:func:`~spacefit.rendering.values.pose_by_view`). The names are not checked here:
    the callers check them against their own vocabulary first.
    """
    check_spp(spp, spp_grad)
    assembly = scene if isinstance(scene, Assembly) else assemble(check_scene(scene))
    names = tuple(names)
    renderer = Renderer(assembly, crop=not any(n in MOVES_VERTICES for n in names) if crop is None else crop)
    spp = spp or assembly.scene.render.spp
    for name, count in (("spp", spp), ("spp_grad", spp_grad or spp)):
        check_sample_count(name, count, assembly.scene.render.sampler)
    intr, window = assembly.intrinsics, renderer.window
    check_memory(intr.width, intr.height, window[2] * window[3], max(spp, spp_grad or spp), split=False)
    steps = np.array([fd_step(assembly.scene, n) for n in names], dtype=float) if fd_steps is None else np.asarray(fd_steps, float)
    return RenderChain(names, renderer, DrJitScene(renderer, spp, spp_grad or spp, integrator),
                       scene_values_fn(assembly, names, ad_names(names, steps)), steps)


def render_function(
    scene: Scene, free: Sequence[str], *, spp: int | None = None, spp_grad: int | None = None, seed: int = 1, seed_grad: int = 2,
) -> Callable[[Float[Array, " n"]], Float[Array, "h w 3"]]:
    """The radiance image (W m^-2 sr^-1) as a differentiable JAX function of the physical values of
    the parameters ``free`` (registry names, in that order).

    The image has the dtype of the input (float32 unless the caller enabled JAX's 64-bit mode).
    ``spp`` / ``spp_grad``: samples per pixel of the primal and the derivative renders (default:
    the scene's); ``seed`` / ``seed_grad`` must differ so that an L2 loss's gradient is unbiased.

    Args:
        scene: the scene whose other values stay fixed.
        free: registered parameter names (:func:`available_parameters`).
        spp, spp_grad: samples per pixel of the primal and the derivative renders.
        seed, seed_grad: their seeds.

    Returns:
        A function of an (n,) array of the free values (physical units, in ``free``'s order) to the
        (h, w, 3) image, differentiable by ``jax.jacfwd`` / ``jax.grad``.

    Raises:
        InputError: a name the scene cannot free, or ``seed == seed_grad``.

    Example:
        >>> import jax.numpy as jnp, spacefit as sf
        >>> scene = sf.default_scene().with_values({"render.resolution": [48, 48], "camera.pixel_pitch_mm": 50, "render.spp": 4})
        >>> image_of = sf.render_function(scene, ["parts.legs.kd"])
        >>> image_of(jnp.array([0.3])).shape
        (48, 48, 3)
    """
    check_seeds([(seed, seed_grad)])
    return render_functions(scene, free, spp=spp, spp_grad=spp_grad)[0](seed, seed_grad)


def check_spp(spp: int | None, spp_grad: int | None) -> None:
    """Raise :class:`InputError` unless the samples per pixel of a chain's primal and derivative
    renders are None (the scene's) or in [1, :data:`~spacefit.scene.schema.MAX_SPP`], ``render.spp``'s range."""
    for name, value in (("spp", spp), ("spp_grad", spp_grad)):
        check_count(name, value, 1, MAX_SPP, "as `render.spp`")


def check_seed(name: str, value: object) -> None:
    """Raise :class:`InputError` unless ``value`` is a fit's render seed: an integer in [0,
    :data:`~spacefit.scene.schema.MAX_SEED`], to which the fit adds its offsets."""
    check_count(name, value, 0, MAX_SEED, "Mitsuba's seeds are 32-bit, and a fit adds offsets", optional=False)


def check_seeds(seeds: Sequence[tuple[int, int]]) -> None:
    """Raise :class:`InputError` for a seed outside [0, :data:`~spacefit.scene.schema.MAX_SEED`] or a
    pair whose primal and derivative seeds are equal."""
    for seed, seed_grad in seeds:
        check_seed("seed", seed)
        check_seed("seed_grad", seed_grad)
    if any(seed == seed_grad for seed, seed_grad in seeds):
        raise InputError("`seed` and `seed_grad` must differ (a shared seed biases L2 gradients).")


def render_functions(
    scene: Scene, free: Sequence[str], *, spp: int | None = None, spp_grad: int | None = None,
) -> tuple[Callable[[int, int], Callable[[Float[Array, " n"]], Float[Array, "h w 3"]]], Renderer]:
    """:func:`render_function` for any seeds on one loaded scene: ``(seed, seed_grad) -> image function``,
    and the renderer (its part image, say)."""
    check_names(check_scene(scene), free)
    chain = render_chain(scene, free, spp=spp, spp_grad=spp_grad)

    def function(seed: int, seed_grad: int) -> ImageFn:
        image = chain.forward(seed, seed_grad)
        return lambda x: image(x).astype(jnp.result_type(x))

    return function, chain.renderer


@dataclass(frozen=True)
class Jacobian:
    """The image and its derivative with respect to each parameter at one point.

    Attributes:
        names: the parameters, in order.
        at: the value of each (physical units).
        image: (h, w, 3) radiance, W m^-2 sr^-1.
        columns: name -> (h, w, 3) d(radiance)/d(parameter), W m^-2 sr^-1 per the parameter's unit.

    Example:
        >>> import spacefit as sf
        >>> scene = sf.default_scene().with_values({"render.resolution": [48, 48], "camera.pixel_pitch_mm": 50, "render.spp": 4})
        >>> j = sf.jacobian(scene, ["parts.legs.kd"])
        >>> j.names, j.image.shape
        (('parts.legs.kd',), (48, 48, 3))
    """

    names: tuple[str, ...]
    at: dict[str, float]
    image: np.ndarray
    columns: dict[str, np.ndarray]


@float64
def jacobian(
    scene: Scene, free: Sequence[str], *, at: Mapping[str, float] | None = None, spp: int | None = None,
    spp_grad: int | None = None, seed: int = 1, seed_grad: int = 2,
) -> Jacobian:
    """The image and d(image)/d(parameter) for each of ``free`` at the scene's values (or ``at``).

    Args:
        scene: the scene.
        free: registered parameter names (:func:`available_parameters`).
        at: values of some of ``free`` (physical units) replacing the scene's.
        spp, spp_grad: samples per pixel of the primal and the derivative renders (None: the scene's).
        seed, seed_grad: their seeds, different.

    Returns:
        A :class:`Jacobian`.

    Raises:
        InputError: a name the scene cannot free (the message lists those it can), a value out of range.

    Example:
        >>> import spacefit as sf
        >>> scene = sf.default_scene().with_values({"render.resolution": [48, 48], "camera.pixel_pitch_mm": 50, "render.spp": 4})
        >>> j = sf.jacobian(scene, ["parts.legs.kd"])
        >>> j.at, j.columns["parts.legs.kd"].shape
        ({'parts.legs.kd': 0.2}, (48, 48, 3))
    """
    return jacobians(scene, free, [(seed, seed_grad)], at=at, spp=spp, spp_grad=spp_grad)[0][0]


@float64
def jacobians(
    scene: Scene, free: Sequence[str], seeds: Sequence[tuple[int, int]], *, at: Mapping[str, float] | None = None,
    spp: int | None = None, spp_grad: int | None = None, progress: Callable[[], None] | None = None,
) -> tuple[list[Jacobian], Renderer]:
    """:func:`jacobian` for each ``(seed, seed_grad)`` pair of ``seeds`` on one loaded scene (independent
    seeds give Monte Carlo errors), and the renderer; ``progress()`` is called after each."""
    names = check_names(check_scene(scene), free)
    check_seeds(seeds)
    if at is not None:
        check_type("at", at, Mapping, "a mapping of parameter names to values")
    at = dict(at or {})
    unknown = set(at) - set(names)
    if unknown:
        raise InputError(f"`at` names {sorted(unknown)}, which are not in `free` {list(names)}.")
    scene_with_values(scene, at)  # each value refused as the scene would refuse it
    function, renderer = render_functions(scene, names, spp=spp, spp_grad=spp_grad)
    x = np.array([at.get(n, scene_value(scene, n)) for n in names], dtype=float)
    out = []
    for seed, seed_grad in seeds:
        fn = function(seed, seed_grad)

        def image_twice(y: Array) -> tuple[Array, Array]:
            image = fn(y)  # noqa: B023  (called at once, within this iteration)
            return image, image  # one evaluation gives the Jacobian and, as auxiliary output, the image

        J, image = jax.jacfwd(image_twice, has_aux=True)(jnp.asarray(x))
        J = np.asarray(J, dtype=np.float32)
        out.append(Jacobian(names, dict(zip(names, x.tolist())), np.asarray(image, dtype=np.float32),
                            {n: J[..., i] for i, n in enumerate(names)}))
        if progress is not None:
            progress()
    return out, renderer
