"""A solve concluded: its outcome (:mod:`spacefit.fitting.drivers`) and record
(:mod:`spacefit.fitting.solve_record`) -> a :class:`~spacefit.fitting.result.FitResult`.

The values with their standard errors (:mod:`spacefit.fitting.uncertainty`), the goodness of fit
(:mod:`spacefit.fitting.judging`), the verdict (:func:`~spacefit.fitting.status.verdict`) and the
warnings that explain it, the renders and residuals, and the fitted scene.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping, Sequence

import jax
import numpy as np

from spacefit.fitting.drivers import Outcome
from spacefit.fitting.goodness import STANDS_OUT, TRIM, Goodness, standing_out
from spacefit.fitting.judging import judged_goodness, part_goodness, part_rows, per_observation
from spacefit.fitting.noise_weight import weight_bias_notes
from spacefit.fitting.observations.base import Sequenced
from spacefit.fitting.pixel_grid import black_sky_notes, grid_notes, unsettled_notes
from spacefit.fitting.problem import Setup
from spacefit.fitting.render_seeds import seed_notes
from spacefit.fitting.result import FitResult
from spacefit.fitting.solve_record import SolveRecord
from spacefit.fitting.status import Status, verdict
from spacefit.fitting.stopping import REJECTED_PATIENCE, REJECTED_RTOL
from spacefit.fitting.uncertainty import estimate, stderr_corr
from spacefit.fitting.value_warnings import warnings_for
from spacefit.precision import on_device
from spacefit.rendering.memory import release_freed_memory
from spacefit.scene.names import Name
from spacefit.scene.parameters import scene_with_values
from spacefit.scene.schema import Scene


def conclude(s: Setup, outcome: Outcome, steps: SolveRecord, solver: str, loss: str) -> FitResult:
    """The :class:`FitResult` of a solve's outcome: values, errors, goodness of fit, verdict, images."""
    problem, status = s.problem, outcome.status
    # a solve that never lowered the loss returns its start, not a point its solver drifted to; an ended
    # solve reported again (``fit(resume=Resume(ended=...))``) its start, which is its end (not rounded through ``u``)
    x = np.asarray(s.solver_params.to_physical(outcome.u) if steps.moved and not steps.reported_again else s.x0, dtype=float)
    n = len(x)
    x_user = np.asarray(s.to_user(on_device(x, np.float64)), dtype=float)
    stderr, corr, loss_value, extras, residuals, quality = np.full(n, np.nan), np.eye(n), math.nan, {}, [], None
    renders: list[np.ndarray] = []
    own_quality: list[Goodness] = []
    per_part: list[dict[str, dict[str, float]]] = [{} for _ in problem.references]
    if status.interrupted:
        loss_value = steps.best_loss
        warnings = ["the fit was interrupted: the values are the best point evaluated so far, with no standard errors."]
    elif np.all(np.isfinite(x_user)):
        if len(problem.references) > 1:
            # a joint fit's compiled solver programs (its step holds the frames' models) dropped before the standard errors,
            # which reuse few of them (3 compiled again): 62 MiB of a 12-frame pass's heap at 64 x 64 px, its peak 70 MiB
            # lower. A single image's fit keeps them: its CPU is the concern, its memory is not. And the pages the solve's
            # threads freed handed back: held in their arenas, the phases after it began 0.2 to 0.5 GB higher
            jax.clear_caches()
            release_freed_memory()
        x_user, cov, loss_value, extras = estimate(s, x, correct=steps.moved)
        if len(problem.references) > 1:
            release_freed_memory()
        stderr, corr = stderr_corr(cov)
        named_stderr = dict(zip(s.user.names, stderr))
        unsettled = unsettled_notes(extras.get("pixel_grid_short", {}))
        unstepped = black_sky_notes(extras.get("pixel_grid_past_black_sky"))
        warnings = (warnings_for(s.user, x_user, stderr, corr) + grid_notes(extras.get("pixel_grid_error", {}), named_stderr) + unsettled + unstepped
                    + seed_notes(extras.get("render_seed_shift", {}), extras.get("render_seed_widened", {}), named_stderr)
                    + weight_bias_notes(extras.get("noise_weight_bias", {}), named_stderr))
        quality, r, noise, renders, signal = judged_goodness(s, on_device(x, np.float64), loss)
        residuals = [*(np.where(used[..., None], ref - render, np.nan) for ref, render, used in zip(problem.references, renders, problem.used)),
                     *(b.data.value - render for b, render in zip(problem.blocks, renders[len(problem.references):]))]
        if loss == "pixel":
            per_part = part_goodness(r, noise, problem, quality)
            own_quality = per_observation(r, noise, s, quality.samples_factor, signal)
        at_bound = any(b.at_bound(float(v)) for b, v in zip(s.user.bijections, x_user))
        pixels = loss == "pixel"
        status = verdict(status, steps.moved, at_bound, quality.misfit and pixels, quality.noise_known and not quality.judged and pixels,
                         bool(unsettled), bool(unstepped))
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
