"""A fitting problem's set-up: observations checked, scenes assembled and loaded, residuals built.

The observations are images (:mod:`spacefit.fitting.observations.image`) and value observations
(tables, light curves: :mod:`spacefit.fitting.observations.base`), whose residual blocks follow the
images' pixels. Nothing is rendered here: every input is checked first (:func:`setup`), so that a bad one is
refused before any work. Every render of a solve uses the same seed (common random numbers), so
the objective is a deterministic function; derivative renders use another seed. In a joint fit
each observation's renderer sees the free values that are its own (``target.attitude_z_deg@k``)
or shared (:meth:`~spacefit.fitting.params.FreeParameters.rendered`); the image nuisances act on
its render in JAX (:mod:`spacefit.fitting.nuisance`), the frames of a joint fit alike as one
program whatever their count (:mod:`spacefit.fitting.frame_models`).
"""

from __future__ import annotations

import dataclasses
import math
import warnings
from contextvars import ContextVar
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np

from spacefit.errors import InputError, InputTypeError, check_choice, check_name_list, quote
from spacefit.executors import Executor
from spacefit.fitting.frame_models import FrameModels, frame_model
from spacefit.fitting.frames import FrameSpec, InProcess, batched_renders, frame_part_image, render_runs, run_frames, share_views
from spacefit.fitting.nuisance import image_model as image_model_of, nuisance_index
from spacefit.fitting.observations.base import Block, Reported, Sequenced, ValueObservation
from spacefit.fitting.observations.image import Observation, check_reference, image_residual, in_unit_of
from spacefit.fitting.params import Bijection, FreeParameters, bijection
from spacefit.fitting.pixel_grid import grid_error_models
from spacefit.rendering.bridge import seeds_array
from spacefit.rendering.derivatives import check_seeds, check_spp
from spacefit.rendering.memory import LARGE_FIT_BYTES, check_fit_memory, describe_fit
from spacefit.rendering.parts import PartImage
from spacefit.scene.assembly import assemble
from spacefit.scene.schema import Scene
from spacefit.scene.sections import FILTER_RADIUS_PX
from spacefit.sensor import saturated_mask
from spacefit.psf import psf_rms_px
from spacefit.units import DN_UNIT, RADIANCE_UNIT
from spacefit.scene.names import Name
from spacefit.scene.parameters import GEOMETRY, available, check_names, fd_step, scene_value, scene_with_values
from spacefit.scene.conversions import G_of, rms_of

INTEGRATORS = ("prb", "direct_projective", "prb_projective")
# Seed offset of the second, independent Jacobian used for the standard errors.
INDEPENDENT_SEED_OFFSET = 1000
# the pixel grid's renders at 4x the resolution take the fit's seed plus this, and that plus INDEPENDENT_SEED_OFFSET
PIXEL_GRID_SEED_OFFSET = 500


@dataclass
class Problem:
    """The residuals of a set of observations as JAX functions of the physical free values x: the
    images' pixels first, then each value observation's block (:mod:`spacefit.fitting.observations`).
    The per-observation fields below are the images'; ``blocks`` holds the others."""

    free: FreeParameters
    residual_x: Callable[[jax.Array], jax.Array]  # physical x -> stacked residuals (J by forward mode)
    residual_x_independent: Callable[[jax.Array], jax.Array]  # the same with independent seeds
    loss_u_reverse: Callable[[jax.Array], jax.Array] | None  # unconstrained u -> the descended loss (reverse mode)
    renders_x: Callable[[jax.Array], list[jax.Array]]  # each observation's model in its data's unit
    part_images: list[PartImage]  # which part each pixel of each image sees
    references: list[np.ndarray]  # the checked references, (h, w, 3) or (h, w, 1) float32, 0 where not used
    # (x, j) -> each observation's model (images, then blocks) at the j-th seeds (0 the fit's, 1 the
    # independent ones, more further independent ones: the goodness of fit's verdict render,
    # spacefit.fitting.goodness) ...
    models_seeded: Callable[[jax.Array, int], list[jax.Array]]
    # ... the stacked residuals of given models (the noise sigma taken at them) ...
    residual_of: Callable[[list[jax.Array]], jax.Array]
    # ... and factor -> the same problem rendered with factor times the samples per pixel (the verdict render)
    resampled: Callable[[int], Problem]
    # physical x -> the residuals a solver descends, at the fit's seeds and at the independent ones: residual_x's
    # but for a sensor's noise, its quasi-deviance's (spacefit.fitting.losses)
    descent_x: Callable[[jax.Array], jax.Array]
    descent_x_independent: Callable[[jax.Array], jax.Array]
    noise_known: bool = False  # every residual is divided by its predicted or stated noise (a sensor per image)
    # per image, how far (px) its render noise spreads before the residuals: the pixel
    # filter's radius and the rms width of the sensor's PSF (0 without a sensor)
    noise_spread_px: tuple[tuple[float, float], ...] = ()
    units: tuple[str, ...] = ()  # per image, the unit of its reference and model image (radiance or DN)
    used: tuple[np.ndarray, ...] = ()  # per image, (h, w) bool: the pixels fitted in every channel
    spp: tuple[int, ...] = ()  # per image, the samples per pixel of its primal renders
    reference_spp: tuple[int | None, ...] = ()  # per image, its reference's (Observation.render_spp)
    blocks: tuple[Block, ...] = ()  # the value observations' residual blocks, after the images' pixels
    dark: tuple[float, ...] = ()  # per image, its model of no light in its unit (a sensor's bias, DN; 0 for radiance)
    # physical x -> (y -> the change of the images' residuals from the fit's model to those made at 4x and 2x the
    # resolution, from two renders at x, the image nuisances y's, and a draw of its render noise:
    # spacefit.fitting.pixel_grid), or None where no image's blur width is free
    pixel_grid: Callable[[np.ndarray], Callable[[np.ndarray], tuple[np.ndarray, np.ndarray, np.ndarray]] | None] | None = None

    @property
    def rendered(self) -> bool:
        """Whether a model is rendered (Monte Carlo): an image, or a rendered value observation."""
        return bool(self.references) or any(b.rendered for b in self.blocks)

    @property
    def pixels(self) -> int:
        """How many of the stacked residuals are the images' (the blocks' follow)."""
        return sum(ref.size for ref in self.references)


def column_owners(free: FreeParameters, blocks: Sequence[Block]) -> tuple[int, ...] | None:
    """Per free value, the image whose residuals alone it moves (its own value, ``image.scale@k``,
    which no value observation knows), -1 for the others; None where every value is shared. The
    normal equations of a joint fit apply their products to one direction for every image's own
    value of one kind (:func:`~spacefit.fitting.normal_equations.probes`)."""
    known = {n for block in blocks for n in block.known}
    owners = tuple(-1 if Name(n).observation is None or n in known else Name(n).observation for n in free.names)
    return owners if any(o >= 0 for o in owners) else None


def _problem(
    observations: Sequence[Observation], free: FreeParameters, loss: str, spp: int | None, spp_grad: int | None,
    seed: int, seed_grad: int, integrator: str, executor: Executor | None = None, blocks: Sequence[Block] = (),
    image_names: frozenset[str] = frozenset(),
) -> Problem:
    residuals, descents, references, spread, to_units, units, used_pixels, specs, shapes, dark = [], [], [], [], [], [], [], [], [], []
    # the image nuisances act on the render in JAX; each renderer sees the other parameters it knows
    # (``image_names``), an observation's own pose (``target.attitude_z_deg@k``) in place of the shared
    # one; every observation's render of a step runs in one batch (spacefit.fitting.frames)
    executor = InProcess() if executor is None else executor
    image_model = image_model_of(free.names)
    rendered = [_seen(free, k, image_names) for k in range(len(observations))]
    for i, obs in enumerate(observations):
        rendered_names, steps = rendered[i][0], free.fd_steps[rendered[i][1]]
        ref, used = check_reference(obs, i)
        scene = obs.scene
        assembly = assemble(scene)
        specs.append(FrameSpec(scene, tuple(rendered_names), tuple(float(v) for v in steps), spp, spp_grad, integrator))
        shapes.append((assembly.intrinsics.height, assembly.intrinsics.width, 3))
        if obs.sensor is not None:
            used = used & ~saturated_mask(ref, obs.sensor)  # a saturated value says only "at least this bright"
        residuals.append(image_residual(obs, ref, used, loss))
        descents.append(image_residual(obs, ref, used, loss, descent=True))
        to_units.append(in_unit_of(obs, ref.shape[-1], assembly.intrinsics))
        units.append(RADIANCE_UNIT if obs.sensor is None else DN_UNIT)
        dark.append(0.0 if obs.sensor is None else float(obs.sensor.bias_dn))
        references.append(ref)
        used_pixels.append(np.all(used, axis=-1))
        blur = 0.0 if obs.sensor is None else psf_rms_px(obs.sensor, assembly.intrinsics, ref.shape[-1])
        spread.append((FILTER_RADIUS_PX[scene.render.filter], blur))
    specs = share_views(specs)  # a pass's frames share a loaded scene
    indices = [r[1] for r in rendered]
    images = batched_renders(executor, specs, indices, shapes) if specs else (lambda x, seeds: ())
    part_images = run_frames(executor, frame_part_image, specs) if specs else []

    # the images' models and residuals, the frames alike (a pass's) as one program (spacefit.fitting.frame_models),
    # compiled once per fit with the seeds an operand: one program at the fit's seeds and at the independent ones
    # (evaluated op by op, the image model's FFTs and the residuals compiled some 170 small XLA programs per fit,
    # 15 s of a 128 x 128 fit's 75 s on 2 cores)
    made = [frame_model(free.names, k, to_units[k], residuals[k], descents[k]) for k in range(len(observations))]
    runs = render_runs(shapes, indices)
    models = FrameModels([m for m, _ in made], [v for _, v in made], runs, shapes, recompute=len(observations) > 1)
    models_residuals = jax.jit(lambda x, seeds: models(images(x, seeds), x))
    main, independent = seeds_array(seed, seed_grad), seeds_array(seed + INDEPENDENT_SEED_OFFSET, seed_grad + INDEPENDENT_SEED_OFFSET)

    def block_models(x: jax.Array, j: int) -> list[jax.Array]:
        return [b.model(x, j) for b in blocks]

    def with_blocks(image_residuals: jax.Array, models: Sequence[jax.Array]) -> jax.Array:
        """The images' residuals followed by each block's, of its model in ``models``."""
        return jnp.concatenate([image_residuals, *(b.residual(m) for b, m in zip(blocks, models))])

    reverse = None
    if not np.any(free.fd_steps > 0) and isinstance(executor, InProcess):  # one Dr.Jit backward pass per observation
        renders_v = [executor.chain(spec).reverse(seed, seed_grad) for spec in specs]

        def reverse(u: jax.Array) -> jax.Array:
            x = free.to_physical(u)
            frames = [jnp.stack([renders_v[k](x[indices[k]]) for k in run]) for run in runs]
            return 0.5 * jnp.sum(with_blocks(models(frames, x)[2], block_models(x, 0)) ** 2)

    def models_seeded(x: jax.Array, j: int) -> list[jax.Array]:
        seeds = seeds_array(seed + j * INDEPENDENT_SEED_OFFSET, seed_grad + j * INDEPENDENT_SEED_OFFSET)
        return [*FrameModels.each(models_residuals(x, seeds)[0]), *block_models(x, j)]

    def residual_at(x: jax.Array, seeds: jax.Array, j: int, kind: int = 1) -> jax.Array:
        """The stacked residuals (``kind`` 1; 2: those a solver descends) at the j-th seeds ``seeds``."""
        return with_blocks(models_residuals(x, seeds)[kind], block_models(x, j))

    n_images = len(observations)
    image_residual_of = jax.jit(lambda models: jnp.concatenate([res(model) for res, model in zip(residuals, models)]) if models
                                else jnp.zeros(0))

    def residual_of(models: list[jax.Array]) -> jax.Array:
        return with_blocks(image_residual_of(models[:n_images]), models[n_images:])

    spps = tuple(spp or o.scene.render.spp for o in observations)
    # the pixel loss's residuals are the pixels', which the pixel grid's change is laid out as
    blurred = [loss == "pixel" and nuisance_index(free.names, "image.blur_sigma_px", k) is not None for k in range(len(observations))]

    def pixel_grid(x: np.ndarray) -> Callable[[np.ndarray], tuple[np.ndarray, np.ndarray, np.ndarray]] | None:
        """``y ->`` the images' residuals with each free blur's model made at 4x and at 2x the resolution, each
        less the fit's own (0 for the other images), from two renders at ``x`` with independent seeds (the
        changes their mean), the image nuisances ``y``'s, and a draw of the first change's render noise (the
        two renders' difference over sqrt 2) (:mod:`spacefit.fitting.pixel_grid`); None: no free blur, or a
        filter it does not model."""
        values = {n: float(v) for n, v in zip(free.names, x) if Name(n).parameter in image_names}
        seeds = (seed + PIXEL_GRID_SEED_OFFSET, seed + PIXEL_GRID_SEED_OFFSET + INDEPENDENT_SEED_OFFSET)
        made = [grid_error_models(obs, scene_with_values(obs.scene, values, observation=k).with_values({"render.spp": spps[k]}),
                                  x, k, free.names, references[k].shape[-1], image_model, to_units[k], seeds) if blurred[k] else None
                for k, obs in enumerate(observations)]
        if not any(m is not None for m in made):
            return None

        def differences(y: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
            parts = []
            for k, models in enumerate(made):
                if models is None:
                    parts.append(np.zeros((3, references[k].size)))
                    continue
                (finest, coarser, grid), (finest_b, coarser_b, grid_b) = models(y)
                own, own_b = residuals[k](grid), residuals[k](grid_b)
                fine_a, fine_b = residuals[k](finest) - own, residuals[k](finest_b) - own_b
                parts.append(np.asarray([0.5 * (fine_a + fine_b), 0.5 * (residuals[k](coarser) - own + residuals[k](coarser_b) - own_b),
                                         (fine_a - fine_b) / math.sqrt(2.0)], dtype=float))
            return tuple(np.concatenate([p[i] for p in parts]) for i in range(3))

        return differences

    def resampled(factor: int) -> Problem:
        finer = [dataclasses.replace(o, scene=o.scene.with_values({"render.spp": factor * n})) for o, n in zip(observations, spps)]
        finer_blocks = [b if b.resampled is None else b.resampled(factor) for b in blocks]
        return _problem(finer, free, loss, None, None, seed, seed_grad, integrator, executor, finer_blocks, image_names)

    return Problem(free, lambda x: residual_at(x, main, 0), lambda x: residual_at(x, independent, 1), reverse,
                   lambda x: models_seeded(x, 0), part_images, references, models_seeded, residual_of, resampled,
                   lambda x: residual_at(x, main, 0, 2), lambda x: residual_at(x, independent, 1, 2), all(o.sensor is not None for o in observations) and all(b.noise_known for b in blocks), tuple(spread),
                   tuple(units), tuple(used_pixels), spps, tuple(o.render_spp for o in observations), tuple(blocks), tuple(dark),
                   pixel_grid if any(blurred) else None)


def _seen(free: FreeParameters, k: int, image_names: frozenset[str]) -> tuple[tuple[str, ...], np.ndarray]:
    """What image k's renderer sees (:meth:`~spacefit.fitting.params.FreeParameters.rendered`), less
    the free values only other kinds of observation know (a tabulated BRDF's factor)."""
    names, indices = free.rendered(k)
    keep = [i for i, name in enumerate(names) if name in image_names]
    return tuple(names[i] for i in keep), indices[keep]


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
    problem = _problem(observations, solver_params, loss, render.spp, render.spp_grad, render.seed, render.seed_grad,
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
    which refuses one this machine cannot hold unless ``allow_large``."""
    height, width = max(o.reference.shape[0] for o in images), max(o.reference.shape[1] for o in images)
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
