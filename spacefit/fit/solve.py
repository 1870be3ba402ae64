"""``fit``: recover scene parameters from reference images with gradient-based solvers.

One function, one result type. Solvers: optimistix ``LevenbergMarquardt`` (``"lm"``),
``GaussNewton`` (``"gn"``), ``Dogleg`` (``"dogleg"``), ``BFGS`` (``"bfgs"``), and optax Adam
(``"adam"``, the stochastic-gradient baseline, with reverse-mode gradients). Every render of a
solve uses the same seed (common random numbers), so the objective is a deterministic function;
derivative renders use another seed.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import lineax as lx
import numpy as np
import optax
import optimistix as optx

from spacefit.errors import InputError, check_choice, check_range
from spacefit.fit.losses import residual_fn
from spacefit.fit.params import FreeParameters, free_parameters, scene_value, scene_values_fn
from spacefit.geometry.wm import wm_G_from_rms, wm_rms
from spacefit.progress import ProgressCallback
from spacefit.render.bridge import DrJitScene, render_params, render_values
from spacefit.render.renderer import Renderer
from spacefit.scene.assembly import assemble
from spacefit.scene.config import Scene

SOLVERS = ("lm", "gn", "dogleg", "bfgs", "adam")
INTEGRATORS = ("prb", "direct_projective", "prb_projective")
# |correlation| above which two parameters are reported as not separately determined.
CORRELATION_WARN = 0.95
# Relative standard error above which a parameter is reported as poorly determined.
REL_STDERR_WARN = 0.2


@dataclass(frozen=True)
class Observation:
    """A reference radiance image (h, w, 3), W m^-2 sr^-1, and the scene it was taken in.

    ``sigma``: the reference's noise standard deviation (scalar or per pixel), or None.
    """

    scene: Scene
    reference: np.ndarray
    sigma: float | np.ndarray | None = None


@dataclass
class FitResult:
    """Outcome of :func:`fit`: values in physical units and how far to trust them.

    Attributes:
        names: free parameter names, in order.
        values: fitted value of each, physical units.
        stderr: standard error of each (from J^T J and the residual); inf if not determined.
        correlation: (n, n) correlation matrix of the estimates.
        success: whether the solver reports convergence.
        status: the solver's status in words.
        warnings: identifiability and convergence warnings, in words.
        history: one entry per step: the point the step evaluated (step 1 evaluates the start;
            the accepted point of the last step is ``values``), its loss, time_s since the start.
        renders: the final render of each observation.
        loss: final loss, 0.5 * sum of squared residuals.
        solver, loss_name, steps, wall_time_s, start: what was run.
        extras: derived quantities, e.g. the rms height (and its standard error) of a (D, G) fit.
    """

    names: tuple[str, ...]
    values: dict[str, float]
    stderr: dict[str, float]
    correlation: np.ndarray
    success: bool
    status: str
    warnings: list[str]
    history: list[dict[str, Any]]
    renders: list[np.ndarray]
    loss: float
    solver: str
    loss_name: str
    steps: int
    wall_time_s: float
    start: dict[str, float] = field(default_factory=dict)
    extras: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary (no images)."""
        d = dataclasses.asdict(self)
        d.pop("renders")
        d["correlation"] = np.asarray(self.correlation).tolist()
        return d


def _status(result: optx.RESULTS) -> tuple[bool, str]:
    for item, words in [
        (optx.RESULTS.successful, "converged"),
        (optx.RESULTS.nonlinear_max_steps_reached, "stopped: maximum number of steps reached"),
        (optx.RESULTS.nonlinear_divergence, "failed: the solve diverged"),
        (optx.RESULTS.nonfinite, "failed: non-finite (NaN or inf) values in the solve"),
    ]:
        if bool(result == item):
            return bool(item == optx.RESULTS.successful), words
    return False, f"failed: {optx.RESULTS[result]}"


def _check_reference(obs: Observation, index: int) -> np.ndarray:
    ref = np.asarray(obs.reference, dtype=np.float32)
    w, h = obs.scene.render.resolution
    if ref.ndim == 2:
        ref = np.repeat(ref[..., None], 3, axis=-1)
    if ref.shape[:2] != (h, w) or ref.shape[-1] < 3:
        raise InputError(
            f"reference {index} has shape {ref.shape}, but its scene renders (height, width) = ({h}, {w}); "
            "render the reference at the scene's resolution or set `render.resolution`."
        )
    ref = ref[..., :3]
    if not np.all(np.isfinite(ref)):
        raise InputError(f"reference {index} holds NaN or infinite pixels ({int(np.sum(~np.isfinite(ref)))}).")
    return ref


# Seed offset of the second, independent Jacobian used for the standard errors.
INDEPENDENT_SEED_OFFSET = 1000


@dataclass
class _Problem:
    free: FreeParameters
    residual_x: Callable[[jax.Array], jax.Array]  # physical x -> stacked residuals (J by forward mode)
    residual_x_independent: Callable[[jax.Array], jax.Array]  # the same with independent seeds
    loss_u_reverse: Callable[[jax.Array], jax.Array] | None  # unconstrained u -> loss (reverse mode)
    renders_x: Callable[[jax.Array], list[jax.Array]]


def _problem(
    observations: Sequence[Observation], free: FreeParameters, loss: str, spp: int | None, spp_grad: int | None,
    seed: int, seed_grad: int, integrator: str,
) -> _Problem:
    renders_x, renders_alt, renders_v, residuals, values_fns = [], [], [], [], []
    geometry = any(n.startswith("wrinkles.") for n in free.names)
    for i, obs in enumerate(observations):
        ref = _check_reference(obs, i)
        scene = obs.scene
        assembly = assemble(scene)
        # D and G move the vertices: render the whole film, the target's window would not hold them
        renderer = Renderer(assembly, crop=not geometry)
        dscene = DrJitScene(renderer, spp or scene.render.spp, spp_grad or spp or scene.render.spp, integrator)
        values_of = scene_values_fn(assembly, free)
        renders_x.append(render_params(dscene, values_of, free.fd_steps, seed, seed_grad))
        alt = INDEPENDENT_SEED_OFFSET
        renders_alt.append(render_params(dscene, values_of, free.fd_steps, seed + alt, seed_grad + alt))
        renders_v.append(render_values(dscene, seed, seed_grad))
        residuals.append(residual_fn(ref, loss, obs.sigma))
        values_fns.append(values_of)

    def stack(renders: list[Callable[[jax.Array], jax.Array]]) -> Callable[[jax.Array], jax.Array]:
        return lambda x: jnp.concatenate([res(render(x)) for res, render in zip(residuals, renders)])

    residual_x = stack(renders_x)

    reverse = None
    if not np.any(free.fd_steps > 0):

        def reverse(u: jax.Array) -> jax.Array:
            x = free.to_physical(u)
            r = jnp.concatenate([res(render(vals(x))) for res, render, vals in zip(residuals, renders_v, values_fns)])
            return 0.5 * jnp.sum(r**2)

    return _Problem(free, residual_x, stack(renders_alt), reverse, lambda x: [render(x) for render in renders_x])


def _covariance(problem: _Problem, x: np.ndarray) -> tuple[np.ndarray, float, np.ndarray]:
    """Covariance of the estimate at ``x`` (physical units), the loss, and the eigenvalues of the
    Fisher information (J^T J) / s^2 under uniform noise.

    The covariance is the heteroscedasticity-consistent "sandwich" (White 1980, with the HC1
    small-sample factor), (J^T J)^-1 J^T diag(r^2) J (J^T J)^-1: glints make the image noise
    largest in the pixels where the Jacobian is largest, and the uniform-noise form s^2 (J^T J)^-1
    understated the scatter of the estimates threefold (D 6.6 of its standard errors off in the
    wrinkles case; 2.3 with the sandwich). Monte Carlo noise in the Jacobian columns would add to
    J^T J as if it were information and shrink the errors, so the products are estimated from two
    Jacobians with independent seeds, sym(J1^T W J2). Rows where neither the residual nor the
    Jacobian is non-zero (black sky) carry no information and are not counted in the degrees of
    freedom. Directions the images do not constrain (eigenvalues of sym(J1^T J2) that are not
    clearly positive) give infinite variance to every parameter they touch.
    """
    r = np.asarray(problem.residual_x(jnp.asarray(x)), dtype=float)
    J1 = np.asarray(jax.jacfwd(problem.residual_x)(jnp.asarray(x)), dtype=float)
    J2 = np.asarray(jax.jacfwd(problem.residual_x_independent)(jnp.asarray(x)), dtype=float)
    if not (np.all(np.isfinite(r)) and np.all(np.isfinite(J1)) and np.all(np.isfinite(J2))):
        n = len(x)
        return np.full((n, n), np.nan), math.nan, np.full(n, np.nan)
    informative = int((np.any(J1 != 0, axis=1) | (r != 0)).sum())
    dof = max(informative - len(x), 1)
    s2 = float(r @ r) / dof

    def cross(w: np.ndarray) -> np.ndarray:  # sym(J1^T diag(w) J2)
        return 0.5 * ((J1 * w[:, None]).T @ J2 + (J2 * w[:, None]).T @ J1)

    eigval, eigvec = np.linalg.eigh(cross(np.ones_like(r)))
    tiny = eigval <= 1e-9 * max(np.abs(eigval).max(), 1e-300)
    bread = (eigvec[:, ~tiny] / eigval[~tiny]) @ eigvec[:, ~tiny].T
    m_val, m_vec = np.linalg.eigh(cross(r**2 * informative / dof))
    meat = (m_vec * np.clip(m_val, 0.0, None)) @ m_vec.T  # the cross form is not PSD by construction
    cov = bread @ meat @ bread
    if tiny.any():
        touched = np.any(np.abs(eigvec[:, tiny]) > 1e-6, axis=1)
        cov[touched, :] = np.inf
        cov[:, touched] = np.inf
    return cov, 0.5 * float(r @ r), np.clip(eigval, 0.0, None) / s2


def _map_covariance(T: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """Delta method: covariance of y(x) from that of x, with T = dy/dx; undetermined stays undetermined."""
    undetermined = ~np.isfinite(np.diag(cov))
    out = T @ np.where(np.isfinite(cov), cov, 0.0) @ T.T
    touched = np.any(np.abs(T[:, undetermined]) > 0, axis=1)
    out[touched, :] = np.inf
    out[:, touched] = np.inf
    return out


def _stderr_corr(cov: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    stderr = np.sqrt(np.diag(cov))
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov / np.outer(stderr, stderr)
    corr = np.where(np.isfinite(corr), corr, 0.0)
    np.fill_diagonal(corr, 1.0)
    return stderr, corr


def _warnings(params: FreeParameters, values: np.ndarray, stderr: np.ndarray, corr: np.ndarray) -> list[str]:
    out = []
    names = params.names
    for name, b, value in zip(names, params.bijections, values):
        if side := b.at_bound(float(value)):
            out.append(f"{name} = {value:.4g} is at the {side} bound of its range {b.describe()}: the solver pushed "
                       "it there, so neither it nor its standard error is an estimate; the model may not be able "
                       "to match the images (another start, or another free parameter?).")
    for i, name in enumerate(names):
        if np.isnan(stderr[i]):
            continue  # no error estimate at all: reported by the caller
        if not np.isfinite(stderr[i]):
            out.append(f"{name} is not determined by these observations (singular J^T J).")
        elif stderr[i] > REL_STDERR_WARN * max(abs(values[i]), 1e-12):
            out.append(f"{name} is poorly determined: standard error {stderr[i]:.3g} on {values[i]:.4g}.")
    for i in range(len(names)):
        for j in range(i + 1, len(names)):
            if abs(corr[i, j]) > CORRELATION_WARN:
                out.append(
                    f"{names[i]} and {names[j]} are correlated ({corr[i, j]:+.3f}): the images determine a "
                    "combination of them better than each; add views, resolution or samples."
                )
    return out


@dataclass
class _Setup:
    """A checked fitting problem: user-facing and solver parameters and the residuals."""

    user: FreeParameters  # the parameters as the user named them
    solver_params: FreeParameters  # the ones the solver moves ((D, rms) in place of (D, G))
    x0_user: np.ndarray
    x0: np.ndarray
    to_user: Callable[[jax.Array], jax.Array]
    problem: _Problem
    rms_index: int | None


def _fit_scene(scene: Scene, free: Sequence[str]) -> Scene:
    """The scene a fit renders. ``wrinkles.model`` 'auto' becomes 'geometry': the fit's parameters act
    on the displaced geometry and on the facets' own roughness, which the effective model merges
    into one roughness. A forced 'effective' model therefore may not free D, G or the rms height,
    nor the roughness of a wrinkled part."""
    w = scene.wrinkles
    if not w.enabled or w.model == "geometry":
        return scene
    if w.model == "auto":
        return dataclasses.replace(scene, wrinkles=dataclasses.replace(w, model="geometry"))
    merged = [n for n in free if n.startswith("wrinkles.")
              or (n.startswith("parts.") and n.split(".")[1] in w.parts and n.split(".")[2].startswith("alpha"))]
    if merged:
        raise InputError(f"{', '.join(map(repr, merged))} cannot be fitted with `wrinkles.model` = 'effective', which merges "
                         "the wrinkles' slopes and the facets' roughness into one roughness; use 'geometry' or 'auto'.")
    return scene


def _setup(
    observations: Observation | Sequence[Observation], free: Sequence[str], start: Mapping[str, float] | None,
    loss: str, spp: int | None, spp_grad: int | None, seed: int, seed_grad: int, integrator: str,
    geometry_jacobian: str, wrinkle_coordinates: str,
) -> _Setup:
    """Check every input and build the problem; nothing is rendered here."""
    observations = [observations] if isinstance(observations, Observation) else list(observations)
    if not observations:
        raise InputError("`observations` must hold at least one reference image.")
    check_choice("integrator", integrator, INTEGRATORS)
    check_choice("geometry_jacobian", geometry_jacobian, ("fd", "ad"))
    check_choice("wrinkle_coordinates", wrinkle_coordinates, ("rms", "G"))
    for name, value in (("spp", spp), ("spp_grad", spp_grad)):
        if value is not None and (isinstance(value, bool) or not isinstance(value, int) or value < 1):
            raise InputError(f"`{name}` must be an integer >= 1, got {value!r}.")
    if seed == seed_grad:
        raise InputError("`seed` and `seed_grad` must differ (a shared seed biases L2 gradients).")
    user = free_parameters(observations[0].scene, free)
    observations = [dataclasses.replace(o, scene=_fit_scene(o.scene, user.names)) for o in observations]
    scene = observations[0].scene
    start = dict(start or {})
    for name in start:
        check_choice("start", name, user.names)
    x0_user = np.array([start.get(n, scene_value(scene, n)) for n in user.names], dtype=float)
    user.check_start(x0_user)
    w = scene.wrinkles
    rms_index = None
    if wrinkle_coordinates == "rms" and {"wrinkles.D", "wrinkles.G"} <= set(user.names):
        i_D, rms_index = user.names.index("wrinkles.D"), user.names.index("wrinkles.G")
        internal = [n if n != "wrinkles.G" else "wrinkles.rms_m" for n in user.names]
        at_start = dataclasses.replace(w, D=x0_user[i_D], G=x0_user[rms_index])
        solver_params = free_parameters(dataclasses.replace(scene, wrinkles=at_start), internal)
        x0 = x0_user.copy()
        x0[rms_index] = float(wm_rms(x0_user[i_D], x0_user[rms_index], gamma=w.gamma, M=w.M, L=w.L, Ls=w.Ls))

        def to_user(x: jax.Array) -> jax.Array:
            return x.at[rms_index].set(wm_G_from_rms(x[i_D], x[rms_index], gamma=w.gamma, M=w.M, L=w.L, Ls=w.Ls))
    else:
        solver_params, x0 = user, x0_user

        def to_user(x: jax.Array) -> jax.Array:
            return x

    if geometry_jacobian == "ad":
        wrinkles = np.array([n.startswith("wrinkles.") for n in solver_params.names])
        solver_params = dataclasses.replace(solver_params, fd_steps=np.where(wrinkles, 0.0, solver_params.fd_steps))
    problem = _problem(observations, solver_params, loss, spp, spp_grad, seed, seed_grad, integrator)
    return _Setup(user, solver_params, x0_user, x0, to_user, problem, rms_index)


def _estimate(setup: _Setup, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, float, dict[str, Any]]:
    """User-facing values, their covariance, the loss and extras at solver values ``x``."""
    cov, loss_value, fisher = _covariance(setup.problem, x)
    extras: dict[str, Any] = {"fisher_eigenvalues": fisher.tolist()}
    if setup.rms_index is not None:
        i = setup.rms_index
        extras.update({"wrinkles.rms_m": float(x[i]), "wrinkles.rms_m.stderr": float(np.sqrt(cov[i, i]))})
        cov = _map_covariance(np.asarray(jax.jacfwd(setup.to_user)(jnp.asarray(x))), cov)
    return np.asarray(setup.to_user(jnp.asarray(x)), dtype=float), cov, loss_value, extras


def fit(
    observations: Observation | Sequence[Observation],
    free: Sequence[str],
    *,
    solver: str = "lm",
    loss: str = "pixel",
    start: Mapping[str, float] | None = None,
    spp: int | None = None,
    spp_grad: int | None = None,
    max_steps: int = 50,
    rtol: float = 1e-3,
    atol: float = 1e-6,
    learning_rate: float = 0.05,
    seed: int = 1,
    seed_grad: int = 2,
    integrator: str = "prb",
    geometry_jacobian: str = "fd",
    wrinkle_coordinates: str = "rms",
    progress: ProgressCallback | None = None,
) -> FitResult:
    """Fit free scene parameters so that renders match reference images.

    Args:
        observations: one or several (reference, scene) pairs of the same target; fitted jointly.
            Fixed parameters come from each scene.
        free: parameter names (see :mod:`spacefit.fit.params`), e.g. ``["parts.panels.alpha_x"]``.
        solver: one of :data:`SOLVERS`.
        loss: ``"pixel"``, ``"pyramid"`` or ``"stats"`` (see :mod:`spacefit.fit.losses`).
        start: start values (physical units); default: the first scene's values.
        spp, spp_grad: samples per pixel of primal and derivative renders (default: the scene's).
        max_steps: solver step limit.
        rtol, atol: optimistix tolerances (Adam: stop when the relative loss change < rtol).
        learning_rate: Adam's step size in unconstrained coordinates.
        seed, seed_grad: seeds of primal and derivative renders; render references with another.
        integrator: AD integrator for derivative renders, one of :data:`INTEGRATORS`.
        geometry_jacobian: ``"fd"`` (central differences with common random numbers) or ``"ad"``
            (the integrator's derivative) for D and G.
        wrinkle_coordinates: with D and G both free, ``"rms"`` solves in (D, rms height), the
            better-determined coordinates, and reports D and G with their covariance mapped by
            the delta method; ``"G"`` solves in (D, G) directly.
        progress: called with (step, max_steps) after each step.

    Raises:
        InputError: for any bad input, before rendering.
    """
    check_choice("solver", solver, SOLVERS)
    if isinstance(max_steps, bool) or not isinstance(max_steps, int) or max_steps < 1:
        raise InputError(f"`max_steps` must be an integer >= 1, got {max_steps!r}.")
    check_range("rtol", rtol, 0.0, lo_open=True)
    check_range("atol", atol, 0.0)
    check_range("learning_rate", learning_rate, 0.0, lo_open=True)
    setup = _setup(observations, free, start, loss, spp, spp_grad, seed, seed_grad, integrator, geometry_jacobian,
                   wrinkle_coordinates)
    fp, problem = setup.solver_params, setup.problem

    t0 = time.perf_counter()
    history: list[dict[str, Any]] = []
    last: dict[str, Any] = {}

    def record(u: np.ndarray, value: np.ndarray) -> None:
        last.update(u=np.asarray(u), loss=float(value))

    def residual_u(u: jax.Array, args: Any) -> jax.Array:
        # renders are float32; the solver works in the dtype of u (float64) throughout
        r = problem.residual_x(fp.to_physical(u)).astype(u.dtype)
        jax.debug.callback(record, u, 0.5 * jnp.sum(r**2))
        return r

    def log_step(step: int) -> bool:
        """Record the step's evaluation; False after a run of non-finite evaluations."""
        x = np.asarray(setup.to_user(fp.to_physical(jnp.asarray(last["u"]))))
        history.append({"step": step, "loss": last["loss"], "values": dict(zip(setup.user.names, x.tolist())),
                        "time_s": time.perf_counter() - t0})
        if progress is not None:
            progress(step, max_steps)
        return not _nonfinite_run(history)

    u = jnp.asarray(fp.to_unconstrained(jnp.asarray(setup.x0)))
    if solver == "adam":
        success, status, u, steps = _adam(problem, residual_u, u, max_steps, rtol, learning_rate, log_step, last)
    else:
        success, status, u, steps = _optimistix(solver, residual_u, u, max_steps, rtol, atol, log_step)

    x = np.asarray(fp.to_physical(u), dtype=float)
    n = len(x)
    if np.all(np.isfinite(np.asarray(setup.to_user(jnp.asarray(x))))):
        x_user, cov, loss_value, extras = _estimate(setup, x)
        stderr, corr = _stderr_corr(cov)
        warnings = _warnings(setup.user, x_user, stderr, corr)
        if not math.isfinite(loss_value):
            success = False
            warnings.insert(0, "the render or its Jacobian at the result is not finite (NaN); no errors are reported.")
        if not success:
            warnings.insert(0, f"the solver did not converge ({status}).")
        renders = [np.asarray(img) for img in problem.renders_x(jnp.asarray(x))]
    else:
        x_user, stderr, corr, loss_value, extras = np.full(n, np.nan), np.full(n, np.nan), np.eye(n), math.nan, {}
        warnings = ["the solve produced non-finite parameters; no estimate is reported."]
        success, renders = False, []
    return FitResult(
        names=setup.user.names,
        values=dict(zip(setup.user.names, x_user.tolist())),
        stderr=dict(zip(setup.user.names, stderr.tolist())),
        correlation=corr,
        success=success,
        status=status,
        warnings=warnings,
        history=history,
        renders=renders,
        loss=loss_value,
        solver=solver,
        loss_name=loss,
        steps=steps,
        wall_time_s=time.perf_counter() - t0,
        start=dict(zip(setup.user.names, setup.x0_user.tolist())),
        extras=extras,
    )


@dataclass(frozen=True)
class Identifiability:
    """What a set of observations can tell about the free parameters at given values.

    Attributes:
        names: free parameter names.
        stderr: standard error each would have (physical units; inf where undetermined).
        correlation: (n, n) correlation of the estimates.
        fisher_eigenvalues: eigenvalues of the Fisher information in the solver's coordinates
            (their square roots are the noise-weighted Jacobian's singular values); 0 marks a
            direction nothing constrains.
        extras: derived quantities, e.g. the rms height's standard error when D and G are free.
    """

    names: tuple[str, ...]
    stderr: dict[str, float]
    correlation: np.ndarray
    fisher_eigenvalues: np.ndarray
    extras: dict[str, Any]


def identifiability(
    observations: Observation | Sequence[Observation],
    free: Sequence[str],
    at: Mapping[str, float],
    *,
    loss: str = "pixel",
    spp: int | None = None,
    seed: int = 1,
    seed_grad: int = 2,
    wrinkle_coordinates: str = "rms",
) -> Identifiability:
    """Standard errors and Fisher information of ``free`` parameters at the values ``at``, no fit.

    With references rendered at ``at`` (and their noise ``sigma``), this predicts how well a fit
    could determine each parameter from these observations.
    """
    setup = _setup(observations, free, at, loss, spp, None, seed, seed_grad, "prb", "fd", wrinkle_coordinates)
    _, cov, _, extras = _estimate(setup, setup.x0)
    stderr, corr = _stderr_corr(cov)
    return Identifiability(setup.user.names, dict(zip(setup.user.names, stderr.tolist())), corr,
                           np.asarray(extras.pop("fisher_eigenvalues")), extras)


# A solve fails when this many consecutive evaluations are not finite; a line search or trust
# region may try (and reject) a single non-finite point.
NONFINITE_PATIENCE = 3
# Adam stops when no unconstrained coordinate moved more than rtol for this many steps.
ADAM_PATIENCE = 5


def _nonfinite_run(history: list[dict[str, Any]]) -> bool:
    recent = history[-NONFINITE_PATIENCE:]
    return len(recent) == NONFINITE_PATIENCE and not any(np.isfinite(h["loss"]) for h in recent)


def _optimistix(solver: str, residual_u, u, max_steps, rtol, atol, log_step) -> tuple[bool, str, jax.Array, int]:
    """Step an optimistix solver interactively, so each step is recorded and shown."""
    if solver == "bfgs":
        obj = optx.BFGS(rtol=rtol, atol=atol)
        f_struct = jax.ShapeDtypeStruct((), u.dtype)
        # BFGS's first step is the raw gradient: scale the loss to 1 at the start so that the step
        # is of order one in unconstrained coordinates (the minimiser is unchanged).
        scale = 1.0 / max(float(0.5 * jnp.sum(residual_u(u, None) ** 2)), 1e-30)
    else:
        # Gauss-Newton and dogleg steps by SVD: the default QR returns NaN where the Jacobian is rank
        # deficient (unidentifiable directions, saturated bijections); SVD takes the minimum-norm step.
        kwargs = {} if solver == "lm" else {"linear_solver": lx.AutoLinearSolver(well_posed=False)}
        obj = {"lm": optx.LevenbergMarquardt, "gn": optx.GaussNewton, "dogleg": optx.Dogleg}[solver](
            rtol=rtol, atol=atol, **kwargs)
        f_struct = jax.eval_shape(lambda y: residual_u(y, None), u)
        scale = 1.0

    def fn(y: jax.Array, args: Any) -> tuple[jax.Array, None]:
        # the interactive solver API takes functions with auxiliary output
        r = residual_u(y, args)
        return (scale * 0.5 * jnp.sum(r**2) if solver == "bfgs" else r), None

    tags: frozenset = frozenset()
    state = obj.init(fn, u, None, {}, f_struct, None, tags)
    step = eqx.filter_jit(obj.step)
    terminate = eqx.filter_jit(obj.terminate)
    result = optx.RESULTS.nonlinear_max_steps_reached
    for k in range(1, max_steps + 1):
        u, state, _ = step(fn, u, None, {}, state, tags)
        if not log_step(k) or not np.all(np.isfinite(np.asarray(u))):
            return False, "failed: the loss or a parameter became NaN", u, k
        done, res = terminate(fn, u, None, {}, state, tags)
        if bool(done):
            result = res
            break
    success, status = _status(result)
    return success, status, u, k


def _adam(problem: _Problem, residual_u, u, max_steps, rtol, learning_rate, log_step, last) -> tuple[bool, str, jax.Array, int]:
    """optax Adam with a cosine-decaying step on the unconstrained vector; reverse-mode gradients
    unless a Jacobian column needs finite differences."""
    if problem.loss_u_reverse is not None:

        def loss_u(y: jax.Array) -> jax.Array:
            value = problem.loss_u_reverse(y)
            jax.debug.callback(lambda a, b: last.update(u=np.asarray(a), loss=float(b)), y, value)
            return value
    else:

        def loss_u(y: jax.Array) -> jax.Array:
            return 0.5 * jnp.sum(residual_u(y, None) ** 2)

    value_and_grad = jax.jit(jax.value_and_grad(loss_u))
    opt = optax.adam(optax.cosine_decay_schedule(learning_rate, max_steps))
    opt_state = opt.init(u)
    still = 0
    for k in range(1, max_steps + 1):
        _, grad = value_and_grad(u)
        if not log_step(k):
            return False, "failed: the loss or a parameter became NaN", u, k
        updates, opt_state = opt.update(grad, opt_state)
        u = optax.apply_updates(u, updates)
        still = still + 1 if float(jnp.max(jnp.abs(updates))) < rtol else 0
        if still >= ADAM_PATIENCE:
            return True, f"converged (no parameter moved more than rtol for {ADAM_PATIENCE} steps)", u, k
    return False, "stopped: maximum number of steps reached", u, max_steps
