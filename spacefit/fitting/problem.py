"""A fitting problem's set-up: observations checked, scenes assembled and loaded, the residuals built.

The observations are images (:mod:`spacefit.fitting.observations.image`) and value observations
(tables, light curves: :mod:`spacefit.fitting.observations.base`). Nothing is rendered here: every input is
checked first (:func:`setup`), so that a bad one is refused before any work; the residuals are
:mod:`spacefit.fitting.residuals`'.
"""

from __future__ import annotations

import dataclasses
import warnings
from contextvars import ContextVar
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import jax
import numpy as np

from spacefit.errors import InputError, InputTypeError, check_choice, check_name_list, quote
from spacefit.executors import Executor
from spacefit.fitting.observations.base import Reported, Sequenced, ValueObservation
from spacefit.fitting.observations.image import Observation
from spacefit.fitting.params import Bijection, FreeParameters, bijection
from spacefit.fitting.residuals import Problem, build_problem
from spacefit.precision import on_device
from spacefit.rendering.derivatives import check_seeds, check_spp
from spacefit.rendering.memory import LARGE_FIT_BYTES, check_fit_memory, describe_fit
from spacefit.scene.schema import Scene
from spacefit.scene.names import Name
from spacefit.scene.parameters import GEOMETRY, available, check_names, fd_step, scene_value, scene_with_values
from spacefit.scene.conversions import G_of, rms_of

INTEGRATORS = ("prb", "direct_projective", "prb_projective")


@dataclass
class Setup:
    """A checked fitting problem: user-facing and solver parameters and the residuals."""

    user: FreeParameters  # the parameters as the user named them
    solver_params: FreeParameters  # the ones the solver moves ((D, rms) in place of (D, G))
    x0_user: np.ndarray
    x0: np.ndarray
    to_user: Callable[[jax.Array], jax.Array]
    problem: Problem
    rms_index: int | None
    scene: Scene | None  # the first image's scene, as given (None: no image)
    noise_given: bool = False  # every observation has a sensor or a sigma: the residuals are in units of the noise
    image_names: frozenset[str] = frozenset()  # the free names (without ``@k``) the images' renderers see
    # each observation as given (a pass whole) and its indices in the per-observation lists (FitResult.entries)
    layout: tuple[tuple[Reported, tuple[int, ...]], ...] = ()

    def user_jacobian(self, x: np.ndarray) -> np.ndarray:
        """The Jacobian of :attr:`to_user` at the solver's values ``x``: the identity where the solver moves the user's
        parameters (no rms height in G's place), built on the host (JAX's forward mode ran some 10 single-operation programs)."""
        if self.rms_index is None:
            return np.eye(len(x))
        return np.asarray(jax.jacfwd(self.to_user)(on_device(x, np.float64)))


def fit_scene(scene: Scene, free: Sequence[str]) -> Scene:
    """The scene a fit renders. ``wrinkles.model`` 'auto' becomes 'geometry': the fit's parameters act
    on the displaced geometry and on the facets' own roughness, which the effective model merges
    into one roughness. A forced 'effective' model therefore may not free D, G or the rms height,
    nor the roughness of a wrinkled part."""
    w = scene.wrinkles
    if not w.enabled or w.model == "geometry":
        return scene
    if w.model == "auto":
        return dataclasses.replace(scene, wrinkles=dataclasses.replace(w, model="geometry"))
    merged = [n for n in free if n in GEOMETRY
              or (n.startswith("parts.") and n.split(".")[1] in w.parts and n.split(".")[2].startswith("alpha"))]
    if merged:
        raise InputError(f"{', '.join(map(repr, merged))} cannot be fitted with `wrinkles.model` = 'effective', which merges "
                         "the wrinkles' slopes and the facets' roughness into one roughness; use 'geometry' or 'auto'.")
    return scene


@dataclass(frozen=True)
class FitRender:
    """How a fit renders: checked on construction.

    Attributes:
        spp, spp_grad: samples per pixel of the primal and the derivative renders (None: the
            scene's ``render.spp``; ``spp_grad`` None: ``spp``).
        seed, seed_grad: seeds of the primal and the derivative renders (must differ: a shared seed
            biases L2 gradients); render references with another.
        integrator: AD integrator of the derivative renders, one of :data:`INTEGRATORS`.
        geometry_jacobian: ``"fd"`` (central differences with common random numbers) or ``"ad"``
            (the integrator's derivative) for the wrinkles' D and G.

    Raises:
        InputError: a sample count or seed out of range, ``seed == seed_grad``, an unknown integrator
            or geometry Jacobian.

    Example:
        >>> import spacefit as sf
        >>> sf.FitRender(spp=8, spp_grad=4)  # sf.fit(..., render=sf.FitRender(spp=8, spp_grad=4))
        FitRender(spp=8, spp_grad=4, seed=1, seed_grad=2, integrator='prb', geometry_jacobian='fd')
        >>> try:
        ...     sf.FitRender(seed=1, seed_grad=1)
        ... except sf.InputError as err:
        ...     print(err)
        `seed` and `seed_grad` must differ (a shared seed biases L2 gradients).
    """

    spp: int | None = None
    spp_grad: int | None = None
    seed: int = 1
    seed_grad: int = 2
    integrator: str = "prb"
    geometry_jacobian: str = "fd"

    def __post_init__(self) -> None:
        check_spp(self.spp, self.spp_grad)
        check_choice("integrator", self.integrator, INTEGRATORS)
        check_choice("geometry_jacobian", self.geometry_jacobian, ("fd", "ad"))
        check_seeds([(self.seed, self.seed_grad)])


# Where a fit's set-up says its size, every fit's (``spacefit fit``: on stderr, :func:`~spacefit.pipeline.fit_to_folder`
# sets it); None: a fit above LARGE_FIT_BYTES warns it.
SAY_SIZE: ContextVar[Callable[[str], None] | None] = ContextVar("SAY_SIZE", default=None)


def setup(
    observations: Observation | ValueObservation | Sequenced | Sequence[Observation | ValueObservation | Sequenced],
    free: Sequence[str], *,
    start: Mapping[str, float] | None = None, loss: str = "pixel", render: FitRender = FitRender(), wrinkle_coordinates: str = "rms",
    executor: Executor | None = None, allow_large: bool = False,
) -> Setup:
    """Check every input and build the problem; nothing is rendered here. ``executor``: where the
    images' renders run, as one batch per step (:mod:`spacefit.fitting.frames`; None: each
    image's own render functions in this process). A fit says its estimated memory (:func:`images_memory`)
    to :data:`SAY_SIZE`, or, unset, warns it when above :data:`~spacefit.rendering.memory.LARGE_FIT_BYTES`.

    Raises:
        InputError: for any bad input; a fit whose estimated memory is more than this machine has
            available, unless ``allow_large``.
    """
    kinds = (Observation, ValueObservation, Sequenced)
    if not isinstance(observations, (*kinds, Sequence)):
        raise InputTypeError(f"`observations` must be an sf.Observation(scene, reference) or a list of them, got {quote(observations)}.")
    observations = [observations] if isinstance(observations, kinds) else list(observations)
    if not observations:
        raise InputError("`observations` must hold at least one observation (an image, a pass, a table, a light curve).")
    for i, obs in enumerate(observations):
        if not isinstance(obs, kinds):
            raise InputTypeError(f"`observations[{i}]` must be an sf.Observation(scene, reference) or another observation "
                                 f"kind (spacefit.fitting.observations), got {quote(obs)}.")
    observations, per_frame, layout = expanded(observations)
    free = [*free, *per_frame] if per_frame and not isinstance(free, str) else free
    if not isinstance(render, FitRender):
        raise InputTypeError(f"`render` must be an sf.FitRender(spp=..., seed=...), got {quote(render)}.")
    check_choice("wrinkle_coordinates", wrinkle_coordinates, ("rms", "G"))
    others = [o for o in observations if isinstance(o, ValueObservation)]
    observations = [o for o in observations if isinstance(o, Observation)]
    given = observations[0].scene if observations else None
    user, image_names = free_of(given, others, free, len(observations))
    observations = [dataclasses.replace(o, scene=fit_scene(o.scene, user.names)) for o in observations]
    if start is not None and not isinstance(start, Mapping):
        raise InputTypeError(f"`start` must be a mapping of free parameter names to values, got {quote(start)}.")
    start = dict(start or {})
    for name in start:
        check_choice("start", name, user.names)
    for k, obs in enumerate(observations):  # a start value is refused as the scene file would refuse it, with its message
        scene_with_values(obs.scene, {n: v for n, v in start.items() if Name(n).parameter in image_names}, observation=k)
    x0_user = np.array([start[n] if n in start else _own_value(n, observations, others, image_names) for n in user.names], dtype=float)
    user.check_start(x0_user)
    if observations:
        say_size(*images_memory(observations, user.names, image_names, render.spp, allow_large=allow_large))
    for other in others:  # a rendered value observation (a light curve's points) says its own
        sized = other.size(user.names, allow_large=allow_large)
        if sized is not None:
            say_size(*sized)
    rms_index = None
    if wrinkle_coordinates == "rms" and {"wrinkles.D", "wrinkles.G"} <= set(user.names):
        scene = observations[0].scene
        w = scene.wrinkles
        i_D, rms_index = user.names.index("wrinkles.D"), user.names.index("wrinkles.G")
        internal = [n if n != "wrinkles.G" else "wrinkles.rms_m" for n in user.names]
        at_start = dataclasses.replace(w, D=x0_user[i_D], G=x0_user[rms_index])
        solver_params, image_names = free_of(dataclasses.replace(scene, wrinkles=at_start), others, internal, len(observations))
        x0 = x0_user.copy()
        x0[rms_index] = float(rms_of(w, x0_user[i_D], x0_user[rms_index]))

        def to_user(x: jax.Array) -> jax.Array:
            return x.at[rms_index].set(G_of(w, x[i_D], x[rms_index]))
    else:
        solver_params, x0 = user, x0_user

        def to_user(x: jax.Array) -> jax.Array:
            return x

    if render.geometry_jacobian == "ad":
        wrinkles = np.array([n in GEOMETRY for n in solver_params.names])
        solver_params = dataclasses.replace(solver_params, fd_steps=np.where(wrinkles, 0.0, solver_params.fd_steps))
    blocks = [o.block(solver_params.names) for o in others]
    problem = build_problem(observations, solver_params, loss, render.spp, render.spp_grad, render.seed, render.seed_grad,
                       render.integrator, executor, blocks, image_names)
    noise_given = all(o.sensor is not None or o.sigma is not None for o in observations) and all(b.noise_known for b in blocks)
    return Setup(user, solver_params, x0_user, x0, to_user, problem, rms_index, given, noise_given, image_names, layout)


def say_size(size: str, estimate: int) -> None:
    """Say a fit's size (in words, its estimated peak memory ``estimate`` in bytes) to :data:`SAY_SIZE`,
    or, unset, warn it when above :data:`~spacefit.rendering.memory.LARGE_FIT_BYTES`."""
    say = SAY_SIZE.get()
    if say is not None:
        say(f"{size} (estimate)")
    elif estimate > LARGE_FIT_BYTES:
        warnings.warn(f"{size} (estimate).", stacklevel=4)


def images_memory(images: Sequence[Observation], free: Sequence[str], image_names: frozenset[str] | set[str], spp: int | None, *,
                  allow_large: bool = False) -> tuple[str, int]:
    """A fit's size in words and its estimated peak memory (bytes) from its images (count, largest size),
    the free parameters each one's renderer sees (``free``'s names in ``image_names``: the shared ones and its
    share of the ``@k`` ones) and ``spp`` (None: the first scene's), :func:`~spacefit.rendering.memory.check_fit_memory`,
    which refuses one this machine cannot hold unless ``allow_large``. The size is each scene's render
    resolution: the references are checked against it later (:func:`check_reference`), so they may not be images yet."""
    width, height = (max(o.scene.render.resolution[k] for o in images) for k in (0, 1))
    seen = [Name(n) for n in free if Name(n).parameter in image_names]
    columns = sum(n.observation is None for n in seen) + -(-sum(n.observation is not None for n in seen) // len(images))
    estimate = check_fit_memory(len(images), width, height, columns, spp or images[0].scene.render.spp, allow_large=allow_large)
    return describe_fit(len(images), width, height, estimate), estimate


def expanded(given: Sequence[Observation | ValueObservation | Sequenced]) -> tuple[
        list[Observation | ValueObservation], list[Name], tuple[tuple[Reported, tuple[int, ...]], ...]]:
    """The observations with each pass's frames' images in its place (a :class:`~spacefit.fitting.observations.base.Sequenced`:
    :class:`~spacefit.fitting.observations.passes.PassObservation`), each pass's per-frame free names,
    and each given observation with its indices in the fit's per-observation lists: the images' (a
    pass's frames) first, in order, then the value observations'."""
    flat: list[Observation | ValueObservation] = []
    names: list[Name] = []
    images: list[tuple[int, ...] | None] = []
    for obs in given:
        first = sum(isinstance(o, Observation) for o in flat)
        if isinstance(obs, Sequenced):
            names += obs.names(first)
            flat += obs.images
            images.append(tuple(range(first, first + len(obs.images))))
        else:
            flat.append(obs)
            images.append((first,) if isinstance(obs, Observation) else None)
    after = iter(range(sum(isinstance(o, Observation) for o in flat), len(flat)))
    return flat, names, tuple((obs, own if own is not None else (next(after),)) for obs, own in zip(given, images))


def _own_value(name: str, images: Sequence[Observation], others: Sequence[ValueObservation], image_names: frozenset[str]) -> float:
    """Where a fit of ``name`` starts by default: an image's scene value (an image's own value,
    ``target.attitude_z_deg@k``, its scene's), or for a value only other kinds know, the first one's."""
    ref = Name(name)
    if ref.parameter in image_names:
        return scene_value(images[ref.observation or 0].scene, name)
    return next(o.start(name) for o in others if name in o.parameters())


def free_of(scene: Scene | None, others: Sequence[ValueObservation], names: Sequence[str],
            images: int) -> tuple[FreeParameters, frozenset[str]]:
    """The free parameters ``names`` of a fit of ``images`` images of ``scene`` (None: no image) and
    the value observations ``others``, and the names (without ``@k``) the images' renderers see.
    A name one of ``others`` depends on is theirs (an image sees it too where its scene has it);
    every other name is checked against the scene (:func:`~spacefit.scene.parameters.check_names`).
    A value's range is its registered one, narrowed where an observation narrows it.

    Raises:
        InputError: for an unknown or repeated name, or two that set one value (the message lists the valid ones).
    """
    names = check_name_list("free", names)
    elsewhere = {n for o in others for n in o.parameters()}
    in_scene = set(available(scene)) if scene is not None else set()
    for_images = tuple(n for n in names if n not in elsewhere or Name(n).parameter in in_scene)
    if not names:
        raise InputError(f"`free` must name at least one parameter; valid: {', '.join(sorted(elsewhere | in_scene))}.")
    if scene is None:
        for name in for_images:
            check_choice("free", name, sorted(elsewhere))
    elif for_images:
        check_names(scene, for_images, image=True, observations=images)
    if len(set(names)) != len(names):
        raise InputError(f"`free` names a parameter twice: {list(names)}.")
    bijections = []
    for name in names:
        ranges = [o.coordinate(name) for o in others if name in o.parameters()] or [bijection(name)]
        bijections.append(Bijection(max(b.lo for b in ranges), min(b.hi for b in ranges)))
    steps = np.array([fd_step(scene, n) if scene is not None and n in for_images else 0.0 for n in names])
    return FreeParameters(names, tuple(bijections), steps), frozenset(Name(n).parameter for n in for_images)
