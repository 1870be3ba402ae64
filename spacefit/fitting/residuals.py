"""A fitting problem's residuals as JAX functions of its free values: images rendered, image models and residuals stacked.

The observations are images (:mod:`spacefit.fitting.observations.image`) and value observations
(tables, light curves: :mod:`spacefit.fitting.observations.base`), whose residual blocks follow the
images' pixels. Every render of a solve uses the same seed (common random numbers), so the objective
is a deterministic function; derivative renders use another seed. In a joint fit each observation's
renderer sees the free values that are its own (``target.attitude_z_deg@k``) or shared
(:meth:`~spacefit.fitting.params.FreeParameters.rendered`); the image nuisances act on its render in
JAX (:mod:`spacefit.fitting.nuisance`), the frames of a joint fit alike as one program whatever their
count (:mod:`spacefit.fitting.frame_models`). The renders are callbacks into Python inside a program
(:func:`~spacefit.fitting.render_batches.batched_renders`), or made before it (:mod:`spacefit.fitting.outside`).
The set-up that checks the inputs and builds the problem is :mod:`spacefit.fitting.problem`.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from spacefit.executors import Executor
from spacefit.formation import noise_variance_terms
from spacefit.fitting.frame_models import FrameModels, concurrently, frame_model
from spacefit.fitting.frames import FrameSpec, InProcess, frame_part_image, run_frames, share_views
from spacefit.fitting.nuisance import image_model as image_model_of, nuisance_index
from spacefit.fitting.observations.base import Block
from spacefit.fitting.observations.image import Observation, check_reference, image_residual, in_unit_of
from spacefit.fitting.outside import DESCENT, Outside, Rendered
from spacefit.fitting.params import FreeParameters
from spacefit.fitting.fine_models import GridModels, grid_error_models
from spacefit.fitting.pixel_grid import GridChanges, ImageColumns
from spacefit.fitting.render_batches import batched_renders, frame_renders, given_renders, render_runs
from spacefit.precision import on_device
from spacefit.programs import AlikePrograms, operand_jit
from spacefit.rendering.bridge import seeds_array
from spacefit.rendering.memory import release_freed_memory
from spacefit.rendering.parts import PartImage
from spacefit.scene.assembly import assemble
from spacefit.scene.sections import FILTER_RADIUS_PX
from spacefit.sensor import saturated_mask
from spacefit.psf import psf_rms_px
from spacefit.units import DN_UNIT, RADIANCE_UNIT
from spacefit.scene.names import Name
from spacefit.scene.parameters import scene_with_values


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
    renders_x: Callable[[jax.Array], list[np.ndarray]]  # each observation's model in its data's unit
    part_images: list[PartImage]  # which part each pixel of each image sees
    references: list[np.ndarray]  # the checked references, (h, w, 3) or (h, w, 1) float32, 0 where not used
    # (x, j) -> each observation's model (images, then blocks) at the j-th seeds (0 the fit's, 1 the
    # independent ones, more further independent ones: the goodness of fit's verdict render,
    # spacefit.fitting.goodness), host arrays ...
    models_seeded: Callable[[jax.Array, int], list[np.ndarray]]
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
    # physical x -> the changes of the images' residuals from the fit's model to those made at 4x and 2x the
    # resolution, from two renders at x, as functions of the image nuisances (spacefit.fitting.pixel_grid.GridChanges),
    # or None where no image's blur width is free
    pixel_grid: Callable[[np.ndarray], GridChanges | None] | None = None
    # the renders made first and handed to programs that call nothing back (spacefit.fitting.outside); None where a
    # value observation is rendered (its own callbacks)
    outside: Outside | None = None
    # per image, its sensor's noise variance as (floor, slope, offset) in DN (formation.noise_variance_terms); None without one
    noise_terms: tuple[tuple[float, float, float] | None, ...] = ()

    @property
    def rendered(self) -> bool:
        """Whether a model is rendered (Monte Carlo): an image, or a rendered value observation."""
        return bool(self.references) or any(b.rendered for b in self.blocks)

    def descent_at(self, x: jax.Array, j: int) -> jax.Array:
        """The residuals a solver descends at ``x`` (concrete) with the j-th seeds (0 or 1)."""
        if self.outside is not None:
            return self.outside.residuals(x, j, DESCENT)
        return (self.descent_x, self.descent_x_independent)[j](x)

    def render_ahead(self, x: jax.Array, j: int) -> None:
        """Begin the renders with their Jacobian at ``x`` (concrete) with the j-th seeds on a thread of their own, for
        :meth:`linearised` to take (:meth:`~spacefit.fitting.outside.Outside.render_ahead`); nothing where the renders
        are callbacks (no :attr:`outside`): the standard errors begin the independent seeds' while the fit's seeds'
        tangents are traced (:func:`~spacefit.fitting.uncertainty.linearise`)."""
        if self.outside is not None:
            self.outside.render_ahead(np.asarray(x), j)

    def linearised(self, x: jax.Array, j: int) -> tuple[jax.Array, Callable[[jax.Array], jax.Array]]:
        """The stacked residuals at ``x`` (concrete) with the j-th seeds (0 or 1) and their tangent map (``jax.linearize``),
        of the renders begun by :meth:`render_ahead` where they were."""
        if self.outside is not None:
            return self.outside.linearised(x, j)
        return jax.linearize((self.residual_x, self.residual_x_independent)[j], x)

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


def build_problem(
    observations: Sequence[Observation], free: FreeParameters, loss: str, spp: int | None, spp_grad: int | None,
    seed: int, seed_grad: int, integrator: str, executor: Executor | None = None, blocks: Sequence[Block] = (),
    image_names: frozenset[str] = frozenset(),
) -> Problem:
    residuals, descents, references, spread, to_units, units, used_pixels, specs, shapes, dark = [], [], [], [], [], [], [], [], [], []
    # the image nuisances act on the render in JAX; each renderer sees the other parameters it knows
    # (``image_names``), an observation's own pose (``target.attitude_z_deg@k``) in place of the shared
    # one; every observation's render of a step runs in one batch (spacefit.fitting.frames)
    executor = InProcess() if executor is None else executor
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

    def seeds_of(j: int) -> jax.Array:
        return seeds_array(seed + j * INDEPENDENT_SEED_OFFSET, seed_grad + j * INDEPENDENT_SEED_OFFSET)

    outside = None
    if not any(b.rendered for b in blocks):
        given = given_renders(indices, runs)

        def render_outside(x: np.ndarray, j: int, jacobian: bool, images: tuple[np.ndarray, ...] | None = None) -> Rendered:
            return (frame_renders(executor, specs, indices, runs, x, np.asarray(seeds_of(j)), jacobian, images) if specs
                    else ((), () if jacobian else None))

        def evaluate(x: jax.Array, images: Sequence[jax.Array], jacobians: Sequence[jax.Array] | None, operands: Any) -> tuple[
                list[jax.Array], jax.Array, jax.Array]:
            stacked, r, descended = models(given(x, images, jacobians), x, operands)
            others = block_models(x, 0)  # none rendered: the seeds change none
            return [*stacked, *others], with_blocks(r, others), with_blocks(descended, others)

        def each(out: list[np.ndarray]) -> list[np.ndarray]:
            """evaluate's models, each batch's stacked, the blocks' after them, one per observation."""
            batches = len(out) - len(blocks)
            return [*FrameModels.each(out[:batches]), *out[batches:]]

        outside = Outside(render_outside, jax.jit(evaluate), each, models.operands)

    def models_seeded(x: jax.Array, j: int) -> list[np.ndarray]:
        if outside is not None:
            return outside.models(x, j)
        return [np.asarray(m) for m in (*FrameModels.each([np.asarray(b) for b in models_residuals(x, seeds_of(j))[0]]),
                                        *block_models(x, j))]

    def residual_at(x: jax.Array, seeds: jax.Array, j: int, kind: int = 1) -> jax.Array:
        """The stacked residuals (``kind`` 1; 2: those a solver descends) at the j-th seeds ``seeds``."""
        return with_blocks(models_residuals(x, seeds)[kind], block_models(x, j))

    n_images = len(observations)
    # the residual functions' arrays (references, masks) the program's operands
    image_residual_of = operand_jit(lambda models: jnp.concatenate([res(model) for res, model in zip(residuals, models)]))

    def residual_of(models: list[jax.Array]) -> jax.Array:
        return with_blocks(image_residual_of(models[:n_images]) if n_images else np.zeros(0), models[n_images:])

    spps = tuple(spp or o.scene.render.spp for o in observations)
    # the pixel loss's residuals are the pixels', which the pixel grid's change is laid out as
    blurred = [loss == "pixel" and nuisance_index(free.names, "image.blur_sigma_px", k) is not None for k in range(len(observations))]

    def pixel_grid(x: np.ndarray) -> GridChanges | None:
        """The images' residuals' changes from the fit's model to those made at 4x and at 2x the resolution, from two
        renders at ``x`` with independent seeds, as functions of the image nuisances (:class:`GridChanges`; 0 for the
        images whose blur is not free) (:mod:`spacefit.fitting.pixel_grid`); None: no free blur, or a filter it does
        not model."""
        values = {n: float(v) for n, v in zip(free.names, x) if Name(n).parameter in image_names}
        seeds = (seed + PIXEL_GRID_SEED_OFFSET, seed + PIXEL_GRID_SEED_OFFSET + INDEPENDENT_SEED_OFFSET)
        # image k's changes read only its own values and the shared ones (``read[k]``, in x's order): its models are made
        # as functions of those alone, so that a pass's frames alike trace alike; the derivatives in another image's own are 0
        owners = column_owners(free, blocks) or (-1,) * len(free.names)
        read = [np.flatnonzero([o in (-1, k) for o in owners]) for k in range(len(observations))]
        names = [[free.names[j] for j in read[k]] for k in range(len(observations))]
        made = [grid_error_models(obs, scene_with_values(obs.scene, values, observation=k).with_values({"render.spp": spps[k]}),
                                  x[read[k]], k, names[k], references[k].shape[-1], image_model_of(names[k]), to_units[k], seeds)
                if blurred[k] else None for k, obs in enumerate(observations)]
        if not any(m is not None for m in made):
            return None
        # a pass's: the pages its programs' and renders' threads freed handed back at each evaluation's end, held in their
        # arenas they lay under the next one's (rendering.memory; 4x renders 6.3 MiB a 128 x 128 px frame)
        several = len(observations) > 1
        if several:
            release_freed_memory()

        def render_changes(k: int, render: jax.Array, y: jax.Array) -> tuple[jax.Array, jax.Array]:
            """Image k's residuals with the model made at 4x from one ``render`` less those with the fit's own, and the
            latter, at the values it reads ``y``."""
            finest, grid = made[k].fine(render, y)
            own = residuals[k](grid)
            return residuals[k](finest) - own, own

        # the renders one after the other (jax.lax.map), not batched: a batch held both renders' temporaries at 4x at once
        def fine_changes(k: int, renders: jax.Array, y: jax.Array) -> jax.Array:
            return jax.lax.map(lambda render: render_changes(k, render, y)[0], renders)

        def settled_changes(k: int, renders: jax.Array, y: jax.Array, directions: jax.Array) -> tuple[jax.Array, ...]:
            def settled_one(render: jax.Array) -> tuple[jax.Array, jax.Array, jax.Array]:
                # the derivatives in forward mode, one direction after another (the primal made once)
                (each, own), tangent = jax.linearize(lambda v: render_changes(k, render, v), y)
                derivatives = jax.lax.map(lambda t: tangent(t)[0], directions)
                return each, residuals[k](made[k].coarser(render, y)) - own, derivatives

            each, coarser, derivatives = jax.lax.map(settled_one, renders)
            return each, coarser.mean(axis=0), derivatives.mean(axis=0)

        programs = AlikePrograms(sum(m is not None for m in made) > 1)  # one program each, not one per operation; a pass's frames share it
        y_of = lambda k, y: on_device(np.asarray(y)[read[k]], np.float64)  # noqa: E731

        def renders_of(m: GridModels) -> jax.Array:
            if m.renders is None:
                raise RuntimeError("the pixel grid's renders were dropped by its last settled evaluation (settled's `last`)")
            return m.renders

        def fine(y: np.ndarray) -> np.ndarray:
            # the images' programs two at a time (concurrently): each runs mostly on one core
            out = np.concatenate(concurrently([lambda k=k, m=m: np.zeros((2, references[k].size)) if m is None else np.asarray(
                programs((fine_changes, k), lambda *a, k=k: fine_changes(k, *a), renders_of(m), y_of(k, y)), dtype=float)
                for k, m in enumerate(made)]), axis=1)
            if several:
                release_freed_memory()
            return out

        def settled_call(k: int, m: GridModels, y: np.ndarray, columns: Sequence[int]) -> tuple[list[int], tuple[Any, ...]]:
            """Image k's own ``columns`` (their indices) and what its settled program is called with (key, function,
            arguments)."""
            own = [i for i, j in enumerate(columns) if j in read[k]]
            directions = np.eye(len(read[k]))[np.searchsorted(read[k], [columns[i] for i in own]).astype(int)]
            return own, ((settled_changes, k, len(own)), lambda *a: settled_changes(k, *a), renders_of(m), y_of(k, y), directions)

        def settled(y: np.ndarray, columns: Sequence[int], last: bool = False) -> tuple[np.ndarray, np.ndarray, ImageColumns]:
            parts, blocks = [], []
            for k, m in enumerate(made):
                size = references[k].size
                if m is None:
                    parts.append((np.zeros((2, size)), np.zeros(size)))
                    blocks.append(((), np.zeros((0, size))))
                    continue
                own, call = settled_call(k, m, y, columns)
                each, coarser, own_derivatives = (np.asarray(p, dtype=float) for p in programs(*call))
                if last:  # each image's renders dropped once read: a pass's frames' outputs took their place, not came on top
                    made[k] = dataclasses.replace(m, renders=None)
                parts.append((each, coarser))
                blocks.append((own, own_derivatives))
            each, coarser = (np.concatenate(p, axis=-1) for p in zip(*parts))
            if several:
                release_freed_memory()
            # each image's derivatives in its own columns, a column made whole when read (held whole: frames^2)
            return each, coarser, ImageColumns(len(columns), [r.size for r in references], blocks)

        def ahead(y: np.ndarray, columns: Sequence[int]) -> None:
            for k, m in enumerate(made):
                if m is not None:
                    programs.compile_ahead(*settled_call(k, m, y, columns)[1])

        return GridChanges(fine, settled, ahead)

    def resampled(factor: int) -> Problem:
        finer = [dataclasses.replace(o, scene=o.scene.with_values({"render.spp": factor * n})) for o, n in zip(observations, spps)]
        finer_blocks = [b if b.resampled is None else b.resampled(factor) for b in blocks]
        return build_problem(finer, free, loss, None, None, seed, seed_grad, integrator, executor, finer_blocks, image_names)

    return Problem(free, lambda x: residual_at(x, main, 0), lambda x: residual_at(x, independent, 1), reverse,
                   lambda x: models_seeded(x, 0), part_images, references, models_seeded, residual_of, resampled,
                   lambda x: residual_at(x, main, 0, 2), lambda x: residual_at(x, independent, 1, 2), all(o.sensor is not None for o in observations) and all(b.noise_known for b in blocks), tuple(spread),
                   tuple(units), tuple(used_pixels), spps, tuple(o.render_spp for o in observations), tuple(blocks), tuple(dark),
                   pixel_grid if any(blurred) else None, outside,
                   tuple(None if o.sensor is None else noise_variance_terms(o.sensor) for o in observations))


def _seen(free: FreeParameters, k: int, image_names: frozenset[str]) -> tuple[tuple[str, ...], np.ndarray]:
    """What image k's renderer sees (:meth:`~spacefit.fitting.params.FreeParameters.rendered`), less
    the free values only other kinds of observation know (a tabulated BRDF's factor)."""
    names, indices = free.rendered(k)
    keep = [i for i, name in enumerate(names) if name in image_names]
    return tuple(names[i] for i in keep), indices[keep]
