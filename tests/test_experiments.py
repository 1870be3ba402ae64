"""The thesis's sweeps (section 4.4) and other studies at a reduced size, run as scripts: sheets
written, radiance linear in the sun; and the sample-allocation bound in closed form."""

from __future__ import annotations

import numpy as np
import pytest
from scripts import read_csv, run_script

import spacefit as sf
from spacefit.studies.costs import allocation_gains


def test_light_level_sweep_is_linear_in_irradiance(tmp_path):
    run_script("thesis_sweeps", "--out", str(tmp_path), "--size", "48", "--spp", "2", "--only", "light_level",
               "--set", "wrinkles.spacing_m=0.2")
    assert (tmp_path / "light_level.png").stat().st_size > 0
    mean = {row["value"]: float(row["mean_radiance"]) for row in read_csv(tmp_path / "sweeps.csv")}
    assert list(mean) == ["0.1", "0.5", "1", "5", "10"]
    # same seed, same paths: radiance scales exactly with the sun's irradiance
    for label, value in mean.items():
        assert value == pytest.approx(mean["1"] * float(label), rel=1e-5)


@pytest.mark.slow  # the study at reduced size, 36 s: the slow set
def test_identifiability_study_shape(tmp_path):
    run_script("identifiability", "--out", str(tmp_path))  # the reduced study: 25 and 70 m at 64 and 128 px, 8 spp
    assert (tmp_path / "identifiability.png").stat().st_size > 0
    rows = [{k: float(v) for k, v in row.items()} for row in read_csv(tmp_path / "identifiability.csv")]
    assert [(r["range_m"], r["width_px"]) for r in rows] == [(25.0, 64), (25.0, 128), (70.0, 64), (70.0, 128)]
    by = {(r["range_m"], r["width_px"]): r for r in rows}
    for width in (64, 128):  # information falls with range at a fixed image size
        assert by[(70.0, width)]["fisher_min"] <= by[(25.0, width)]["fisher_min"]
    assert by[(25.0, 128)]["fisher_min"] >= by[(25.0, 64)]["fisher_min"]  # and rises with resolution
    assert all(r["se_D"] > 0 for r in rows)


def test_wrinkle_previews_put_the_default_in_the_mli_range_and_the_literal_reading_beyond(tmp_path):
    run_script("wrinkle_previews", "--out", str(tmp_path), "--size", "48", "--spp", "1")
    rows = {row["reading"]: {k: float(v) for k, v in row.items() if k != "reading"} for row in read_csv(tmp_path / "wrinkles.csv")}
    assert {p.name for p in tmp_path.iterdir()} == {"default.png", "thesis_literal.png", "wrinkles.csv"}
    lo, hi = sf.MLI_SLOPE_RANGE
    assert lo <= rows["default"]["rms_slope"] <= hi and rows["default"]["fold_fraction"] < 0.01
    assert rows["thesis_literal"]["rms_slope"] > hi and rows["thesis_literal"]["fold_fraction"] > 0.01


def test_sample_allocation_bound_matches_its_closed_form():
    """Two pixels of sigma 1 and 3: samples in proportion to sigma need (mean sigma)^2 / mean sigma^2
    = 4 / 5 of uniform sampling's; a first pass that knows sigma exactly and spends a quarter
    uniformly gets n = 0.25 + 0.75 * 2 sigma / 4 = (0.625, 1.375) and needs (1 / 0.625 + 9 / 1.375) / 10."""
    gains = allocation_gains(np.array([1.0, 3.0]), np.array([1.0, 3.0]))
    assert gains["ideal"] == pytest.approx(0.8)
    assert gains["two_pass"] == pytest.approx((1 / 0.625 + 9 / 1.375) / 10)
    # equal sigmas: nothing to gain; a noisy first pass only loses
    flat = allocation_gains(np.ones(4), np.array([0.5, 1.0, 1.5, 1.0]))
    assert flat["ideal"] == pytest.approx(1.0) and flat["two_pass"] > 1.0


def test_the_frozen_call_s_steps_are_still_the_renderer_s_and_the_fixed_cost_benchmark_gives_its_verdict():
    """``make bench``'s fixed-cost section at its smallest: profile_frozen_call.py re-runs a primal render and a
    forward-mode column step by step as the renderer runs them and asserts each image equals the renderer's, bit for
    bit (its copy of the steps had fallen behind the renderer's three frozen passes, and ``make bench`` stopped
    there); bench_fixed_cost.py reads the frozen calls' fixed cost from its zero-work line."""
    out = run_script("profile_frozen_call", "--calls", "2")
    assert "outside the kernels" in out and out.count("outside the kernels") == 2
    out = run_script("bench_fixed_cost", "--calls", "2", "--rounds", "1")
    verdicts = [line for line in out.splitlines() if line.startswith("per-call fixed cost")]
    assert [v.split(":")[0] for v in verdicts] == ["per-call fixed cost, primal", "per-call fixed cost, derivative"]
    assert all("the zero-work line at 0 spp" in v for v in verdicts)
