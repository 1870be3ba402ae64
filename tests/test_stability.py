"""Failure classes of a fit against known truth, and the solver-stability study at its reduced size."""

from __future__ import annotations

import math
from collections import Counter

import numpy as np
import pytest
from scripts import read_csv, run_script

import spacefit as sf
from spacefit import FitResult, InputError, Renderer, Status
from spacefit.studies.failures import FAILURE_CLASSES, classify

TRUTH = {"parts.panels.alpha_x": 0.15, "parts.legs.kd": 0.5}


def result(values: dict[str, float], stderr: dict[str, float], success: bool = True, status: Status = Status.CONVERGED,
           loss: float = 1.0) -> FitResult:
    """A FitResult as fit() would return it, without rendering."""
    names = tuple(values)
    return FitResult(names=names, values=values, stderr=stderr, correlation=np.eye(len(names)), success=success,
                     status=status, warnings=[], history=[], renders=[], loss=loss, solver="lm", loss_name="pixel",
                     steps=5, wall_time_s=1.0)


SMALL_SE = {"parts.panels.alpha_x": 0.001, "parts.legs.kd": 0.001}
NEAR = {"parts.panels.alpha_x": 0.153, "parts.legs.kd": 0.49}  # within 5 %
FAR = {"parts.panels.alpha_x": 0.153, "parts.legs.kd": 0.40}  # kd 20 % off


@pytest.mark.parametrize(
    ("values", "stderr", "success", "status", "loss", "expected"),
    [
        (NEAR, SMALL_SE, True, Status.CONVERGED, 1.0, "success"),
        (NEAR, SMALL_SE, False, Status.MAX_STEPS, 1.0, "success"),  # close enough
        ({**NEAR, "parts.legs.kd": math.nan}, SMALL_SE, False, Status.MAX_STEPS, math.nan, "nan"),
        (NEAR, SMALL_SE, True, Status.CONVERGED, math.nan, "nan"),  # the loss alone
        (NEAR, SMALL_SE, False, Status.NONFINITE, 1.0, "nan"),  # the status alone
        (NEAR, {**SMALL_SE, "parts.legs.kd": math.inf}, True, Status.CONVERGED, 1.0, "unidentifiable"),  # lucky hit
        (FAR, {**SMALL_SE, "parts.legs.kd": math.nan}, True, Status.CONVERGED, 1.0, "unidentifiable"),
        (FAR, {**SMALL_SE, "parts.legs.kd": 0.06}, True, Status.CONVERGED, 1.0, "unidentifiable"),  # 0.1 <= 2 x 0.06
        (FAR, {**SMALL_SE, "parts.legs.kd": 0.06}, False, Status.MAX_STEPS, 1.0, "unidentifiable"),  # before stalled
        (FAR, SMALL_SE, False, Status.MAX_STEPS, 1.0, "stalled"),
        (FAR, SMALL_SE, False, Status.NO_PROGRESS, 1.0, "stalled"),
        (FAR, SMALL_SE, False, Status.MISFIT, 1.0, "wrong_minimum"),  # the solver converged; the verdict says misfit
        (FAR, SMALL_SE, False, Status.AT_BOUND, 1.0, "wrong_minimum"),
        (FAR, SMALL_SE, True, Status.CONVERGED, 1.0, "wrong_minimum"),
        (FAR, {**SMALL_SE, "parts.legs.kd": 0.04}, True, Status.CONVERGED, 1.0, "wrong_minimum"),  # 0.1 > 2 x 0.04
    ],
)
def test_classify_rules_in_order(values, stderr, success, status, loss, expected):
    assert classify(result(values, stderr, success, status, loss), TRUTH) == expected


def test_nan_comes_before_everything():
    nan_values = dict.fromkeys(TRUTH, math.nan)
    assert classify(result(nan_values, dict.fromkeys(TRUTH, math.nan), False, "failed", math.nan), TRUTH) == "nan"


def test_tolerance_is_relative_except_D():
    truth = {"wrinkles.D": 2.4, "wrinkles.G": 0.04}
    se = {"wrinkles.D": 1e-4, "wrinkles.G": 1e-5}
    assert classify(result({"wrinkles.D": 2.415, "wrinkles.G": 0.0415}, se), truth) == "success"  # D within 0.02
    off = result({"wrinkles.D": 2.43, "wrinkles.G": 0.0415}, se)
    assert classify(off, truth) == "wrong_minimum"
    assert classify(off, truth, tolerance=0.5) == "wrong_minimum"  # a float leaves D at 0.02 absolute
    assert classify(off, truth, tolerance={"wrinkles.D": 0.05}) == "success"  # G keeps 5 % relative
    assert classify(off, truth, tolerance={"wrinkles.D": 0.05, "wrinkles.G": 0.01}) == "wrong_minimum"


def test_classify_refuses_incomplete_truth():
    with pytest.raises(InputError, match="parts.legs.kd"):
        classify(result(NEAR, SMALL_SE), {"parts.panels.alpha_x": 0.15})
    with pytest.raises(InputError, match="non-zero"):
        classify(result(NEAR, SMALL_SE), {**TRUTH, "parts.legs.kd": 0.0})


def test_edge_on_view_shows_the_panels_as_a_line():
    """The study's edge-on attitude (experiments/stability.py EDGE_ON): the panels cover a fraction of
    the pixels they cover face-on."""
    edge_on_attitude = {"target.attitude_deg": [-81.6, 0, 0]}  # 3 sin a + 25 cos a = 0.68: the camera in the panel plane

    def panel_pixels(more: dict | None = None) -> int:
        # white panels at two albedos, lit from the camera, direct light only: the pixels that change
        images = [Renderer(sf.load_case("panels").scene().with_values({
            "render.resolution": [32, 32], "camera.pixel_pitch_mm": 75, "render.spp": 4, "render.depth": 1,
            "sun.direction": [-4, -3, -25], "parts.panels": {"material": "white_paint", "kd": kd}, **(more or {}),
        })).render(seed=1) for kd in (1.0, 0.5)]
        return int(np.sum(np.abs(images[0] - images[1]).max(axis=-1) > 0))

    face_on, edge_on = panel_pixels(), panel_pixels(edge_on_attitude)
    assert 0 < edge_on < 0.4 * face_on, (edge_on, face_on)


@pytest.mark.slow  # the study at reduced size, 44 s: the slow set
def test_stability_study_shape(tmp_path):
    """The reduced study, run as a script: every condition's values with both solvers, each run
    classified, files written, the easy start recovered."""
    run_script("stability", "--out", str(tmp_path), "--jobs", "2")
    rows = read_csv(tmp_path / "stability.csv")
    assert {"condition", "value", "solver", "class", "errors", "steps", "time_s"} <= set(rows[0])
    # the reduced conditions (stability.CONDITIONS' second column, no D), each value with lm and adam
    assert {r["condition"] for r in rows} == {"start_offset", "alpha", "sun_elevation_deg", "noise", "view"}
    runs = [(r["condition"], r["value"], r["solver"]) for r in rows]
    assert len(set(runs)) == len(runs) == 2 * len({(c, v) for c, v, _ in runs})
    assert {s for _, _, s in runs} == {"lm", "adam"}
    assert all(r["class"] in FAILURE_CLASSES for r in rows), [r for r in rows if r["class"] not in FAILURE_CLASSES]
    counts = Counter(r["class"] for r in rows)
    assert sum(counts.values()) == len(rows)
    easy = min((v for c, v, _ in runs if c == "start_offset"), key=lambda v: abs(float(v)))  # the start nearest the truth
    by_run = {run: r for run, r in zip(runs, rows)}
    assert by_run[("start_offset", easy, "lm")]["class"] == "success", by_run[("start_offset", easy, "lm")]
    assert (tmp_path / "stability.png").stat().st_size > 0
