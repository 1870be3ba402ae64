"""``fit``: recover parameters from observations (images, tables, light curves) with gradient-based solvers.

One function, one result type. The set-up is :mod:`spacefit.fitting.problem`, the solvers
:mod:`spacefit.fitting.solvers` and their drivers :mod:`spacefit.fitting.drivers`; this module runs
the solve, which :mod:`spacefit.fitting.solve_record` records step by step and
:mod:`spacefit.fitting.conclusion` makes a result of (the standard errors, the goodness of fit, the verdict).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from spacefit.errors import check_choice, check_count, check_type
from spacefit.executors import Cluster
from spacefit.fitting.compile_cache import use_compile_cache
from spacefit.fitting.conclusion import conclude
from spacefit.fitting.drivers import Outcome, RenderedFirst, drive
from spacefit.fitting.frames import frame_executor
from spacefit.fitting.normal_equations import all_shared
from spacefit.fitting.observations.base import Sequenced, ValueObservation
from spacefit.fitting.observations.image import Observation
from spacefit.fitting.outside import DESCENT
from spacefit.fitting.problem import FitRender, Setup, setup
from spacefit.fitting.residuals import column_owners
from spacefit.fitting.result import FitResult
from spacefit.fitting.resume import Resume
from spacefit.fitting.solve_record import SolveRecord
from spacefit.fitting.solvers import Solver, is_least_squares, make_solver, solver_name, with_owners
from spacefit.fitting.status import Status
from spacefit.interrupts import Terminated, deferred_interrupts
from spacefit.precision import float64, on_device
from spacefit.progress import ProgressCallback

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
    steps = SolveRecord(s, stop == "noise" and is_least_squares(engine) and problem.rendered, max_steps, progress, resume.on_step)
    u = jnp.asarray(fp.to_unconstrained(on_device(s.x0, np.float64)))
    if resume.ended is not None:
        return conclude(s, steps.ended(resume.ended, u), steps, solver_name(engine), loss)
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
    return conclude(s, outcome, steps, solver_name(engine), loss)


def _rendered_first(s: Setup, steps: SolveRecord | None = None) -> RenderedFirst | None:
    """The solver's residuals with their renders made before each step (:mod:`spacefit.fitting.outside`), where the
    problem has them; each step's renders told to ``steps`` (:meth:`~spacefit.fitting.solve_record.SolveRecord.rendered`)."""
    fp, outside = s.solver_params, s.problem.outside
    if outside is None:
        return None
    columns: list[tuple[tuple[int, ...], np.dtype]] = []  # the Jacobian columns' shapes, from the renders made with them

    def rendered(u: jax.Array, jacobian: bool, images: tuple[np.ndarray, ...] | None = None) -> Any:
        x = np.asarray(fp.to_physical(u))
        made = outside.render(x, 0, jacobian, images)
        if jacobian:
            columns[:] = [(c.shape, c.dtype) for c in made[1]]
            if steps is not None:
                steps.rendered(x, made)
        else:
            made = (made[0], tuple(np.zeros(shape, dtype) for shape, dtype in columns))
        return (*made, outside.operands(x.dtype))  # the step's operands: the renders and the frames' own arrays

    def linearised(u: jax.Array, operands: Any) -> Any:
        with_columns = rendered(u, True, operands[0])
        if steps is not None and steps.noise_stop:
            # the point the solver is about to accept: the noise floor's record renders it with the independent seeds
            # next (SolveRecord.record), begun while the solver's step runs
            outside.render_images_ahead(np.asarray(fp.to_physical(u)), 1)
        return with_columns

    def residual(u: jax.Array, renders: Any) -> jax.Array:
        return outside.evaluate(fp.to_physical(u), *renders)[DESCENT].astype(u.dtype)  # as residual_u's

    return RenderedFirst(rendered, linearised, residual, columns_held=all_shared(column_owners(fp, s.problem.blocks)))
