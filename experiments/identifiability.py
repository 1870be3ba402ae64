"""Identifiability of D and G against range and resolution at the thesis's optics.

The thesis's scene (Table 4-2: f = 7000 mm, field of view 19.5 deg, target attitude [90, 0, 0],
sun along the view) with the thesis's wrinkles read literally (``data/scenes/thesis-literal.toml``:
D 2.3, G 10 m, L 0.1 m; the default scene's G is 1e-5 m since issue 13), references with 2 %
Gaussian noise; for each camera range and image width, the standard errors of D, G and the rms
height that a fit could reach, their correlation, and the Fisher information's eigenvalues (in
(D, rms height)), from :func:`spacefit.fitting.identifiability`, without fitting. Writes
``identifiability.csv`` and ``identifiability.png`` to ``--out``.

Run: ``.venv/bin/python experiments/identifiability.py [--full]``.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import matplotlib
import numpy as np
from studyio import save_figure, write_csv

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from spacefit import Observation, identifiability  # noqa: E402
from spacefit.progress import Progress  # noqa: E402
from spacefit.rendering.renderer import Renderer  # noqa: E402
from spacefit.scene.assembly import assemble  # noqa: E402
from spacefit.scene.toml import load_scene  # noqa: E402

LITERAL = Path(__file__).resolve().parents[1] / "data" / "scenes" / "thesis-literal.toml"
FREE = ["wrinkles.D", "wrinkles.G"]
NOISE = 0.02
NOISE_SEED = 11


def observation(range_m: float, width: int, spp: int) -> Observation:
    """The thesis's view from ``range_m`` at ``width`` px (same field of view), with 2 % noise."""
    scene = load_scene(LITERAL, [f"camera.position_m=[0, 0, {range_m}]", f"render.resolution=[{width}, {width}]",
                              f"camera.pixel_pitch_mm={4.0 * 600 / width}", f"render.spp={spp}", "render.seed=7"])
    image = Renderer(assemble(scene)).render()
    sigma = NOISE * float(image[image.max(axis=-1) > 0].mean())
    noisy = image + np.random.default_rng(NOISE_SEED).normal(0.0, sigma, image.shape).astype(np.float32)
    return Observation(scene, noisy, sigma)


def run_identifiability(out: Path, ranges: list[float], widths: list[int], spp: int) -> list[dict[str, object]]:
    """Standard errors and Fisher eigenvalues over a range x width grid; writes CSV and PNG."""
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    progress = Progress("identifiability", delay=0.0)
    for i, d in enumerate(ranges):
        for width in widths:
            obs = observation(d, width, spp)
            info = identifiability(obs, FREE, {"wrinkles.D": obs.scene.wrinkles.D, "wrinkles.G": obs.scene.wrinkles.G})
            rows.append({
                "range_m": d, "width_px": width, "pixel_m": d * 4.0 * 600 / width / 7000.0,
                "se_D": info.stderr["wrinkles.D"], "se_G_rel": info.stderr["wrinkles.G"] / obs.scene.wrinkles.G,
                "se_rms_rel": info.extras["wrinkles.rms_m.stderr"] / info.extras["wrinkles.rms_m"],
                "corr_DG": float(info.correlation[0, 1]),
                "fisher_min": float(info.fisher_eigenvalues.min()), "fisher_max": float(info.fisher_eigenvalues.max()),
            })
        progress(i + 1, len(ranges))
    write_csv(out / "identifiability.csv", rows)
    fig, ax = plt.subplots(1, 2, figsize=(10, 3.8))
    for width in widths:
        sel = [r for r in rows if r["width_px"] == width]
        ax[0].semilogy([r["range_m"] for r in sel], [min(r["se_D"], 1e3) for r in sel], "o-", label=f"{width} px")
        ax[1].semilogy([r["range_m"] for r in sel], [max(r["fisher_min"], 1e-12) for r in sel], "o-", label=f"{width} px")
    ax[0].axhline(0.02, color="grey", ls=":")
    ax[0].set_ylabel("standard error of D (inf drawn at 1e3)")
    ax[1].set_ylabel("smallest Fisher eigenvalue, (D, rms)")
    for a in ax:
        a.set_xlabel("camera range (m)")
        a.legend()
    fig.suptitle("thesis optics and wrinkles, 2 % noise")
    save_figure(fig, out / "identifiability.png")
    return rows


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", default="experiments/results/identifiability")
    p.add_argument("--full", action="store_true", help="ranges 15-90 m at 150, 300, 600 px (several minutes)")
    args = p.parse_args()
    if args.full:
        rows = run_identifiability(Path(args.out), [15.0, 25.0, 40.0, 70.0, 90.0], [150, 300, 600], spp=20)
    else:
        rows = run_identifiability(Path(args.out), [25.0, 70.0], [64, 128], spp=8)
    for row in rows:
        print(row)


if __name__ == "__main__":
    main()
