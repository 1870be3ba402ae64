"""Level of detail: displaced wrinkle geometry against an effective roughness, across range.

Gentle wrinkles (``data/scenes/gentle-wrinkles.toml``: L 0.4 m, Ls 0.1 m, D 2.4, G 3e-4 m, rms
height 1.7 cm, rms slope 0.3) on the MLI body, thesis optics at 128 x 128 px. For each range, renders each model twice (two seeds) at the
same samples per pixel and records, over the geometry's lit pixels:

- ``error_effective``: relative RMSE of the effective image against the geometry image;
- ``noise_geometry`` / ``noise_effective``: relative RMSE between each model's two seeds, which is
  sqrt(2) times its Monte Carlo noise;
- ``bias_effective``: the error with both noises taken out, sqrt(error^2 - noise_g^2/2 - noise_e^2/2)
  (0 when negative): the part that more samples would not remove, which the tolerance
  (:data:`spacefit.scene.lod.LOD_TOLERANCE`) bounds; ``bias_interior`` / ``bias_edge`` split it
  (squares add up) between pixels whose four neighbours are lit and the target's edge pixels;
- ``flux_ratio``: total radiance of the effective image over the geometry's;
- the cost of each model (assembly + one render, after a warm-up), and ``speedup_equal_noise``:
  what the geometry costs over what the effective model costs at the geometry's noise, which
  needs (noise_e / noise_g)^2 of the samples;
- the model ``wrinkles.model = 'auto'`` picks.

Writes ``lod.csv`` and ``lod.png`` to ``--out``.

Run: ``.venv/bin/python experiments/lod_study.py [--quick] [--ranges M ...] [--spp N]``.
"""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path

import matplotlib
import numpy as np
from studyio import save_figure, write_csv

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from spacefit.progress import Progress  # noqa: E402
from spacefit.rendering.renderer import Renderer  # noqa: E402
from spacefit.scene.assembly import assemble  # noqa: E402
from spacefit.scene.sections import WrinkleSettings  # noqa: E402
from spacefit.scene.toml import load_scene
from spacefit.scene.lod import LOD_TOLERANCE  # noqa: E402

GENTLE = Path(__file__).resolve().parents[1] / "data" / "scenes" / "gentle-wrinkles.toml"


def timed_render(overrides: list[str], seed: int) -> tuple[np.ndarray, float, dict]:
    t0 = time.perf_counter()
    assembly = assemble(load_scene(GENTLE, overrides))
    image = Renderer(assembly).render(seed=seed)
    return image, time.perf_counter() - t0, assembly.lod["body"]


def run_study(out: Path, ranges: list[float], spp: int, wrinkle_seeds: tuple[int, ...] = (0,)) -> list[dict[str, object]]:
    """Measure error, noise and cost of both models at each range; write lod.csv and lod.png.

    Pixels are pooled over ``wrinkle_seeds`` (independent W-M phases), which at long range, where
    the body covers few pixels, is what makes the bias estimate precise; ``bias_upper`` adds two
    standard errors of the per-pixel estimate.
    """
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    progress = Progress("level of detail", delay=0.0)
    for model in ("geometry", "effective"):  # warm-up: JAX compilation and the cached refinement
        timed_render([f"camera.position_m=[0, 0, {ranges[0]}]", "render.spp=1", f"wrinkles.model='{model}'"], 0)
    for i, d in enumerate(ranges):
        base = [f"camera.position_m=[0, 0, {d}]", f"render.spp={spp}"]
        effective, t_effective, _ = timed_render(base + ["wrinkles.model='effective'"], seed=3)
        effective2, _, _ = timed_render(base + ["wrinkles.model='effective'"], seed=4)
        auto = assemble(load_scene(GENTLE, base + ["wrinkles.model='auto'"])).lod["body"]
        # per lit pixel and channel: geometry, effective, and the squared differences effective - geometry,
        # geometry seed to seed, effective seed to seed
        pooled: list[np.ndarray] = []
        t_geometry = 0.0
        for ws in wrinkle_seeds:
            geometry, t, choice = timed_render(base + ["wrinkles.model='geometry'", f"wrinkles.seed={ws}"], seed=1)
            geometry2, _, _ = timed_render(base + ["wrinkles.model='geometry'", f"wrinkles.seed={ws}"], seed=2)
            t_geometry += t / len(wrinkle_seeds)
            lit = geometry.max(axis=-1) > 0
            interior = lit & np.all([np.roll(lit, s, axis=a) for s in (1, -1) for a in (0, 1)], axis=0)
            g = geometry[lit]
            e = effective[lit]
            pooled.append(np.stack([g, e, (e - g) ** 2, (geometry2[lit] - g) ** 2, (effective2[lit] - e) ** 2,
                                    np.broadcast_to(interior[lit][:, None], g.shape)]))
        g, e, d_error, d_geometry, d_effective, inside = np.concatenate(pooled, axis=1)
        inside = inside[:, 0] > 0
        m2 = g.mean() ** 2
        error, noise_g, noise_e = (math.sqrt(x.mean() / m2) for x in (d_error, d_geometry, d_effective))
        # per pixel, an unbiased estimate of bias^2 * m^2; its standard error gives an upper bound
        bias2 = (d_error - d_geometry / 2 - d_effective / 2).mean(axis=-1)
        bias2_upper = (bias2.mean() + 2 * bias2.std() / math.sqrt(bias2.size)) / m2
        # the bias's share from interior and from edge pixels, same normalisation (squares add up)
        shares = {name: round(math.sqrt(max(bias2[mask].sum() / bias2.size / m2, 0.0)), 4)
                  for name, mask in (("bias_interior", inside), ("bias_edge", ~inside))}

        rows.append({
            "range_m": d, "footprint_m": round(choice.footprint_m, 4), "footprint_over_L": round(choice.footprint_over_L, 3),
            "lit_pixels": len(g),
            "error_effective": round(error, 4), "noise_geometry": round(noise_g, 4), "noise_effective": round(noise_e, 4),
            "bias_effective": round(math.sqrt(max(bias2.mean() / m2, 0.0)), 4),
            "bias_upper": round(math.sqrt(max(bias2_upper, 0.0)), 4),
            "interior_pixels": int(inside.sum()), **shares,
            "flux_ratio": round(float(e.sum() / g.sum()), 4),
            "time_geometry_s": round(t_geometry, 3), "time_effective_s": round(t_effective, 3),
            "speedup_equal_noise": round(t_geometry / (t_effective * (noise_e / noise_g) ** 2), 1),
            "auto_model": auto.model, "effective_alpha": round(choice.effective_alpha, 4),
        })
        progress(i + 1, len(ranges))
    write_csv(out / "lod.csv", rows)
    plot(rows, out / "lod.png", spp, len(wrinkle_seeds))
    return rows


def plot(rows: list[dict[str, object]], path: Path, spp: int, seeds: int) -> None:
    """Error, bias and noise of the models against footprint / L (left), their cost (right)."""
    fig, ax = plt.subplots(1, 2, figsize=(10, 3.8))
    ratio = [r["footprint_over_L"] for r in rows]
    ax[0].plot(ratio, [r["error_effective"] for r in rows], "o-", label="effective vs geometry")
    ax[0].plot(ratio, [r["bias_effective"] for r in rows], "o-", label="the same, noise taken out (bias)")
    ax[0].plot(ratio, [r["bias_upper"] for r in rows], "v:", label="bias + 2 standard errors")
    ax[0].plot(ratio, [r["noise_geometry"] for r in rows], "s--", label="geometry, seed to seed")
    ax[0].plot(ratio, [r["noise_effective"] for r in rows], "s--", label="effective, seed to seed")
    ax[0].axhline(LOD_TOLERANCE, color="k", lw=0.8, ls=":", label=f"tolerance {LOD_TOLERANCE:g}")
    ax[0].axvline(WrinkleSettings.lod_footprint, color="k", lw=0.8, ls="-.",
                  label=f"default lod_footprint {WrinkleSettings.lod_footprint:g}")
    ax[0].set_xscale("log")
    ax[0].set_yscale("log")
    ax[0].set_xlabel("pixel footprint / L")
    ax[0].set_ylabel("relative RMSE (lit pixels)")
    ax[0].legend(fontsize=7)
    ax[1].plot(ratio, [r["time_geometry_s"] for r in rows], "o-", label="geometry")
    ax[1].plot(ratio, [r["time_effective_s"] for r in rows], "s-", label="effective, same spp")
    ax[1].plot(ratio, [r["time_geometry_s"] / r["speedup_equal_noise"] for r in rows], "s--",
               label="effective, at the geometry's noise")
    ax[1].set_xscale("log")
    ax[1].set_yscale("log")
    ax[1].set_xlabel("pixel footprint / L")
    ax[1].set_ylabel("assembly + render (s)")
    ax[1].legend()
    fig.suptitle(f"level of detail, gentle wrinkles, 128 x 128 px, {spp} spp, {seeds} wrinkle seed(s)")
    save_figure(fig, path)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", default="experiments/results/lod")
    p.add_argument("--quick", action="store_true", help="three ranges, 32 spp, one wrinkle seed")
    p.add_argument("--ranges", type=float, nargs="+", metavar="M", help="camera ranges, m (default: --quick's or the full study's)")
    p.add_argument("--spp", type=int, help="samples per pixel (default: 32 with --quick, else 4096)")
    args = p.parse_args()
    ranges = args.ranges or ([15.0, 60.0, 240.0] if args.quick else [10.0, 20.0, 40.0, 70.0, 120.0, 200.0, 350.0, 450.0, 600.0, 800.0])
    spp = args.spp or (32 if args.quick else 4096)
    for row in run_study(Path(args.out), ranges, spp, (0,) if args.quick else (0, 1, 2, 3)):
        print(row)


if __name__ == "__main__":
    main()
