"""Solver stability: how often each solver recovers the truth, and how the others fail.

One-dimensional sweeps around the panels case (experiments/cases.py; free: panel alpha_x, alpha_y
and leg kd), and around the wrinkles case for D (free: D, G). For each condition value a reference
is rendered at the truth, every solver fits it from the condition's start, and the outcome is
classified by :func:`spacefit.fitting.failures.classify` (default tolerance: 5 % relative, 0.02 in D):

- ``start_offset``: start = truth * (1 + f) for each parameter (kd held inside (0, 1), below).
- ``alpha``: true panel alpha_x = alpha_y = a, leg kd 0.5; start 50 % off as in the panels case
  (alpha_x and kd -50 %, alpha_y +50 %).
- ``sun_elevation_deg``: angle between the sunlight and the panel plane (the panels face +z), the
  light coming from +y; 90 is the panels case's sun.
- ``noise``: Gaussian image noise, a fraction of the mean lit radiance; the fit is told sigma.
- ``view``: ``edge_on``, the target turned (attitude [-81.6, 0, 0]) so that the camera lies in the
  panel plane, which then covers a line of pixels; ``shadow``, the sun from below the panel plane
  (direction [0, 0, 1]) with the camera above.
- ``D`` (``--full`` only): the wrinkles case with true D 2.05 and 2.95, G 0.04 m; start D 2.5,
  G 0.06 m, at the case's own 64 x 64 px and 64 spp.

A start beyond a finite bound of a parameter's range is moved to 90 % of the way from the truth to
that bound (kd 0.5 started at +100 % starts at 0.95). Fits render at 128 spp against 256-spp
references: at 8 and 16 spp the fit's own Monte Carlo noise biases the L2 estimate (by -22 % in kd
at 32 x 32 px and 8 spp, -8 % in alpha_x at 64 x 64 px and 16 spp, beyond the 5 % tolerance), so no
solver could succeed; at these image sizes the samples cost little next to the solver's overheads.

Writes ``stability.csv`` (condition, value, solver, class, errors: signed relative errors, absolute
in D; steps, time_s, status) and ``stability.png`` (per condition, the class of each solver x value).

Run: ``.venv/bin/python experiments/stability.py [--full] [--jobs N] [--out DIR]``. Default (reduced):
32 x 32 px at 32 spp, solvers lm and adam, the hardest value of each condition (and two start offsets), 6 steps,
no D conditions (about half a minute on 2 cores); ``--full``: 64 x 64 px, all five solvers and values, 30 steps, and the D conditions.
``--jobs N`` runs the trials in N processes.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import multiprocessing
import time
from collections import Counter
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from pathlib import Path

import matplotlib
import numpy as np
from studyio import save_figure, write_csv

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.colors import ListedColormap  # noqa: E402
from matplotlib.patches import Patch  # noqa: E402

from spacefit.studies.failures import FAILURE_CLASSES, classify, errors  # noqa: E402

import spacefit as sf  # noqa: E402
from spacefit import SOLVERS, InputError, Observation, fit  # noqa: E402
from spacefit.progress import Progress  # noqa: E402

INVALID = "invalid input"
# Target attitude, deg, that puts the camera of the panels case ([4, 3, 25] m) in the panel plane
# (object z = 0.68 m, turned about x): 3 sin a + 25 cos a = 0.68.
EDGE_ON = {"target.attitude_deg": [-81.6, 0, 0]}
# Sun travelling up: the panels' upper faces, the ones the camera sees, are in shadow.
SHADOW = {"sun.direction": [0, 0, 1]}
# Condition: (values of the full study, values of the reduced one).
CONDITIONS: dict[str, tuple[tuple[float | str, ...], tuple[float | str, ...]]] = {
    "start_offset": ((-0.8, -0.5, 0.5, 1.0, 3.0), (-0.5, 3.0)),
    "alpha": ((0.005, 0.02, 0.1, 0.3, 0.8), (0.005,)),
    "sun_elevation_deg": ((90.0, 60.0, 30.0, 10.0, 3.0), (3.0,)),
    "noise": ((0.0, 0.01, 0.02, 0.05, 0.1), (0.1,)),
    "view": (("edge_on", "shadow"), ("shadow",)),
    "D": ((2.05, 2.95), ()),
}
PANELS, WRINKLES = sf.load_case("panels"), sf.load_case("wrinkles")
# The panels case's start as a relative offset from its truth (alpha_x -50 %, alpha_y +50 %, kd -50 %).
PANELS_OFFSET = {k: PANELS.start[k] / v - 1.0 for k, v in PANELS.truth.items()}


@dataclass(frozen=True)
class Size:
    """How large a study: image width and height (px), fit and reference samples per pixel,
    solver steps and solvers (the D conditions keep the wrinkles case's own image size and spp)."""

    width: int
    spp: int
    reference_spp: int
    max_steps: int
    solvers: tuple[str, ...]


REDUCED = Size(32, 32, 128, 6, ("lm", "adam"))
FULL = Size(64, 128, 256, 30, SOLVERS)


def offset_start(truth: dict[str, float], offset: dict[str, float]) -> dict[str, float]:
    """Start values truth * (1 + offset), each moved inside its parameter's open range: a start
    beyond a finite bound goes to 90 % of the way from the truth to that bound."""
    start = {}
    for name, value in truth.items():
        b = sf.PARAMETERS[name].bounds if name in sf.PARAMETERS else sf.PARAMETERS[f"parts.P.{name.rsplit('.', 1)[-1]}"].bounds
        x = value * (1.0 + offset[name])
        if x >= b.hi:
            x = value + 0.9 * (b.hi - value)
        elif x <= b.lo:
            x = value - 0.9 * (value - b.lo)
        start[name] = x
    return start


def trial(condition: str, value: float | str, size: Size) -> tuple[sf.Case, float]:
    """The case (truth scene, start) and the reference noise (a fraction of the lit mean) of one condition value."""
    if condition == "D":
        G = WRINKLES.truth["wrinkles.G"]
        start = {"wrinkles.D": 2.5, "wrinkles.G": 1.5 * G}
        return dataclasses.replace(WRINKLES.with_values({"wrinkles.D": float(value)}), start=start), 0.0
    w = size.width
    base = PANELS.with_values({"render.resolution": [w, w], "camera.pixel_pitch_mm": 18.75 * 128 / w,
                               "render.spp": size.reference_spp}, name=f"{condition}={value}")
    base = dataclasses.replace(base, fit_values={"render.spp": size.spp})
    if condition == "start_offset":
        return dataclasses.replace(base, start=offset_start(PANELS.truth, dict.fromkeys(PANELS.truth, value))), 0.0
    if condition == "alpha":
        truth = {"parts.panels.alpha_x": value, "parts.panels.alpha_y": value, "parts.legs.kd": 0.5}
        return dataclasses.replace(base.with_values(truth), start=offset_start(truth, PANELS_OFFSET)), 0.0
    if condition == "sun_elevation_deg":
        e = math.radians(float(value))
        return base.with_values({"sun.direction": [0, -math.cos(e), -math.sin(e)]}), 0.0
    if condition == "noise":
        return base, float(value)
    if condition == "view":
        return base.with_values({"edge_on": EDGE_ON, "shadow": SHADOW}[str(value)]), 0.0
    raise ValueError(f"unknown condition {condition!r}; valid: {', '.join(CONDITIONS)}.")


def _row(condition: str, value: float | str, solver: str, cls: str, errs: str = "", steps: int = 0,
         time_s: float = 0.0, status: str = "") -> dict[str, object]:
    return {"condition": condition, "value": value, "solver": solver, "class": cls, "errors": errs, "steps": steps,
            "time_s": round(time_s, 2), "status": status}


def run_trial(condition: str, value: float | str, solver: str, size: Size) -> dict[str, object]:
    """Render the reference of one condition value (seeded: the same for every solver) and fit it."""
    try:
        case, noise = trial(condition, value, size)
        image, sigma = case.reference(100.0 * noise)
        observation = Observation(case.scene(), image, sigma)
        t0 = time.perf_counter()
        result = fit(observation, list(case.free), solver=solver, start=case.start, max_steps=size.max_steps)
    except InputError as e:
        return _row(condition, value, solver, INVALID, status=str(e))
    errs = "; ".join(f"{k}={v:+.4f}" for k, v in errors(result.values, case.truth).items())
    return _row(condition, value, solver, classify(result, case.truth), errs, result.steps,
                time.perf_counter() - t0, result.status)


def plot(rows: list[dict[str, object]], path: Path, title: str) -> None:
    """One panel per condition: the class of each (solver, value) run as a coloured cell."""
    classes = [*FAILURE_CLASSES, INVALID]
    colours = ListedColormap(["#2ca02c", "#d62728", "#ff7f0e", "#9467bd", "#7f7f7f", "#000000"])
    conditions = list(dict.fromkeys(r["condition"] for r in rows))
    cols = min(3, len(conditions))
    nrows = math.ceil(len(conditions) / cols)
    fig, axes = plt.subplots(nrows, cols, figsize=(4.2 * cols, 2.6 * nrows + 0.8), squeeze=False)
    for ax, condition in zip(axes.flat, conditions):
        sub = [r for r in rows if r["condition"] == condition]
        values = list(dict.fromkeys(r["value"] for r in sub))
        solvers = list(dict.fromkeys(r["solver"] for r in sub))
        grid = np.zeros((len(solvers), len(values)))
        for r in sub:
            grid[solvers.index(r["solver"]), values.index(r["value"])] = classes.index(r["class"])
        ax.imshow(grid, cmap=colours, vmin=-0.5, vmax=len(classes) - 0.5, aspect="auto")
        ax.set_xticks(range(len(values)), [str(v) for v in values])
        ax.set_yticks(range(len(solvers)), solvers)
        ax.set_xlabel(condition)
    for ax in axes.flat[len(conditions):]:
        ax.axis("off")
    fig.legend(handles=[Patch(color=colours(i), label=c) for i, c in enumerate(classes)], loc="lower center",
               ncol=len(classes), frameon=False)
    fig.suptitle(title)
    save_figure(fig, path, rect=(0, 0.07, 1, 1))


def run_stability(out: Path, full: bool, jobs: int = 1) -> list[dict[str, object]]:
    """Fit every condition value with every solver, classify each run; write stability.csv / .png.

    Reduced (``full`` False): :data:`REDUCED`, the second column of :data:`CONDITIONS` (no D);
    full: :data:`FULL`, every value. ``jobs`` > 1 runs the trials in that many processes (each
    renders on one thread when render.deterministic). Rows, in plan order: condition, value,
    solver, class, errors, steps, time_s (fit wall time, s), status (the solver's, or the input
    error of an invalid run).
    """
    if jobs < 1:
        raise InputError(f"`jobs` must be >= 1; got {jobs}.")
    size = FULL if full else REDUCED
    out.mkdir(parents=True, exist_ok=True)
    plan = [(c, v, s) for c, (all_values, reduced) in CONDITIONS.items() for v in (all_values if full else reduced)
            for s in size.solvers]
    progress = Progress("stability", delay=0.0)
    if jobs == 1:
        rows = []
        for i, (condition, value, solver) in enumerate(plan):
            rows.append(run_trial(condition, value, solver, size))
            progress(i + 1, len(plan))
    else:
        with ProcessPoolExecutor(jobs, mp_context=multiprocessing.get_context("spawn")) as pool:
            futures = [pool.submit(run_trial, *item, size) for item in plan]
            for i, _ in enumerate(as_completed(futures)):
                progress(i + 1, len(plan))
            rows = [f.result() for f in futures]
    write_csv(out / "stability.csv", rows)
    plot(rows, out / "stability.png", f"solver stability, {size.width} x {size.width} px, {size.spp} spp, "
         f"{size.max_steps} steps")
    return rows


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", default="experiments/results/stability")
    p.add_argument("--full", action="store_true", help="64 x 64 px, all solvers and values, 30 steps, D conditions")
    p.add_argument("--jobs", type=int, default=1, help="trials run in this many processes (default 1)")
    args = p.parse_args()
    t0 = time.perf_counter()
    rows = run_stability(Path(args.out), args.full, args.jobs)
    for solver in dict.fromkeys(r["solver"] for r in rows):
        counts = Counter(r["class"] for r in rows if r["solver"] == solver)
        print(f"{solver:7s}", ", ".join(f"{c} {counts[c]}" for c in [*FAILURE_CLASSES, INVALID] if counts[c]))
    print(f"{len(rows)} runs in {time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()
