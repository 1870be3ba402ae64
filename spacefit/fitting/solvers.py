"""The solvers by name: a name or an optimistix solver object -> the solver object a fit steps.

By name, the defaults: optimistix ``LevenbergMarquardt`` (``"lm"``), ``GaussNewton`` (``"gn"``),
``Dogleg`` (``"dogleg"``), ``BFGS`` (``"bfgs"``), and optax Adam (``"adam"``, :class:`Adam`, the
stochastic-gradient baseline, with reverse-mode gradients when every column allows it). Any
optimistix least-squares solver or minimiser object may be given instead; its tolerances travel
with it. :mod:`spacefit.fitting.drivers` steps them.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Union

import jax
import optimistix as optx

from spacefit.errors import InputTypeError, check_choice, check_range, quote
from spacefit.fitting.normal_equations import NormalEquations

# Adam stops when no unconstrained coordinate moved more than rtol for this many steps.
ADAM_PATIENCE = 5
# The tolerances of the solvers named by :data:`SOLVERS`.
DEFAULT_RTOL, DEFAULT_ATOL = 1e-3, 1e-6


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
