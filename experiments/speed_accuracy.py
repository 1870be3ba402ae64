"""Speed against accuracy (issue 33, item 6): a fit's wall time against the error it reaches, over the fit's
samples per pixel and its resolution, for an image fit and a light-curve fit, at small sizes.

- Image fit: the panels case (its three materials free, LM from 20 % off) fitted to a reference rendered at
  ``REFERENCE_SPP`` (no noise but its own render noise, so the error is the fit's own), at each resolution
  over the same field of view and each fit spp. Error: the largest relative error of the three materials.
- Light-curve fit: the panels case with a white body (kd 0.5) turned through ``ANGLES_DEG`` about z,
  magnitudes rendered at ``REFERENCE_SPP`` (``sf.light_curve``), the body's kd fitted from 0.3
  (``sf.fit_light_curve``, 0.01 mag stated error) at each resolution and fit spp. Error: |kd / 0.5 - 1|.

Each row: kind, resolution, spp, wall time of the fit call (set-up and JAX's compilation included, which
every fit pays again; the process warm: a first fit of each kind is run and not recorded), steps, error.
The rows that no other row beats in both time and error are the front; the default spp (16: the panels
case's scene and ``sf.FitRender``'s default of the scene's spp) at the largest resolution measured is marked.
The CSV is written after each row; ``--plot-only`` draws the chart from it again. Writes ``speed_accuracy.csv`` and
``speed_accuracy.png`` to ``--out`` and prints the table with the machine's load.
Run: ``.venv/bin/python experiments/speed_accuracy.py [--out experiments/results/speed_accuracy]``.
"""

from __future__ import annotations

import argparse
import csv
import functools
import os
import time
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from studyio import machine, save_figure, write_csv  # noqa: E402

import spacefit as sf  # noqa: E402

REFERENCE_SPP = 512
SPPS = (2, 4, 8, 16, 32)
IMAGE_RESOLUTIONS = (32, 64)
CURVE_RESOLUTIONS = (12, 24)
ANGLES_DEG = (0.0, 72.0, 144.0, 216.0, 288.0)
FIT_FIELD_PX, FIT_PITCH_MM = 128, 37.5  # the panels case's field of view: 128 px of 37.5 mm


def image_scene(size: int) -> sf.Scene:
    """The panels case's truth at ``size`` x ``size`` px over its own field of view."""
    return sf.load_case("panels").truth_scene.with_values({"render.resolution": [size, size],
                                                           "camera.pixel_pitch_mm": FIT_PITCH_MM * FIT_FIELD_PX / size})


@functools.cache
def image_reference(size: int) -> np.ndarray:
    """The image fit's reference at ``size`` px, rendered at REFERENCE_SPP."""
    return np.asarray(sf.render(image_scene(size).with_values({"render.spp": REFERENCE_SPP, "render.seed": 11})))


def image_fit(size: int, spp: int) -> dict[str, object]:
    """One image fit at ``size`` px and ``spp``; its row."""
    case = sf.load_case("panels")
    truth, reference = image_scene(size), image_reference(size)
    t0 = time.perf_counter()
    result = sf.fit(sf.Observation(truth, reference), list(case.free), start={n: 1.2 * v for n, v in case.truth.items()},
                    render=sf.FitRender(spp=spp), max_steps=30)
    wall = time.perf_counter() - t0
    error = max(abs(result.values[n] / v - 1.0) for n, v in case.truth.items())
    return {"kind": "image", "resolution": size, "spp": spp, "wall_s": round(wall, 3), "steps": result.steps, "error": error}


def curve_scene(size: int) -> sf.Scene:
    """The panels case with a white body (kd 0.5) at ``size`` x ``size`` px over a 2400 mm field."""
    return sf.load_case("panels").truth_scene.with_values({"render.resolution": [size, size], "camera.pixel_pitch_mm": 2400.0 / size,
                                                           "parts.body.material": "white_paint", "parts.body.kd": 0.5})


@functools.cache
def curve_reference(size: int) -> np.ndarray:
    """The light-curve fit's magnitudes at ``size`` px, rendered at REFERENCE_SPP."""
    return sf.light_curve(curve_scene(size).with_values({"render.spp": REFERENCE_SPP}), attitude_deg=list(ANGLES_DEG), quiet=True).magnitude


def curve_fit(size: int, spp: int) -> dict[str, object]:
    """One light-curve fit at ``size`` px and ``spp``; its row."""
    scene = curve_scene(size)
    t0 = time.perf_counter()
    result = sf.fit_light_curve(scene.with_values({"parts.body.kd": 0.3, "render.spp": spp}), ["parts.body.kd"],
                                [{"target.attitude_z_deg": a} for a in ANGLES_DEG], curve_reference(size), 0.01, quiet=True)
    wall = time.perf_counter() - t0
    return {"kind": "light curve", "resolution": size, "spp": spp, "wall_s": round(wall, 3), "steps": result.steps,
            "error": abs(result.values["parts.body.kd"] / 0.5 - 1.0)}


def front(rows: list[dict[str, object]]) -> list[dict[str, object]]:
    """The rows no other row of their kind beats in both wall time and error, fastest first."""
    return sorted((r for r in rows if not any(o is not r and o["kind"] == r["kind"] and o["wall_s"] <= r["wall_s"] and o["error"] < r["error"]
                                              for o in rows)), key=lambda r: r["wall_s"])


def plot(rows: list[dict[str, object]], defaults: dict[str, tuple[int, int]], path: Path) -> None:
    """Error against wall time per kind, one line per resolution through its spp, the front and the default marked."""
    kinds = sorted({r["kind"] for r in rows})
    fig, axes = plt.subplots(1, len(kinds), figsize=(5.0 * len(kinds), 3.8))
    for ax, kind in zip(np.atleast_1d(axes), kinds):
        mine = [r for r in rows if r["kind"] == kind]
        for size in sorted({r["resolution"] for r in mine}):
            line = sorted((r for r in mine if r["resolution"] == size), key=lambda r: r["spp"])
            ax.loglog([r["wall_s"] for r in line], [max(r["error"], 1e-5) for r in line], "o-", label=f"{size} x {size} px")
            for r in line:
                ax.annotate(str(r["spp"]), (r["wall_s"], max(r["error"], 1e-5)), fontsize=7, xytext=(3, 3), textcoords="offset points")
        best = front(mine)
        ax.loglog([r["wall_s"] for r in best], [max(r["error"], 1e-5) for r in best], "k--", lw=0.8, label="front")
        default = next(r for r in mine if (r["resolution"], r["spp"]) == defaults[kind])
        ax.plot(default["wall_s"], max(default["error"], 1e-5), "r*", ms=12, label="default")
        ax.set_xlabel("fit wall time, s")
        ax.set_ylabel("largest relative error of the fitted values")
        ax.set_title(f"{kind} fit (labels: spp)", fontsize=9)
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=7)
    save_figure(fig, path)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", type=Path, default=Path(__file__).resolve().parent / "results" / "speed_accuracy")
    p.add_argument("--plot-only", action="store_true", help="draw the chart and print the fronts of the saved speed_accuracy.csv")
    args = p.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    if args.plot_only:
        report(read_rows(args.out / "speed_accuracy.csv"), args.out)
        return
    print(f"machine: {machine()}; load {os.getloadavg()[0]:.1f}", flush=True)
    rows = []
    for kind, sizes, run in (("image", IMAGE_RESOLUTIONS, image_fit), ("light curve", CURVE_RESOLUTIONS, curve_fit)):
        run(sizes[0], SPPS[0])  # warm-up: the process's first fit of a kind loads what every later one reuses
        for size in sizes:
            for spp in SPPS:
                rows.append(run(size, spp))
                print(f"{kind:12s} {size:3d} px {spp:3d} spp: {rows[-1]['wall_s']:6.2f} s, {rows[-1]['steps']:2d} steps, "
                      f"error {rows[-1]['error']:.2%}; load {os.getloadavg()[0]:.1f}", flush=True)
                write_csv(args.out / "speed_accuracy.csv", rows)  # after each row: a run cut short keeps what it measured
    report(rows, args.out)


def read_rows(path: Path) -> list[dict[str, object]]:
    """The rows of a saved speed_accuracy.csv, numbers as numbers."""
    with open(path, newline="") as f:
        return [{"kind": r["kind"], "resolution": int(r["resolution"]), "spp": int(r["spp"]), "wall_s": float(r["wall_s"]),
                 "steps": int(r["steps"]), "error": float(r["error"])} for r in csv.DictReader(f)]


def report(rows: list[dict[str, object]], out: Path) -> None:
    """Draw ``rows``' chart into ``out`` and print each kind's front; the default is the largest resolution measured at 16 spp."""
    defaults = {kind: (max(r["resolution"] for r in rows if r["kind"] == kind), 16) for kind in sorted({r["kind"] for r in rows})}
    plot(rows, defaults, out / "speed_accuracy.png")
    for kind in defaults:
        print(f"{kind} front: " + ", ".join(f"{r['resolution']} px {r['spp']} spp ({r['wall_s']:.1f} s, {r['error']:.2%})"
                                            for r in front([r for r in rows if r["kind"] == kind])))


if __name__ == "__main__":
    main()
