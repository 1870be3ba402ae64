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
from dataclasses import dataclass
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from spacefit.errors import check_choice, check_count, check_type
from spacefit.executors import Cluster
from spacefit.fitting.compile_cache import use_compile_cache
from spacefit.fitting.frames import frame_executor
from spacefit.fitting.goodness import STANDS_OUT, TRIM, Goodness, standing_out
from spacefit.fitting.judging import judged_goodness, part_goodness, part_rows, per_observation
from spacefit.fitting.observations.base import Sequenced, ValueObservation
from spacefit.fitting.observations.image import Observation
from spacefit.fitting.pixel_grid import grid_notes
from spacefit.fitting.problem import FitRender, Setup, setup
from spacefit.fitting.render_seeds import seed_notes
from spacefit.fitting.residuals import column_owners
from spacefit.fitting.result import FitResult
from spacefit.fitting.resume import Resume
from spacefit.fitting.outside import DESCENT
from spacefit.fitting.solvers import (Outcome, RenderedFirst, Solver, Status, Step, drive, is_least_squares, make_solver, solver_name,
                                      with_owners)
from spacefit.fitting.stopping import REJECTED_PATIENCE, REJECTED_RTOL, NoiseFloor, loss_noise
from spacefit.fitting.noise_weight import weight_bias_notes
from spacefit.fitting.uncertainty import estimate, stderr_corr, warnings_for
from spacefit.interrupts import Terminated, deferred_interrupts
from spacefit.precision import float64
from spacefit.progress import ProgressCallback
from spacefit.scene.schema import Scene
from spacefit.scene.names import Name
from spacefit.scene.parameters import scene_with_values

# A solve fails when this many consecutive evaluations are not finite; a line search or trust
# region may try (and reject) a single non-finite point.
NONFINITE_PATIENCE = 3
DEFAULT_MAX_STEPS = 50
STOP_RULES = ("noise", "tolerance")


@dataclass(frozen=True)
class FitOptions:
    """The settings of :func:`fit` as one value (:func:`fit_to_folder` takes it);
    the home of ``fit``'s defaults. ``solver``, ``max_steps`` and ``stop`` are checked on
    construction, the rest by ``fit``'s set-up against the observations.

    Attributes:
        solver, loss, start, render, max_steps, stop, wrinkle_coordinates, allow_large: :func:`fit`'s arguments of
            those names; by default ``"lm"``, ``"pixel"``, the first scene's values, the scene's spp
            (``FitRender()``), 50 steps, ``"noise"``, ``"rms"`` and False.

    Raises:
        InputError: an unknown solver or stop rule, or ``max_steps`` < 1.

    Example:
        >>> import spacefit as sf
        >>> options = sf.FitOptions(solver="gn", max_steps=20)
        >>> options.keywords()["max_steps"]  # sf.fit(observations, free, **options.keywords())
        20
        >>> try:
        ...     sf.FitOptions(solver="newton")
        ... except sf.InputError as err:
        ...     print(err)
        `solver` must be one of 'adam', 'bfgs', 'dogleg', 'gn', 'lm'; got 'newton'.
    """

    solver: str | Solver = "lm"
    loss: str = "pixel"
    start: Mapping[str, float] | None = None
    render: FitRender = FitRender()
    max_steps: int = DEFAULT_MAX_STEPS
    stop: str = "noise"
    wrinkle_coordinates: str = "rms"
    allow_large: bool = False

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
    observations: Observation | ValueObservation | Sequenced | Sequence[Observation | ValueObservation | Sequenced],
    free: Sequence[str],
    *,
    solver: str | Solver = FitOptions.solver,
    loss: str = FitOptions.loss,
    start: Mapping[str, float] | None = FitOptions.start,
    render: FitRender = FitOptions.render,
    max_steps: int = FitOptions.max_steps,
    stop: str = FitOptions.stop,
    wrinkle_coordinates: str = FitOptions.wrinkle_coordinates,
    allow_large: bool = FitOptions.allow_large,
    progress: ProgressCallback | None = None,
    resume: Resume = Resume(),
    cluster: Cluster | None = None,
) -> FitResult:
    """Fit free parameters so that the models of the observations match them.

    Args:
        observations: one or several observations of the same target, fitted jointly: images
            (:class:`Observation`, (reference, scene) pairs), passes
            (:class:`PassObservation`: its frames' images, each frame's
            ``per_frame`` values freed) and other kinds (:class:`BRDFTableObservation`,
            light curves). Fixed
            parameters come from each image's scene or each observation's own values.
        free: registered parameter names (:func:`available_parameters`, :data:`PARAMETERS`), e.g. ``["parts.panels.alpha_x"]``,
            shared by every observation that depends on them (an image of part ``panels`` and a BRDF
            table or a light curve of it); a per-observation name's ``@k`` counts the images.
        solver: a name in :data:`SOLVERS` (its defaults: rtol 1e-3, atol 1e-6; Adam's learning rate
            0.05), or an optimistix least-squares solver or minimiser, or :class:`Adam`, with its own
            tolerances (e.g. ``optx.LevenbergMarquardt(rtol=1e-4, atol=1e-8)``, ``sf.Adam(0.1)``).
        loss: ``"pixel"``, ``"pyramid"`` or ``"stats"`` (see :data:`LOSSES`).
        start: start values (physical units); default: the first scene's values.
        render: how the fit renders (:class:`FitRender`: samples per pixel, seeds, integrator,
            the wrinkles' Jacobian method); render references with other seeds.
        max_steps: solver step limit.
        stop: ``"noise"``: least-squares solvers stop as well when the expected decrease of the loss
            is below its Monte Carlo noise (:attr:`Status.NOISE_FLOOR`;
            one more primal render per accepted step) or when their trial steps keep finding no lower
            loss (:attr:`Status.NO_BETTER_POINT`), BFGS and Adam on their tolerances;
            ``"tolerance"``: every solver only on its tolerances.
        wrinkle_coordinates: with D and G both free, ``"rms"`` solves in (D, rms height), the
            better-determined coordinates, and reports D and G with their covariance mapped by
            the delta method; ``"G"`` solves in (D, G) directly.
        progress: called with (step, max_steps) after each step.
        resume: the checkpoint plumbing (:class:`Resume`): what each step and
            the end report, and the record of an ended or interrupted solve to end or go on as it would have.
        cluster: where the observations' renders and Jacobian columns run, as one batch per step: None, in this process, observation by observation; an
            int N, a new local dask cluster of N worker processes; a scheduler address; a
            ``distributed.Client``. The status is the same and the values within 1e-3 of their
            standard errors (measured the same bit for bit in every case but one: docs/measurements/performance.md).

    The result's :attr:`~FitResult.status` is a verdict (:class:`Status`): no step that lowered
    the loss (:attr:`Status.NO_PROGRESS`), a parameter at a bound (:attr:`Status.AT_BOUND`) and
    residuals beyond the noise (:attr:`Status.MISFIT`) are
    failures, whatever the solver said. An interruption (Ctrl-C or SIGTERM; taken at the end of
    the current step, at once if repeated) stops the solve and returns the best point evaluated so
    far with status :attr:`Status.INTERRUPTED` (:attr:`Status.TERMINATED` for SIGTERM), no
    standard errors and no renders.

    The defaults are :class:`FitOptions`'s, which holds these settings as one value.

    Raises:
        InputError: for any bad input, before rendering; a fit too large for this machine's memory (its estimate and
            the memory available in the message), unless ``allow_large``.

    Returns:
        A :class:`FitResult`: the values with standard errors, the status (the verdict), the goodness
        of fit, the history of steps, and for images the renders and residuals.

    Example:
        A BRDF table's Lambert albedo, the cheapest fit (an image fit takes
        ``sf.Observation(scene, reference, sigma=...)`` the same way):

        >>> import numpy as np, spacefit as sf
        >>> zenith = np.radians([10.0, 30.0, 50.0, 70.0])  # the light's; the detector looks down the normal
        >>> wi = np.stack([np.sin(zenith), 0 * zenith, np.cos(zenith)], axis=1)
        >>> wo = np.tile([0.0, 0.0, 1.0], (4, 1))
        >>> table = sf.BRDFTable(wi=wi, wo=wo, value=np.full(4, 0.3 / np.pi), sigma=np.full(4, 0.002), source="white paint")
        >>> result = sf.fit([sf.BRDFTableObservation(table, "lambert", part="paint")], ["parts.paint.kd"])
        >>> result.status.success, round(result.values["parts.paint.kd"], 3), round(result.stderr["parts.paint.kd"], 4)
        (True, 0.3, 0.0031)
    """
    engine = _checked_solver(solver, max_steps, stop)
    check_type("resume", resume, Resume, "an sf.Resume(on_step=..., ...)")
    use_compile_cache()  # the solver's programs from disk when a process before compiled them
    executor = frame_executor(cluster)
    try:
        s = setup(observations, free, start=start, loss=loss, render=render, wrinkle_coordinates=wrinkle_coordinates,
                  executor=executor, allow_large=allow_large)
        return _solve(s, engine, max_steps, stop, loss, progress, resume)
    finally:
        executor.close()
        # JAX's caches keep every fit's traced programs, and what their callbacks reach (loaded scenes,
        # compiled renders), keyed by its solver's functions for the life of the process: 13.6 MiB per
        # fit, freed neither by the fit's end nor by gc (docs/measurements/reliability.md, "Memory per fit").
        jax.clear_caches()


def _solve(s: Setup, engine: Solver, max_steps: int, stop: str, loss: str, progress: ProgressCallback | None,
           resume: Resume) -> FitResult:
    """Run the solver on a set-up problem (or report the ended solve ``resume.ended`` again; or go on with
    the interrupted one of ``resume.history``) and make its result."""
    fp, problem = s.solver_params, s.problem

    def residual_u(u: jax.Array) -> jax.Array:
        # renders are float32; the solver works in the dtype of u (float64) throughout. The residuals it
        # descends: its direction descends the loss its steps are judged by (spacefit.fitting.losses)
        return problem.descent_x(fp.to_physical(u)).astype(u.dtype)

    # a model without Monte Carlo noise (closed-form value observations only) has no noise floor to stop at
    steps = _Steps(s, stop == "noise" and is_least_squares(engine) and problem.rendered, max_steps, progress, resume.on_step)
    u = jnp.asarray(fp.to_unconstrained(jnp.asarray(s.x0)))
    if resume.ended is not None:
        return _result(s, steps.ended(resume.ended, u), steps, solver_name(engine), loss)
    if resume.history:
        steps.resumed(resume.history, u)
    told = with_owners(engine, column_owners(fp, problem.blocks))  # a pass's frames' own columns grouped
    try:
        with deferred_interrupts() as interrupts:
            outcome = steps.run(drive(told, residual_u, u, max_steps, problem.loss_u_reverse, _rendered_first(s, steps)), interrupts)
    except KeyboardInterrupt as signal:
        best = steps.best_u if steps.best_u is not None else u
        outcome = Outcome(Status.TERMINATED if isinstance(signal, Terminated) else Status.INTERRUPTED, best, len(steps.history))
    if resume.on_end is not None and not outcome.status.interrupted:
        resume.on_end(steps.ending(outcome))
    return _result(s, outcome, steps, solver_name(engine), loss)


def _rendered_first(s: Setup, steps: _Steps | None = None) -> RenderedFirst | None:
    """The solver's residuals with their renders made before each step (:mod:`spacefit.fitting.outside`), where the
    problem has them; each step's renders told to ``steps`` (:meth:`_Steps.rendered`)."""
    fp, outside = s.solver_params, s.problem.outside
    if outside is None:
        return None

    def render(u: jax.Array) -> Any:
        x = np.asarray(fp.to_physical(u))
        rendered = outside.render(x, 0, True)
        if steps is not None:
            steps.rendered(x, rendered)
        return rendered

    def residual(u: jax.Array, rendered: Any) -> jax.Array:
        return outside.evaluate(fp.to_physical(u), *rendered)[DESCENT].astype(u.dtype)  # as residual_u's

    return RenderedFirst(render, residual)


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
        self.last: tuple[np.ndarray, Any] | None = None  # the last step's point and renders (rendered first)

    def rendered(self, x: np.ndarray, rendered: Any) -> None:
        """The renders with their Jacobian (the fit's seeds) made at ``x`` for the step to be recorded next."""
        self.last = (x, rendered)

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
        # (a resumed solve's first step evaluates its best point again: no step of the interrupted solve's)
        accepted = not self.restarted and self.floor.record(step.loss, new_point=not same)
        if accepted:
            self.best_u, self.best_loss = step.u, step.loss
            if self.last is not None and np.array_equal(self.last[0], x_solver):  # the errors linearise here with these renders
                x_rendered, rendered = self.last
                problem.outside.keep(x_rendered, 0, rendered)
            if self.noise_stop:
                r = step.residuals if step.residuals is not None else np.asarray(problem.descent_at(x_solver, 0))
                self.floor.set_noise(loss_noise(r, np.asarray(problem.descent_at(x_solver, 1))))
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
        as the solve recorded it, an evaluation of the best point again a rejected step)."""
        self.history = [{**entry, "loss": _number(entry["loss"]), "loss_noise": _number(entry["loss_noise"])} for entry in history]
        best = None
        for entry in self.history:
            self.floor.record(entry["loss"], new_point=best is None or entry["values"] != best)
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


def verdict(status: Status, moved: bool, at_bound: bool, misfit: bool, unjudged: bool = False) -> Status:
    """The fit's status from the solver's: a solve that ended without failing is
    :attr:`Status.NO_PROGRESS` if no step lowered the loss, else :attr:`Status.AT_BOUND` if a
    parameter ended at a bound, else :attr:`Status.UNJUDGED` if its residuals could not be judged
    (``unjudged``), else :attr:`Status.MISFIT` if the residuals exceed the noise."""
    if status not in (Status.CONVERGED, Status.NOISE_FLOOR, Status.NO_BETTER_POINT, Status.MAX_STEPS):
        return status
    if not moved:
        return Status.NO_PROGRESS
    if at_bound:
        return Status.AT_BOUND
    if unjudged:
        return Status.UNJUDGED
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
        named_stderr = dict(zip(s.user.names, stderr))
        warnings = (warnings_for(s.user, x_user, stderr, corr) + grid_notes(extras.get("pixel_grid_error", {}), named_stderr)
                    + seed_notes(extras.get("render_seed_shift", {}), extras.get("render_seed_widened", {}), named_stderr)
                    + weight_bias_notes(extras.get("noise_weight_bias", {}), named_stderr))
        quality, r, noise, renders, signal = judged_goodness(s, jnp.asarray(x), loss)
        residuals = [*(np.where(used[..., None], ref - render, np.nan) for ref, render, used in zip(problem.references, renders, problem.used)),
                     *(b.data.value - render for b, render in zip(problem.blocks, renders[len(problem.references):]))]
        if loss == "pixel":
            per_part = part_goodness(r, noise, problem, quality)
            own_quality = per_observation(r, noise, s, quality.samples_factor, signal)
        at_bound = any(b.at_bound(float(v)) for b, v in zip(s.user.bijections, x_user))
        pixels = loss == "pixel"
        status = verdict(status, steps.moved, at_bound, quality.misfit and pixels, quality.noise_known and not quality.judged and pixels)
        if not math.isfinite(loss_value):
            status = Status.NONFINITE
            warnings.insert(0, "the render or its Jacobian at the result is not finite (NaN); no errors are reported.")
        if status is Status.MISFIT:
            warnings.insert(0, f"a misfit: {quality.line()}; the standard errors assume a correct model and are too small.")
        elif status is Status.UNJUDGED:
            warnings.insert(0, f"no verdict: {quality.line()}.")
        elif status is Status.NO_PROGRESS:
            why = (f": its last {REJECTED_PATIENCE} trial steps each raised the loss by less than {REJECTED_RTOL:g} of the start's, so "
                   "the solver stopped; no step along its direction lowers the loss here (the start is the loss's minimum for these "
                   "free parameters, or the data need another one freed)" if outcome.status is Status.NO_BETTER_POINT else "")
            warnings.insert(0, f"the fit did not succeed ({status}){why}; {quality.line()}.")
        elif not status.success:
            warnings.insert(0, f"the fit did not succeed ({status}).")
        warnings += _own_misfits(s, own_quality)
    else:
        warnings = ["the solve produced non-finite parameters; no estimate is reported."]
        status = Status.NONFINITE
    values = dict(zip(s.user.names, x_user.tolist()))
    return FitResult(
        names=s.user.names, values=values, stderr=dict(zip(s.user.names, stderr.tolist())), correlation=corr,
        success=status.success, status=status, warnings=warnings, history=steps.history, renders=renders, loss=loss_value,
        solver=solver, loss_name=loss, steps=outcome.steps, wall_time_s=time.perf_counter() - steps.t0,
        start=dict(zip(s.user.names, s.x0_user.tolist())), extras=extras,
        parts=[part_rows(*row) for row in zip(problem.part_images, problem.references, renders, problem.units, problem.used, per_part)],
        scene=_fitted_scene(s, values) if np.all(np.isfinite(x_user)) else None,
        units=[*problem.units, *(b.data.unit for b in problem.blocks)], goodness=quality, residuals=residuals,
        observation_goodness=own_quality, observations=tuple(o for o, _ in s.layout), entries=tuple(e for _, e in s.layout),
    )


def _own_misfits(s: Setup, own: Sequence[Goodness]) -> list[str]:
    """A warning per observation whose own residuals are a misfit (:func:`~spacefit.fitting.judging.per_observation`),
    or, without a known noise, stand out from the others' (:func:`~spacefit.fitting.goodness.standing_out`), named by
    its frame where it is a pass's: a pooled verdict within range can hold a frame that is not."""
    out, apart = [], standing_out(own)
    for observation, entries in s.layout:
        for j, k in enumerate(entries):
            name = f"frame {j} of the pass (observation {k})" if isinstance(observation, Sequenced) else f"observation {k}"
            if k < len(own) and own[k].misfit:
                out.append(f"{name} is a misfit on its own: chi^2/dof {own[k].chi2_dof:.3f} above its limit {own[k].limit:.3f}.")
            if k in apart:
                out.append(f"{name}'s residuals stand out from the others': their mean square over its render noise's "
                           f"({own[k].robust_spread:.3g}, the largest {100 * TRIM:g} % left out) is {apart[k]:.3g} times the other "
                           f"observations' median (above {STANDS_OUT:g}); with the noise unknown (estimated from {own[k].basis}) this "
                           "may be a model error of its own (a pose, a blur, a gain), and the standard errors of what it "
                           "determines may be understated.")
    return out


def _fitted_scene(s: Setup, values: Mapping[str, float]) -> Scene | None:
    """The first image's scene with the fitted values it knows (None without an image)."""
    if s.scene is None:
        return None
    return scene_with_values(s.scene, {n: v for n, v in values.items() if Name(n).parameter in s.image_names}, observation=0)


def _nonfinite_run(history: list[dict[str, Any]]) -> bool:
    recent = history[-NONFINITE_PATIENCE:]
    return len(recent) == NONFINITE_PATIENCE and not any(np.isfinite(h["loss"]) for h in recent)


