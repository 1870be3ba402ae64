"""The forward-cost and fit-cost studies at their reduced sizes: the shape of their results."""

from __future__ import annotations

import csv

import numpy as np

import fit_cost  # noqa: E402
import forward_pareto  # noqa: E402


def test_pareto_front_of_a_hand_made_set():
    points = [(1.0, 0.5), (2.0, 0.6), (2.0, 0.3), (3.0, 0.3), (4.0, 0.1), (0.5, 0.9)]
    assert forward_pareto.pareto_front(points) == [5, 0, 2, 4]


def test_forward_study_shape(tmp_path):
    rows = forward_pareto.run_forward(tmp_path, full=False)
    widths, spps, depths, _ = forward_pareto.REDUCED
    assert len(rows) == len(widths) * len(spps) * len(depths)
    assert (tmp_path / "forward_pareto.png").stat().st_size > 0
    assert len(list(csv.DictReader(open(tmp_path / "forward.csv")))) == len(rows)
    deepest = [r for r in rows if r["depth"] == max(depths)]
    error = {s: np.mean([r["rel_rmse"] for r in deepest if r["spp"] == s]) for s in spps}
    assert error[max(spps)] < error[min(spps)]  # more samples, less error, on average over resolutions
    front = forward_pareto.pareto_front([(r["time_s"], r["rel_rmse"]) for r in rows])
    assert front and all(rows[a]["time_s"] <= rows[b]["time_s"] and rows[a]["rel_rmse"] > rows[b]["rel_rmse"]
                         for a, b in zip(front, front[1:]))


def test_fit_cost_study_shape(tmp_path):
    rows = fit_cost.run_fit_cost(tmp_path, full=False)
    expected = {(w, s, solver) for w, s in fit_cost.REDUCED["panels"] for solver in ("lm", "adam")}
    assert {(r["width_px"], r["spp"], r["solver"]) for r in rows} == expected
    assert all(np.isfinite(r["time_s"]) and r["time_s"] > 0 and r["max_rel_error"] >= 0 for r in rows)
    assert (tmp_path / "fit_cost.png").stat().st_size > 0
