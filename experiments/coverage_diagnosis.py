"""Where the scatter of the nuisance study's estimates comes from (issue 34: alpha_y's coverage, the
pixel grid's step), one source at a time, each estimate linearised at the truth (no fits).

The exposures of ``experiments/coverage.py --free nuisances --supersample 4 --size 48`` (the same
truth, sensor and seeds' rule), all eight parameters free:

* ``photon``: one linearisation (render seeds 123, 124) and ``--count`` exposures: the two-seed
  estimator's step ``-(J^T J)^-1 J^T r`` of each exposure's residuals at the fixed model; its
  scatter per parameter against the covariance's photon part ``sqrt((J^T J)^-1)`` (the bread);
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
  through its feedback ``(I - D)^-1`` (:func:`spacefit.fitting.pixel_grid.grid_feedback`, as
  :func:`spacefit.fitting.uncertainty.estimate` now does): their ratio per parameter; with
  ``--rescore DIR ...``, those runs' ``coverage.csv`` scored again with each standard error times
  the mean ratio (the statistical part and the carried remainder as the fits had them).

Run: ``.venv/bin/python experiments/coverage_diagnosis.py photon|render|exposures|fine|feedback [--count N]``
(``photon`` about a minute, the others about 20 s per estimate on a quiet machine).
"""

from __future__ import annotations

import argparse
import os
import subprocess
from pathlib import Path
from unittest import mock

import jax.numpy as jnp
import numpy as np
from coverage import NOISE_LEVELS, NUISANCE_TRUTH, case_at, read_rows, sensor_for, summarise, table, truth_image
from studyio import machine

import spacefit as sf
from spacefit.fitting.observations.image import check_reference, image_residual
from spacefit.fitting.problem import setup
from spacefit.fitting.uncertainty import _pseudo_inverse, estimate, linearise
from spacefit.precision import float64
from spacefit.scene.assembly import assemble


@float64
def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("source", choices=("photon", "render", "exposures", "fine", "feedback"))
    parser.add_argument("--first-exposure", type=int, default=1000, help="photon: the first exposure's noise seed")
    parser.add_argument("--count", type=int, default=None, help="draws (default: photon 400, else 12)")
    parser.add_argument("--rescore", type=Path, nargs="+", metavar="DIR", help="feedback: these runs' coverage.csv scored again")
    args = parser.parse_args()
    count = args.count or (400 if args.source == "photon" else 12)
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True).stdout.strip()
    print(f"{machine()}, load {os.getloadavg()[0]:.1f}, commit {commit}", flush=True)
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
    if args.source == "photon":
        s = problem(exposure, seed=11)
        lin = linearise(s.problem, s.x0)
        bread = _pseudo_inverse(lin.information)[0]
        model = s.problem.renders_x(jnp.asarray(s.x0))[0]
        steps = []
        for k in range(count):
            obs = sf.Observation(scene, sf.observe(truth, sensor, intrinsics, args.first_exposure + k).astype(float), sensor=sensor)
            ref, used = check_reference(obs, 0)
            r = jnp.asarray(np.asarray(image_residual(obs, ref, used, "pixel")(model), dtype=float))
            steps.append(-bread @ (0.5 * (np.asarray(lin.J1T(r)) + np.asarray(lin.J2T(r)))))
        spread, predicted = np.std(steps, axis=0, ddof=1), np.sqrt(np.diag(bread))
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
    print(f"{args.source}: {count} draws; per parameter the scatter, {label}, their ratio")
    for n, a, b in zip(names, spread, predicted):
        print(f"  {n}: {a:.4g}  {b:.4g}  {a / b:.3f}")


def feedback_ratio(s: object) -> np.ndarray:
    """Per parameter, the standard error of :func:`~spacefit.fitting.uncertainty.estimate` at the set-up's
    start over the same with the pixel grid's step taken as a constant (its feedback D set to 0; the
    same seeds, so the same renders)."""
    constant = lambda differences, step, at, columns, stderr: np.zeros((len(at), len(at)))  # noqa: E731
    with mock.patch("spacefit.fitting.uncertainty.grid_feedback", constant):
        before = np.diag(estimate(s, s.x0)[1])
    return np.sqrt(np.diag(estimate(s, s.x0)[1]) / before)


if __name__ == "__main__":
    main()
