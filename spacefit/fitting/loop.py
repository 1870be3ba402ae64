"""``fit``: recover parameters from observations (images, tables, light curves) with gradient-based solvers.

One function, one result type. The set-up is :mod:`spacefit.fitting.problem`, the solvers
:mod:`spacefit.fitting.solvers`, the standard errors :mod:`spacefit.fitting.uncertainty`; this module runs
the loop and records each step.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Generator, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from spacefit.display import fit_html
from spacefit.errors import InputError, check_choice, check_count, check_type
from spacefit.executors import Cluster
from spacefit.fitting.frames import frame_executor
from spacefit.fitting.goodness import Goodness, goodness, part_chi2, verdict_factor
from spacefit.fitting.observations.base import ValueObservation
from spacefit.fitting.observations.image import Observation
from spacefit.fitting.problem import FitRender, Problem, Setup, setup
from spacefit.fitting.resume import Resume
from spacefit.fitting.solvers import Outcome, Solver, Status, Step, drive, is_least_squares, make_solver, solver_name
from spacefit.fitting.stopping import NoiseFloor, loss_noise
from spacefit.fitting.uncertainty import estimate, stderr_corr, warnings_for
from spacefit.interrupts import Terminated, deferred_interrupts
from spacefit.precision import float64
from spacefit.progress import ProgressCallback
from spacefit.rendering.renderer import mitsuba_scene_dict
from spacefit.rendering.memory import check_memory
from spacefit.rendering.parts import PartImage
from spacefit.scene.schema import Scene
from spacefit.scene.parameters import is_nuisance, observation_of, parameter, scene_with_values
from spacefit.units import DN_UNIT

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
        success: whether the fit succeeded: the solver converged, at least one step lowered the
            loss, no parameter is at a bound and the residuals are within the noise
            (``status.success``).
        status: how the fit ended, a verdict (``str(status)`` is its words; :class:`Status`).
        warnings: identifiability and convergence warnings, in words.
        history: one entry per step: the point the step evaluated (step 1 evaluates the start;
            the accepted point of the last step is ``values``), its loss, ``accepted`` (the step
            evaluated another point than the best so far and lowered its loss: accepted losses never rise), ``loss_noise`` (the loss's
            Monte Carlo noise at the best point so far, :mod:`~spacefit.fitting.stopping`),
            time_s since the start.
        renders: each observation's final model, the images' first (the render with the image
            nuisances), then the other kinds' (their predicted values), in the unit of its data: ``units``.
        units: per observation, the unit of its data and model: for an image W m^-2 sr^-1 (radiance),
            or DN where it has a sensor (the sensor's expected DN of the render); a value
            observation's own (sr^-1 for a BRDF table, W m^-2 for a light curve's irradiances).
        loss: final loss, 0.5 * sum of squared residuals.
        solver, loss_name, steps, wall_time_s, start: what was run.
        extras: derived quantities, e.g. the rms height (and its standard error) of a (D, G) fit.
        parts: per observation, per part (and the whole ``target``): the fitted pixels (not masked
            out) that see it and the mean of the reference and of the fit's render there, in ``units`` (keys
            ``reference_mean_w_m2_sr`` and ``fit_mean_w_m2_sr``, or ``reference_mean_dn`` and ``fit_mean_dn``).
            With the pixel loss, each row also holds ``chi2_per_value`` (the noise known) or
            ``r2_over_render_noise`` (mean r^2 over the render noise's, :mod:`~spacefit.fitting.goodness`).
        scene: the first observation's scene with the fitted values: ``scene.to_toml()`` is a scene
            file that renders the fit again (the image nuisances are not scene values); None if
            the values are not finite.
        goodness: the goodness of fit at the result (:class:`~spacefit.fitting.goodness.Goodness`);
            None where there is no finite result (interrupted, non-finite).
        residuals: per observation, data - model in ``units`` (for an image NaN where not fitted).
        observation_goodness: per observation, the goodness of fit of its own residuals (the
            pixel loss), counting as free the shared parameters and its own (``name@k``; a value
            observation those it depends on).
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
    goodness: Goodness | None = None
    residuals: list[np.ndarray] = field(default_factory=list)
    observation_goodness: list[Goodness] = field(default_factory=list)

    def _repr_html_(self) -> str:
        return fit_html(self)

    def mitsuba_scene_dict(self) -> dict[str, Any]:
        """The fitted scene as a Mitsuba scene dictionary (``mi.load_dict`` loads it).

        Raises:
            InputError: if the fit has no scene (its values are not finite).
        """
        if self.scene is None:
            raise InputError("this fit has no fitted scene: its values are not finite.")
        return mitsuba_scene_dict(self.scene)

    def uncertainty(self) -> dict[str, Any]:
        """The values, standard errors and correlation matrix (rows and columns in ``names`` order),
        with each parameter's unit: JSON-ready (``uncertainty.json`` of a fit's folder).
        ``stderr_valid`` is False for a misfit (the errors assume a correct model: they are too
        small, not scaled) and where the fit did not succeed; ``stderr_note`` says why."""
        return {"names": list(self.names), "values": self.values, "stderr": self.stderr,
                "units": {n: parameter(n).unit for n in self.names},
                "correlation": np.asarray(self.correlation).tolist(), "nuisances": list(self.nuisances),
                "stderr_valid": self.success, "stderr_note": self.stderr_note}

    @property
    def stderr_note(self) -> str:
        """Whether the standard errors can be taken as such, in words ("" when they can)."""
        if self.status is Status.MISFIT:
            return "misfit: the errors assume a correct model and are too small (not scaled)"
        return "" if self.success else f"not an estimate: {self.status}"

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
        d.pop("residuals")
        d.pop("scene")
        d["goodness"] = None if self.goodness is None else self.goodness.to_dict()
        d["observation_goodness"] = [q.to_dict() for q in self.observation_goodness]
        d["nuisances"] = list(self.nuisances)
        d["correlation"] = np.asarray(self.correlation).tolist()
        d["status"] = self.status.value
        return d


@dataclass(frozen=True)
class FitOptions:
    """The settings of :func:`fit` as one value (:func:`~spacefit.pipeline.fit_to_folder` takes it);
    the home of ``fit``'s defaults. ``solver``, ``max_steps`` and ``stop`` are checked on
    construction, the rest by ``fit``'s set-up against the observations.

    Attributes:
        solver, loss, start, render, max_steps, stop, wrinkle_coordinates: :func:`fit`'s arguments of
            those names; by default ``"lm"``, ``"pixel"``, the first scene's values, the scene's spp
            (``FitRender()``), 50 steps, ``"noise"`` and ``"rms"``.
    """

    solver: str | Solver = "lm"
    loss: str = "pixel"
    start: Mapping[str, float] | None = None
    render: FitRender = FitRender()
    max_steps: int = DEFAULT_MAX_STEPS
    stop: str = "noise"
    wrinkle_coordinates: str = "rms"

    def __post_init__(self) -> None:
        _checked_solver(self.solver, self.max_steps, self.stop)

    def keywords(self) -> dict[str, Any]:
        """The settings as :func:`fit`'s keyword arguments."""
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: the render settings as a table, a solver object by its repr (fit.json's ``inputs.options``)."""
        return {**self.keywords(), "render": dataclasses.asdict(self.render),
                "solver": self.solver if isinstance(self.solver, str) else repr(self.solver)}


def _checked_solver(solver: str | Solver, max_steps: int, stop: str) -> Solver:
    """The solver object of ``solver``, after checking it, ``max_steps`` and ``stop``."""
    engine = make_solver(solver)
    check_count("max_steps", max_steps, optional=False)
    check_choice("stop", stop, STOP_RULES)
    return engine


@float64
def fit(
    observations: Observation | ValueObservation | Sequence[Observation | ValueObservation],
    free: Sequence[str],
    *,
    solver: str | Solver = FitOptions.solver,
    loss: str = FitOptions.loss,
    start: Mapping[str, float] | None = FitOptions.start,
    render: FitRender = FitOptions.render,
    max_steps: int = FitOptions.max_steps,
    stop: str = FitOptions.stop,
    wrinkle_coordinates: str = FitOptions.wrinkle_coordinates,
    progress: ProgressCallback | None = None,
    resume: Resume = Resume(),
    cluster: Cluster | None = None,
) -> FitResult:
    """Fit free parameters so that the models of the observations match them.

    Args:
        observations: one or several observations of the same target, fitted jointly: images
            (:class:`~spacefit.fitting.observations.image.Observation`, (reference, scene) pairs) and
            other kinds (:mod:`spacefit.fitting.observations`: BRDF tables, light curves). Fixed
            parameters come from each image's scene or each observation's own values.
        free: registered parameter names (:mod:`spacefit.scene.parameters`), e.g. ``["parts.panels.alpha_x"]``,
            shared by every observation that depends on them (an image of part ``panels`` and a BRDF
            table or a light curve of it); a per-observation name's ``@k`` counts the images.
        solver: a name in :data:`SOLVERS` (its defaults: rtol 1e-3, atol 1e-6; Adam's learning rate
            0.05), or an optimistix least-squares solver or minimiser, or :class:`Adam`, with its own
            tolerances (e.g. ``optx.LevenbergMarquardt(rtol=1e-4, atol=1e-8)``, ``sf.Adam(0.1)``).
        loss: ``"pixel"``, ``"pyramid"`` or ``"stats"`` (see :mod:`spacefit.fitting.losses`).
        start: start values (physical units); default: the first scene's values.
        render: how the fit renders (:class:`FitRender`: samples per pixel, seeds, integrator,
            the wrinkles' Jacobian method); render references with other seeds.
        max_steps: solver step limit.
        stop: ``"noise"``: least-squares solvers stop as well when the expected decrease of the loss
            is below its Monte Carlo noise (:attr:`Status.NOISE_FLOOR`, :mod:`spacefit.fitting.stopping`;
            one more primal render per accepted step) or when their trial steps keep finding no lower
            loss (:attr:`Status.NO_BETTER_POINT`), BFGS and Adam on their tolerances;
            ``"tolerance"``: every solver only on its tolerances.
        wrinkle_coordinates: with D and G both free, ``"rms"`` solves in (D, rms height), the
            better-determined coordinates, and reports D and G with their covariance mapped by
            the delta method; ``"G"`` solves in (D, G) directly.
        progress: called with (step, max_steps) after each step.
        resume: the checkpoint plumbing (:class:`~spacefit.fitting.resume.Resume`): what each step and
            the end report, and the record of an ended or interrupted solve to end or go on as it would have.
        cluster: where the observations' renders and Jacobian columns run, as one batch per step
            (:mod:`spacefit.fitting.frames`): None, in this process, observation by observation; an
            int N, a new local dask cluster of N worker processes; a scheduler address; a
            ``distributed.Client``. The values are the same bit for bit.

    The result's :attr:`~FitResult.status` is a verdict (:class:`Status`): no step that lowered
    the loss (:attr:`Status.NO_PROGRESS`), a parameter at a bound (:attr:`Status.AT_BOUND`) and
    residuals beyond the noise (:attr:`Status.MISFIT`, :mod:`spacefit.fitting.goodness`) are
    failures, whatever the solver said. An interruption (Ctrl-C or SIGTERM; taken at the end of
    the current step, at once if repeated) stops the solve and returns the best point evaluated so
    far with status :attr:`Status.INTERRUPTED` (:attr:`Status.TERMINATED` for SIGTERM), no
    standard errors and no renders.

    The defaults are :class:`FitOptions`'s, which holds these settings as one value.

    Raises:
        InputError: for any bad input, before rendering.
    """
    engine = _checked_solver(solver, max_steps, stop)
    check_type("resume", resume, Resume, "an sf.Resume(on_step=..., ...)")
    executor = frame_executor(cluster)
    try:
        s = setup(observations, free, start=start, loss=loss, render=render, wrinkle_coordinates=wrinkle_coordinates,
                  executor=executor)
        return _solve(s, engine, max_steps, stop, loss, progress, resume)
    finally:
        executor.close()


def _solve(s: Setup, engine: Solver, max_steps: int, stop: str, loss: str, progress: ProgressCallback | None,
           resume: Resume) -> FitResult:
    """Run the solver on a set-up problem (or report the ended solve ``resume.ended`` again; or go on with
    the interrupted one of ``resume.history``) and make its result."""
    fp, problem = s.solver_params, s.problem

    def residual_u(u: jax.Array) -> jax.Array:
        # renders are float32; the solver works in the dtype of u (float64) throughout
        return problem.residual_x(fp.to_physical(u)).astype(u.dtype)

    # a model without Monte Carlo noise (closed-form value observations only) has no noise floor to stop at
    steps = _Steps(s, stop == "noise" and is_least_squares(engine) and problem.rendered, max_steps, progress, resume.on_step)
    u = jnp.asarray(fp.to_unconstrained(jnp.asarray(s.x0)))
    if resume.ended is not None:
        return _result(s, steps.ended(resume.ended, u), steps, solver_name(engine), loss)
    if resume.history:
        steps.resumed(resume.history, u)
    try:
        with deferred_interrupts() as interrupts:
            outcome = steps.run(drive(engine, residual_u, u, max_steps, problem.loss_u_reverse), interrupts)
    except KeyboardInterrupt as signal:
        best = steps.best_u if steps.best_u is not None else u
        outcome = Outcome(Status.TERMINATED if isinstance(signal, Terminated) else Status.INTERRUPTED, best, len(steps.history))
    if resume.on_end is not None and not outcome.status.interrupted:
        resume.on_end(steps.ending(outcome))
    return _result(s, outcome, steps, solver_name(engine), loss)


class _Steps:
    """The record of a solve: each step the driver yields becomes a history entry; the accepted /
    rejected bookkeeping and the stops that are not the solver's own (non-finite run, noise floor)."""

    def __init__(self, s: Setup, noise_stop: bool, max_steps: int, progress: ProgressCallback | None,
                 on_step: Callable[[dict[str, Any]], None] | None) -> None:
        self.s, self.noise_stop, self.max_steps, self.progress, self.on_step = s, noise_stop, max_steps, progress, on_step
        self.history: list[dict[str, Any]] = []
        self.floor = NoiseFloor()
        self.best_u: np.ndarray | None = None
        self.best_loss = math.nan
        self.reported_again = False  # the record of an ended solve (:meth:`ended`), not a solve
        self.restarted = False  # an interrupted solve goes on (:meth:`resumed`): its first step evaluates its best point again
        self.t0 = time.perf_counter()

    def run(self, driver: Generator[Step, None, Outcome], interrupts: Any) -> Outcome:
        """Record the driver's steps until it ends or a stop of this record's own."""
        k = len(self.history)
        while True:
            try:
                step = next(driver)
            except StopIteration as end:
                return end.value
            k += 1
            status = self.record(k, step)
            interrupts.check()
            if _nonfinite_run(self.history):
                status = Status.NONFINITE
            if status is not None:
                driver.close()
                # the step that reached the noise floor may be a rejected trial: the best point is the result
                stopped_here = status in (Status.NOISE_FLOOR, Status.NO_BETTER_POINT)
                return Outcome(status, jnp.asarray(self.best_u) if stopped_here else step.iterate, k)

    def record(self, k: int, step: Step) -> Status | None:
        """Record one step; :attr:`Status.NOISE_FLOOR` or :attr:`Status.NO_BETTER_POINT` when the solve
        should stop there (:mod:`spacefit.fitting.stopping`)."""
        s, problem = self.s, self.s.problem
        x_solver = s.solver_params.to_physical(jnp.asarray(step.u, dtype=jnp.float64))  # the solve's precision (fit is float64)
        # the same point evaluated again is no step, whatever the rounding of its loss (a solver that
        # cannot move re-evaluates its point, and the sum's rounding differs between compiled steps)
        same = self.best_u is not None and np.array_equal(step.u, self.best_u)
        accepted = not same and self.floor.record(step.loss)
        if accepted:
            self.best_u, self.best_loss = step.u, step.loss
            if self.noise_stop:
                r = step.residuals if step.residuals is not None else np.asarray(problem.residual_x(x_solver))
                self.floor.set_noise(loss_noise(r, np.asarray(problem.residual_x_independent(x_solver))))
        x = np.asarray(s.to_user(x_solver))
        self.history.append({"step": k, "loss": step.loss, "accepted": accepted, "loss_noise": self.floor.noise,
                             "values": dict(zip(s.user.names, x.tolist())), "time_s": time.perf_counter() - self.t0})
        if self.progress is not None:
            self.progress(k, self.max_steps)
        if self.on_step is not None:
            self.on_step(self.history[-1])
        if not self.noise_stop or self.restarted:
            self.restarted = False  # the best point evaluated again is no step of the interrupted solve's
            return None
        if self.floor.reached(step.loss, accepted):
            return Status.NOISE_FLOOR
        return Status.NO_BETTER_POINT if self.floor.no_better_point() else None

    def resumed(self, history: Sequence[Mapping[str, Any]], u: jax.Array) -> None:
        """Go on with the interrupted solve whose steps were ``history`` and whose best point is ``u``:
        its entries begin this history, and the stop rule's record is theirs again (each loss recorded
        as the solve recorded it, the evaluations of the best point again left out)."""
        self.history = [{**entry, "loss": _number(entry["loss"]), "loss_noise": _number(entry["loss_noise"])} for entry in history]
        best = None
        for entry in self.history:
            if best is None or entry["values"] != best:
                self.floor.record(entry["loss"])
            if entry["accepted"] or best is None:
                best = entry["values"]
        self.floor.set_noise(self.history[-1]["loss_noise"])
        self.best_u, self.best_loss, self.restarted = np.asarray(u), self.floor.best, True
        self.max_steps += len(self.history)

    def ending(self, outcome: Outcome) -> dict[str, Any]:
        """The record of an ended solve that :meth:`ended` (``fit(resume=Resume(ended=...))``) takes: status, steps,
        history and the values the result reports (the start where no step lowered the loss)."""
        x = self.s.solver_params.to_physical(jnp.asarray(outcome.u)) if self.moved else jnp.asarray(self.s.x0)
        values = dict(zip(self.s.user.names, np.asarray(self.s.to_user(x)).tolist()))
        return {"status": outcome.status.value, "steps": outcome.steps, "values": values, "history": self.history}

    def ended(self, record: Mapping[str, Any], u: jax.Array) -> Outcome:
        """The outcome of the ended solve ``record`` (:meth:`ending`), whose end point is ``u``; its history becomes this one."""
        self.history = [dict(entry) for entry in record["history"]]
        self.best_u, self.reported_again = u, True
        return Outcome(Status(record["status"]), u, int(record["steps"]))

    @property
    def moved(self) -> bool:
        """Whether a step after the first (which evaluates the start) lowered the loss."""
        return any(h["accepted"] for h in self.history[1:])


def _number(value: float | None) -> float:
    """A number of a history read back from JSON, where NaN is null."""
    return math.nan if value is None else float(value)


def verdict(status: Status, moved: bool, at_bound: bool, misfit: bool) -> Status:
    """The fit's status from the solver's: a solve that ended without failing is
    :attr:`Status.NO_PROGRESS` if no step lowered the loss, else :attr:`Status.AT_BOUND` if a
    parameter ended at a bound, else :attr:`Status.MISFIT` if the residuals exceed the noise."""
    if status not in (Status.CONVERGED, Status.NOISE_FLOOR, Status.NO_BETTER_POINT, Status.MAX_STEPS):
        return status
    if not moved:
        return Status.NO_PROGRESS
    if at_bound:
        return Status.AT_BOUND
    if misfit:
        return Status.MISFIT
    return status


def _result(s: Setup, outcome: Outcome, steps: _Steps, solver: str, loss: str) -> FitResult:
    """The :class:`FitResult` of a solve's outcome: values, errors, goodness of fit, verdict, images."""
    problem, status = s.problem, outcome.status
    # a solve that never lowered the loss returns its start, not a point its solver drifted to; an ended
    # solve reported again (``fit(resume=Resume(ended=...))``) its start, which is its end (not rounded through ``u``)
    x = np.asarray(s.solver_params.to_physical(outcome.u) if steps.moved and not steps.reported_again else s.x0, dtype=float)
    n = len(x)
    x_user = np.asarray(s.to_user(jnp.asarray(x)), dtype=float)
    stderr, corr, loss_value, extras, residuals, quality = np.full(n, np.nan), np.eye(n), math.nan, {}, [], None
    renders: list[np.ndarray] = []
    own_quality: list[Goodness] = []
    per_part: list[dict[str, dict[str, float]]] = [{} for _ in problem.references]
    if status.interrupted:
        loss_value = steps.best_loss
        warnings = ["the fit was interrupted: the values are the best point evaluated so far, with no standard errors."]
    elif np.all(np.isfinite(x_user)):
        x_user, cov, loss_value, extras = estimate(s, x, correct=steps.moved)
        stderr, corr = stderr_corr(cov)
        warnings = warnings_for(s.user, x_user, stderr, corr)
        quality, r, noise, renders = judged_goodness(s, jnp.asarray(x), loss)
        residuals = [*(np.where(used[..., None], ref - render, np.nan) for ref, render, used in zip(problem.references, renders, problem.used)),
                     *(b.data.value - render for b, render in zip(problem.blocks, renders[len(problem.references):]))]
        if loss == "pixel":
            per_part = _per_part(r, noise, problem, quality)
            own_quality = per_observation(r, noise, s, quality.samples_factor)
        at_bound = any(b.at_bound(float(v)) for b, v in zip(s.user.bijections, x_user))
        status = verdict(status, steps.moved, at_bound, quality.misfit and loss == "pixel")
        if not math.isfinite(loss_value):
            status = Status.NONFINITE
            warnings.insert(0, "the render or its Jacobian at the result is not finite (NaN); no errors are reported.")
        if status is Status.MISFIT:
            warnings.insert(0, f"a misfit: {quality.line()}; the standard errors assume a correct model and are too small.")
        elif not status.success:
            warnings.insert(0, f"the fit did not succeed ({status}).")
    else:
        warnings = ["the solve produced non-finite parameters; no estimate is reported."]
        status = Status.NONFINITE
    values = dict(zip(s.user.names, x_user.tolist()))
    return FitResult(
        names=s.user.names, values=values, stderr=dict(zip(s.user.names, stderr.tolist())), correlation=corr,
        success=status.success, status=status, warnings=warnings, history=steps.history, renders=renders, loss=loss_value,
        solver=solver, loss_name=loss, steps=outcome.steps, wall_time_s=time.perf_counter() - steps.t0,
        start=dict(zip(s.user.names, s.x0_user.tolist())), extras=extras,
        parts=[_part_rows(*row) for row in zip(problem.part_images, problem.references, renders, problem.units, problem.used, per_part)],
        scene=_fitted_scene(s, values) if np.all(np.isfinite(x_user)) else None,
        units=[*problem.units, *(b.data.unit for b in problem.blocks)], goodness=quality, residuals=residuals,
        observation_goodness=own_quality,
    )


def _fitted_scene(s: Setup, values: Mapping[str, float]) -> Scene | None:
    """The first image's scene with the fitted values it knows (None without an image)."""
    if s.scene is None:
        return None
    return scene_with_values(s.scene, {n: v for n, v in values.items() if observation_of(n)[0] in s.image_names}, observation=0)


def judged_goodness(s: Setup, x: jax.Array, loss: str) -> tuple[Goodness, np.ndarray, np.ndarray, list[np.ndarray]]:
    """The goodness of fit at ``x`` (:mod:`~spacefit.fitting.goodness`), the residuals it judged and a
    draw of their render noise, and each observation's model (images, then value observations) at the
    fit's seeds. With the noise known the judged model is the mean of two renders with independent
    seeds at :func:`verdict_factor` times the fit's samples per pixel (the fit's own two where that is
    1; primal renders only), the noise sigma taken at it; else the fit's own render. A model that is
    not rendered is the same at every seed: its render noise is 0."""
    problem = s.problem
    renders = [problem.models_seeded(x, 0), problem.models_seeded(x, 1)]
    if s.noise_given:
        r, noise = _mean_and_noise(problem, renders)
        k = verdict_factor(2.0 * goodness(r, noise, 0, True).render_noise, max(problem.spp)) if problem.spp else 1
        while k > 1 and not _affordable(problem, k):
            k //= 2
        if k > 1:
            finer = problem.resampled(k)
            r, noise = _mean_and_noise(finer, [finer.models_seeded(x, 0), finer.models_seeded(x, 1)])
        judged = 2 * k
    else:
        judged = 1
        r, r_alt = (np.asarray(problem.residual_of(m), dtype=np.float64) for m in renders)
        noise = (r - r_alt) / math.sqrt(2.0)
    verdict_spp = [judged * spp for spp in problem.spp]
    ratios = [_reference_ratio(spp, ref) for spp, ref in zip(verdict_spp, problem.reference_spp)]
    pixels = loss == "pixel"
    if pixels:
        values = r.size - problem.pixels  # the value observations' residuals, after the pixels: no reference render noise
        ratio = np.concatenate([np.repeat(ratios, [ref.size for ref in problem.references]), np.zeros(values)])
        fitted = np.concatenate([*(np.broadcast_to(used[..., None], ref.shape).ravel() for ref, used in zip(problem.references, problem.used)),
                                 np.ones(values, dtype=bool)])
    else:
        ratio, fitted = float(np.mean(ratios or [0.0])), None
    quality = goodness(r, noise, len(s.x0), s.noise_given, [ref.shape for ref in problem.references] if pixels else [],
                       fitted=fitted, reference_ratio=ratio, samples_factor=judged, verdict_spp=verdict_spp,
                       reference_spp=problem.reference_spp)
    return quality, r, noise, [np.asarray(m) for m in renders[0]]


def _reference_ratio(spp: int, reference_spp: int | None) -> float:
    """A reference's render noise over the judged model's, per value: the model's samples per pixel
    ``spp`` over the reference's (0 for a real observation, ``reference_spp`` None)."""
    return spp / reference_spp if reference_spp else 0.0


def _affordable(problem: Problem, factor: int) -> bool:
    """Whether every observation's whole film rendered at ``factor`` times its samples per pixel in one
    wavefront (a fit's render) fits this machine (:func:`~spacefit.rendering.renderer.check_memory`):
    a verdict render takes fewer samples rather than lose the fit's result."""
    try:
        for ref, spp in zip(problem.references, problem.spp):
            check_memory(ref.shape[1], ref.shape[0], ref.shape[0] * ref.shape[1], factor * spp, split=False)
    except InputError:
        return False
    return True


def _mean_and_noise(problem: Problem, renders: list[list[jax.Array]]) -> tuple[np.ndarray, np.ndarray]:
    """The residuals of the mean of two renders (each a list of model images), the noise sigma taken
    at that mean, and a draw of their render noise: half the two renders' difference, weighted as the
    residuals are (their derivative along it)."""
    mean = [(a + b) / 2 for a, b in zip(*renders)]
    half = [(a - b) / 2 for a, b in zip(*renders)]
    r, noise = jax.jvp(problem.residual_of, (mean,), (half,))
    return np.asarray(r, dtype=float), np.asarray(noise, dtype=float)


def per_observation(r: np.ndarray, noise: np.ndarray, s: Setup, factor: int) -> list[Goodness]:
    """Per observation (images, then value observations), the goodness of fit of its own residuals
    (pixel loss), with the shared free parameters and its own (``name@k``) counted as free (a value
    observation: those it depends on); ``factor``: the judged model's samples over the fit's."""
    out, offset, problem = [], 0, s.problem
    for k, ref in enumerate(problem.references):
        rows = slice(offset, offset + ref.size)
        offset = rows.stop
        n_k = sum(1 for name in s.user.names if observation_of(name)[1] in (None, k))
        spp, reference = factor * problem.spp[k], problem.reference_spp[k]
        out.append(goodness(r[rows], noise[rows], n_k, s.noise_given, [ref.shape], fitted=np.broadcast_to(problem.used[k][..., None], ref.shape),
                            reference_ratio=_reference_ratio(spp, reference), samples_factor=factor, verdict_spp=[spp],
                            reference_spp=[reference]))
    for block in problem.blocks:
        rows = slice(offset, offset + block.data.value.size)
        offset = rows.stop
        out.append(goodness(r[rows], noise[rows], len(block.known), block.noise_known, fitted=np.ones(rows.stop - rows.start, bool),
                            samples_factor=factor))
    return out


def _per_part(r: np.ndarray, noise: np.ndarray, problem: Problem, quality: Goodness) -> list[dict[str, dict[str, float]]]:
    """Per observation, per part: ``chi2_per_value`` (noise known) or ``r2_over_render_noise``."""
    key = "chi2_per_value" if quality.noise_known else "r2_over_render_noise"
    out, offset = [], 0
    for parts, ref, used in zip(problem.part_images, problem.references, problem.used):
        rows = slice(offset, offset + ref.size)
        offset = rows.stop
        values = part_chi2(r[rows].reshape(ref.shape), noise[rows].reshape(ref.shape), parts, used,
                           1.0 if quality.noise_known else quality.render_noise, quality.noise_known)
        out.append({name: {key: value} for name, value in values.items()})
    return out


def _nonfinite_run(history: list[dict[str, Any]]) -> bool:
    recent = history[-NONFINITE_PATIENCE:]
    return len(recent) == NONFINITE_PATIENCE and not any(np.isfinite(h["loss"]) for h in recent)


def _part_rows(parts: PartImage, reference: np.ndarray, render: np.ndarray, unit: str, used: np.ndarray,
               spread: Mapping[str, float]) -> dict[str, dict[str, float]]:
    """Per part: its fitted pixels (``used``), the mean of the reference and of the fit's render there, in ``unit``,
    and ``spread``'s value (chi^2 per value, or mean r^2 over the render noise's; absent for the losses that
    are not per pixel)."""
    (pixels, ref), (_, fitted) = parts.means(reference, used), parts.means(render, used)
    suffix = "dn" if unit == DN_UNIT else "w_m2_sr"
    return {name: {"pixels": int(n), f"reference_mean_{suffix}": float(r), f"fit_mean_{suffix}": float(f), **spread.get(name, {})}
            for name, n, r, f in zip(parts.regions, pixels, ref, fitted)}
