"""Calibration of the noise-aware standard errors, and the error of the recovered materials
against the PSF width and the noise level.

The panels case (alpha_x 0.15, alpha_y 0.03, kd 0.5) at ``--size`` px, same field of view, seen by
a known :class:`spacefit.Sensor` (10 mm aperture with diffraction, a Gaussian PSF of
``psf_sigma_px``, shot and read noise, 14 bits); the exposure is set so that the brightest glint
collects ``peak_electrons``. The truth is rendered once at ``--truth-spp``; each realisation is one
simulated exposure (:func:`spacefit.observe`, its own noise seed), fitted from 20 % off the truth
with the sensor known (DN residuals weighted by the predicted Poisson-Gaussian noise) and its own
render seed, so that the render noise of the fit is part of what the errors must cover.

* coverage: over ``--realisations`` exposures, the fraction whose 1-sigma interval holds the truth,
  per parameter (68 % if the errors are calibrated);
* with ``--free nuisances``, the coverage with the nuisances free beside the materials: the target's
  attitude (x and z), the image shift and the PSF width (:data:`BLUR`), whose truths (:data:`NUISANCE_TRUTH`:
  0.3 and -0.2 deg, 0.4 and -0.25 px, 0.8 px) the simulated exposures carry: the truth is rendered at
  the turned pose and blurred and shifted by the fit's own image model (the sensor then has no PSF of
  its own, only diffraction); fits start from the scene's pose, no shift and the PSF's default start.
  ``coverage_table.md`` says per parameter whether its errors are calibrated, and if not, whether the
  estimates are biased (mean z) or the errors too small (rms z); no error chart;
* ``--supersample S`` (with the nuisances free): observations made as issue 34's hidden ones were, not
  by the fit's own image model: the truth rendered with the box filter at S times the resolution per
  axis (the same samples per sensor pixel, ``--truth-spp / S^2`` per fine pixel), blurred by the
  continuous Gaussian (0.8 px) and shifted at the fine scale, where the pixel grid aliases nothing
  (the Gaussian's transfer at the fine Nyquist frequency S / 2 cycles per px is below 1e-12 for
  S >= 4), binned S x S to the sensor's pixels (the detector integrates over its pixel), then exposed
  through the sensor. The fits render with the box filter (a detector's pixel response: the default
  tent filter adds 1/12 px^2 of blur, the PSF width then comes out sqrt(0.8^2 - 1/12) = 0.75 px)
  and their own seeds; the results go to ``nuisances_supersampled/``. Each row also holds the
  fit's pixel-grid step (``pixel_grid_error``, :mod:`spacefit.fitting.pixel_grid`), the bound on what
  remains of it that the standard error carries (``pixel_grid_remainder``) and the standard error
  without it (``statistical_stderr``, ``covered_statistical``);
* ``--linearised``: the nuisance study without fits, each exposure's estimate one Gauss-Newton step
  from the truth: the fit's own minimum of 0.5 |r|^2 (with the errors of a fit that stops there)
  against the two-seed estimate spacefit reports, to tell a bias of the estimate from a scale of
  its errors in seconds per exposure (``linearised.csv``, ``linearised_fit_minimum.md``,
  ``linearised_two-seed.md``);
* error chart: the rms error (relative) of each parameter over ``--chart-realisations`` exposures,
  for each PSF width and noise level, beside the mean reported standard error.

Writes ``coverage.csv`` (one row per fit, saved after each fit: a run into a folder that holds some
fits only those it lacks), ``coverage_summary.csv``, ``coverage_table.md`` (each coverage with its 95 %
binomial interval) and ``coverage.png`` to ``--out``; ``--pool DIR ...`` tables several runs' exposures
together (``coverage_pooled.md``). Run: ``.venv/bin/python experiments/coverage.py [--full] [--free nuisances]``:
by default 10 exposures for the coverage and 2 per chart point (about 5 minutes on 2 cores); ``--full``:
50 and 5 (about 20 minutes on a quiet machine), the results in ``experiments/results/coverage/``
(``experiments/results/coverage/nuisances/`` with the nuisances free; ``--realisations`` overrides the count). A fit takes 8 to 18 s at 48 px, 32 spp, mostly JAX's
compilation of the solver's step for the new problem, so the study has no CI test of its own; the
reduced, linearised study is ``tests/test_noise_model.py``.
"""

from __future__ import annotations

import argparse
import csv
import os
from collections.abc import Callable
from pathlib import Path

import jax
import jax.numpy as jnp
import matplotlib
import numpy as np
from studyio import save_figure, write_csv

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

import spacefit as sf  # noqa: E402
from spacefit.fitting.nuisance import image_model  # noqa: E402
from spacefit.fitting.problem import setup  # noqa: E402
from spacefit.fitting.uncertainty import covariance  # noqa: E402
from spacefit.precision import float64  # noqa: E402
from spacefit.scene.assembly import assemble  # noqa: E402
from spacefit.scene.parameters import scene_with_values  # noqa: E402
from spacefit.detector import electrons_per_radiance  # noqa: E402

CASE = "panels"
START_FACTOR = 1.2
ONE_SIGMA = 0.6827
NOISE_LEVELS = {"low": 20000.0, "high": 2000.0}  # peak electrons of the brightest glint
PSF_WIDTHS_PX = (0.0, 1.0, 2.0)
# The fit's PSF width (px): one name for the whole study.
BLUR = "image.blur_sigma_px"
# The nuisances' truths in the exposures of ``--free nuisances`` (deg, px); fits start from the
# scene's pose (0 deg), no shift and the PSF width's default start.
NUISANCE_TRUTH = {"target.attitude_x_deg": 0.3, "target.attitude_z_deg": -0.2, "image.shift_x_px": 0.4,
                  "image.shift_y_px": -0.25, BLUR: 0.8}
CALIBRATED = (ONE_SIGMA - 0.1, ONE_SIGMA + 0.1)


def case_at(size: int, spp: int, pixel_filter: str | None = None) -> sf.Case:
    """The panels case at ``size`` px with the same field of view, fits at ``spp``, with the case's
    pixel filter or ``pixel_filter``."""
    values = {"render.resolution": [size, size], "camera.pixel_pitch_mm": 18.75 * 128 / size, "render.spp": spp}
    return sf.load_case(CASE).with_values({**values, **({"render.filter": pixel_filter} if pixel_filter else {})})


def sensor_for(truth: np.ndarray, scene: sf.Scene, peak_electrons: float, psf_sigma_px: float) -> sf.Sensor:
    """A sensor whose exposure puts ``peak_electrons`` in the brightest pixel of ``truth`` (before the PSF)."""
    unit = sf.Sensor(exposure_time_s=1.0, psf_sigma_px=psf_sigma_px, full_well_electrons=None, bit_depth=16)
    per_second = float((np.asarray(truth) * electrons_per_radiance(unit, assemble(scene).intrinsics, 3)).max())
    return sf.Sensor(exposure_time_s=peak_electrons / per_second, psf_sigma_px=psf_sigma_px, full_well_electrons=None, bit_depth=16)


def truth_image(case: sf.Case, truth_spp: int, nuisances: bool, supersample: int = 1) -> np.ndarray:
    """The case's truth rendered at ``truth_spp``; with ``nuisances``, at the turned pose of
    :data:`NUISANCE_TRUTH` and then blurred and shifted by the fit's image model (its Fourier
    ringing, at most 0.05 % of the brightest pixel, clipped at 0: radiance is never negative).
    With ``supersample`` S > 1 (and ``nuisances``): rendered with the box filter at S times the
    resolution and ``truth_spp / S^2`` samples per fine pixel, blurred and shifted there (the widths
    and shifts times S), and binned S x S: the sensor's pixels integrate the blurred image."""
    pose = {n: v for n, v in NUISANCE_TRUTH.items() if n.startswith("target.")}
    image = [n for n in NUISANCE_TRUTH if n not in pose]
    if supersample > 1:
        if not nuisances:
            raise ValueError("--supersample makes the observations of the nuisance study (--free nuisances)")
        w, h = case.truth_scene.render.resolution
        pitch = case.truth_scene.camera.pixel_pitch_mm
        fine = case.truth_scene.with_values({"render.resolution": [supersample * w, supersample * h], "render.filter": "box",
                                             "camera.pixel_pitch_mm": pitch / supersample,
                                             "render.spp": max(1, truth_spp // supersample**2)})
        render = np.asarray(sf.render(scene_with_values(fine, pose)), dtype=float)
        blurred = image_model(image)(jnp.asarray(render), supersample * jnp.asarray([NUISANCE_TRUTH[n] for n in image]), 0)
        binned = np.asarray(blurred, dtype=float).reshape(h, supersample, w, supersample, -1).mean(axis=(1, 3))
        return np.maximum(binned, 0.0)
    scene = case.truth_scene.with_values({"render.spp": truth_spp})
    if not nuisances:
        return np.asarray(sf.render(scene), dtype=float)
    render = np.asarray(sf.render(scene_with_values(scene, pose)), dtype=float)
    model = image_model(image)
    return np.maximum(np.asarray(model(jnp.asarray(render), jnp.asarray([NUISANCE_TRUTH[n] for n in image]), 0), dtype=float), 0.0)


def realisations(case: sf.Case, truth: np.ndarray, sensor: sf.Sensor, count: int, first_seed: int,
                 nuisances: bool = False, done: list[dict[str, object]] = (),
                 saved: Callable[[list[dict[str, object]]], None] = lambda rows: None) -> list[dict[str, object]]:
    """Fit ``count`` simulated exposures of ``truth`` (with the nuisances of :data:`NUISANCE_TRUTH`
    free if ``nuisances``); one row per fit and parameter. Seeds with rows in ``done`` (a run's saved
    rows) are not fitted again, their rows kept; ``saved`` is called with the rows after each fit."""
    scene = case.scene()
    intrinsics = assemble(scene).intrinsics
    start = {n: START_FACTOR * v for n, v in case.truth.items()}
    truths = {**case.truth, **(NUISANCE_TRUTH if nuisances else {})}
    seeds = range(first_seed, first_seed + count)
    rows = [r for r in done if int(r["seed"]) in seeds]
    for seed in seeds:
        if any(int(r["seed"]) == seed for r in rows):
            continue
        dn = sf.observe(truth, sensor, intrinsics, seed).astype(float)
        result = sf.fit(sf.Observation(scene, dn, sensor=sensor), list(truths), start=start,
                        render=sf.FitRender(seed=2 * seed + 101, seed_grad=2 * seed + 102))
        grid = result.extras.get("pixel_grid_error", {})
        remainder = result.extras.get("pixel_grid_remainder", {})
        for name, true in truths.items():
            value, stderr = result.values[name], result.stderr[name]
            statistical = float(np.sqrt(max(stderr**2 - remainder.get(name, 0.0) ** 2, 0.0)))  # without the pixel grid's carried remainder
            rows.append({"seed": seed, "psf_sigma_px": sensor.psf_sigma_px, "exposure_time_s": sensor.exposure_time_s,
                         "parameter": name, "truth": true, "value": value, "stderr": stderr, "z": (value - true) / stderr,
                         "covered": bool(abs(value - true) <= stderr), "pixel_grid_error": grid.get(name, 0.0),
                         "pixel_grid_remainder": remainder.get(name, 0.0),
                         "statistical_stderr": statistical, "covered_statistical": bool(abs(value - true) <= statistical),
                         "steps": result.steps, "status": result.status.name})
        print(f"seed {seed}, sigma {sensor.psf_sigma_px:g} px: {result.status.name}, {result.wall_time_s:.1f} s, "
              f"load {os.getloadavg()[0]:.1f}", flush=True)
        saved(rows)
    return rows


def read_rows(path: Path) -> list[dict[str, object]]:
    """The rows of a ``coverage.csv`` as :func:`realisations` made them (numbers as floats, flags as bools)."""
    def value(text: str) -> object:
        if text in ("True", "False"):
            return text == "True"
        try:
            return float(text)
        except ValueError:
            return text
    with open(path, newline="") as f:
        return [{k: value(v) for k, v in row.items()} for row in csv.DictReader(f)]


def wilson(covered: int, n: int, z: float = 1.96) -> tuple[float, float]:
    """The Wilson score interval (95 % for ``z`` 1.96) of a binomial proportion, ``covered`` of ``n``
    (Wilson 1927, J. Am. Stat. Assoc. 22(158)): where the true coverage lies given the exposures drawn."""
    p, z2 = covered / n, z * z / n
    centre, half = (p + z2 / 2) / (1 + z2), z * np.sqrt(p * (1 - p) / n + z2 / (4 * n)) / (1 + z2)
    return float(centre - half), float(centre + half)


def summarise(rows: list[dict[str, object]], key: tuple[str, ...]) -> list[dict[str, object]]:
    """Per ``key`` group and parameter: coverage, rms relative error, mean relative standard error,
    and the mean and rms of the z-scores (error / standard error)."""
    groups: dict[tuple, list[dict[str, object]]] = {}
    for row in rows:
        groups.setdefault(tuple(row[k] for k in key) + (row["parameter"],), []).append(row)
    out = []
    for group, items in groups.items():
        truth = float(items[0]["truth"])
        errors = np.array([float(r["value"]) - truth for r in items])
        z = np.array([float(r["z"]) for r in items])
        covered = int(sum(bool(r["covered"]) for r in items))
        low, high = wilson(covered, len(items))
        out.append({**dict(zip((*key, "parameter"), group)), "n": len(items),
                    "coverage": covered / len(items), "coverage_low": low, "coverage_high": high,
                    "rms_error_rel": float(np.sqrt(np.mean(errors**2)) / abs(truth)),
                    "mean_stderr_rel": float(np.mean([float(r["stderr"]) for r in items]) / abs(truth)),
                    "mean_z": float(np.mean(z)), "rms_z": float(np.sqrt(np.mean(z**2)))})
    return out


def verdict(row: dict[str, object]) -> str:
    """Whether a parameter's 1-sigma intervals are calibrated (coverage 68 +- 10 %), and if not, why:
    errors too large (coverage above), a bias (the mean z-score carries more than half of the mean
    square) or errors too small."""
    if CALIBRATED[0] <= float(row["coverage"]) <= CALIBRATED[1]:
        return "calibrated"
    mean_z, rms_z = float(row["mean_z"]), float(row["rms_z"])
    if float(row["coverage"]) > CALIBRATED[1]:
        return f"not calibrated: errors too large, rms z {rms_z:.2f}"
    if mean_z**2 > 0.5 * rms_z**2:
        return f"not calibrated: biased, mean z {mean_z:+.2f}"
    return f"not calibrated: errors too small, rms z {rms_z:.2f}"


@float64
def linearised(case: sf.Case, truth: np.ndarray, sensor: sf.Sensor, count: int, first_seed: int) -> list[dict[str, object]]:
    """The nuisance study linearised at the truth, fit by fit as :func:`realisations` seeds them:
    per exposure the fit's minimum of 0.5 |r|^2 (one Gauss-Newton step from the truth with the
    fit's Jacobian) with the errors of a fit that stops there (the render and Jacobian noise at
    full weight), and the estimate spacefit reports (the root of the two-seed equation,
    :func:`~spacefit.fitting.uncertainty.covariance`) with its errors. No solver, so no compilation:
    seconds per exposure. One row per exposure, estimator and parameter (``study`` = estimator)."""
    scene = case.scene()
    intrinsics = assemble(scene).intrinsics
    truths = {**case.truth, **NUISANCE_TRUTH}
    rows = []
    for k in range(count):
        seed = first_seed + k
        dn = sf.observe(truth, sensor, intrinsics, seed).astype(float)
        s = setup(sf.Observation(scene, dn, sensor=sensor), list(truths), start=truths,
                  render=sf.FitRender(seed=2 * seed + 101, seed_grad=2 * seed + 102))
        x = jnp.asarray(s.x0)
        r = np.asarray(s.problem.residual_x(x))
        J1, J2 = (np.asarray(jax.jacfwd(f)(x)) for f in (s.problem.residual_x, s.problem.residual_x_independent))
        cov, _, _, step = covariance(s.problem, s.x0)
        bread = np.linalg.inv(0.5 * (J1.T @ J2 + J2.T @ J1))
        # cov = bread + B N B / 2 (the two-seed estimate); a fit that stops at its minimum has bread + B N B
        estimators = {"fit minimum": (-np.linalg.lstsq(J1, r, rcond=None)[0], 2.0 * cov - bread), "two-seed": (step, cov)}
        for study, (error, c) in estimators.items():
            for j, (name, true) in enumerate(truths.items()):
                stderr = float(np.sqrt(c[j, j]))
                rows.append({"study": study, "noise": "high", "seed": seed, "psf_sigma_px": sensor.psf_sigma_px,
                             "parameter": name, "truth": true, "value": true + float(error[j]), "stderr": stderr,
                             "z": float(error[j]) / stderr, "covered": bool(abs(error[j]) <= stderr)})
        print(f"seed {seed}: linearised", flush=True)
    return rows


def run_coverage(out: Path, *, size: int, spp: int, truth_spp: int, realisations_count: int,
                 chart_realisations: int, nuisances: bool = False,
                 supersample: int = 1, first_seed: int = 1) -> tuple[list[dict[str, object]], list[dict[str, object]]]:
    """The coverage study (high noise: 2000 electrons in the brightest glint; the sensor's PSF 1 px,
    or with ``nuisances`` free, none of its own but the blur of :data:`NUISANCE_TRUTH`) and, without
    ``nuisances``, the error chart; writes the CSVs, the table and the PNG. ``supersample`` > 1: the
    observations made at that many times the resolution and the fits rendered with the box filter
    (:func:`truth_image`). The coverage's rows are saved after each fit; a run into a folder that holds
    some (``coverage.csv``) fits only the seeds they lack."""
    out.mkdir(parents=True, exist_ok=True)
    case = case_at(size, spp, "box" if supersample > 1 else None)
    truth = truth_image(case, truth_spp, nuisances, supersample)
    coverage_sensor = sensor_for(truth, case.scene(), NOISE_LEVELS["high"], 0.0 if nuisances else 1.0)
    done = read_rows(out / "coverage.csv") if (out / "coverage.csv").exists() else []
    saved = lambda rows: write_csv(out / "coverage.csv", [{**r, "study": "coverage", "noise": "high"} for r in rows])  # noqa: E731
    rows = [{**row, "study": "coverage", "noise": "high"}
            for row in realisations(case, truth, coverage_sensor, realisations_count, first_seed=first_seed, nuisances=nuisances,
                                    done=[r for r in done if r["study"] == "coverage"], saved=saved)]
    if not nuisances:
        plain = truth_image(case, truth_spp, False)
        for noise, peak in NOISE_LEVELS.items():
            for width in PSF_WIDTHS_PX:
                sensor = sensor_for(plain, case.scene(), peak, width)
                for row in realisations(case, plain, sensor, chart_realisations, first_seed=1000):
                    rows.append({**row, "study": "chart", "noise": noise})
    write_csv(out / "coverage.csv", rows)
    return write_summary(out, rows)


def run_linearised(out: Path, *, size: int, spp: int, truth_spp: int, count: int) -> None:
    """The nuisance study linearised at the truth (:func:`linearised`, the sensor of
    :func:`run_coverage`): writes ``linearised.csv`` and one table per estimator,
    ``linearised_fit_minimum.md`` and ``linearised_two-seed.md``."""
    out.mkdir(parents=True, exist_ok=True)
    case = case_at(size, spp)
    truth = truth_image(case, truth_spp, True)
    rows = linearised(case, truth, sensor_for(truth, case.scene(), NOISE_LEVELS["high"], 0.0), count, first_seed=1)
    write_csv(out / "linearised.csv", rows)
    for study in ("fit minimum", "two-seed"):
        mine = [r for r in rows if r["study"] == study]
        (out / f"linearised_{study.replace(' ', '_')}.md").write_text(table(mine, summarise(mine, ("noise", "psf_sigma_px"))))


def table(rows: list[dict[str, object]], coverage: list[dict[str, object]]) -> str:
    """The per-parameter coverage of :func:`summarise` as a Markdown table, with :func:`verdict`."""
    lines = ["| parameter | truth | exposures | 1-sigma coverage [95 % interval] | mean z | rms z | rms error | mean stderr | verdict |",
             "|---|---|---|---|---|---|---|---|---|"]
    for r in coverage:
        truth = float(next(x["truth"] for x in rows if x["parameter"] == r["parameter"]))
        lines.append(f"| {r['parameter']} | {truth:g} | {r['n']} | {100 * r['coverage']:.0f} % [{100 * r['coverage_low']:.0f}, "
                     f"{100 * r['coverage_high']:.0f}] | {r['mean_z']:+.2f} | {r['rms_z']:.2f} | "
                     f"{r['rms_error_rel'] * abs(truth):.3g} | {r['mean_stderr_rel'] * abs(truth):.3g} | {verdict(r)} |")
    return "\n".join(lines) + "\n"


def write_summary(out: Path, rows: list[dict[str, object]]) -> tuple[list[dict[str, object]], list[dict[str, object]]]:
    """Summarise the fits' ``rows`` (of :func:`realisations`, with ``study`` and ``noise``): write
    ``coverage_summary.csv``, ``coverage_table.md`` and ``coverage.png``; return the coverage and
    the chart's summaries."""
    key = ("noise", "psf_sigma_px")
    coverage = summarise([r for r in rows if r["study"] == "coverage"], key)
    chart = summarise([r for r in rows if r["study"] == "chart"], key)
    write_csv(out / "coverage_summary.csv", [{"study": "coverage", **r} for r in coverage] + [{"study": "chart", **r} for r in chart])
    (out / "coverage_table.md").write_text(table([r for r in rows if r["study"] == "coverage"], coverage))
    _chart(out / "coverage.png", chart, coverage)
    return coverage, chart


def pool(folders: list[Path], out: Path) -> str:
    """The coverage table of the exposures of several runs' ``coverage.csv`` together (a seed fitted in
    two runs counted once, from the first), written to ``out/coverage_pooled.md`` with the runs named."""
    rows, seen = [], set()
    for folder in folders:
        mine = [r for r in read_rows(folder / "coverage.csv") if r["study"] == "coverage" and int(r["seed"]) not in seen]
        seen |= {int(r["seed"]) for r in mine}
        rows += mine
    text = table(rows, summarise(rows, ("noise", "psf_sigma_px")))
    text += f"\nPooled: {', '.join(str(f) for f in folders)}; seeds {min(seen)} to {max(seen)}, {len(seen)} exposures.\n"
    out.mkdir(parents=True, exist_ok=True)
    (out / "coverage_pooled.md").write_text(text)
    return text


def _chart(path: Path, chart: list[dict[str, object]], coverage: list[dict[str, object]]) -> None:
    names = sorted({str(r["parameter"]) for r in chart})
    fig, axes = plt.subplots(1, len(names) + 1, figsize=(4.0 * len(names) + max(4.0, 0.6 * len(coverage)), 3.6), squeeze=False)
    axes = axes[0]
    for ax, name in zip(axes, names):
        for i, noise in enumerate(NOISE_LEVELS):
            rows = sorted((r for r in chart if r["parameter"] == name and r["noise"] == noise), key=lambda r: r["psf_sigma_px"])
            x = [r["psf_sigma_px"] for r in rows]
            ax.plot(x, [100 * r["rms_error_rel"] for r in rows], "o-", color=f"C{i}", label=f"rms error, {noise} noise")
            ax.plot(x, [100 * r["mean_stderr_rel"] for r in rows], "s--", color=f"C{i}", alpha=0.6, label=f"reported stderr, {noise} noise")
        ax.set_title(name, fontsize=9)
        ax.set_xlabel("PSF sigma (px)")
        ax.set_ylabel("relative error (%)")
        ax.grid(alpha=0.3)
    if names:
        axes[0].legend(fontsize=7)
    ax = axes[-1]
    ax.bar(range(len(coverage)), [100 * r["coverage"] for r in coverage], color="C2")
    ax.axhspan(58, 78, color="0.8", zorder=0, label="68 +- 10 %")
    ax.set_xticks(range(len(coverage)), [str(r["parameter"]).split(".", 1)[1] for r in coverage], fontsize=8,
                  rotation=30 if len(coverage) > 3 else 0, ha="right" if len(coverage) > 3 else "center")
    ax.set_ylabel("1-sigma coverage (%)")
    ax.set_title(f"coverage over {coverage[0]['n']} exposures", fontsize=9)
    ax.legend(fontsize=7)
    save_figure(fig, path)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, help="default: experiments/results/coverage/ (nuisances/ under it with --free nuisances)")
    parser.add_argument("--size", type=int, default=48)
    parser.add_argument("--spp", type=int, default=32)
    # the truth render's own noise is one error shared by every exposure, which no error bar covers:
    # at 512 spp (a quarter of the fits' noise at 32 spp) it was 0.5 % of kd
    parser.add_argument("--truth-spp", type=int, default=4096)
    parser.add_argument("--full", action="store_true", help="50 exposures for the coverage, 5 per chart point")
    parser.add_argument("--free", choices=("materials", "nuisances"), default="materials",
                        help="free the materials only, or the nuisances too (pose, shift, PSF width; no chart)")
    parser.add_argument("--realisations", type=int, help="exposures for the coverage (default 10, --full 50)")
    parser.add_argument("--supersample", type=int, default=1,
                        help="with --free nuisances: observations made at this many times the resolution, blurred "
                             "there and binned (as issue 34's hidden ones); the fits render with the box filter")
    parser.add_argument("--first-seed", type=int, default=1, help="the first exposure's noise seed (the fits' seeds follow from it)")
    parser.add_argument("--linearised", action="store_true",
                        help="the nuisance study linearised at the truth, fit minimum against the two-seed estimate (no fits)")
    parser.add_argument("--pool", type=Path, nargs="+", metavar="DIR",
                        help="no fits: the coverage of the exposures in these runs' coverage.csv together (each seed once), "
                             "its table written to --out as coverage_pooled.md")
    args = parser.parse_args()
    if args.pool:
        print(pool(args.pool, args.out or args.pool[0]))
        return
    nuisances = args.free == "nuisances" or args.linearised
    folder = ("nuisances_supersampled" if args.supersample > 1 else "nuisances") if nuisances else ""
    out = args.out or Path(__file__).parent / "results" / "coverage" / folder
    count = args.realisations or (50 if args.full else 10)
    if args.linearised:
        run_linearised(out, size=args.size, spp=args.spp, truth_spp=args.truth_spp, count=count)
        for study in ("fit_minimum", "two-seed"):
            print(study, (out / f"linearised_{study}.md").read_text(), sep="\n")
        return
    coverage, chart = run_coverage(out, size=args.size, spp=args.spp, truth_spp=args.truth_spp, realisations_count=count,
                                   chart_realisations=5 if args.full else 2, nuisances=nuisances, supersample=args.supersample,
                                   first_seed=args.first_seed)
    print((out / "coverage_table.md").read_text())
    for row in chart:
        print(row)


if __name__ == "__main__":
    main()
