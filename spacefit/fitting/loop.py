"""``fit``: recover scene parameters from reference images with gradient-based solvers.

One function, one result type. The set-up is :mod:`spacefit.fitting.problem`, the solvers
:mod:`spacefit.fitting.solvers`, the standard errors :mod:`spacefit.fitting.uncertainty`; this module runs
the loop and records each step.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from spacefit.errors import InputError, check_choice, check_count, check_range
from spacefit.fitting.problem import Observation, setup
from spacefit.fitting.solvers import LEAST_SQUARES, SOLVERS, Options, Status
from spacefit.fitting.stopping import NoiseFloor, loss_noise
from spacefit.fitting.uncertainty import estimate, stderr_corr, warnings_for
from spacefit.interrupts import Terminated, deferred_interrupts
from spacefit.precision import float64
from spacefit.progress import ProgressCallback
from spacefit.rendering.renderer import PartImage
from spacefit.scene.schema import Scene
from spacefit.scene.parameters import is_nuisance, parameter, scene_with_values
from spacefit.sensor import DN_UNIT

# A solve fails when this many consecutive evaluations are not finite; a line search or trust
# region may try (and reject) a single non-finite point.
NONFINITE_PATIENCE = 3
DEFAULT_MAX_STEPS = 50
STOP_RULES = ("noise", "tolerance")


@dataclass
class FitResult:
    """Outcome of :func:`fit`: values in physical units and how far to trust them.

    Attributes:
        names: free parameter names, in order.
        values: fitted value of each, physical units; :attr:`estimates` and :attr:`nuisances` split them.
        stderr: standard error of each (from J^T J and the residual); inf if not determined.
        correlation: (n, n) correlation matrix of the estimates.
        success: whether the solver reports convergence (and the result is finite).
        status: how the solve ended (``str(status)`` is its words).
        warnings: identifiability and convergence warnings, in words.
        history: one entry per step: the point the step evaluated (step 1 evaluates the start;
            the accepted point of the last step is ``values``), its loss, ``accepted`` (the step
            lowered the best loss so far: accepted losses never rise), ``loss_noise`` (the loss's
            Monte Carlo noise at the best point so far, :mod:`~spacefit.fitting.stopping`),
            time_s since the start.
        renders: each observation's final model image (the render with the image nuisances), in the
            unit of its reference: ``units``.
        units: per observation, the unit of its reference and render: W m^-2 sr^-1 (radiance), or
            DN where the observation has a sensor (the sensor's expected DN of the render).
        loss: final loss, 0.5 * sum of squared residuals.
        solver, loss_name, steps, wall_time_s, start: what was run.
        extras: derived quantities, e.g. the rms height (and its standard error) of a (D, G) fit.
        parts: per observation, per part (and the whole ``target``): the fitted pixels (not masked
            out) that see it and the mean of the reference and of the fit's render there, in ``units`` (keys
            ``reference_mean_w_m2_sr`` and ``fit_mean_w_m2_sr``, or ``reference_mean_dn`` and ``fit_mean_dn``).
        scene: the first observation's scene with the fitted values: ``scene.to_toml()`` is a scene
            file that renders the fit again (the image nuisances are not scene values); None if
            the values are not finite.
    """

    names: tuple[str, ...]
    values: dict[str, float]
    stderr: dict[str, float]
    correlation: np.ndarray
    success: bool
    status: Status
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
    parts: list[dict[str, dict[str, float]]] = field(default_factory=list)
    scene: Scene | None = None
    units: list[str] = field(default_factory=list)

    def mitsuba_scene_dict(self) -> dict[str, Any]:
        """The fitted scene as a Mitsuba scene dictionary (``mi.load_dict`` loads it).

        Raises:
            InputError: if the fit has no scene (its values are not finite).
        """
        if self.scene is None:
            raise InputError("this fit has no fitted scene: its values are not finite.")
        from spacefit.rendering.renderer import mitsuba_scene_dict

        return mitsuba_scene_dict(self.scene)

    def uncertainty(self) -> dict[str, Any]:
        """The values, standard errors and correlation matrix (rows and columns in ``names`` order),
        with each parameter's unit: JSON-ready (``uncertainty.json`` of a fit's folder)."""
        return {"names": list(self.names), "values": self.values, "stderr": self.stderr,
                "units": {n: parameter(n).unit for n in self.names},
                "correlation": np.asarray(self.correlation).tolist(), "nuisances": list(self.nuisances)}

    @property
    def nuisances(self) -> dict[str, float]:
        """The fitted nuisance parameters (image gain, offset, PSF, shift; the target's pose, the camera's
        roll), physical units."""
        return {n: v for n, v in self.values.items() if is_nuisance(n)}

    @property
    def estimates(self) -> dict[str, float]:
        """The fitted values of the parameters that are not nuisances (materials, wrinkles, sun)."""
        return {n: v for n, v in self.values.items() if not is_nuisance(n)}

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary (no images); ``nuisances`` names the nuisance parameters among ``names``."""
        d = dataclasses.asdict(self)
        d.pop("renders")
        d.pop("scene")
        d["nuisances"] = list(self.nuisances)
        d["correlation"] = np.asarray(self.correlation).tolist()
        d["status"] = self.status.value
        return d


@float64
def fit(
    observations: Observation | Sequence[Observation],
    free: Sequence[str],
    *,
    solver: str = "lm",
    loss: str = "pixel",
    start: Mapping[str, float] | None = None,
    spp: int | None = None,
    spp_grad: int | None = None,
    max_steps: int = DEFAULT_MAX_STEPS,
    rtol: float = 1e-3,
    atol: float = 1e-6,
    learning_rate: float = 0.05,
    seed: int = 1,
    seed_grad: int = 2,
    stop: str = "noise",
    integrator: str = "prb",
    geometry_jacobian: str = "fd",
    wrinkle_coordinates: str = "rms",
    progress: ProgressCallback | None = None,
    on_step: Callable[[dict[str, Any]], None] | None = None,
) -> FitResult:
    """Fit free scene parameters so that renders match reference images.

    Args:
        observations: one or several (reference, scene) pairs of the same target; fitted jointly.
            Fixed parameters come from each scene.
        free: parameter names (see :mod:`spacefit.fitting.params`), e.g. ``["parts.panels.alpha_x"]``.
        solver: one of :data:`SOLVERS`.
        loss: ``"pixel"``, ``"pyramid"`` or ``"stats"`` (see :mod:`spacefit.fitting.losses`).
        start: start values (physical units); default: the first scene's values.
        spp, spp_grad: samples per pixel of primal and derivative renders (default: the scene's).
        max_steps: solver step limit.
        rtol, atol: optimistix tolerances (Adam: stop when the relative loss change < rtol).
        learning_rate: Adam's step size in unconstrained coordinates.
        seed, seed_grad: seeds of primal and derivative renders; render references with another.
        stop: ``"noise"``: the least-squares solvers (:data:`LEAST_SQUARES`) stop as well when the
            expected decrease of the loss is below its Monte Carlo noise (:attr:`Status.NOISE_FLOOR`,
            :mod:`spacefit.fitting.stopping`; one more primal render per accepted step), BFGS and
            Adam on their tolerances; ``"tolerance"``: every solver only on its tolerances.
        integrator: AD integrator for derivative renders, one of :data:`INTEGRATORS`.
        geometry_jacobian: ``"fd"`` (central differences with common random numbers) or ``"ad"``
            (the integrator's derivative) for D and G.
        wrinkle_coordinates: with D and G both free, ``"rms"`` solves in (D, rms height), the
            better-determined coordinates, and reports D and G with their covariance mapped by
            the delta method; ``"G"`` solves in (D, G) directly.
        progress: called with (step, max_steps) after each step.
        on_step: called with each step's history entry (step, loss, values, time_s), e.g. to
            checkpoint the best point so far.

    An interruption (Ctrl-C or SIGTERM; taken at the end of the current step, at once if repeated)
    stops the solve and returns the best point evaluated so far with status
    :attr:`Status.INTERRUPTED` (:attr:`Status.TERMINATED` for SIGTERM), no standard errors and no renders.

    Raises:
        InputError: for any bad input, before rendering.
    """
    check_choice("solver", solver, SOLVERS)
    check_count("max_steps", max_steps)
    check_range("rtol", rtol, 0.0, lo_open=True)
    check_range("atol", atol, 0.0)
    check_range("learning_rate", learning_rate, 0.0, lo_open=True)
    check_choice("stop", stop, STOP_RULES)
    noise_stop = stop == "noise" and solver in LEAST_SQUARES
    s = setup(observations, free, start, loss, spp, spp_grad, seed, seed_grad, integrator, geometry_jacobian,
              wrinkle_coordinates)
    fp, problem = s.solver_params, s.problem

    t0 = time.perf_counter()
    history: list[dict[str, Any]] = []
    last: dict[str, Any] = {}

    def record(u: np.ndarray, value: np.ndarray, r: np.ndarray | None = None) -> None:
        last.update(u=np.asarray(u), loss=float(value), r=None if r is None else np.asarray(r))

    def residual_u(u: jax.Array, args: Any) -> jax.Array:
        # renders are float32; the solver works in the dtype of u (float64) throughout
        r = problem.residual_x(fp.to_physical(u)).astype(u.dtype)
        jax.debug.callback(record, u, 0.5 * jnp.sum(r**2), r)
        return r

    loss_u_reverse = None
    if problem.loss_u_reverse is not None:

        def loss_u_reverse(u: jax.Array) -> jax.Array:
            value = problem.loss_u_reverse(u)
            jax.debug.callback(record, u, value)
            return value

    def log_step(step: int) -> Status | None:
        """Record the step's evaluation; a status after a run of non-finite evaluations or at the noise floor."""
        x_solver = fp.to_physical(jnp.asarray(last["u"]))
        accepted = floor.record(last["loss"])
        if accepted:
            best.update(u=last["u"], loss=last["loss"])
            if noise_stop:
                r = last["r"] if last["r"] is not None else np.asarray(problem.residual_x(x_solver))
                floor.set_noise(loss_noise(r, np.asarray(problem.residual_x_independent(x_solver))))
        x = np.asarray(s.to_user(x_solver))
        history.append({"step": step, "loss": last["loss"], "accepted": accepted, "loss_noise": floor.noise,
                        "values": dict(zip(s.user.names, x.tolist())), "time_s": time.perf_counter() - t0})
        if progress is not None:
            progress(step, max_steps)
        if on_step is not None:
            on_step(history[-1])
        interrupts.check()
        if _nonfinite_run(history):
            return Status.NONFINITE
        return Status.NOISE_FLOOR if noise_stop and floor.reached(last["loss"], accepted) else None

    best: dict[str, Any] = {}
    floor = NoiseFloor()
    u = jnp.asarray(fp.to_unconstrained(jnp.asarray(s.x0)))
    try:
        with deferred_interrupts() as interrupts:
            outcome = SOLVERS[solver](solver, residual_u, u, Options(max_steps, rtol, atol, learning_rate), log_step,
                                      loss_u_reverse)
        status, u, steps = outcome.status, outcome.u, outcome.steps
        if status is Status.NOISE_FLOOR:
            u = jnp.asarray(best["u"])  # the step that stopped the solve may be a rejected trial
    except KeyboardInterrupt as stop:
        status, steps = Status.TERMINATED if isinstance(stop, Terminated) else Status.INTERRUPTED, len(history)
        u = jnp.asarray(best["u"]) if best else u
    success = status.success

    x = np.asarray(fp.to_physical(u), dtype=float)
    n = len(x)
    if status.interrupted:
        x_user, stderr, corr = np.asarray(s.to_user(jnp.asarray(x)), dtype=float), np.full(n, np.nan), np.eye(n)
        loss_value, extras, renders = best.get("loss", math.nan), {}, []
        warnings = ["the fit was interrupted: the values are the best point evaluated so far, with no standard errors."]
    elif np.all(np.isfinite(np.asarray(s.to_user(jnp.asarray(x))))):
        x_user, cov, loss_value, extras = estimate(s, x)
        stderr, corr = stderr_corr(cov)
        warnings = warnings_for(s.user, x_user, stderr, corr)
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
        names=s.user.names,
        values=dict(zip(s.user.names, x_user.tolist())),
        stderr=dict(zip(s.user.names, stderr.tolist())),
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
        start=dict(zip(s.user.names, s.x0_user.tolist())),
        extras=extras,
        parts=[_part_rows(*row) for row in zip(problem.part_images, problem.references, renders, problem.units, problem.used)],
        scene=scene_with_values(s.scene, dict(zip(s.user.names, x_user.tolist())), observation=0) if np.all(np.isfinite(x_user)) else None,
        units=list(problem.units),
    )


def _nonfinite_run(history: list[dict[str, Any]]) -> bool:
    recent = history[-NONFINITE_PATIENCE:]
    return len(recent) == NONFINITE_PATIENCE and not any(np.isfinite(h["loss"]) for h in recent)


def _part_rows(parts: PartImage, reference: np.ndarray, render: np.ndarray, unit: str,
               used: np.ndarray) -> dict[str, dict[str, float]]:
    """Per part: its fitted pixels (``used``), and the mean of the reference and of the fit's render there, in ``unit``."""
    ref, fitted = parts.table(reference, used), parts.table(render, used)
    suffix = "dn" if unit == DN_UNIT else "w_m2_sr"
    return {name: {"pixels": row["pixels"], f"reference_mean_{suffix}": row["mean_radiance_w_m2_sr"],
                   f"fit_mean_{suffix}": fitted[name]["mean_radiance_w_m2_sr"]} for name, row in ref.items()}
