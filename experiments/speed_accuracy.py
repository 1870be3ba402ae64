"""Speed against accuracy (issue 33, item 6): a fit's cost against the error it reaches, over the fit's
samples per pixel and its resolution, for an image fit and a light-curve fit, at small sizes.

- Image fit: the panels case (its three materials free, LM from 20 % off) fitted to a reference rendered at
  ``REFERENCE_SPP`` (no noise but its own render noise, so the error is the fit's own), at each resolution
  over the same field of view and each fit spp. Error: the largest relative error of the three materials.
- Light-curve fit: the panels case with a white body (kd 0.5) at ``CURVE_SCENE_PX`` px turned through
  ``ANGLES_DEG`` about z, magnitudes rendered at ``REFERENCE_SPP`` (``sf.light_curve``), the body's kd fitted
  from 0.3 (``sf.fit_light_curve``, 0.01 mag stated error) on each film (``film_px``) and fit spp, and once
  with the film the fit chooses itself (``film_px`` None: the coarsest whose render noise is at most half the
  magnitudes' error) at the default spp. Error: |kd / 0.5 - 1|.

Each setting is fitted with ``--seeds`` render seeds; its row holds the rms of their errors and the mean
wall and CPU time of the fit call (set-up and JAX's compilation included, which every fit pays again; the
process warm: a first fit of each kind is run and not recorded). CPU time (the process's, all threads) is
the chart's axis: on a shared machine wall time is mostly waiting for a core. The rows that no other row
beats in both CPU time and error are the front; the default (16 spp, the panels case's scene and
``sf.FitRender``'s default of the scene's; for the light curve the film it chooses) is marked. The CSV
is written after each setting; ``--plot-only`` draws the chart from it again. Writes ``speed_accuracy.csv``
and ``speed_accuracy.png`` to ``--out`` and prints the table with the machine's load and commit.
Run: ``nice -n 10 .venv/bin/python experiments/speed_accuracy.py [--seeds 3] [--out DIR]``.
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
from studyio import commit, machine, save_figure, write_csv  # noqa: E402

import spacefit as sf  # noqa: E402

REFERENCE_SPP = 512
SPPS = (2, 4, 8, 16, 32)
DEFAULT_SPP = 16
IMAGE_RESOLUTIONS = (32, 64)
CURVE_SCENE_PX = 48
CURVE_FILMS = (12, 24, 48)
ANGLES_DEG = (0.0, 72.0, 144.0, 216.0, 288.0)
FIT_FIELD_PX, FIT_PITCH_MM = 128, 37.5  # the panels case's field of view: 128 px of 37.5 mm
CHOSEN = 0  # a light-curve row's resolution when the fit chose its film itself


def image_scene(size: int) -> sf.Scene:
    """The panels case's truth at ``size`` x ``size`` px over its own field of view."""
    return sf.load_case("panels").truth_scene.with_values({"render.resolution": [size, size],
                                                           "camera.pixel_pitch_mm": FIT_PITCH_MM * FIT_FIELD_PX / size})


@functools.cache
def image_reference(size: int) -> np.ndarray:
    """The image fit's reference at ``size`` px, rendered at REFERENCE_SPP."""
    return np.asarray(sf.render(image_scene(size).with_values({"render.spp": REFERENCE_SPP, "render.seed": 11})))


def image_fit(size: int, spp: int, seed: int) -> tuple[float, int]:
    """One image fit at ``size`` px, ``spp`` and render seed ``seed``: its error and step count."""
    case = sf.load_case("panels")
    result = sf.fit(sf.Observation(image_scene(size), image_reference(size)), list(case.free),
                    start={n: 1.2 * v for n, v in case.truth.items()},
                    render=sf.FitRender(spp=spp, seed=seed, seed_grad=seed + 100), max_steps=30)
    return max(abs(result.values[n] / v - 1.0) for n, v in case.truth.items()), result.steps


def curve_scene() -> sf.Scene:
    """The panels case with a white body (kd 0.5) at CURVE_SCENE_PX px over a 2400 mm field."""
    return sf.load_case("panels").truth_scene.with_values({"render.resolution": [CURVE_SCENE_PX, CURVE_SCENE_PX],
                                                           "camera.pixel_pitch_mm": 2400.0 / CURVE_SCENE_PX,
                                                           "parts.body.material": "white_paint", "parts.body.kd": 0.5})


@functools.cache
def curve_reference() -> np.ndarray:
    """The light-curve fit's magnitudes, rendered at REFERENCE_SPP."""
    return sf.light_curve(curve_scene().with_values({"render.spp": REFERENCE_SPP}), attitude_deg=list(ANGLES_DEG), quiet=True).magnitude


def curve_fit(film: int, spp: int, seed: int) -> tuple[float, int]:
    """One light-curve fit on a ``film`` px film (CHOSEN: the fit's own choice), ``spp`` and seed ``seed``: its error and step count."""
    result = sf.fit_light_curve(curve_scene().with_values({"parts.body.kd": 0.3, "render.spp": spp}), ["parts.body.kd"],
                                [{"target.attitude_z_deg": a} for a in ANGLES_DEG], curve_reference(), 0.01, seed=seed,
                                film_px=film or None, quiet=True)
    return abs(result.values["parts.body.kd"] / 0.5 - 1.0), result.steps


def setting(kind: str, size: int, spp: int, seeds: int) -> dict[str, object]:
    """The row of one setting: the rms error over ``seeds`` render seeds, the mean wall and CPU time and steps of a fit."""
    run = image_fit if kind == "image" else curve_fit
    errors, walls, cpus, steps = [], [], [], []
    for seed in range(1, seeds + 1):
        t0, c0 = time.perf_counter(), time.process_time()
        error, n = run(size, spp, 10 * seed)
        walls.append(time.perf_counter() - t0)
        cpus.append(time.process_time() - c0)
        errors.append(error)
        steps.append(n)
    return {"kind": kind, "resolution": size, "spp": spp, "seeds": seeds, "wall_s": round(float(np.mean(walls)), 3),
            "cpu_s": round(float(np.mean(cpus)), 3), "steps": round(float(np.mean(steps)), 1),
            "error": float(np.sqrt(np.mean(np.square(errors))))}


def settings() -> list[tuple[str, int, int]]:
    """Every (kind, resolution, spp) measured: each resolution at each spp, and the light curve's own film choice."""
    return ([("image", size, spp) for size in IMAGE_RESOLUTIONS for spp in SPPS]
            + [("light curve", film, spp) for film in CURVE_FILMS for spp in SPPS] + [("light curve", CHOSEN, DEFAULT_SPP)])


def is_default(row: dict[str, object]) -> bool:
    """Whether ``row`` is its kind's default: 16 spp at the largest image resolution; the film a light-curve fit chooses."""
    if row["kind"] == "image":
        return (row["resolution"], row["spp"]) == (max(IMAGE_RESOLUTIONS), DEFAULT_SPP)
    return (row["resolution"], row["spp"]) == (CHOSEN, DEFAULT_SPP)


def front(rows: list[dict[str, object]]) -> list[dict[str, object]]:
    """The rows no other row of their kind beats in both CPU time and error, cheapest first."""
    return sorted((r for r in rows if not any(o is not r and o["kind"] == r["kind"] and o["cpu_s"] <= r["cpu_s"] and o["error"] < r["error"]
                                              for o in rows)), key=lambda r: r["cpu_s"])


def label(row: dict[str, object]) -> str:
    """A setting's name: its resolution (the light curve's film, or "film chosen") and spp."""
    where = "film chosen" if row["kind"] == "light curve" and row["resolution"] == CHOSEN else f"{row['resolution']} px"
    return f"{where} {row['spp']} spp"


def plot(rows: list[dict[str, object]], path: Path) -> None:
    """Error against CPU time per kind, one line per resolution through its spp, the front and the default marked."""
    kinds = sorted({r["kind"] for r in rows})
    fig, axes = plt.subplots(1, len(kinds), figsize=(5.0 * len(kinds), 3.8))
    for ax, kind in zip(np.atleast_1d(axes), kinds):
        mine = [r for r in rows if r["kind"] == kind]
        for size in sorted({r["resolution"] for r in mine} - {CHOSEN}):
            line = sorted((r for r in mine if r["resolution"] == size), key=lambda r: r["spp"])
            ax.loglog([r["cpu_s"] for r in line], [max(r["error"], 1e-5) for r in line], "o-",
                      label=f"{size} x {size} px" + (" film" if kind == "light curve" else ""))
            for r in line:
                ax.annotate(str(r["spp"]), (r["cpu_s"], max(r["error"], 1e-5)), fontsize=7, xytext=(3, 3), textcoords="offset points")
        best = front(mine)
        ax.loglog([r["cpu_s"] for r in best], [max(r["error"], 1e-5) for r in best], "k--", lw=0.8, label="front")
        for r in (r for r in mine if is_default(r)):
            ax.plot(r["cpu_s"], max(r["error"], 1e-5), "r*", ms=12, label=f"default ({label(r)})")
        ax.set_xlabel("fit CPU time, s (2 threads)")
        ax.set_ylabel("rms over seeds of the largest relative error")
        ax.set_title(f"{kind} fit (labels: spp)", fontsize=9)
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=7)
    save_figure(fig, path)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", type=Path, default=Path(__file__).resolve().parent / "results" / "speed_accuracy")
    p.add_argument("--seeds", type=int, default=3, help="render seeds per setting (the error is their rms)")
    p.add_argument("--plot-only", action="store_true", help="draw the chart and print the fronts of the saved speed_accuracy.csv")
    args = p.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    if args.plot_only:
        report(read_rows(args.out / "speed_accuracy.csv"), args.out)
        return
    print(f"machine: {machine()}; commit {commit()}; load {os.getloadavg()[0]:.1f}", flush=True)
    image_fit(IMAGE_RESOLUTIONS[0], SPPS[0], 1)  # warm-up: the process's first fit of a kind loads what every later one reuses
    curve_fit(CURVE_FILMS[0], SPPS[0], 1)
    rows = []
    for kind, size, spp in settings():
        rows.append(setting(kind, size, spp, args.seeds))
        r = rows[-1]
        print(f"{kind:12s} {label(r):22s}: {r['cpu_s']:6.2f} s CPU, {r['wall_s']:6.2f} s wall, {r['steps']:4.1f} steps, "
              f"rms error {r['error']:.2%}; load {os.getloadavg()[0]:.1f}", flush=True)
        write_csv(args.out / "speed_accuracy.csv", rows)  # after each setting: a run cut short keeps what it measured
    report(rows, args.out)


def read_rows(path: Path) -> list[dict[str, object]]:
    """The rows of a saved speed_accuracy.csv, numbers as numbers."""
    with open(path, newline="") as f:
        return [{"kind": r["kind"], "resolution": int(r["resolution"]), "spp": int(r["spp"]), "seeds": int(r["seeds"]),
                 "wall_s": float(r["wall_s"]), "cpu_s": float(r["cpu_s"]), "steps": float(r["steps"]), "error": float(r["error"])}
                for r in csv.DictReader(f)]


def report(rows: list[dict[str, object]], out: Path) -> None:
    """Draw ``rows``' chart into ``out`` and print each kind's front and whether its default is on it."""
    plot(rows, out / "speed_accuracy.png")
    for kind in sorted({r["kind"] for r in rows}):
        best = front([r for r in rows if r["kind"] == kind])
        default = next((r for r in rows if r["kind"] == kind and is_default(r)), None)
        print(f"{kind} front: " + ", ".join(f"{label(r)} ({r['cpu_s']:.1f} s CPU, {r['error']:.2%})" for r in best)
              + (f"; default {label(default)} {'on' if default in best else 'NOT on'} the front" if default else ""))


if __name__ == "__main__":
    main()
