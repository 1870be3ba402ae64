"""Fit cost against parameter error: every solver at several render budgets (resolution, spp).

On the materials case (panels' alpha_x, alpha_y, legs' kd) and the wrinkles case (D, G) of
experiments/cases.py: the reference is rendered at the budget's resolution (the case's field of
view kept) and fitted from the case's start. Errors: ``max_rel_error`` over the parameters other
than D (relative), ``D_abs_error`` for D. Writes ``fit_cost.csv`` and ``fit_cost.png`` to ``--out``.

Run: ``.venv/bin/python experiments/fit_cost.py [--full]``. Reduced (default): the panels case at
32 and 64 px, 8 spp, solvers lm and adam, 8 steps; ``--full``: both cases, three budgets for the
materials and two for the wrinkles, all five solvers, 40 steps.
"""

from __future__ import annotations

import dataclasses

import argparse
from pathlib import Path

import matplotlib
import numpy as np
from studyio import save_figure, write_csv

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

import spacefit as sf  # noqa: E402
from spacefit import SOLVERS, Adam, Observation, fit  # noqa: E402
from spacefit.progress import Progress  # noqa: E402

# case -> [(width px, spp)]; the case's native width and pixel pitch set the field of view.
REDUCED = {"panels": [(32, 8), (64, 8)]}
FULL = {"panels": [(64, 16), (128, 16), (128, 64)], "wrinkles": [(64, 32), (64, 128)]}
CASES = {"panels": 128, "wrinkles": 64}  # the case name and its native width, px


def at_budget(name: str, width: int, spp: int) -> sf.Case:
    """The case rendered at ``width`` px (same field of view), its fits at ``spp`` samples per pixel."""
    case = sf.load_case(name)
    pitch = case.truth_scene.camera.pixel_pitch_mm * CASES[name] / width
    case = case.with_values({"render.resolution": [width, width], "camera.pixel_pitch_mm": pitch})
    return dataclasses.replace(case, fit_values={"render.spp": spp})


def run_fit_cost(out: Path, full: bool) -> list[dict[str, object]]:
    """Fit every (case, budget, solver); write fit_cost.csv and fit_cost.png; return the rows."""
    out.mkdir(parents=True, exist_ok=True)
    budgets = FULL if full else REDUCED
    solvers = list(SOLVERS) if full else ["lm", "adam"]
    max_steps = 40 if full else 8
    runs = [(name, b, s) for name, bs in budgets.items() for b in bs for s in solvers]
    rows: list[dict[str, object]] = []
    progress = Progress("fit cost", delay=0.0)
    for k, (name, (width, spp), solver) in enumerate(runs):
        case = at_budget(name, width, spp)
        reference, _ = case.reference()
        r = fit(Observation(case.scene(), reference), list(case.free), solver=Adam(0.1) if solver == "adam" else solver,
                start=case.start, max_steps=max_steps)
        rel = [abs(r.values[n] / v - 1.0) for n, v in case.truth.items() if n != "wrinkles.D"]
        rows.append({"case": name, "width_px": width, "spp": spp, "solver": solver, "steps": r.steps,
                     "time_s": round(r.wall_time_s, 3), "max_rel_error": round(max(rel), 5) if rel else "",
                     "D_abs_error": round(abs(r.values["wrinkles.D"] - case.truth["wrinkles.D"]), 5) if "wrinkles.D" in case.truth else "",
                     "success": r.success, "status": r.status})
        progress(k + 1, len(runs))
    write_csv(out / "fit_cost.csv", rows)
    plot(out / "fit_cost.png", rows)
    return rows


def plot(path: Path, rows: list[dict[str, object]]) -> None:
    """Error against wall time per case: marker per solver, colour per budget."""
    cases = list(dict.fromkeys(r["case"] for r in rows))
    fig, axes = plt.subplots(1, len(cases), figsize=(6 * len(cases), 4.2), squeeze=False)
    markers = dict(zip(SOLVERS, "osD^v"))
    for ax, name in zip(axes[0], cases):
        sel = [r for r in rows if r["case"] == name]
        budgets = list(dict.fromkeys((r["width_px"], r["spp"]) for r in sel))
        colours = dict(zip(budgets, plt.cm.plasma(np.linspace(0.1, 0.8, len(budgets)))))
        for r in sel:
            error = float(r["max_rel_error"]) if r["max_rel_error"] != "" else float(r["D_abs_error"])
            ax.scatter(r["time_s"], max(error, 1e-5), marker=markers[r["solver"]], color=colours[(r["width_px"], r["spp"])], s=40)
        for solver in dict.fromkeys(r["solver"] for r in sel):
            ax.scatter([], [], marker=markers[solver], color="grey", label=solver)
        for b in budgets:
            ax.scatter([], [], marker="s", color=colours[b], label=f"{b[0]} px, {b[1]} spp")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("fit wall time (s)")
        ax.set_ylabel("max relative error" if name != "wrinkles" else "max relative error (G), else |D error|")
        ax.set_title(f"{name} case")
        ax.legend(fontsize=7)
    save_figure(fig, path)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", default="experiments/results/fit_cost")
    p.add_argument("--full", action="store_true")
    args = p.parse_args()
    for row in run_fit_cost(Path(args.out), args.full):
        print(row)


if __name__ == "__main__":
    main()
