"""Level of detail: displaced wrinkle geometry against an effective roughness, across range.

Gentle wrinkles (L 0.4 m, Ls 0.1 m, D 2.4, G 3e-4 m: rms height 1.7 cm, rms slope 0.3) on the MLI
body, thesis optics at 128 x 128 px. For each range, renders the displaced geometry twice (two
seeds: the noise floor) and the effective model once, all at high samples, and records the relative
RMSE of the effective image against the geometry image over the lit pixels, the noise floor, and
the cost of each (assembly + render). Writes ``lod.csv`` and ``lod.png`` to ``--out``.

Run: ``.venv/bin/python experiments/lod_study.py [--quick]``.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import matplotlib
import numpy as np
from studyio import relative_rmse, write_csv

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from spacefit.progress import Progress  # noqa: E402
from spacefit.render import Renderer  # noqa: E402
from spacefit.scene.assembly import assemble  # noqa: E402
from spacefit.scene.config import load_scene  # noqa: E402

GENTLE = ["wrinkles.L=0.4", "wrinkles.Ls=0.1", "wrinkles.D=2.4", "wrinkles.G=3e-4", "wrinkles.spacing_m=0.03",
          "render.resolution=[128, 128]", "camera.pixel_pitch_mm=18.75", "target.attitude_deg=[20, 30, 0]",
          "sun.direction=[0.3, -0.2, -1]"]


def timed_render(overrides: list[str], seed: int) -> tuple[np.ndarray, float, dict]:
    t0 = time.perf_counter()
    assembly = assemble(load_scene(None, overrides))
    image = Renderer(assembly).render(seed=seed)
    return image, time.perf_counter() - t0, assembly.lod["body"]


def run_study(out: Path, ranges: list[float], spp: int) -> list[dict[str, object]]:
    """Measure error and cost of both models at each range; write lod.csv and lod.png."""
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    progress = Progress("level of detail", delay=0.0)
    for i, d in enumerate(ranges):
        base = GENTLE + [f"camera.position_m=[0, 0, {d}]", f"render.spp={spp}"]
        geometry, t_geometry, choice = timed_render(base + ["wrinkles.model='geometry'"], seed=1)
        geometry2, _, _ = timed_render(base + ["wrinkles.model='geometry'"], seed=2)
        effective, t_effective, _ = timed_render(base + ["wrinkles.model='effective'"], seed=1)
        auto = assemble(load_scene(None, base + ["wrinkles.model='auto'"])).lod["body"]
        rows.append({
            "range_m": d, "footprint_m": round(choice.footprint_m, 4), "footprint_over_L": round(choice.footprint_over_L, 3),
            "error_effective": round(relative_rmse(effective, geometry), 4),
            "flux_ratio": round(float(effective.sum() / geometry.sum()), 4),
            "noise_floor": round(relative_rmse(geometry2, geometry), 4),
            "time_geometry_s": round(t_geometry, 3), "time_effective_s": round(t_effective, 3),
            "auto_model": auto.model, "effective_alpha": choice.effective_alpha,
        })
        progress(i + 1, len(ranges))
    write_csv(out / "lod.csv", rows)
    fig, ax = plt.subplots(1, 2, figsize=(10, 3.8))
    ratio = [r["footprint_over_L"] for r in rows]
    ax[0].plot(ratio, [r["error_effective"] for r in rows], "o-", label="effective vs geometry")
    ax[0].plot(ratio, [r["noise_floor"] for r in rows], "s--", label="geometry, seed to seed")
    ax[0].set_xscale("log")
    ax[0].set_xlabel("pixel footprint / L")
    ax[0].set_ylabel("relative RMSE (lit pixels)")
    ax[0].legend()
    ax[1].plot(ratio, [r["time_geometry_s"] for r in rows], "o-", label="geometry")
    ax[1].plot(ratio, [r["time_effective_s"] for r in rows], "s-", label="effective")
    ax[1].set_xscale("log")
    ax[1].set_xlabel("pixel footprint / L")
    ax[1].set_ylabel("assembly + render (s)")
    ax[1].legend()
    fig.suptitle(f"level of detail, gentle wrinkles, 128 x 128 px, {spp} spp")
    fig.tight_layout()
    fig.savefig(out / "lod.png", dpi=110)
    plt.close(fig)
    return rows


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", default="experiments/results/lod")
    p.add_argument("--quick", action="store_true", help="three ranges, 32 spp")
    args = p.parse_args()
    ranges = [15.0, 60.0, 240.0] if args.quick else [10.0, 20.0, 40.0, 70.0, 120.0, 200.0, 350.0]
    for row in run_study(Path(args.out), ranges, 32 if args.quick else 256):
        print(row)


if __name__ == "__main__":
    main()
