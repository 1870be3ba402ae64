"""A fitting problem's set-up: observations checked, scenes assembled and loaded, residuals built.

Nothing is rendered here: every input is checked first (:func:`setup`), so that a bad one is
refused before any work. Every render of a solve uses the same seed (common random numbers), so
the objective is a deterministic function; derivative renders use another seed. In a joint fit
each observation's renderer sees the free values that are its own (``target.attitude_z_deg@k``)
or shared (:meth:`~spacefit.fitting.params.FreeParameters.rendered`); the image nuisances act on
its render in JAX (:mod:`spacefit.fitting.nuisance`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from spacefit.errors import NEGATIVE_SIGMAS, InputError, InputTypeError, check_array, check_choice, check_count, negative_pixels, quote
from spacefit.formation import dn_fn, noise_variance_dn
from spacefit.executors import Executor
from spacefit.fitting.frames import FrameSpec, InProcess, batched_renders, frame_part_image, run_frames, share_views
from spacefit.fitting.losses import residual_fn
from spacefit.fitting.nuisance import image_model as image_model_of
from spacefit.fitting.params import FreeParameters, free_parameters
from spacefit.geometry.frames import Intrinsics
from spacefit.rendering.bridge import seeds_array
from spacefit.rendering.derivatives import check_seeds, check_spp
from spacefit.rendering.parts import PartImage
from spacefit.scene.assembly import assemble
from spacefit.scene.schema import Scene
from spacefit.scene.sections import FILTER_RADIUS_PX, check_scene
from spacefit.sensor import Sensor, check_flat, read_sensor_file, saturated_mask
from spacefit.psf import psf_rms_px
from spacefit.units import DN_UNIT, RADIANCE_UNIT
from spacefit.scene.parameters import GEOMETRY, observation_of, scene_value, scene_with_values
from spacefit.scene.conversions import G_of, rms_of

INTEGRATORS = ("prb", "direct_projective", "prb_projective")
# Seed offset of the second, independent Jacobian used for the standard errors.
INDEPENDENT_SEED_OFFSET = 1000


@dataclass(frozen=True)
class Observation:
    """A reference radiance image (h, w, 3), W m^-2 sr^-1, and the scene it was taken in.

    ``sigma``: the reference's noise standard deviation (scalar or per pixel), or None.
    ``sensor``: the camera that measured it, if known: the reference is then in DN (as
    :func:`~spacefit.imageio.read_image` gives it), the model is the sensor's
    :func:`~spacefit.formation.expected_dn` of the render, each pixel is weighted by its predicted
    Poisson-Gaussian noise (:func:`~spacefit.formation.noise_variance_dn` at the model's DN, held fixed in derivatives),
    saturated pixels are left out, and the standard errors are the noise model's (J^T W J)^-1
    instead of the sandwich. ``sigma`` must then be None.
    ``mask``: which values to fit, (h, w) or (h, w, channels) bool, True = use (None: all). The
    residuals of the others are 0 in every loss and they count for nothing (not in the degrees of
    freedom, not in the noise floor); they may hold anything, NaN included.
    ``sensor_sources``: where each sensor value came from (field -> "header KEY", "sensor file",
    ...; :func:`~spacefit.imageio.sensor_of`), None for a sensor given whole.
    ``notes``: what a report should say about the file (e.g. a row order it did not state).
    ``flat``: with a sensor, a flat-field map ((h, w) or (h, w, channels), > 0) multiplying the
    expected signal above the bias (:func:`~spacefit.formation.expected_dn`); None: uniform.
    ``render_spp``: the samples per pixel a simulated reference was rendered with, whose Monte Carlo
    noise the goodness of fit then expects (:mod:`~spacefit.fitting.goodness`); None: a real
    observation, without render noise.
    :meth:`from_file` reads all of these from an image file (``render_spp`` from a FITS ``RENDSPP``
    card or a spacefit sidecar).
    """

    scene: Scene
    reference: np.ndarray
    sigma: float | np.ndarray | None = None
    sensor: Sensor | None = None
    mask: np.ndarray | None = None
    sensor_sources: Mapping[str, str] | None = None
    notes: tuple[str, ...] = ()
    flat: np.ndarray | None = None
    render_spp: int | None = None

    def __post_init__(self) -> None:
        check_scene(self.scene, "Observation.scene")
        check_count("Observation.render_spp", self.render_spp)
        if self.sensor is not None and not isinstance(self.sensor, Sensor):
            raise InputTypeError(f"`Observation.sensor` must be an sf.Sensor or None, got {quote(self.sensor)}.")
        if self.flat is not None and self.sensor is None:
            raise InputError("`Observation.flat` multiplies a sensor's expected DN: give the sensor too (or divide a radiance image by it).")
        if self.sensor is not None and self.sigma is not None:
            raise InputError("`Observation.sigma` must be None when `Observation.sensor` is given: the sensor predicts each pixel's noise.")
        ref = check_array("Observation.reference", self.reference)
        if self.sigma is not None:
            _check_sigma(check_array("Observation.sigma", self.sigma), ref.shape)
        if self.mask is not None:
            mask = check_array("Observation.mask", self.mask, "a bool array")
            if not mask.any():
                raise InputError(f"`Observation.mask` is False everywhere ({mask.size} values): it leaves nothing to fit.")

    @classmethod
    def from_file(
        cls, path: str | Path, scene: Scene, *, sensor: Sensor | Mapping[str, Any] | None = None, unit: str | None = None,
        response: str | None = None, mask: str | Path | np.ndarray | None = None, sigma: float | np.ndarray | None = None,
        sensor_file: str | Path | None = None, sensor_defaults: str | None = None, row_order: str | None = None,
        flat: str | Path | np.ndarray | None = None,
    ) -> Observation:
        """The observation in an image file (EXR, FITS, PNG, TIFF; :func:`~spacefit.imageio.read_image`,
        which takes ``unit``, ``response``, ``mask``, ``sigma`` and ``row_order``), with its
        usable-pixel mask (saturated, transparent and user-masked pixels left out).

        Radiance is fitted as radiance (``sigma`` its noise). DN are fitted with their sensor
        (:func:`~spacefit.imageio.sensor_of`): ``sensor`` as given (an sf.Sensor), or the file's own
        values (FITS header keywords, spacefit sidecar) replaced by those of the sensor file
        ``sensor_file`` (:func:`~spacefit.sensor.read_sensor_file`) and then of a mapping ``sensor``;
        a value the fit needs that none gives is refused unless ``sensor_defaults="illustrative"``.
        The sources are kept in ``sensor_sources``. ``flat``: a flat-field map of a DN image, an
        array or an image file (FITS, or PNG / TIFF read as linear), multiplying the expected
        signal above the bias. A one-channel image is fitted as grey (one
        residual per pixel, against the mean of the render's channels).

        Raises:
            InputError: DN with a sensor value missing (naming each and the three ways to give it),
                a ``sensor`` for radiance or a ``sigma`` for DN, and every refusal of ``read_image``,
                naming the file.
        """
        from spacefit.imageio import read_image, sensor_of  # deferred: FITS and TIFF readers (astropy, tifffile): only files need them

        image = read_image(path, unit=unit, response=response, mask=mask, sigma=sigma, row_order=row_order)
        notes, render_spp = tuple(image.metadata["notes"]), image.metadata.get("render_spp")
        if image.unit == RADIANCE_UNIT:
            if sensor is not None or sensor_file is not None or flat is not None:
                raise InputError(f"{image.path!r} holds radiance ({RADIANCE_UNIT}); `sensor` describes the camera of a DN "
                                 "image: leave it out.")
            return cls(scene, image.data, sigma, mask=image.mask, notes=notes, render_spp=render_spp)
        if sigma is not None:
            raise InputError(f"{image.path!r} holds DN: its noise is its sensor's; leave `sigma` out.")
        from_file = read_sensor_file(sensor_file) if sensor_file is not None else None
        measured, sources = sensor_of(image, sensor, sensor_file=from_file, defaults=sensor_defaults)
        if isinstance(flat, (str, Path)):
            flat = read_image(flat, unit="DN", response="linear", row_order=row_order).data
        relative = None if flat is None else check_flat(flat, image.data.shape, f"the flat field of {image.path!r}")
        return cls(scene, image.data, sensor=measured, mask=image.mask, sensor_sources=sources, notes=notes, flat=relative,
                   render_spp=render_spp)


def _check_sigma(sigma: np.ndarray, shape: tuple[int, ...]) -> None:
    """Refuse a noise sigma whose shape is neither a scalar's nor that of the reference (``shape``)
    or of its pixels; its values are checked with the residuals (:func:`~spacefit.fitting.losses.residual_fn`)."""
    if sigma.ndim and sigma.shape not in (shape, shape[:2]):
        raise InputError(f"`Observation.sigma` has shape {sigma.shape}; its reference is {shape}: give one number, "
                         f"(height, width) = {shape[:2]} or {shape}.")


def check_reference(obs: Observation, index: int) -> tuple[np.ndarray, np.ndarray]:
    """The observation's reference as a float32 (h, w, 3) array, or (h, w, 1) for a one-channel
    (grey) image, checked against its scene, with masked-out values set to 0, and its bool mask of
    the values to fit (same shape)."""
    ref = np.asarray(obs.reference, dtype=np.float32)
    w, h = obs.scene.render.resolution
    if ref.ndim == 2:
        ref = ref[..., None]
    if ref.ndim != 3 or ref.shape[:2] != (h, w) or ref.shape[-1] not in (1, 3):
        raise InputError(
            f"reference {index} has shape {ref.shape}, but its scene renders (height, width) = ({h}, {w}) with 1 (grey) "
            "or 3 (RGB) channels; render the reference at the scene's resolution or set `render.resolution`."
        )
    used = np.ones(ref.shape, dtype=bool) if obs.mask is None else _mask(obs.mask, ref.shape, index)
    nonfinite = int(np.any(~np.isfinite(ref) & used, axis=-1).sum())
    if nonfinite:
        raise InputError(f"reference {index} holds NaN or infinite pixels ({nonfinite}); leave them out with its mask "
                         "(`Observation.mask` False there).")
    if obs.sensor is not None:  # DN: bias + gain * electrons, rounded; read noise the only way below the bias
        s = obs.sensor
        read_dn, floor = s.read_noise_electrons * s.gain_dn_per_electron, s.bias_dn - 0.5
        below = negative_pixels(ref - np.float32(floor), read_dn, used)
        if below:
            raise InputError(f"reference {index} holds {below} pixels below {floor - NEGATIVE_SIGMAS * read_dn:g} DN: its "
                             f"sensor's bias ({s.bias_dn:g} DN) less half a DN and {NEGATIVE_SIGMAS:g} sigma of read noise "
                             f"({read_dn:g} DN), which its DN never reach; give the sensor's bias_dn, read_noise_electrons and "
                             "gain_dn_per_electron (a bias-subtracted image has bias_dn = 0), or mask the pixels.")
    elif below := negative_pixels(ref, obs.sigma, used):
        noise = "" if obs.sigma is None else f" by more than {NEGATIVE_SIGMAS:g} of its stated sigma"
        raise InputError(f"reference {index} holds {below} pixels with negative values{noise}: radiance is never negative; give "
                         "the image's noise sigma, or fit the DN it was measured in with its sensor.")
    return np.where(used, ref, np.float32(0.0)), used


def _mask(mask: np.ndarray, shape: tuple[int, ...], index: int) -> np.ndarray:
    """An observation's mask broadcast to its reference's (h, w, c) shape."""
    m = np.asarray(mask)
    m = m[..., None] if m.ndim == 2 else m
    if m.ndim != 3 or m.shape[:2] != shape[:2] or m.shape[2] not in (1, shape[2]):
        raise InputError(f"mask {index} (`Observation.mask`) has shape {m.shape}; its reference is {shape}: give "
                         f"(height, width) = {shape[:2]} or (height, width, channels) = {shape}.")
    return np.broadcast_to(m, shape)


@dataclass
class Problem:
    """The residuals of a set of observations as JAX functions of the physical free values x."""

    free: FreeParameters
    residual_x: Callable[[jax.Array], jax.Array]  # physical x -> stacked residuals (J by forward mode)
    residual_x_independent: Callable[[jax.Array], jax.Array]  # the same with independent seeds
    loss_u_reverse: Callable[[jax.Array], jax.Array] | None  # unconstrained u -> loss (reverse mode)
    renders_x: Callable[[jax.Array], list[jax.Array]]  # each observation's model image in its reference's unit
    part_images: list[PartImage]  # which part each pixel of each observation sees
    references: list[np.ndarray]  # the checked references, (h, w, 3) or (h, w, 1) float32, 0 where not used
    # (x, j) -> each observation's model image at the j-th seeds (0 the fit's, 1 the independent ones, more
    # further independent ones: the goodness of fit's verdict render, spacefit.fitting.goodness) ...
    models_seeded: Callable[[jax.Array, int], list[jax.Array]]
    # ... the stacked residuals of given model images (the noise sigma taken at them) ...
    residual_of: Callable[[list[jax.Array]], jax.Array]
    # ... and factor -> the same problem rendered with factor times the samples per pixel (the verdict render)
    resampled: Callable[[int], Problem]
    noise_known: bool = False  # every residual is divided by its predicted noise (a sensor per observation)
    # per observation, how far (px) its render noise spreads before the residuals: the pixel
    # filter's radius and the rms width of the sensor's PSF (0 without a sensor)
    noise_spread_px: tuple[tuple[float, float], ...] = ()
    units: tuple[str, ...] = ()  # per observation, the unit of its reference and model image (radiance or DN)
    used: tuple[np.ndarray, ...] = ()  # per observation, (h, w) bool: the pixels fitted in every channel
    spp: tuple[int, ...] = ()  # per observation, the samples per pixel of its primal renders
    reference_spp: tuple[int | None, ...] = ()  # per observation, its reference's (Observation.render_spp)


def _problem(
    observations: Sequence[Observation], free: FreeParameters, loss: str, spp: int | None, spp_grad: int | None,
    seed: int, seed_grad: int, integrator: str, executor: Executor | None = None,
) -> Problem:
    residuals, references, spread, to_units, units, used_pixels, specs, shapes = [], [], [], [], [], [], [], []
    # the image nuisances act on the render in JAX; each renderer sees the other parameters, an
    # observation's own pose (``target.attitude_z_deg@k``) in place of the shared one; every
    # observation's render of a step runs in one batch (spacefit.fitting.frames)
    executor = InProcess() if executor is None else executor
    image_model = image_model_of(free.names)
    rendered = [free.rendered(k) for k in range(len(observations))]
    for i, obs in enumerate(observations):
        rendered_names, steps = rendered[i][0], free.fd_steps[rendered[i][1]]
        ref, used = check_reference(obs, i)
        scene = obs.scene
        assembly = assemble(scene)
        specs.append(FrameSpec(scene, tuple(rendered_names), tuple(float(v) for v in steps), spp, spp_grad, integrator))
        shapes.append((assembly.intrinsics.height, assembly.intrinsics.width, 3))
        if obs.sensor is not None:
            used = used & ~saturated_mask(ref, obs.sensor)  # a saturated value says only "at least this bright"
        residuals.append(_residual(obs, ref, used, loss))
        to_units.append(_in_unit_of(obs, ref.shape[-1], assembly.intrinsics))
        units.append(RADIANCE_UNIT if obs.sensor is None else DN_UNIT)
        references.append(ref)
        used_pixels.append(np.all(used, axis=-1))
        blur = 0.0 if obs.sensor is None else psf_rms_px(obs.sensor, assembly.intrinsics, ref.shape[-1])
        spread.append((FILTER_RADIUS_PX[scene.render.filter], blur))
    specs = share_views(specs)  # a pass's frames share a loaded scene
    indices = [r[1] for r in rendered]
    images = batched_renders(executor, specs, indices, shapes)
    part_images = run_frames(executor, frame_part_image, specs)

    def stack(images: Callable[[jax.Array], Sequence[jax.Array]]) -> Callable[[jax.Array], tuple[list[jax.Array], jax.Array]]:
        """x -> each observation's model image and the stacked residuals."""
        def both(x: jax.Array) -> tuple[list[jax.Array], jax.Array]:
            models = [to_units[k](image_model(image, x, k)) for k, image in enumerate(images(x))]
            return models, jnp.concatenate([res(model) for res, model in zip(residuals, models)])
        return both

    # compiled once per fit, the seeds an operand: one program for the model images and residuals at the
    # fit's seeds and at the independent ones (evaluated op by op, the image model's FFTs and the
    # residuals compiled some 170 small XLA programs per fit, 15 s of a 128 x 128 fit's 75 s on 2 cores)
    models_residuals = jax.jit(lambda x, seeds: stack(lambda y: images(y, seeds))(x))
    main, independent = seeds_array(seed, seed_grad), seeds_array(seed + INDEPENDENT_SEED_OFFSET, seed_grad + INDEPENDENT_SEED_OFFSET)
    reverse = None
    if not np.any(free.fd_steps > 0) and isinstance(executor, InProcess):  # one Dr.Jit backward pass per observation
        renders_v = [executor.chain(spec).reverse(seed, seed_grad) for spec in specs]

        def reverse(u: jax.Array) -> jax.Array:
            frames = lambda x: [render(x[indices[k]]) for k, render in enumerate(renders_v)]  # noqa: E731
            return 0.5 * jnp.sum(stack(frames)(free.to_physical(u))[1] ** 2)

    def models_seeded(x: jax.Array, j: int) -> list[jax.Array]:
        return models_residuals(x, seeds_array(seed + j * INDEPENDENT_SEED_OFFSET, seed_grad + j * INDEPENDENT_SEED_OFFSET))[0]

    residual_of = jax.jit(lambda models: jnp.concatenate([res(model) for res, model in zip(residuals, models)]))
    spps = tuple(spp or o.scene.render.spp for o in observations)

    def resampled(factor: int) -> Problem:
        finer = [dataclasses.replace(o, scene=o.scene.with_values({"render.spp": factor * n})) for o, n in zip(observations, spps)]
        return _problem(finer, free, loss, None, None, seed, seed_grad, integrator, executor)

    return Problem(free, lambda x: models_residuals(x, main)[1], lambda x: models_residuals(x, independent)[1], reverse,
                   lambda x: models_residuals(x, main)[0], part_images, references, models_seeded, residual_of, resampled,
                   all(o.sensor is not None for o in observations), tuple(spread), tuple(units), tuple(used_pixels), spps,
                   tuple(o.render_spp for o in observations))


def _in_unit_of(obs: Observation, channels: int, intrinsics: Intrinsics) -> Callable[[jax.Array], jax.Array]:
    """A model radiance image (h, w, 3) as the observation sees it: its ``channels`` (a grey image
    sees the mean of the render's channels, which are equal: the scene is grey), in radiance or,
    with a sensor, in the sensor's expected DN."""
    to_dn = (lambda image: image) if obs.sensor is None else dn_fn(obs.sensor, intrinsics, channels, obs.flat)
    if channels == 1:
        return lambda image: to_dn(jnp.mean(image, axis=-1, keepdims=True))
    return to_dn


def _residual(obs: Observation, reference: np.ndarray, used: np.ndarray, loss: str) -> Callable[[jax.Array], jax.Array]:
    """The residuals of a model image in the reference's unit, 0 where ``used`` is False: in
    radiance, or with a sensor, in DN divided by the noise the sensor predicts at the model's DN."""
    if obs.sensor is None:
        return residual_fn(reference, loss, obs.sigma, used)
    sensor = obs.sensor
    return residual_fn(reference, loss, lambda dn: jnp.sqrt(noise_variance_dn(dn, sensor)), used)


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
    scene: Scene  # the first observation's scene, as given
    noise_given: bool = False  # every observation has a sensor or a sigma: the residuals are in units of the noise


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


def setup(
    observations: Observation | Sequence[Observation], free: Sequence[str], *, start: Mapping[str, float] | None = None,
    loss: str = "pixel", render: FitRender = FitRender(), wrinkle_coordinates: str = "rms", executor: Executor | None = None,
) -> Setup:
    """Check every input and build the problem; nothing is rendered here. ``executor``: where the
    observations' renders run, as one batch per step (:mod:`spacefit.fitting.frames`; None: each
    observation's own render functions in this process).

    Raises:
        InputError: for any bad input.
    """
    if not isinstance(observations, (Observation, Sequence)):
        raise InputTypeError(f"`observations` must be an sf.Observation(scene, reference) or a list of them, got {quote(observations)}.")
    observations = [observations] if isinstance(observations, Observation) else list(observations)
    if not observations:
        raise InputError("`observations` must hold at least one reference image.")
    for i, obs in enumerate(observations):
        if not isinstance(obs, Observation):
            raise InputTypeError(f"`observations[{i}]` must be an sf.Observation(scene, reference), got {quote(obs)}.")
    if not isinstance(render, FitRender):
        raise InputTypeError(f"`render` must be an sf.FitRender(spp=..., seed=...), got {quote(render)}.")
    check_choice("wrinkle_coordinates", wrinkle_coordinates, ("rms", "G"))
    user = free_parameters(observations[0].scene, free, len(observations))
    given = observations[0].scene
    observations = [dataclasses.replace(o, scene=fit_scene(o.scene, user.names)) for o in observations]
    scene = observations[0].scene
    if start is not None and not isinstance(start, Mapping):
        raise InputTypeError(f"`start` must be a mapping of free parameter names to values, got {quote(start)}.")
    start = dict(start or {})
    for name in start:
        check_choice("start", name, user.names)
    for k, obs in enumerate(observations):  # a start value is refused as the scene file would refuse it, with its message
        scene_with_values(obs.scene, start, observation=k)
    # an observation's own value (``target.attitude_z_deg@k``) starts at its scene's
    x0_user = np.array([start.get(n, scene_value(observations[observation_of(n)[1] or 0].scene, n)) for n in user.names],
                       dtype=float)
    user.check_start(x0_user)
    w = scene.wrinkles
    rms_index = None
    if wrinkle_coordinates == "rms" and {"wrinkles.D", "wrinkles.G"} <= set(user.names):
        i_D, rms_index = user.names.index("wrinkles.D"), user.names.index("wrinkles.G")
        internal = [n if n != "wrinkles.G" else "wrinkles.rms_m" for n in user.names]
        at_start = dataclasses.replace(w, D=x0_user[i_D], G=x0_user[rms_index])
        solver_params = free_parameters(dataclasses.replace(scene, wrinkles=at_start), internal, len(observations))
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
    problem = _problem(observations, solver_params, loss, render.spp, render.spp_grad, render.seed, render.seed_grad,
                       render.integrator, executor)
    noise_given = all(o.sensor is not None or o.sigma is not None for o in observations)
    return Setup(user, solver_params, x0_user, x0, to_user, problem, rms_index, given, noise_given)
