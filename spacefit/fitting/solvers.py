"""The solver registry: a name -> a driver that steps one solver and reports a structured status.

Drivers: optimistix ``LevenbergMarquardt`` (``"lm"``), ``GaussNewton`` (``"gn"``), ``Dogleg``
(``"dogleg"``), ``BFGS`` (``"bfgs"``), and optax Adam (``"adam"``, the stochastic-gradient
baseline, with reverse-mode gradients when every column allows it). Each is stepped interactively
so that every step is recorded and shown; each returns a :class:`Status`, never text to parse.
"""

from __future__ import annotations

import enum
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import lineax as lx
import numpy as np
import optax
import optimistix as optx

# Residuals of an unconstrained vector u (with the optimistix ``args``, unused).
ResidualFn = Callable[[jax.Array, Any], jax.Array]
# Records the step's evaluation; a Status stops the solve (a run of non-finite evaluations, the
# noise floor), None goes on.
StepLogger = Callable[[int], "Status | None"]
# Adam stops when no unconstrained coordinate moved more than rtol for this many steps.
ADAM_PATIENCE = 5


class Status(enum.Enum):
    """How a solve ended. ``value`` is the words a report prints."""

    CONVERGED = "converged"
    NOISE_FLOOR = "converged: the expected decrease of the loss is below its Monte Carlo noise"
    MAX_STEPS = "stopped: maximum number of steps reached"
    DIVERGED = "failed: the solve diverged"
    NONFINITE = "failed: the loss or a parameter became NaN"
    FAILED = "failed: the solver reported an error"
    INTERRUPTED = "stopped: interrupted (the best point so far is reported, without errors)"
    TERMINATED = "stopped: terminated by SIGTERM (the best point so far is reported, without errors)"

    @property
    def success(self) -> bool:
        """Whether the solver reports convergence."""
        return self in (Status.CONVERGED, Status.NOISE_FLOOR)

    @property
    def interrupted(self) -> bool:
        """Whether a signal (Ctrl-C or SIGTERM) stopped the solve."""
        return self in (Status.INTERRUPTED, Status.TERMINATED)

    def __str__(self) -> str:
        return self.value


@dataclass(frozen=True)
class Outcome:
    """What a driver returns: the status, the unconstrained point reached and the steps taken."""

    status: Status
    u: jax.Array
    steps: int


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


@dataclass(frozen=True)
class Options:
    """Solver settings shared by every driver."""

    max_steps: int
    rtol: float
    atol: float
    learning_rate: float


def _optimistix(name: str, residual_u: ResidualFn, u: jax.Array, opts: Options, log_step: StepLogger,
                loss_u_reverse: Callable[[jax.Array], jax.Array] | None) -> Outcome:
    """Step an optimistix solver interactively, so each step is recorded and shown."""
    if name == "bfgs":
        obj = optx.BFGS(rtol=opts.rtol, atol=opts.atol)
        f_struct = jax.ShapeDtypeStruct((), u.dtype)
        # BFGS's first step is the raw gradient: scale the loss to 1 at the start so that the step
        # is of order one in unconstrained coordinates (the minimiser is unchanged).
        scale = 1.0 / max(float(0.5 * jnp.sum(residual_u(u, None) ** 2)), 1e-30)
    else:
        # Gauss-Newton and dogleg steps by SVD: the default QR returns NaN where the Jacobian is rank
        # deficient (unidentifiable directions, saturated bijections); SVD takes the minimum-norm step.
        kwargs = {} if name == "lm" else {"linear_solver": lx.AutoLinearSolver(well_posed=False)}
        obj = {"lm": optx.LevenbergMarquardt, "gn": optx.GaussNewton, "dogleg": optx.Dogleg}[name](
            rtol=opts.rtol, atol=opts.atol, **kwargs)
        f_struct = jax.eval_shape(lambda y: residual_u(y, None), u)
        scale = 1.0

    def fn(y: jax.Array, args: Any) -> tuple[jax.Array, None]:
        # the interactive solver API takes functions with auxiliary output
        r = residual_u(y, args)
        return (scale * 0.5 * jnp.sum(r**2) if name == "bfgs" else r), None

    tags: frozenset = frozenset()
    state = obj.init(fn, u, None, {}, f_struct, None, tags)
    step = eqx.filter_jit(obj.step)
    terminate = eqx.filter_jit(obj.terminate)
    result = optx.RESULTS.nonlinear_max_steps_reached
    k = 0
    for k in range(1, opts.max_steps + 1):
        u, state, _ = step(fn, u, None, {}, state, tags)
        stop = log_step(k)
        if stop is not None:
            return Outcome(stop, u, k)
        if not np.all(np.isfinite(np.asarray(u))):
            return Outcome(Status.NONFINITE, u, k)
        done, res = terminate(fn, u, None, {}, state, tags)
        if bool(done):
            result = res
            break
    return Outcome(_status(result), u, k)


def _adam(name: str, residual_u: ResidualFn, u: jax.Array, opts: Options, log_step: StepLogger,
          loss_u_reverse: Callable[[jax.Array], jax.Array] | None) -> Outcome:
    """optax Adam with a cosine-decaying step on the unconstrained vector; reverse-mode gradients
    (``loss_u_reverse``) unless a Jacobian column needs finite differences."""

    def loss_u(y: jax.Array) -> jax.Array:
        if loss_u_reverse is not None:
            return loss_u_reverse(y)
        return 0.5 * jnp.sum(residual_u(y, None) ** 2)

    value_and_grad = jax.jit(jax.value_and_grad(loss_u))
    opt = optax.adam(optax.cosine_decay_schedule(opts.learning_rate, opts.max_steps))
    opt_state = opt.init(u)
    still = 0
    for k in range(1, opts.max_steps + 1):
        _, grad = value_and_grad(u)
        stop = log_step(k)
        if stop is not None:
            return Outcome(stop, u, k)
        updates, opt_state = opt.update(grad, opt_state)
        u = optax.apply_updates(u, updates)
        still = still + 1 if float(jnp.max(jnp.abs(updates))) < opts.rtol else 0
        if still >= ADAM_PATIENCE:
            return Outcome(Status.CONVERGED, u, k)
    return Outcome(Status.MAX_STEPS, u, opts.max_steps)


Driver = Callable[[str, ResidualFn, jax.Array, Options, StepLogger, Callable[[jax.Array], jax.Array] | None], Outcome]
SOLVERS: dict[str, Driver] = {"lm": _optimistix, "gn": _optimistix, "dogleg": _optimistix, "bfgs": _optimistix, "adam": _adam}
# The solvers whose rejected steps mean "no better point nearby", where the noise-floor stop applies;
# BFGS rejects line-search trials and Adam takes noisy steps by design (stopped there by the noise
# rule, BFGS's D, G fit ended at D +0.016 and G +7.5 % against +0.002 and +2 % by its tolerances).
LEAST_SQUARES = ("lm", "gn", "dogleg")
