"""When a fit has learned what the data hold: the Monte Carlo noise of the loss and the stop rule.

Renders with another seed scatter the fitted values by their Monte Carlo standard errors; a
step that moves the parameters by a fraction of that scatter steers by render noise. In loss
units, a move of one standard deviation of the render-noise scatter changes the loss 0.5 sum r^2
by half the residuals' render variance (for any direction, the covariance being v (J^T J)^-1):
:func:`loss_noise` estimates it from the residuals of one point rendered with two independent
seeds. :class:`NoiseFloor` watches the steps of a solve: a step is *accepted* when it lowers the
best loss so far (so accepted losses never rise), and the solve stops
(:attr:`~spacefit.fitting.status.Status.NOISE_FLOOR`) as soon as

* the decrease the next step can be expected to bring, the last accepted decrease scaled by the
  ratio of the last two (a converging solver's decreases shrink), is below :data:`NOISE_FACTOR`
  times that noise, or
* a step is rejected by less than that: the solver is chasing noise;

and, with :attr:`~spacefit.fitting.status.Status.NO_BETTER_POINT`, when the solver keeps trying
points no better than the best (measured on a 128 x 128 fit with a sensor: 14 of 19 steps rejected,
each by 0.1 to 6 in loss against a noise of 0.02, about 20 s after the optimum), as soon as

* two successive rejected steps' losses differ by less than the loss's noise (the solver re-tries
  what it tried: its trial points look alike to the data), or
* the solver's next trial point is the rejected one again (within :data:`RETRY_RTOL` of the rejected step's
  length from it, and so, the loss being smooth, a loss within the loss's noise of the rejected one: the first
  rule, known before the point is rendered; measured on the 8-parameter observation fit of
  ``experiments/bench_fit_process.py``: a Levenberg-Marquardt step whose damping
  rose after a rejection moved its trial point by 5e-7 of the rejected step, the losses 2e-9 apart), or
* :data:`REJECTED_PATIENCE` steps in a row are rejected, each by less than :data:`REJECTED_RTOL` of
  the best loss (a relative change the estimates cannot feel). This one applies from the start too:
  a solver whose smallest trial steps raise the loss (its direction does not descend it here: a start
  at the loss's minimum for its free parameters, a Jacobian dominated by its Monte Carlo noise) stops
  after them, where it had re-tried the start to its step limit (28 steps of a materials-only fit with a pose
  error, issue 34), and the verdict says that no step lowered the loss. An evaluation of the best point
  itself again (a trial step too small to move it) is such a rejected step.

Either says "no better point nearby", not "the residuals are at the noise": the fit's verdict
(:func:`~spacefit.fitting.status.verdict`) still calls a fit whose residuals exceed the noise a misfit.

The loss is 0.5 sum r^2 (dimensionless when the residuals are divided by a noise sigma, else
(W m^-2 sr^-1)^2).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

# The solve stops when the expected decrease is below this fraction of the loss's noise: steps
# that would move the parameters by less than sqrt(0.1) = 0.3 of their Monte Carlo scatter.
NOISE_FACTOR = 0.1
# A loss is a sum of float32 render values: two evaluations of one point, or of points a rounding
# apart, differ in the last digits with the order of a parallel sum. A decrease smaller than this
# fraction of the loss is no step (a solver that cannot move would otherwise "converge" by it).
ROUNDING = 1e-6
# The solve stops after this many consecutive rejected steps, each rejected by less than
# REJECTED_RTOL of the best loss.
REJECTED_PATIENCE = 3
REJECTED_RTOL = 1e-3
# A trial point within this fraction of the rejected step's length from the rejected point is that point again.
RETRY_RTOL = 1e-4


def loss_noise(r: np.ndarray, r_alt: np.ndarray) -> float:
    """The loss change of a parameter move of one Monte Carlo standard deviation, from the
    residuals ``r`` and ``r_alt`` of one point rendered with two independent seeds (same shape).

    Half the mean render variance, (r - r_alt)^2 / 2, of the elements either render sees (pixels
    of black sky carry no noise and no information); 0 if there are none.
    """
    r, r_alt = np.ravel(np.asarray(r, dtype=float)), np.ravel(np.asarray(r_alt, dtype=float))
    seen = (r != 0) | (r_alt != 0)
    return float(0.5 * np.mean(0.5 * (r[seen] - r_alt[seen]) ** 2)) if seen.any() else 0.0


@dataclass
class NoiseFloor:
    """The accepted / rejected bookkeeping of a solve and its noise-floor stop rule.

    Attributes:
        best: the lowest finite loss evaluated so far.
        noise: the loss's noise at the best point, :func:`loss_noise` (NaN until set by :meth:`set_noise`).
        decreases: the decrease of the best loss at each accepted step after the first.
        rejected: the losses of the rejected steps since the last accepted one.
    """

    best: float = math.inf
    noise: float = math.nan
    decreases: list[float] = field(default_factory=list)
    rejected: list[float] = field(default_factory=list)

    def record(self, loss: float, new_point: bool = True) -> bool:
        """Record a step's loss; True if the step is accepted (a finite loss below the best so far by
        more than the loss's rounding, :data:`ROUNDING`). ``new_point`` False: the step evaluated the
        best point again, a rejected step whatever its loss's rounding."""
        below = self.best - ROUNDING * abs(self.best) if math.isfinite(self.best) else self.best
        if not (new_point and math.isfinite(loss) and loss < below):
            self.rejected.append(loss)
            return False
        if math.isfinite(self.best):
            self.decreases.append(self.best - loss)
        self.best = loss
        self.rejected = []
        return True

    def set_noise(self, noise: float) -> None:
        """The loss's noise at the best point (:func:`loss_noise`)."""
        self.noise = float(noise)

    def predicted_decrease(self) -> float:
        """The decrease the next accepted step can be expected to bring (inf before two accepted steps)."""
        if not self.decreases:
            return math.inf
        last = self.decreases[-1]
        if len(self.decreases) == 1 or self.decreases[-2] <= 0.0:
            return last
        return last * min(1.0, last / self.decreases[-2])

    def reached(self, loss: float, accepted: bool) -> bool:
        """Whether the solve should stop after a step of ``loss`` (accepted or not)."""
        if not (self.decreases and math.isfinite(self.noise)):
            return False  # the solve has not moved yet
        threshold = NOISE_FACTOR * self.noise
        if accepted:
            return self.predicted_decrease() < threshold
        return math.isfinite(loss) and loss - self.best < threshold

    def retried(self, moved: float, apart: float, loss: float) -> bool:
        """Whether the solver's next trial point is the rejected one of ``loss`` again: ``apart`` from it, the rejected
        step ``moved`` from the best point (lengths in one coordinate system), within :data:`RETRY_RTOL` of that, and its
        loss expected within the loss's noise of ``loss`` (the rejected step's change of the loss times apart / moved):
        what :meth:`no_better_point` would stop at once that point were evaluated. Only after the solve has moved."""
        if not (self.decreases and math.isfinite(self.noise) and math.isfinite(loss) and moved > 0.0):
            return False
        ratio = apart / moved
        return ratio <= RETRY_RTOL and ratio * abs(loss - self.best) < self.noise

    def no_better_point(self) -> bool:
        """Whether the rejected steps since the last accepted one say that there is no better point
        nearby: after the solve has moved, the last two differ by less than the loss's noise; from the
        start on, the last :data:`REJECTED_PATIENCE` were each rejected by less than :data:`REJECTED_RTOL`
        of the best loss."""
        last = [loss for loss in self.rejected[-REJECTED_PATIENCE:] if math.isfinite(loss)]
        if self.decreases and len(last) >= 2 and math.isfinite(self.noise) and abs(last[-1] - last[-2]) < self.noise:
            return True
        return len(last) == REJECTED_PATIENCE and all(loss - self.best < REJECTED_RTOL * abs(self.best) for loss in last)
