"""How a fit ended: :class:`Status`, the solver's own ending and the verdict :func:`verdict` makes of it.

A solver's driver (:mod:`spacefit.fitting.drivers`) ends with one of the solver's endings; the fit
(:mod:`spacefit.fitting.loop`) then judges a solve that did not fail (no progress, a bound, the
residuals against the noise) and reports the verdict as its status, never text to parse.
"""

from __future__ import annotations

import enum


class Status(enum.Enum):
    """How a fit ended. ``value`` is the words a report prints on its first line.

    The solver's own endings (converged, noise floor, step limit, failures, signals), and six
    verdicts on a solve that ended without a failure, in this order of precedence:
    :attr:`NO_PROGRESS` (no step lowered the loss: the start is returned), :attr:`AT_BOUND` (a
    parameter ended at a bound of its range), :attr:`UNJUDGED` (the noise is known but the model's
    own render noise is too large to judge its residuals), :attr:`MISFIT` (the residuals exceed the noise, :attr:`FitResult.goodness`),
    :attr:`UNSTEPPED` (with a blur free, the step to the model made at 4x the resolution not taken: its iterations moved
    a blur or shift past the black sky its finer models were sized for, or a render at 4x is not finite) and :attr:`UNSETTLED` (that step short of its
    fixed point); neither over :attr:`MAX_STEPS`, the solver's own shortfall. Only :attr:`CONVERGED`, :attr:`NOISE_FLOOR` and
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
    NO_BETTER_POINT = ("converged: the solver's trial steps found no lower loss (successive rejected steps, or a rejected "
                       "point about to be tried again, within the loss's Monte Carlo noise of each other, or within a relative "
                       "1e-3 of the best)")
    MAX_STEPS = "stopped: maximum number of steps reached"
    NO_PROGRESS = "failed: no step lowered the loss; the values are the start"
    AT_BOUND = "failed: a parameter is at a bound of its range; neither it nor its error is an estimate"
    MISFIT = "misfit: the residuals exceed the noise; the model or its nuisances miss something, the error bars are too small"
    UNJUDGED = ("not judged: the model's own render noise is above the data's noise, so chi^2 cannot tell a misfit; "
                "render with more samples")
    UNSETTLED = ("not settled: the pixel grid's step to a model made at a finer resolution stopped short of its fixed point; "
                 "the values it moves are short of it by more than its tolerance (the warnings name them)")
    UNSTEPPED = ("not stepped: the pixel grid's step to a model made at a finer resolution moved a blur or shift past the black "
                 "sky its finer models were sized for (or a render at that resolution is not finite); the values and their "
                 "errors are the fit's on the pixel grid, without the step (the warnings name the values and their reach)")
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

    @property
    def headline(self) -> str:
        """The status in a few words, for a panel's title: its description's first clause, and the status's name in words
        where that says more ("converged: no better point", "failed: at bound", "misfit", "not judged")."""
        first, words = self.value.split(":")[0], self.name.lower().replace("_", " ")
        return first if first.startswith("not ") or words in first else f"{first}: {words}"

    def __str__(self) -> str:
        return self.value


def verdict(status: Status, moved: bool, at_bound: bool, misfit: bool, unjudged: bool = False, unsettled: bool = False,
            unstepped: bool = False) -> Status:
    """The fit's status from the solver's: a solve that ended without failing is
    :attr:`Status.NO_PROGRESS` if no step lowered the loss, else :attr:`Status.AT_BOUND` if a
    parameter ended at a bound, else :attr:`Status.UNJUDGED` if its residuals could not be judged
    (``unjudged``), else :attr:`Status.MISFIT` if the residuals exceed the noise, else, one that
    did not stop at its step limit, :attr:`Status.UNSTEPPED` if the pixel grid's step was not taken (``unstepped``),
    else :attr:`Status.UNSETTLED` if it stopped short of its fixed point (``unsettled``)."""
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
    if status is Status.MAX_STEPS:
        return status
    if unstepped:
        return Status.UNSTEPPED
    if unsettled:
        return Status.UNSETTLED
    return status
