"""The record of a solve: each step a driver yields becomes a history entry.

:class:`SolveRecord` keeps the best point and its loss, the accepted / rejected bookkeeping, and the
stops that are not the solver's own: a run of non-finite evaluations and the noise floor
(:mod:`spacefit.fitting.stopping`). It also reads an interrupted or ended solve back
(``fit(resume=...)``).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Generator, Mapping, Sequence
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from spacefit.fitting.drivers import Outcome, Step
from spacefit.fitting.problem import Setup
from spacefit.fitting.status import Status
from spacefit.fitting.stopping import NoiseFloor, loss_noise
from spacefit.precision import on_device
from spacefit.progress import ProgressCallback

# A solve fails when this many consecutive evaluations are not finite; a line search or trust
# region may try (and reject) a single non-finite point.
NONFINITE_PATIENCE = 3


class SolveRecord:
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
                return Outcome(status, on_device(self.best_u, np.float64) if stopped_here else step.iterate, k)

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
        if self.floor.no_better_point():
            return Status.NO_BETTER_POINT
        # the solver about to evaluate the point it was just rejected at again (known before it is rendered)
        retry = not accepted and step.next_u is not None and self.best_u is not None
        if retry and self.floor.retried(float(np.linalg.norm(step.u - self.best_u)), float(np.linalg.norm(step.next_u - step.u)), step.loss):
            return Status.NO_BETTER_POINT
        return None

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
        x = self.s.solver_params.to_physical(jnp.asarray(outcome.u)) if self.moved else on_device(self.s.x0, np.float64)
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


def _nonfinite_run(history: list[dict[str, Any]]) -> bool:
    recent = history[-NONFINITE_PATIENCE:]
    return len(recent) == NONFINITE_PATIENCE and not any(np.isfinite(h["loss"]) for h in recent)
