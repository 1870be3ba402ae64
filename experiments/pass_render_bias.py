"""The render noise's bias of a pass fit's estimate, without fits: pass_coverage.py's pass (the blur not free) at the
truth, its references noise-free (the expected DN of one render at ``--truth-spp``, no photon noise), linearised with
``--count`` pairs of render seeds at each of ``--spp``: each draw's estimate is the root of the two-seed estimating
equation one Gauss-Newton step from the truth (:func:`spacefit.fitting.uncertainty.covariance`'s correction), so its
mean over the draws is the estimator's bias from the fit's own render noise (the references' noise is one draw, the
same at every spp), beside the noise weight's bias that :func:`spacefit.fitting.noise_weight.weight_bias` predicts
(``weight_bias``). Prints per spp and material the mean change (+- its standard error) and the mean standard error
the fit reports; writes ``render_bias.csv`` to ``--out``. Run:
``nice -n 10 .venv/bin/python experiments/pass_render_bias.py --out DIR``.
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import numpy as np
from bench_pass import MATERIALS, PER_FRAME, SENSOR, base
from coverage import read_rows
from pass_coverage import frame_truths, reference
from studyio import commit, machine, write_csv

import spacefit as sf
from spacefit.fitting.problem import setup
from spacefit.fitting.noise_weight import weight_bias
from spacefit.fitting.uncertainty import covariance, linearise
from spacefit.formation import expected_dn
from spacefit.scene.assembly import assemble
from spacefit.scene.parameters import scene_value


def observations(size: int, n: int, truth_spp: int) -> tuple[list[sf.Observation], dict[str, float]]:
    """The pass's noise-free observations (expected DN of a render at ``truth_spp``) and the free values' truths."""
    scenes = [base(size).with_values(f) for f in sf.arc_pass(n)]
    nuisances = frame_truths(n)
    obs = []
    for k, (scene, truth) in enumerate(zip(scenes, nuisances)):
        pose = {name: scene_value(scene, name) + truth[name] for name in ("target.attitude_x_deg", "target.attitude_z_deg")}
        radiance = reference(scene.with_values(pose), truth_spp, 90000 + k, 0.0)
        dn = np.asarray(expected_dn(radiance, SENSOR, assemble(scene).intrinsics), dtype=float)
        obs.append(sf.Observation(scene, dn, sensor=SENSOR, render_spp=truth_spp))
    return obs, {**MATERIALS, **{f"{name}@{k}": t[name] for k, t in enumerate(nuisances) for name in PER_FRAME}}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--size", type=int, default=64)
    p.add_argument("--frames", type=int, default=6)
    p.add_argument("--truth-spp", type=int, default=4096)
    p.add_argument("--spp", type=int, nargs="+", default=[16, 64])
    p.add_argument("--count", type=int, default=8)
    p.add_argument("--first-draw", type=int, default=0, help="the first draw's index (its seeds: 5001 + 2 k and 5002 + 2 k)")
    p.add_argument("--out", type=Path, required=True)
    args = p.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    print(f"machine: {machine()}; commit {commit()}; {args.frames} frames at {args.size} px, references {args.truth_spp} spp, "
          f"noise-free; load {os.getloadavg()[0]:.1f}", flush=True)
    obs, truths = observations(args.size, args.frames, args.truth_spp)
    path = args.out / "render_bias.csv"
    rows = read_rows(path) if path.exists() else []
    for spp in args.spp:
        for k in range(args.first_draw, args.first_draw + args.count):
            if any(int(r["spp"]) == spp and int(r["draw"]) == k for r in rows):
                continue
            t0 = time.perf_counter()
            s = setup(obs, list(truths), start=truths, render=sf.FitRender(spp=spp, seed=2 * k + 5001, seed_grad=2 * k + 5002))
            lin = linearise(s.problem, s.x0)
            cov, _, _, correction = covariance(s.problem, s.x0, lin)
            stderr = np.sqrt(np.diag(cov))
            bias = weight_bias(s.problem, lin.r, lin.r_alt, lin.step)
            for i, name in enumerate(s.solver_params.names):
                if name in MATERIALS:
                    rows.append({"spp": spp, "draw": k, "parameter": name, "change": float(correction[i]), "stderr": float(stderr[i]),
                                 "weight_bias": float(bias[i])})
            kd = rows[-1] if rows[-1]["parameter"] == "parts.legs.kd" else next(r for r in rows[::-1] if r["parameter"] == "parts.legs.kd")
            print(f"spp {spp}, draw {k}: kd change {kd['change']:+.5f} (stderr {kd['stderr']:.5f}; the weight's bias "
                  f"{kd['weight_bias']:+.5f}), {time.perf_counter() - t0:.1f} s; "
                  f"load {os.getloadavg()[0]:.1f}", flush=True)
            write_csv(path, rows)
    for spp in args.spp:
        for name in MATERIALS:
            c = np.array([float(r["change"]) for r in rows if int(r["spp"]) == spp and r["parameter"] == name])
            se = np.mean([float(r["stderr"]) for r in rows if int(r["spp"]) == spp and r["parameter"] == name])
            print(f"spp {spp:4d} {name}: mean change {c.mean():+.6f} +- {c.std(ddof=1) / np.sqrt(len(c)):.6f} ({len(c)} draws; "
                  f"{c.mean() / se:+.2f} of the mean stderr {se:.5f})")


if __name__ == "__main__":
    main()
