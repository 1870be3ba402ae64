"""The solvers' drivers: a solver object -> a generator that steps it and yields its steps.

Each solver (:mod:`spacefit.fitting.solvers`) is stepped interactively: a driver is a generator that
yields one :class:`Step` per evaluation (the point, its loss and residuals) and returns an
:class:`Outcome` with a :class:`~spacefit.fitting.status.Status`, never text to parse; the caller
records the steps and may stop the solve.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Generator
from dataclasses import dataclass
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from spacefit.fitting.compile_cache import CALLBACK_COMPILER_OPTIONS, jit_calling_back
from spacefit.fitting.normal_equations import held_columns
from spacefit.fitting.solvers import ADAM_PATIENCE, Adam, Solver, is_least_squares
from spacefit.fitting.status import Status

# Residuals of an unconstrained vector u.
ResidualFn = Callable[[jax.Array], jax.Array]


@dataclass(frozen=True)
class Step:
    """One evaluation of a solve, as a driver yields it.

    Attributes:
        u: the unconstrained point evaluated.
        loss: its loss, 0.5 sum r^2.
        residuals: its residuals (None where only the loss was evaluated: Adam's reverse mode).
        iterate: the solver's point after the step (the accepted point so far).
        next_u: the point the solver evaluates next, where known before it is rendered (the Gauss-Newton family's
            trial point, :func:`_rendered_first`); None where not.
    """

    u: np.ndarray
    loss: float
    residuals: np.ndarray | None
    iterate: jax.Array
    next_u: np.ndarray | None = None


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
        render: (unconstrained u (concrete), with the Jacobian) -> the renders at u, the step's operands; without the
            Jacobian, zeros hold its columns' place (a step that rejects u reads none of them).
        linearised: (u, ``render(u, False)``'s operands) -> ``render(u, True)``'s: the Jacobian's columns rendered beside
            the images made.
        residual: (u, renders) -> the residuals at u from renders made at u: a function with no callback.
        columns_held: every Jacobian column moves every observation's residuals (an image fitted alone): the solver's
            state holds the Jacobian's columns (:func:`~spacefit.fitting.normal_equations.held_columns`), not the
            residuals' linearisation.
    """

    render: Callable[[jax.Array, bool], Any]
    linearised: Callable[[jax.Array, Any], Any]
    residual: Callable[[jax.Array, Any], jax.Array]
    columns_held: bool = False


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


def _rejects_above(solver: optx.AbstractGaussNewton) -> bool:
    """Whether the solver rejects a trial point whose loss is above its last accepted point's on that alone: its search a
    trust region (optimistix's ``ClassicalTrustRegion``, ``LinearTrustRegion``), which accepts a point where the loss
    changed by at most ``low_cutoff`` times the change its model predicts (never a rise for the Gauss-Newton family's
    descent directions), with ``low_cutoff`` >= 0. Not Gauss-Newton's (its every step accepted)."""
    search = solver.search
    return isinstance(search, (optx.ClassicalTrustRegion, optx.LinearTrustRegion)) and float(search.low_cutoff) >= 0.0


def _accepts(after: Any, before: Any) -> bool:
    """Whether the Gauss-Newton-family step from state ``before`` to ``after`` accepted its trial point."""
    return int(after.num_accepted_steps) > int(before.num_accepted_steps)


def _linearisation_once(state: Any) -> Any:
    """A Gauss-Newton-family solver's state with its accepted point's linearisation held once: optimistix keeps it as
    ``f_info`` and again as its descent's ``descent_state.f_info`` (a damped Newton descent's), equal after every step (both
    taken from the trial on acceptance, both kept on rejection; both zeros at the start), but two outputs of the compiled
    step, two copies: of a pass's, every frame's Jacobian columns, images and residuals (1.7 MiB a 128 x 128 px frame).
    The step's next call takes the state as its input beside its new one, so the copy lay under each step's peak."""
    if getattr(state.descent_state, "f_info", None) is None:
        return state
    return eqx.tree_at(lambda s: s.descent_state.f_info, state, state.f_info)


def _rendered_first(solver: optx.AbstractGaussNewton, given: RenderedFirst, u: jax.Array, max_steps: int) -> Driver:
    """Step a Gauss-Newton-family solver with the renders made before each step at its trial point
    (its state's ``y_eval``), handed to the compiled step as its ``args``: no program calls back.

    A trial point's Jacobian is read only where the step accepts it (optimistix's ``AbstractGaussNewton.step``: a rejected
    step keeps its state's, whatever the trial's), so where the solver rejects on the loss alone (:func:`_rejects_above`)
    a trial whose loss is above the last accepted point's is stepped on its images, zeros in its Jacobian's place: the
    same state bit for bit, without the Jacobian's render (a pass's: every frame's). Should that step accept the point
    after all (a rounding tie), it is stepped again from the same state on the point's Jacobian."""
    held = [given.residual]  # dropped when the solve ends (as :func:`_optimistix`'s)
    on_loss = _rejects_above(solver)

    def residual(y: jax.Array, args: Any) -> jax.Array:
        return held[0](y, args)

    linearisable = held_columns(residual) if given.columns_held else residual

    def fn(y: jax.Array, args: Any) -> tuple[jax.Array, None]:
        return linearisable(y, args), None

    def evaluated(y: jax.Array, args: Any) -> tuple[jax.Array, jax.Array]:
        r = held[0](y, args)
        return r, 0.5 * jnp.sum(r**2)

    tags: frozenset = frozenset()
    try:
        args = given.render(u, True)
        step, terminate, evaluate = eqx.filter_jit(solver.step), eqx.filter_jit(solver.terminate), jax.jit(evaluated)
        first = evaluate(u, args)  # the first step's (its trial point is u), and the residuals' shape without another trace
        # one program: optimistix's init, run op by op, made some 24 single-operation programs, each traced and lowered per process
        state = _linearisation_once(eqx.filter_jit(solver.init)(fn, u, args, {}, jax.ShapeDtypeStruct(first[0].shape, first[0].dtype),
                                                                None, tags))
        accepted_loss = math.inf  # the loss of the solver's last accepted point (the first step accepts its own)

        def advance(k: int, u: jax.Array) -> Step:
            nonlocal state, args, accepted_loss
            trial = state.y_eval
            if k == 1 or not on_loss:
                if k > 1:
                    args = given.render(trial, True)
                r, value = first if k == 1 else evaluate(trial, args)
                taken = step(fn, u, args, {}, state, tags)
            else:
                args = given.render(trial, False)
                r, value = evaluate(trial, args)
                taken = step(fn, u, args, {}, state, tags) if float(value) > accepted_loss else None
                if taken is None or _accepts(taken[1], state):
                    args = given.linearised(trial, args)
                    taken = step(fn, u, args, {}, state, tags)
            u, after, _ = taken
            if _accepts(after, state):
                accepted_loss = float(value)
            state = _linearisation_once(after)
            return Step(np.asarray(trial), float(value), np.asarray(r), iterate=u, next_u=np.asarray(state.y_eval))

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
