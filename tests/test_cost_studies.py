"""The forward-cost and fit-cost studies at their reduced sizes, run as scripts: the shape of their
results; and the Pareto front in closed form."""

from __future__ import annotations

import numpy as np
from scripts import read_csv, run_script

from spacefit.studies.costs import pareto_front


def test_pareto_front_of_a_hand_made_set():
    points = [(1.0, 0.5), (2.0, 0.6), (2.0, 0.3), (3.0, 0.3), (4.0, 0.1), (0.5, 0.9)]
    assert pareto_front(points) == [5, 0, 2, 4]


def test_forward_study_shape(tmp_path):
    out = run_script("forward_pareto", "--out", str(tmp_path))
    rows = [{k: float(v) for k, v in row.items()} for row in read_csv(tmp_path / "forward.csv")]
    # the reduced study (forward_pareto.REDUCED): 64 and 128 px, spp 1 to 16, depths 1 to 3
    spps, depths = (1, 2, 4, 8, 16), (1, 2, 3)
    assert sorted((r["resolution"], r["spp"], r["depth"]) for r in rows) == [(w, s, d) for w in (64, 128) for s in spps for d in depths]
    assert (tmp_path / "forward_pareto.png").stat().st_size > 0
    deepest = [r for r in rows if r["depth"] == max(depths)]
    error = {s: np.mean([r["rel_rmse"] for r in deepest if r["spp"] == s]) for s in spps}
    assert error[max(spps)] < error[min(spps)]  # more samples, less error, on average over resolutions
    front = pareto_front([(r["time_s"], r["rel_rmse"]) for r in rows])
    assert front and all(rows[a]["time_s"] <= rows[b]["time_s"] and rows[a]["rel_rmse"] > rows[b]["rel_rmse"]
                         for a, b in zip(front, front[1:]))
    assert f"{len(rows)} configurations" in out and len(out.splitlines()) == len(front) + 1  # the front, printed


def test_fit_cost_study_shape(tmp_path):
    run_script("fit_cost", "--out", str(tmp_path))
    rows = read_csv(tmp_path / "fit_cost.csv")
    # the reduced study (fit_cost.REDUCED): the panels case at 32 and 64 px, 8 spp, with lm and adam
    assert {(int(r["width_px"]), int(r["spp"]), r["solver"]) for r in rows} == {(w, 8, s) for w in (32, 64) for s in ("lm", "adam")}
    assert all(np.isfinite(float(r["time_s"])) and float(r["time_s"]) > 0 and float(r["max_rel_error"]) >= 0 for r in rows)
    assert (tmp_path / "fit_cost.png").stat().st_size > 0
