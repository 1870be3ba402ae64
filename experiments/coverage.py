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
* error chart: the rms error (relative) of each parameter over ``--chart-realisations`` exposures,
  for each PSF width and noise level, beside the mean reported standard error.

Writes ``coverage.csv`` (one row per fit), ``coverage_summary.csv`` and ``coverage.png`` to ``--out``.
Run: ``.venv/bin/python experiments/coverage.py [--full]``: by default 10 exposures for the coverage
and 2 per chart point (about 5 minutes on 2 cores); ``--full``: 50 and 5 (about 20 minutes on a quiet machine), the
results in ``experiments/results/coverage/``. A fit takes 8 to 18 s at 48 px, 32 spp, mostly JAX's
compilation of the solver's step for the new problem, so the study has no CI test of its own; the
reduced, linearised study is ``tests/test_noise_model.py``.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import matplotlib
import numpy as np
from studyio import save_figure, write_csv

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

import spacefit as sf  # noqa: E402
from spacefit.scene.assembly import assemble  # noqa: E402
from spacefit.sensor import electrons_per_radiance  # noqa: E402

CASE = "panels"
START_FACTOR = 1.2
ONE_SIGMA = 0.6827
NOISE_LEVELS = {"low": 20000.0, "high": 2000.0}  # peak electrons of the brightest glint
PSF_WIDTHS_PX = (0.0, 1.0, 2.0)


def case_at(size: int, spp: int) -> sf.Case:
    """The panels case at ``size`` px with the same field of view, fits at ``spp``."""
    return sf.load_case(CASE).with_values({"render.resolution": [size, size], "camera.pixel_pitch_mm": 18.75 * 128 / size,
                                           "render.spp": spp})


def sensor_for(truth: np.ndarray, scene: sf.Scene, peak_electrons: float, psf_sigma_px: float) -> sf.Sensor:
    """A sensor whose exposure puts ``peak_electrons`` in the brightest pixel of ``truth`` (before the PSF)."""
    unit = sf.Sensor(exposure_time_s=1.0, psf_sigma_px=psf_sigma_px, full_well_electrons=None, bit_depth=16)
    per_second = float((np.asarray(truth) * electrons_per_radiance(unit, assemble(scene).intrinsics, 3)).max())
    return sf.Sensor(exposure_time_s=peak_electrons / per_second, psf_sigma_px=psf_sigma_px, full_well_electrons=None, bit_depth=16)


def realisations(case: sf.Case, truth: np.ndarray, sensor: sf.Sensor, count: int, first_seed: int) -> list[dict[str, object]]:
    """Fit ``count`` simulated exposures of ``truth``; one row per fit and parameter."""
    scene = case.scene()
    intrinsics = assemble(scene).intrinsics
    start = {n: START_FACTOR * v for n, v in case.truth.items()}
    rows = []
    for k in range(count):
        seed = first_seed + k
        dn = sf.observe(truth, sensor, intrinsics, seed).astype(float)
        result = sf.fit(sf.Observation(scene, dn, sensor=sensor), list(case.free), start=start,
                        render=sf.FitRender(seed=2 * seed + 101, seed_grad=2 * seed + 102))
        for name, true in case.truth.items():
            value, stderr = result.values[name], result.stderr[name]
            rows.append({"seed": seed, "psf_sigma_px": sensor.psf_sigma_px, "exposure_time_s": sensor.exposure_time_s,
                         "parameter": name, "truth": true, "value": value, "stderr": stderr,
                         "covered": bool(abs(value - true) <= stderr), "steps": result.steps, "status": result.status.name})
        print(f"seed {seed}, sigma {sensor.psf_sigma_px:g} px: {result.status.name}, {result.wall_time_s:.1f} s", flush=True)
    return rows


def summarise(rows: list[dict[str, object]], key: tuple[str, ...]) -> list[dict[str, object]]:
    """Per ``key`` group and parameter: coverage, rms relative error and mean relative standard error."""
    groups: dict[tuple, list[dict[str, object]]] = {}
    for row in rows:
        groups.setdefault(tuple(row[k] for k in key) + (row["parameter"],), []).append(row)
    out = []
    for group, items in groups.items():
        truth = float(items[0]["truth"])
        errors = np.array([float(r["value"]) - truth for r in items])
        out.append({**dict(zip((*key, "parameter"), group)), "n": len(items),
                    "coverage": float(np.mean([r["covered"] for r in items])),
                    "rms_error_rel": float(np.sqrt(np.mean(errors**2)) / truth),
                    "mean_stderr_rel": float(np.mean([float(r["stderr"]) for r in items]) / truth)})
    return out


def run_coverage(out: Path, *, size: int, spp: int, truth_spp: int, realisations_count: int,
                 chart_realisations: int) -> tuple[list[dict[str, object]], list[dict[str, object]]]:
    """The coverage study (high noise: 2000 electrons in the brightest glint; the sensor's PSF 1 px)
    and the error chart; writes the CSVs and the PNG."""
    out.mkdir(parents=True, exist_ok=True)
    case = case_at(size, spp)
    truth = np.asarray(sf.render(case.truth_scene.with_values({"render.spp": truth_spp})), dtype=float)
    rows = []
    coverage_sensor = sensor_for(truth, case.scene(), NOISE_LEVELS["high"], 1.0)
    for row in realisations(case, truth, coverage_sensor, realisations_count, first_seed=1):
        rows.append({**row, "study": "coverage", "noise": "high"})
    for noise, peak in NOISE_LEVELS.items():
        for width in PSF_WIDTHS_PX:
            sensor = sensor_for(truth, case.scene(), peak, width)
            for row in realisations(case, truth, sensor, chart_realisations, first_seed=1000):
                rows.append({**row, "study": "chart", "noise": noise})
    write_csv(out / "coverage.csv", rows)
    return write_summary(out, rows)


def write_summary(out: Path, rows: list[dict[str, object]]) -> tuple[list[dict[str, object]], list[dict[str, object]]]:
    """Summarise the fits' ``rows`` (of :func:`realisations`, with ``study`` and ``noise``): write
    ``coverage_summary.csv`` and ``coverage.png``; return the coverage and the chart's summaries."""
    key = ("noise", "psf_sigma_px")
    coverage = summarise([r for r in rows if r["study"] == "coverage"], key)
    chart = summarise([r for r in rows if r["study"] == "chart"], key)
    write_csv(out / "coverage_summary.csv", [{"study": "coverage", **r} for r in coverage] + [{"study": "chart", **r} for r in chart])
    _chart(out / "coverage.png", chart, coverage)
    return coverage, chart


def _chart(path: Path, chart: list[dict[str, object]], coverage: list[dict[str, object]]) -> None:
    names = sorted({str(r["parameter"]) for r in chart})
    fig, axes = plt.subplots(1, len(names) + 1, figsize=(4.0 * (len(names) + 1), 3.6))
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
    axes[0].legend(fontsize=7)
    ax = axes[-1]
    ax.bar(range(len(coverage)), [100 * r["coverage"] for r in coverage], color="C2")
    ax.axhspan(58, 78, color="0.8", zorder=0, label="68 +- 10 %")
    ax.set_xticks(range(len(coverage)), [str(r["parameter"]).split(".", 1)[1] for r in coverage], fontsize=8)
    ax.set_ylabel("1-sigma coverage (%)")
    ax.set_title(f"coverage over {coverage[0]['n']} exposures", fontsize=9)
    ax.legend(fontsize=7)
    save_figure(fig, path)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=Path(__file__).parent / "results" / "coverage")
    parser.add_argument("--size", type=int, default=48)
    parser.add_argument("--spp", type=int, default=32)
    # the truth render's own noise is one error shared by every exposure, which no error bar covers:
    # at 512 spp (a quarter of the fits' noise at 32 spp) it was 0.5 % of kd
    parser.add_argument("--truth-spp", type=int, default=4096)
    parser.add_argument("--full", action="store_true", help="50 exposures for the coverage, 5 per chart point")
    args = parser.parse_args()
    coverage, chart = run_coverage(args.out, size=args.size, spp=args.spp, truth_spp=args.truth_spp,
                                   realisations_count=50 if args.full else 10, chart_realisations=5 if args.full else 2)
    for row in coverage + chart:
        print(row)


if __name__ == "__main__":
    main()
