"""The solvers: a name or an optimistix solver object -> a driver that steps it and yields its steps.

By name, the defaults: optimistix ``LevenbergMarquardt`` (``"lm"``), ``GaussNewton`` (``"gn"``),
``Dogleg`` (``"dogleg"``), ``BFGS`` (``"bfgs"``), and optax Adam (``"adam"``, :class:`Adam`, the
stochastic-gradient baseline, with reverse-mode gradients when every column allows it). Any
optimistix least-squares solver or minimiser object may be given instead; its tolerances travel
with it. Each is stepped interactively: a driver is a generator that yields one :class:`Step` per
evaluation (the point, its loss and residuals) and returns an :class:`Outcome` with a
:class:`Status`, never text to parse; the caller records the steps and may stop the solve.
"""

from __future__ import annotations

import dataclasses
import enum
from collections.abc import Callable, Generator
from dataclasses import dataclass
from typing import Any, Union

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from spacefit.errors import InputTypeError, check_choice, check_range, quote
from spacefit.fitting.compile_cache import CALLBACK_COMPILER_OPTIONS, jit_calling_back
from spacefit.fitting.normal_equations import NormalEquations

# Residuals of an unconstrained vector u.
ResidualFn = Callable[[jax.Array], jax.Array]
# Adam stops when no unconstrained coordinate moved more than rtol for this many steps.
ADAM_PATIENCE = 5
# The tolerances of the solvers named by :data:`SOLVERS`.
DEFAULT_RTOL, DEFAULT_ATOL = 1e-3, 1e-6


class Status(enum.Enum):
    """How a fit ended. ``value`` is the words a report prints on its first line.

    The solver's own endings (converged, noise floor, step limit, failures, signals), and four
    verdicts on a solve that ended without a failure, in this order of precedence:
    :attr:`NO_PROGRESS` (no step lowered the loss: the start is returned), :attr:`AT_BOUND` (a
    parameter ended at a bound of its range), :attr:`UNJUDGED` (the noise is known but the model's
    own render noise is too large to judge its residuals) and :attr:`MISFIT` (the residuals exceed the noise, :attr:`FitResult.goodness`). Only :attr:`CONVERGED`, :attr:`NOISE_FLOOR` and
    :attr:`NO_BETTER_POINT` (``sf.fit(stop=...)``) are a success, and only where the
    verdicts leave them: a solve stopped there whose residuals exceed the noise is a :attr:`MISFIT`.

    Example:
        >>> import spacefit as sf
        >>> sf.Status.CONVERGED.success, sf.Status.MISFIT.success
        (True, False)
        >>> sf.Status.CONVERGED.value
        'converged'
    """

    CONVERGED = "converged"
    NOISE_FLOOR = "converged: the expected decrease of the loss is below its Monte Carlo noise"
    NO_BETTER_POINT = ("converged: the solver's trial steps found no lower loss (successive rejected steps within the "
                       "loss's Monte Carlo noise of each other, or within a relative 1e-3 of the best)")
    MAX_STEPS = "stopped: maximum number of steps reached"
    NO_PROGRESS = "failed: no step lowered the loss; the values are the start"
    AT_BOUND = "failed: a parameter is at a bound of its range; neither it nor its error is an estimate"
    MISFIT = "misfit: the residuals exceed the noise; the model or its nuisances miss something, the error bars are too small"
    UNJUDGED = ("not judged: the model's own render noise is above the data's noise, so chi^2 cannot tell a misfit; "
                "render with more samples")
    DIVERGED = "failed: the solve diverged"
    NONFINITE = "failed: the loss or a parameter became NaN"
    FAILED = "failed: the solver reported an error"
    INTERRUPTED = "stopped: interrupted (the best point so far is reported, without errors)"
    TERMINATED = "stopped: terminated by SIGTERM (the best point so far is reported, without errors)"

    @property
    def success(self) -> bool:
        """Whether the fit converged to an estimate that its data do not contradict."""
        return self in (Status.CONVERGED, Status.NOISE_FLOOR, Status.NO_BETTER_POINT)

    @property
    def interrupted(self) -> bool:
        """Whether a signal (Ctrl-C or SIGTERM) stopped the solve."""
        return self in (Status.INTERRUPTED, Status.TERMINATED)

    def __str__(self) -> str:
        return self.value


@dataclass(frozen=True)
class Adam:
    """optax Adam (Kingma & Ba 2015, arXiv:1412.6980) with a cosine-decaying step on the
    unconstrained vector.

    Attributes:
        learning_rate: the initial step size in unconstrained coordinates.
        rtol: stop when no unconstrained coordinate moved more than this for :data:`ADAM_PATIENCE` steps.

    Raises:
        InputError: ``learning_rate`` or ``rtol`` not > 0.

    Example:
        >>> import spacefit as sf
        >>> sf.Adam(learning_rate=0.1)  # sf.fit(..., solver=sf.Adam(learning_rate=0.1))
        Adam(learning_rate=0.1, rtol=0.001)
    """

    learning_rate: float = 0.05
    rtol: float = DEFAULT_RTOL

    def __post_init__(self) -> None:
        check_range("Adam.learning_rate", self.learning_rate, 0.0, lo_open=True)
        check_range("Adam.rtol", self.rtol, 0.0, lo_open=True)


Solver = Union[optx.AbstractLeastSquaresSolver, optx.AbstractMinimiser, Adam]


def _normal(cls: type) -> Callable[[], Solver]:
    # Steps from J^T J formed a few columns at a time (spacefit.fitting.normal_equations): a joint
    # fit's Jacobian, rows of every frame by columns of every frame's values, is never held whole
    # (optimistix's default QR materialises it, and returns NaN where it is rank deficient:
    # unidentifiable directions, saturated bijections; the pseudo-inverse takes the minimum-norm step).
    return lambda: cls(rtol=DEFAULT_RTOL, atol=DEFAULT_ATOL, linear_solver=NormalEquations())


#: The solvers ``sf.fit(solver=...)`` takes by name, each a function returning the solver object with
#: its default tolerances: ``lm`` (Levenberg-Marquardt, the default), ``gn`` (Gauss-Newton), ``dogleg``
#: and ``bfgs`` (optimistix) and ``adam`` (:class:`Adam`). Pass a solver object instead of a name to
#: set other tolerances.
#:
#: Example:
#:     >>> import spacefit as sf
#:     >>> list(sf.SOLVERS)
#:     ['lm', 'gn', 'dogleg', 'bfgs', 'adam']
#:     >>> type(sf.SOLVERS["lm"]()).__name__
#:     'LevenbergMarquardt'
SOLVERS: dict[str, Callable[[], Solver]] = {
    "lm": _normal(optx.LevenbergMarquardt),
    "gn": _normal(optx.GaussNewton),
    "dogleg": _normal(optx.Dogleg),
    "bfgs": lambda: optx.BFGS(rtol=DEFAULT_RTOL, atol=DEFAULT_ATOL),
    "adam": Adam,
}


def make_solver(solver: str | Solver) -> Solver:
    """The solver object of a name in :data:`SOLVERS` (its defaults), or ``solver`` itself if it is one.

    Raises:
        InputError: an unknown name, or an object that is no optimistix solver nor :class:`Adam`.
    """
    if isinstance(solver, str):
        check_choice("solver", solver, tuple(SOLVERS))
        return SOLVERS[solver]()
    if not isinstance(solver, (optx.AbstractLeastSquaresSolver, optx.AbstractMinimiser, Adam)):
        raise InputTypeError(f"`solver` must be a name ({', '.join(SOLVERS)}), an optimistix least-squares solver or "
                             f"minimiser, or sf.Adam, got {quote(solver)}.")
    return solver


def with_owners(solver: Solver, owners: tuple[int, ...] | None) -> Solver:
    """``solver`` with each of its :class:`NormalEquations` told which observation's residuals alone
    each column moves (:func:`~spacefit.fitting.residuals.column_owners`): a joint fit's J^T J then costs
    a product per shared value and per kind of own value, not per value. Other linear solvers as they are."""
    def told(leaf: Any) -> Any:
        return dataclasses.replace(leaf, owners=owners) if isinstance(leaf, NormalEquations) else leaf

    return jax.tree_util.tree_map(told, solver, is_leaf=lambda leaf: isinstance(leaf, NormalEquations))


def solver_name(solver: Solver) -> str:
    """A solver's name in :data:`SOLVERS` if it is of one of their types, else its class name."""
    names = {optx.LevenbergMarquardt: "lm", optx.GaussNewton: "gn", optx.Dogleg: "dogleg", optx.BFGS: "bfgs", Adam: "adam"}
    return names.get(type(solver), type(solver).__name__)


def is_least_squares(solver: Solver) -> bool:
    """Whether the solver takes residuals (a rejected step then means "no better point nearby", where
    the noise-floor stop applies); BFGS rejects line-search trials and Adam takes noisy steps by
    design (stopped there by the noise rule, BFGS's D, G fit ended at D +0.016 and G +7.5 %
    against +0.002 and +2 % by its tolerances)."""
    return isinstance(solver, optx.AbstractLeastSquaresSolver)


@dataclass(frozen=True)
class Step:
    """One evaluation of a solve, as a driver yields it.

    Attributes:
        u: the unconstrained point evaluated.
        loss: its loss, 0.5 sum r^2.
        residuals: its residuals (None where only the loss was evaluated: Adam's reverse mode).
        iterate: the solver's point after the step (the accepted point so far).
    """

    u: np.ndarray
    loss: float
    residuals: np.ndarray | None
    iterate: jax.Array


@dataclass(frozen=True)
class Outcome:
    """What a driver returns: the status, the unconstrained point reached and the steps taken."""

    status: Status
    u: jax.Array
    steps: int


Driver = Generator[Step, None, Outcome]


@dataclass(frozen=True)
class RenderedFirst:
    """Residuals whose renders are made before the solver's compiled step runs
    (:mod:`spacefit.fitting.outside`), so that the step calls nothing back and JAX's cache keeps it.

    Attributes:
        render: unconstrained u (concrete) -> the renders at u, the step's operands.
        residual: (u, renders) -> the residuals at u from renders made at u: a function with no callback.
    """

    render: Callable[[jax.Array], Any]
    residual: Callable[[jax.Array, Any], jax.Array]


class _Evaluations:
    """The last point a compiled solver step evaluated, taken out with ``jax.debug.callback``: the
    solvers evaluate trial points inside their compiled steps and return only the accepted ones."""

    def __init__(self) -> None:
        self.last: tuple[np.ndarray, float, np.ndarray | None] | None = None

    def keep(self, u: jax.Array, value: jax.Array, r: jax.Array | None = None) -> None:
        # jax.debug.callback puts its arguments on a device in the thread that calls it, whose JAX need not be in
        # 64-bit mode (a thread of XLA's, now and then): float64 would arrive rounded to float32. They travel as bits.
        arrays = [jnp.asarray(a) for a in (u, value, r) if a is not None]
        kinds = [(np.dtype(a.dtype), a.shape) for a in arrays]

        def store(*bits: np.ndarray) -> None:
            u_, value_, *r_ = (np.ascontiguousarray(b).view(dtype).reshape(shape) for b, (dtype, shape) in zip(bits, kinds))
            self.last = (u_, float(value_), r_[0] if r_ else None)

        jax.debug.callback(store, *(jax.lax.bitcast_convert_type(a, jnp.uint32) for a in arrays))

    def step(self, iterate: jax.Array) -> Step:
        assert self.last is not None, "the solver step evaluated nothing"
        return Step(*self.last, iterate=iterate)


def drive(solver: Solver, residual_u: ResidualFn, u: jax.Array, max_steps: int,
          loss_u_reverse: Callable[[jax.Array], jax.Array] | None, rendered_first: RenderedFirst | None = None) -> Driver:
    """Step ``solver`` from ``u`` for at most ``max_steps`` steps, yielding each :class:`Step`.
    ``loss_u_reverse``: the loss by reverse mode, which Adam uses where given. ``rendered_first``: the
    same residuals with their renders made before each step, which the Gauss-Newton family
    (``lm``, ``gn``, ``dogleg``) steps on (its step evaluates its function at its state's trial point only)."""
    if isinstance(solver, Adam):
        return _adam(solver, residual_u, u, max_steps, loss_u_reverse)
    if rendered_first is not None and isinstance(solver, optx.AbstractGaussNewton):
        return _rendered_first(solver, rendered_first, u, max_steps)
    return _optimistix(solver, residual_u, u, max_steps)


def _status(result: optx.RESULTS) -> Status:
    for item, status in [
        (optx.RESULTS.successful, Status.CONVERGED),
        (optx.RESULTS.nonlinear_max_steps_reached, Status.MAX_STEPS),
        (optx.RESULTS.nonlinear_divergence, Status.DIVERGED),
        (optx.RESULTS.nonfinite, Status.NONFINITE),
    ]:
        if bool(result == item):
            return status
    return Status.FAILED


def _optimistix(solver: Solver, residual_u: ResidualFn, u: jax.Array, max_steps: int) -> Driver:
    """Step an optimistix solver interactively, so each step is recorded and shown."""
    seen = _Evaluations()
    least_squares = is_least_squares(solver)
    if least_squares:
        f_struct = jax.eval_shape(residual_u, u)
        scale = 1.0
    else:
        f_struct = jax.ShapeDtypeStruct((), u.dtype)
        # a minimiser's (BFGS's) first step is the raw gradient: scale the loss to 1 at the start so
        # that the step is of order one in unconstrained coordinates (the minimiser is unchanged).
        scale = 1.0 / max(float(0.5 * jnp.sum(residual_u(u) ** 2)), 1e-30)

    # fn is a static leaf of the arguments of the filter_jit'ed step: JAX's caches keyed by the
    # arguments' tree (donation_vector's lru_cache, 4096 entries) keep it for the life of the process.
    # What it reaches (the problem: loaded scenes, compiled renders) is held here and dropped when
    # the solve ends, so that a process that fits again and again keeps a few hundred bytes per fit,
    # not the fit (13.6 MiB per fit before).
    held = [residual_u, seen]

    def fn(y: jax.Array, args: Any) -> tuple[jax.Array, None]:
        # the interactive solver API takes functions with auxiliary output
        residual, evaluations = held
        r = residual(y)
        value = 0.5 * jnp.sum(r**2)
        evaluations.keep(y, value, r)
        return (r if least_squares else scale * value), None

    tags: frozenset = frozenset()
    try:
        state = solver.init(fn, u, None, {}, f_struct, None, tags)
        step = eqx.filter_jit(solver.step, compiler_options=CALLBACK_COMPILER_OPTIONS)  # its renders call back
        terminate = eqx.filter_jit(solver.terminate)

        def advance(k: int, u: jax.Array) -> Step:
            nonlocal state
            u, state, _ = step(fn, u, None, {}, state, tags)
            return seen.step(u)

        return (yield from _stepped(advance, lambda u: terminate(fn, u, None, {}, state, tags), u, max_steps))
    finally:
        held.clear()


def _stepped(advance: Callable[[int, jax.Array], Step], terminate: Callable[[jax.Array], tuple[jax.Array, Any]], u: jax.Array,
             max_steps: int) -> Driver:
    """An optimistix solver's steps: ``advance(k, u)`` takes step k from ``u`` and says it, until the
    solver's ``terminate(u)``, a non-finite point or ``max_steps``."""
    result = optx.RESULTS.nonlinear_max_steps_reached
    k = 0
    for k in range(1, max_steps + 1):
        taken = advance(k, u)
        u = taken.iterate
        yield taken
        if not np.all(np.isfinite(np.asarray(u))):
            return Outcome(Status.NONFINITE, u, k)
        done, res = terminate(u)
        if bool(done):
            result = res
            break
    return Outcome(_status(result), u, k)


def _rendered_first(solver: optx.AbstractGaussNewton, given: RenderedFirst, u: jax.Array, max_steps: int) -> Driver:
    """Step a Gauss-Newton-family solver with the renders made before each step at its trial point
    (its state's ``y_eval``), handed to the compiled step as its ``args``: no program calls back."""
    held = [given.residual]  # dropped when the solve ends (as :func:`_optimistix`'s)

    def fn(y: jax.Array, args: Any) -> tuple[jax.Array, None]:
        return held[0](y, args), None

    def evaluated(y: jax.Array, args: Any) -> tuple[jax.Array, jax.Array]:
        r = held[0](y, args)
        return r, 0.5 * jnp.sum(r**2)

    tags: frozenset = frozenset()
    try:
        args = given.render(u)
        step, terminate, evaluate = eqx.filter_jit(solver.step), eqx.filter_jit(solver.terminate), jax.jit(evaluated)
        first = evaluate(u, args)  # the first step's (its trial point is u), and the residuals' shape without another trace
        # one program: optimistix's init, run op by op, made some 24 single-operation programs, each traced and lowered per process
        state = eqx.filter_jit(solver.init)(fn, u, args, {}, jax.ShapeDtypeStruct(first[0].shape, first[0].dtype), None, tags)

        def advance(k: int, u: jax.Array) -> Step:
            nonlocal state, args
            trial = state.y_eval
            if k > 1:
                args = given.render(trial)
            r, value = first if k == 1 else evaluate(trial, args)
            u, state, _ = step(fn, u, args, {}, state, tags)
            return Step(np.asarray(trial), float(value), np.asarray(r), iterate=u)

        return (yield from _stepped(advance, lambda u: terminate(fn, u, args, {}, state, tags), u, max_steps))
    finally:
        held.clear()


def _adam(solver: Adam, residual_u: ResidualFn, u: jax.Array, max_steps: int,
          loss_u_reverse: Callable[[jax.Array], jax.Array] | None) -> Driver:
    """optax Adam with a cosine-decaying step on the unconstrained vector; reverse-mode gradients
    (``loss_u_reverse``) unless a Jacobian column needs finite differences."""
    seen = _Evaluations()

    def loss_u(y: jax.Array) -> jax.Array:
        if loss_u_reverse is not None:
            value = loss_u_reverse(y)
            seen.keep(y, value)
            return value
        r = residual_u(y)
        value = 0.5 * jnp.sum(r**2)
        seen.keep(y, value, r)
        return value

    import optax  # here: its import (0.2-0.6 s, with chex) is only Adam's, not the least-squares solvers' of every default fit

    value_and_grad = jit_calling_back(jax.value_and_grad(loss_u))
    opt = optax.adam(optax.cosine_decay_schedule(solver.learning_rate, max_steps))
    opt_state = opt.init(u)
    still = 0
    for k in range(1, max_steps + 1):
        _, grad = value_and_grad(u)
        yield seen.step(u)
        updates, opt_state = opt.update(grad, opt_state)
        u = optax.apply_updates(u, updates)
        still = still + 1 if float(jnp.max(jnp.abs(updates))) < solver.rtol else 0
        if still >= ADAM_PATIENCE:
            return Outcome(Status.CONVERGED, u, k)
    return Outcome(Status.MAX_STEPS, u, max_steps)
