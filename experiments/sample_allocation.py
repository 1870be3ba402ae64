"""What spending samples where radiance varies could buy: the bound on adaptive sampling.

The forward study's error is the relative RMSE over lit pixels (``studyio.relative_rmse``), whose
square is the mean over lit pixels of the per-pixel variance sigma_i^2 / n_i at n_i samples. With
the same total of samples, that mean is smallest when n_i is proportional to sigma_i; then it is
(mean sigma_i)^2 / n, against mean(sigma_i^2) / n for uniform sampling. So at equal error an
ideal adaptive sampler needs ``(mean sigma)^2 / mean(sigma^2)`` of the uniform sampler's samples.
A practical one estimates sigma_i from a first pass: here a quarter of the samples, uniform, then
the rest in proportion to the spread of each pixel's first-pass samples (rendered one sample at a
time); its error follows from the true sigma_i, with no further render
(:func:`spacefit.studies.costs.allocation_gains`).

For each view of ``forward_pareto.VIEWS`` (600 px, depth 2, spacefit's mask, the default sampler ``multijitter``),
sigma_i is measured from ``--seeds`` renders at ``--spp`` (all channels of a pixel share its
samples, so sigma_i^2 is the mean of its channels' variances). It assumes a pixel's variance falls
as 1 / n (true for independent samples; stratified ones do better in smooth pixels, so the bound
is if anything generous to adaptive sampling) and that every sample costs the same. Writes
``sample_allocation.csv`` to ``--out``.

Run: ``.venv/bin/python experiments/sample_allocation.py [--seeds 16] [--spp 16]``.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from forward_pareto import REFERENCE_SEED, VIEWS
from studyio import machine, write_csv

from spacefit.rendering.renderer import Renderer
from spacefit.scene.assembly import assemble
from spacefit.scene.toml import load_scene
from spacefit.studies.costs import PILOT_FRACTION, allocation_gains


def pixel_sigma(images: np.ndarray) -> np.ndarray:
    """Per-pixel standard deviation of one render from ``images`` (seeds, h, w, c): the root mean
    over channels of the variance across seeds."""
    return np.sqrt(images.var(axis=0, ddof=1).mean(axis=-1))


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", type=Path, default=Path("experiments/results/forward"))
    p.add_argument("--seeds", type=int, default=16, help="renders per view to measure each pixel's variance")
    p.add_argument("--spp", type=int, default=16)
    p.add_argument("--reference-spp", type=int, default=1024)
    args = p.parse_args()
    rows = []
    for view, extra in VIEWS.items():
        base = ["render.deterministic=false", *extra]
        renderer = Renderer(assemble(load_scene(None, base)))  # the default sampler, multijitter
        lit = renderer.render(spp=args.reference_spp, seed=REFERENCE_SEED).max(axis=-1) > 0
        images = np.stack([renderer.render(spp=args.spp, seed=seed) for seed in range(1, args.seeds + 1)])
        # the first pass's samples one at a time: their spread is each pixel's per-sample sigma
        pilot = np.stack([renderer.render(spp=1, seed=seed)
                          for seed in range(args.seeds + 1, args.seeds + 1 + max(2, round(PILOT_FRACTION * args.spp)))])
        sigma, pilot_sigma = pixel_sigma(images)[lit], pixel_sigma(pilot)[lit]
        gains = allocation_gains(sigma, pilot_sigma)
        top = np.sort(sigma**2)[::-1]
        rows.append({"view": view, "spp": args.spp, "seeds": args.seeds, "lit_pixels": int(lit.sum()),
                     "variance_share_of_top_1pct_pixels": round(float(top[: max(1, top.size // 100)].sum() / top.sum()), 4),
                     "samples_at_equal_error_ideal": round(gains["ideal"], 4),
                     "samples_at_equal_error_two_pass": round(gains["two_pass"], 4)})
        print(rows[-1], flush=True)
    args.out.mkdir(parents=True, exist_ok=True)
    write_csv(args.out / "sample_allocation.csv", rows)
    print(f"{machine()}; wrote {args.out / 'sample_allocation.csv'}")


if __name__ == "__main__":
    main()
