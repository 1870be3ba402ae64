"""Coverage of a pass fit's 1-sigma intervals: bench_pass.py's pass (the panels case along :func:`spacefit.arc_pass`,
DN through its sensor, each frame's target turned off its table's attitude; the three materials and the blur shared,
each frame's attitude x and z, shift and scale its own; LM at 16 spp from bench_pass's start) at reduced size, each
realisation a fresh pass: the references rendered with their own seeds at ``--truth-spp`` and exposed with their own
noise, the fit with its own render seeds. Per parameter (the per-frame nuisances pooled by kind): the coverage with its
95 % Wilson interval, mean z and rms z.

Variants (``--variant``), the same seeds in each:

* ``bound``: bench_pass's pass: the blur's truth 0 (no blur: the references rendered at 1x with the case's tent
  filter, as :func:`spacefit.simulate_pass` makes them), at the lower bound of its range, and free;
* ``fixed``: the same references, the blur not free (its default, no blur: the truth);
* ``inside``: the blur's truth ``--blur`` px (0.5), inside its range: each reference rendered at 4x with the box
  filter (``--truth-spp / 16`` per fine pixel), blurred at the fine scale by the fit's own image model, then each
  pixel's tent response (:func:`spacefit.fitting.fine_models.response_matrix`), as the pixel-grid check models it.

Writes ``fits.csv`` (one row per fit and parameter, saved after each fit; a run into a folder that holds some fits only
those it lacks) and ``summary_<variant>.md`` to ``--out``. Run:
``nice -n 10 .venv/bin/python experiments/pass_coverage.py --variant bound --realisations 16 --out DIR``.
"""

from __future__ import annotations

import argparse
import os
import resource
import time
from pathlib import Path

import jax.numpy as jnp
import numpy as np
from bench_pass import MATERIALS, PER_FRAME, SENSOR, START, base
from coverage import read_rows, wilson
from studyio import commit, machine, write_csv

import spacefit as sf
from spacefit.fitting.nuisance import image_model
from spacefit.fitting.fine_models import SUPERSAMPLE, response_matrix, supersampled
from spacefit.scene.assembly import assemble
from spacefit.scene.parameters import scene_value

BLUR = "image.blur_sigma_px"
VARIANTS = ("bound", "fixed", "inside")


def frame_truths(n: int) -> list[dict[str, float]]:
    """Each frame's attitude errors (deg), bench_pass's draw (seed 3), and its image nuisances' truths."""
    rng = np.random.default_rng(3)
    return [{"target.attitude_x_deg": float(a), "target.attitude_z_deg": float(b), "image.shift_x_px": 0.0,
             "image.shift_y_px": 0.0, "image.scale": 1.0} for a, b in rng.uniform(-0.3, 0.3, (n, 2))]


def reference(scene: sf.Scene, spp: int, seed: int, blur_px: float) -> np.ndarray:
    """The true radiance of one frame at ``spp``: rendered at 1x with the scene's filter (no blur), or at
    :data:`SUPERSAMPLE` x with the box filter, blurred by ``blur_px`` there and given each pixel's response."""
    scene = scene.with_values({"render.spp": spp, "render.seed": seed})
    if blur_px == 0.0:
        return np.asarray(sf.render(scene), dtype=float)
    fine = np.asarray(sf.render(supersampled(scene, SUPERSAMPLE)), dtype=float)
    blurred = image_model([BLUR])(jnp.asarray(fine), jnp.asarray([SUPERSAMPLE * blur_px]), 0)
    w, h = scene.render.resolution
    rows, cols = (response_matrix(m, SUPERSAMPLE, scene.render.filter) for m in (h, w))
    return np.maximum(np.einsum("iy,yxc,jx->ijc", rows, np.asarray(blurred, dtype=float), cols), 0.0)


def realisation(size: int, n: int, seed: int, variant: str, blur_px: float, truth_spp: int, fit_spp: int,
                max_steps: int) -> list[dict[str, object]]:
    """One fresh pass (references with seeds from ``seed``) fitted; one row per parameter."""
    scenes = [base(size).with_values(f) for f in sf.arc_pass(n)]
    nuisances = frame_truths(n)
    truth_blur = blur_px if variant == "inside" else 0.0
    obs = []
    for k, (scene, truth) in enumerate(zip(scenes, nuisances)):
        pose = {name: scene_value(scene, name) + truth[name] for name in ("target.attitude_x_deg", "target.attitude_z_deg")}
        radiance = reference(scene.with_values(pose), truth_spp, 1000 * seed + k, truth_blur)
        dn = sf.observe(radiance, SENSOR, assemble(scene).intrinsics, 1000 * seed + 500 + k)
        obs.append(sf.Observation(scene, dn, sensor=SENSOR, render_spp=truth_spp))
    truths = {**MATERIALS, **({BLUR: truth_blur} if variant != "fixed" else {}),
              **{f"{name}@{k}": t[name] for k, t in enumerate(nuisances) for name in PER_FRAME}}
    t0, cpu0 = time.perf_counter(), time.process_time()
    result = sf.fit(obs, list(truths), start=START, max_steps=max_steps,
                    render=sf.FitRender(spp=fit_spp, seed=2 * seed + 101, seed_grad=2 * seed + 102))
    wall, cpu = time.perf_counter() - t0, time.process_time() - cpu0
    correction = result.extras.get("noise_bias_correction", {})
    grid = result.extras.get("pixel_grid_error", {})
    g = result.goodness
    warned = " | ".join(w for w in result.warnings if BLUR in w or "bound" in w)
    rows = []
    for name, true in truths.items():
        value, stderr = float(result.values[name]), float(result.stderr[name])
        rows.append({"variant": variant, "fit_spp": fit_spp, "seed": seed, "parameter": name, "kind": name.split("@")[0], "truth": true, "value": value,
                     "stderr": stderr, "z": (value - true) / stderr, "covered": bool(abs(value - true) <= stderr),
                     "corr_with_blur": float(result.correlation[result.names.index(name), result.names.index(BLUR)])
                     if BLUR in truths else float("nan"),
                     "noise_bias_correction_solver": float(correction.get(name, 0.0)),
                     "pixel_grid_error_solver": float(grid.get(name, 0.0)), "chi2_dof": float(g.chi2_dof),
                     "chi2_limit": float(g.limit), "steps": result.steps, "status": result.status.name, "wall_s": round(wall, 1),
                     "cpu_s": round(cpu, 1), "blur_warnings": warned})
    return rows


def pooled(rows: list[dict[str, object]]) -> list[dict[str, object]]:
    """Per variant and kind (a per-frame nuisance pooled over the frames): :func:`coverage.summarise`'s figures."""
    out = []
    for variant in VARIANTS:
        mine = [r for r in rows if r["variant"] == variant]
        for kind in dict.fromkeys(r["kind"] for r in mine):
            items = [r for r in mine if r["kind"] == kind]
            z = np.array([float(r["z"]) for r in items])
            covered = int(sum(bool(r["covered"]) for r in items))
            low, high = wilson(covered, len(items))
            out.append({"variant": variant, "parameter": kind, "n": len(items), "coverage": covered / len(items),
                        "coverage_low": low, "coverage_high": high, "mean_z": float(z.mean()), "rms_z": float(np.sqrt(np.mean(z**2))),
                        "sem_z": float(z.std(ddof=1) / np.sqrt(len(z))) if len(z) > 1 else float("nan"),
                        "mean_value": float(np.mean([float(r["value"]) for r in items])),
                        "mean_stderr": float(np.mean([float(r["stderr"]) for r in items]))})
    return out


def table(summary: list[dict[str, object]], variant: str) -> str:
    """The summary of one variant as a markdown table."""
    lines = ["| parameter | fits | 1-sigma coverage [95 %] | mean z (+- sem) | rms z | mean value | mean stderr |", "|---|---|---|---|---|---|---|"]
    for s in (s for s in summary if s["variant"] == variant):
        lines.append(f"| {s['parameter']} | {s['n']} | {s['coverage']:.0%} [{s['coverage_low']:.0%}, {s['coverage_high']:.0%}] | "
                     f"{s['mean_z']:+.2f} (+- {s['sem_z']:.2f}) | {s['rms_z']:.2f} | {s['mean_value']:.5g} | {s['mean_stderr']:.3g} |")
    return "\n".join(lines)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--variant", choices=VARIANTS, default="bound")
    p.add_argument("--size", type=int, default=64)
    p.add_argument("--frames", type=int, default=6)
    p.add_argument("--realisations", type=int, default=16)
    p.add_argument("--first-seed", type=int, default=1)
    p.add_argument("--truth-spp", type=int, default=256)
    p.add_argument("--fit-spp", type=int, default=16)
    p.add_argument("--max-steps", type=int, default=12)
    p.add_argument("--blur", type=float, default=0.5, help="the blur's truth in the variant inside (px)")
    p.add_argument("--out", type=Path, required=True)
    args = p.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    path = args.out / "fits.csv"
    # rows saved before the column fit_spp was made at this run's (a folder holds one count of samples)
    rows = [{"variant": r["variant"], "fit_spp": r.get("fit_spp", args.fit_spp), **r} for r in read_rows(path)] if path.exists() else []
    print(f"machine: {machine()}; commit {commit()}; {args.variant}: {args.frames} frames at {args.size} px, fit {args.fit_spp} spp, "
          f"references {args.truth_spp} spp; load {os.getloadavg()[0]:.1f}", flush=True)
    for seed in range(args.first_seed, args.first_seed + args.realisations):
        if any(r["variant"] == args.variant and int(r["seed"]) == seed for r in rows):
            continue
        new = realisation(args.size, args.frames, seed, args.variant, args.blur, args.truth_spp, args.fit_spp, args.max_steps)
        rows += new
        write_csv(path, rows)
        kd = next(r for r in new if r["parameter"] == "parts.legs.kd")
        blur = next((r for r in new if r["parameter"] == BLUR), None)
        print(f"seed {seed}: {kd['status']} {kd['steps']} steps, {kd['wall_s']} s wall, {kd['cpu_s']} s CPU, "
              f"peak {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MiB; kd {kd['value']:.5f} +- {kd['stderr']:.5f} "
              f"(z {kd['z']:+.2f}); " + (f"blur {blur['value']:.4f} +- {blur['stderr']:.4f}; " if blur else "")
              + f"chi2/dof {kd['chi2_dof']:.3f} (limit {kd['chi2_limit']:.3f}); load {os.getloadavg()[0]:.1f}", flush=True)
    summary = pooled(rows)
    write_csv(args.out / "summary.csv", summary)
    for variant in dict.fromkeys(r["variant"] for r in rows):
        text = table(summary, variant)
        (args.out / f"summary_{variant}.md").write_text(text + "\n")
        print(f"\n{variant}:\n{text}", flush=True)


if __name__ == "__main__":
    main()
