"""Forward cost against image error for the default scene (thesis Table 4-2): the Pareto front.

Sweeps samples per pixel, resolution (the thesis's field of view kept: pixel pitch 4 mm * 600 /
width) and trace depth. Image error is the relative RMSE over the reference's lit pixels
(``studyio.relative_rmse``) against a high-sample reference of the same resolution at the
deepest depth swept, rendered with another seed: at shallower depths it holds the bias of the
missing bounces as well as the noise. Wall time is the median of a few renders after a first
(compiling) render, with ``render.deterministic=false`` (all render threads; the CSV's ``threads``
column). Writes ``forward.csv`` and ``forward_pareto.png`` to ``--out``.

Run: ``.venv/bin/python experiments/forward_pareto.py [--full] [--out experiments/results/forward]``.
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import matplotlib
import numpy as np

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from studyio import relative_rmse, save_figure, write_csv  # noqa: E402

from spacefit.progress import Progress  # noqa: E402

# Seed of the high-spp references: the synthetic cases' (data/synthetic/*.toml), never a test render's.
REFERENCE_SEED = 7
from spacefit.rendering.renderer import Renderer  # noqa: E402
from spacefit.rendering.backend import dr  # noqa: E402
from spacefit.scene.assembly import assemble  # noqa: E402
from spacefit.scene.config import load_scene  # noqa: E402

# (widths px, spp values, depths, reference spp)
REDUCED = ([64, 128], [1, 2, 4, 8, 16], [1, 2, 3], 256)
FULL = ([150, 300, 600], [1, 2, 4, 8, 16, 32, 64], [1, 2, 3, 4, 5], 1024)
# Timed renders per configuration, after one untimed (compiling) render.
REPEATS = 3


def pareto_front(points: list[tuple[float, float]]) -> list[int]:
    """Indices of the non-dominated (time, error) points, sorted by time (errors then strictly fall).

    A point is dominated when another is no slower and no less accurate; of identical points the
    first is kept.
    """
    order = sorted(range(len(points)), key=lambda i: (points[i][0], points[i][1], i))
    front: list[int] = []
    for i in order:
        if not front or points[i][1] < points[front[-1]][1]:
            front.append(i)
    return front


def scene_overrides(width: int, depth: int) -> list[str]:
    """Table 4-2 scene at ``width`` x ``width`` px (same field of view), trace depth, all threads."""
    return [f"render.resolution=[{width}, {width}]", f"camera.pixel_pitch_mm={4.0 * 600 / width}",
            f"render.depth={depth}", "render.deterministic=false"]


def timed(renderer: Renderer, spp: int) -> tuple[float, np.ndarray]:
    """Median wall time (s) of REPEATS renders after a compiling one, and the first timed image."""
    renderer.render(spp=spp, seed=0)
    times, images = [], []
    for seed in range(1, REPEATS + 1):
        t0 = time.perf_counter()
        images.append(renderer.render(spp=spp, seed=seed))
        times.append(time.perf_counter() - t0)
    return statistics.median(times), images[0]


def run_forward(out: Path, full: bool) -> list[dict[str, object]]:
    """Time and error of every (resolution, spp, depth); write forward.csv and forward_pareto.png."""
    widths, spps, depths, reference_spp = FULL if full else REDUCED
    out.mkdir(parents=True, exist_ok=True)
    rows: list[dict[str, object]] = []
    progress = Progress("forward cost", delay=0.0)
    total = len(widths) * len(depths)
    for i, width in enumerate(widths):
        reference = Renderer(assemble(load_scene(None, scene_overrides(width, max(depths))))).render(
            spp=reference_spp, seed=REFERENCE_SEED)
        for j, depth in enumerate(depths):
            renderer = Renderer(assemble(load_scene(None, scene_overrides(width, depth))))
            for spp in spps:
                time_s, image = timed(renderer, spp)
                rows.append({"resolution": width, "spp": spp, "depth": depth, "time_s": round(time_s, 5),
                             "rel_rmse": round(relative_rmse(image, reference), 5), "threads": dr.thread_count()})
            progress(i * len(depths) + j + 1, total)
    write_csv(out / "forward.csv", rows)
    plot(out / "forward_pareto.png", rows, reference_spp, max(depths))
    return rows


def plot(path: Path, rows: list[dict[str, object]], reference_spp: int, reference_depth: int) -> None:
    """Error against time, log-log: colour per resolution, marker per depth, the Pareto front as a line."""
    fig, ax = plt.subplots(figsize=(8, 5.5))
    widths = sorted({r["resolution"] for r in rows})
    depths = sorted({r["depth"] for r in rows})
    colours = dict(zip(widths, plt.cm.viridis([k / max(len(widths) - 1, 1) for k in range(len(widths))])))
    markers = dict(zip(depths, "osD^v<>ph"))
    for r in rows:
        ax.scatter(r["time_s"], r["rel_rmse"], color=colours[r["resolution"]], marker=markers[r["depth"]], s=28,
                   alpha=0.8)
    front = [rows[i] for i in pareto_front([(r["time_s"], r["rel_rmse"]) for r in rows])]
    ax.plot([r["time_s"] for r in front], [r["rel_rmse"] for r in front], "k-", lw=1, label="Pareto front")
    for r in front:
        ax.annotate(f"{r['resolution']}px {r['spp']}spp d{r['depth']}", (r["time_s"], r["rel_rmse"]), fontsize=6,
                    xytext=(3, 3), textcoords="offset points")
    for w in widths:
        ax.scatter([], [], color=colours[w], marker="o", label=f"{w} x {w} px")
    for d in depths:
        ax.scatter([], [], color="grey", marker=markers[d], label=f"depth {d}")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel(f"render wall time (s), median of {REPEATS} after compiling, {rows[0]['threads']} threads "
                  "(render.deterministic=false)")
    ax.set_ylabel("relative RMSE over lit pixels")
    ax.set_title(f"default scene (Table 4-2 optics): error against a {reference_spp} spp, depth {reference_depth} "
                 "reference", fontsize=10)
    ax.legend(fontsize=7, ncol=2)
    save_figure(fig, path)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", default="experiments/results/forward")
    p.add_argument("--full", action="store_true", help="150/300/600 px, spp 1-64, depths 1-5, reference 1024 spp")
    args = p.parse_args()
    rows = run_forward(Path(args.out), args.full)
    front = pareto_front([(r["time_s"], r["rel_rmse"]) for r in rows])
    print(f"wrote {len(rows)} configurations to {args.out}; Pareto front:")
    for i in front:
        print(rows[i])


if __name__ == "__main__":
    main()
