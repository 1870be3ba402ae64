"""Where the scatter of the nuisance study's estimates comes from (issue 34: alpha_y's coverage, the
pixel grid's step), one source at a time, each estimate linearised at the truth (no fits).

The exposures of ``experiments/coverage.py --free nuisances --supersample 4 --size 48`` (the same
truth, sensor and seeds' rule), all eight parameters free:

* ``photon``: one linearisation (render seeds 123, 124) and ``--count`` exposures: the two-seed
  estimator's step ``-(J^T J)^-1 J^T r`` of each exposure's residuals at the fixed model; its
  scatter per parameter against the covariance's photon part ``sqrt((J^T J)^-1)`` (the bread), and
  its kurtosis (a fixed linear map of independent pixel noises whose fourth cumulants are those of
  Poisson counts, positive, and of Gaussian read noise, 0: at least 3 but for the draws);
* ``render``: one exposure (seed 11) and ``--count`` pairs of the fit's render seeds
  (``2 s + 101``, ``2 s + 102``, as the study seeds a fit): the shipped estimate
  (:func:`spacefit.fitting.uncertainty.estimate`) per pair, its scatter against the covariance's
  render and Jacobian noise part (``sqrt(stderr^2 - bread)``);
* ``exposures``: the study's exposures (seeds 11, 12, ...) each with its fit's render seeds: the
  shipped estimate linearised at the truth, against the fits' values in the study's ``coverage.csv``
  (what the fits add: their stopping and non-linearity);
* ``fine``: one exposure and render seed pair, ``--count`` seeds of the scene (which the pixel
  grid's renders at 4x took before they took the fit's): the pixel grid's step per seed;
* ``feedback``: the study's exposures (seeds 11, 12, ...) linearised at the truth, each standard
  error with the pixel grid's step taken as a constant (as the fits of ``--rescore`` had it) and
  through its feedback ``(I - D)^-1`` (:func:`spacefit.fitting.pixel_grid.grid_step`, as
  :func:`spacefit.fitting.uncertainty.estimate` now does): their ratio per parameter; with
  ``--rescore DIR ...``, those runs' ``coverage.csv`` scored again with each standard error times
  the mean ratio (the statistical part and the carried remainder as the fits had them);
* ``decompose``: the fits of runs' ``coverage.csv`` (``--rows DIR ...``) split, exposure by exposure, into
  the photon noise's part (``photon``'s step of that exposure's residuals at one fixed linearisation) and
  what the fit adds (its render and Jacobian noise, the pixel grid's step, its stopping): per parameter the
  slope of the fit's error on the photon step (1 for a fit that is linear in the data; below 1 for one that
  stops short of its minimum), their correlation, the photon steps' scatter and the remainder's against
  the bread (the remainder holds the fit's render and Jacobian noise, which ``render`` measures against
  what the covariance carries, and the fixed linearisation's Jacobian noise), the remainder's correlation
  with the photon step's size, and the kurtosis of the fits' z-scores, of the photon steps and of the
  remainder (3 for a normal distribution; a flat top below);
* ``fit-root``: ``--count`` study fits (exposures from ``--first-exposure``), and at each fit's end point the
  two-seed correction it took (``c1``) and the corrections that would follow at the corrected point and
  after (``c2``, ``c3``), over the standard error: how far one Gauss-Newton step leaves the estimate from
  the root of the two-seed equation.

Run: ``.venv/bin/python experiments/coverage_diagnosis.py photon|render|exposures|fine|feedback|decompose|fit-root [--count N]``
(``photon`` about a minute, ``decompose`` a minute per 120 exposures, ``fit-root`` a fit per exposure (20 to
100 s), the others about 20 s per estimate on a quiet machine).
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import os
from collections.abc import Callable
from pathlib import Path
from unittest import mock

import jax.numpy as jnp
import numpy as np
from scipy import stats
from coverage import NOISE_LEVELS, NUISANCE_TRUTH, START_FACTOR, case_at, read_rows, sensor_for, summarise, table, truth_image
from studyio import commit, machine

import spacefit as sf
import spacefit.fitting.conclusion as conclusion
from spacefit.fitting.observations.image import check_reference, image_residual
from spacefit.fitting.pixel_grid import GridStep
from spacefit.fitting.problem import setup
from spacefit.fitting.uncertainty import _pseudo_inverse, covariance, estimate, grid_step, linearise
from spacefit.precision import float64
from spacefit.scene.assembly import assemble


@float64
def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("source", choices=("photon", "render", "exposures", "fine", "feedback", "decompose", "fit-root"))
    parser.add_argument("--first-exposure", type=int, default=1000, help="photon: the first exposure's noise seed")
    parser.add_argument("--count", type=int, default=None, help="draws (default: photon 400, else 12)")
    parser.add_argument("--rescore", type=Path, nargs="+", metavar="DIR", help="feedback: these runs' coverage.csv scored again")
    parser.add_argument("--rows", type=Path, nargs="+", metavar="DIR", help="decompose: these runs' coverage.csv (each seed once)")
    args = parser.parse_args()
    count = args.count or (400 if args.source == "photon" else 12)
    print(f"{machine()}, load {os.getloadavg()[0]:.1f}, commit {commit()}", flush=True)
    case = case_at(48, 32, "box")
    truth = truth_image(case, 4096, True, 4)
    scene = case.scene()
    sensor = sensor_for(truth, scene, NOISE_LEVELS["high"], 0.0)
    intrinsics = assemble(scene).intrinsics
    truths = {**case.truth, **NUISANCE_TRUTH}
    names = list(truths)

    def problem(dn: np.ndarray, seed: int = 11, scene_seed: int | None = None) -> object:
        seen = scene if scene_seed is None else scene.with_values({"render.seed": scene_seed})
        return setup(sf.Observation(seen, dn, sensor=sensor), names, start=truths,
                     render=sf.FitRender(seed=2 * seed + 101, seed_grad=2 * seed + 102))

    exposure = sf.observe(truth, sensor, intrinsics, 11).astype(float)
    if args.source == "feedback":
        ratios = [feedback_ratio(problem(sf.observe(truth, sensor, intrinsics, 11 + k).astype(float), seed=11 + k)) for k in range(count)]
        print(f"feedback: {count} exposures; per parameter the standard error through (I - D)^-1 over the one with a constant step")
        for n, r in zip(names, np.transpose(ratios)):
            print(f"  {n}: mean {np.mean(r):.3f}, {np.min(r):.3f} to {np.max(r):.3f}")
        if args.rescore:
            factor = dict(zip(names, np.mean(ratios, axis=0)))
            rows = [r for folder in args.rescore for r in read_rows(folder / "coverage.csv") if r["study"] == "coverage"]
            rows = [{**r, "stderr": r["stderr"] * factor[r["parameter"]], "z": r["z"] / factor[r["parameter"]],
                     "covered": abs(r["value"] - r["truth"]) <= r["stderr"] * factor[r["parameter"]]} for r in rows]
            print(table(rows, summarise(rows, ("noise", "psf_sigma_px"))))
        return
    if args.source == "fit-root":
        fit_root(case, sensor, truths, lambda seed: sf.observe(truth, sensor, intrinsics, seed).astype(float),
                 range(args.first_exposure, args.first_exposure + count))
        return
    if args.source in ("photon", "decompose"):
        s = problem(exposure, seed=11)
        lin = linearise(s.problem, s.x0)
        bread = _pseudo_inverse(lin.information)[0]
        model = s.problem.renders_x(jnp.asarray(s.x0))[0]
        fits: dict[int, dict[str, dict[str, object]]] = {}
        for r in (r for folder in args.rows or () for r in read_rows(folder / "coverage.csv") if r["study"] == "coverage"):
            fits.setdefault(int(r["seed"]), {}).setdefault(str(r["parameter"]), r)
        seeds = sorted(fits) if args.source == "decompose" else range(args.first_exposure, args.first_exposure + count)
        steps = []
        for seed in seeds:
            obs = sf.Observation(scene, sf.observe(truth, sensor, intrinsics, seed).astype(float), sensor=sensor)
            ref, used = check_reference(obs, 0)
            steps.append(lin.step(np.asarray(image_residual(obs, ref, used, "pixel")(model), dtype=float)))
        if args.source == "decompose":
            print(decomposition(names, [[fits[seed][n] for n in names] for seed in seeds], np.asarray(steps), bread))
            return
        spread, predicted = np.std(steps, axis=0, ddof=1), np.sqrt(np.diag(bread))
        shape = stats.kurtosis(steps, axis=0, fisher=False)  # at least 3: a fixed linear map of independent Poisson and read noises
    else:
        values, parts = [], []
        for k in range(count):
            if args.source == "fine":
                s = problem(exposure, scene_seed=1000 + 7 * k)
            else:
                s = problem(exposure if args.source == "render" else sf.observe(truth, sensor, intrinsics, 11 + k).astype(float), seed=11 + k)
            x, cov, _, extras = estimate(s, s.x0)
            bread = _pseudo_inverse(linearise(s.problem, s.x0).information)[0]
            values.append([extras["pixel_grid_error"][n] for n in names] if args.source == "fine" else x)
            parts.append(np.sqrt(np.clip(np.diag(cov) - np.diag(bread), 0.0, None)) if args.source == "render" else np.sqrt(np.diag(cov)))
            print(f"draw {k}: " + ", ".join(f"{n} {v:+.4g}" for n, v in zip(names, values[-1])), flush=True)
        spread, predicted = np.std(values, axis=0, ddof=1), np.mean(parts, axis=0)
    if args.source == "exposures":  # the scatter about the truth (rms error), not about the mean
        spread = np.sqrt(np.mean((np.asarray(values) - np.array(list(truths.values()))) ** 2, axis=0))
    label = {"photon": "the bread", "render": "the covariance's render and Jacobian part", "exposures": "the mean standard error",
             "fine": "the standard error"}[args.source]
    print(f"{args.source}: {count} draws; per parameter the scatter, {label}, their ratio"
          + (", the steps' kurtosis" if args.source == "photon" else ""))
    for j, (n, a, b) in enumerate(zip(names, spread, predicted)):
        print(f"  {n}: {a:.4g}  {b:.4g}  {a / b:.3f}" + (f"  {shape[j]:.2f}" if args.source == "photon" else ""))


def decomposition(names: list[str], fits: list[list[dict[str, object]]], steps: np.ndarray, bread: np.ndarray) -> str:
    """The ``decompose`` table: ``fits`` per exposure and parameter (rows of ``coverage.csv``), ``steps`` the
    photon steps of the same exposures (exposures x parameters), ``bread`` the photon part's covariance."""
    lines = [f"decompose: {len(fits)} exposures; the fits' error against the photon step of the same exposure",
             "| parameter | slope | correlation | photon scatter / bread | remainder / bread "
             "| corr(remainder, abs(photon)) | kurtosis: fits' z | photon | remainder |", "|---|---|---|---|---|---|---|---|---|"]
    for j, name in enumerate(names):
        error = np.array([float(f[j]["value"]) - float(f[j]["truth"]) for f in fits])
        z = np.array([float(f[j]["z"]) for f in fits])
        photon, sd = steps[:, j], math.sqrt(bread[j, j])
        slope = float(np.polyfit(photon, error, 1)[0])
        remainder = error - slope * photon
        lines.append(f"| {name} | {slope:.3f} | {np.corrcoef(photon, error)[0, 1]:.3f} | {np.std(photon, ddof=1) / sd:.3f} | "
                     f"{np.std(remainder, ddof=1) / sd:.3f} | "
                     f"{np.corrcoef(remainder, np.abs(photon - photon.mean()))[0, 1]:+.2f} | {stats.kurtosis(z, fisher=False):.2f} | "
                     f"{stats.kurtosis(photon, fisher=False):.2f} | {stats.kurtosis(remainder, fisher=False):.2f} |")
    return "\n".join(lines)


def fit_root(case: sf.Case, sensor: sf.Sensor, truths: dict[str, float], exposure: Callable[[int], np.ndarray], seeds: range) -> None:
    """The ``fit-root`` diagnostic: each seed's study fit, and at its end point the two-seed corrections
    ``c1`` (the one the fit took), ``c2`` and ``c3`` (at the point each previous one leads to), over the
    fit's standard errors, printed per parameter."""
    caught: dict[str, object] = {}
    shipped = conclusion.estimate

    def spy(s: object, x: np.ndarray, correct: bool = True) -> tuple:
        caught["s"], caught["x"] = s, np.asarray(x)
        return shipped(s, x, correct)

    start = {n: START_FACTOR * v for n, v in case.truth.items()}
    for seed in seeds:
        with mock.patch.object(conclusion, "estimate", spy):
            result = sf.fit(sf.Observation(case.scene(), exposure(seed), sensor=sensor), list(truths), start=start,
                            render=sf.FitRender(seed=2 * seed + 101, seed_grad=2 * seed + 102))
        s, x = caught["s"], caught["x"]
        corrections = [covariance(s.problem, x)[3]]
        for _ in range(2):
            corrections.append(covariance(s.problem, x + sum(corrections))[3])
        print(f"seed {seed}: {result.status.name}, {result.steps} steps, load {os.getloadavg()[0]:.1f}")
        for j, n in enumerate(truths):
            se = result.stderr[n]
            print(f"  {n}: z {(result.values[n] - truths[n]) / se:+.3f}, c1 {corrections[0][j] / se:+.3f}, "
                  f"c2 {corrections[1][j] / se:+.3f}, c3 {corrections[2][j] / se:+.3f} (of the standard error)", flush=True)


def feedback_ratio(s: object) -> np.ndarray:
    """Per parameter, the standard error of :func:`~spacefit.fitting.uncertainty.estimate` at the set-up's
    start over the same with the pixel grid's step taken as a constant (its feedback D set to 0; the
    same seeds, so the same renders)."""
    def constant(*args: object) -> GridStep:
        step = grid_step(*args)
        return dataclasses.replace(step, feedback=np.zeros_like(step.feedback))

    with mock.patch("spacefit.fitting.uncertainty.grid_step", constant):
        before = np.diag(estimate(s, s.x0)[1])
    return np.sqrt(np.diag(estimate(s, s.x0)[1]) / before)


if __name__ == "__main__":
    main()
