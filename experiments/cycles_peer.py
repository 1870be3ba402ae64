"""spacefit's forward render against Blender Cycles (bpy 5.0.1) at equal image error, in both views, two ways.

* **Like for like**: the same box filter in both (no neighbour-correlating splat), Cycles given the same
  window (spacefit's film window, as Cycles' render border), spacefit with its default sampler and its
  silhouette mask (:func:`spacefit.rendering.window.target_mask`, which Cycles has no equivalent of).
* **Pipeline**: each as it renders by default: spacefit's tent filter (splatted: it lowers the per-pixel
  error by correlating neighbours), its mask and default sampler; Cycles on the whole film with the
  Gaussian of the tent's standard deviation (:data:`spacefit.rendering.cycles.CYCLES_FILTERS`;
  importance-sampled, so uncorrelated); and plain Mitsuba (whole film, ``independent``, tent) as a yardstick.

For each view of ``forward_pareto.VIEWS`` (600 px, depth 2, 2 threads) and each filter the scene spacefit
assembles is exported (:func:`spacefit.rendering.cycles.export_view`: a PLY per part in world coordinates,
flat-shaded as spacefit renders it, and ``scene.json`` with the camera, sun, materials and render settings)
and rendered by ``cycles_render.py`` in ``.venv-peers`` (``make peers``). First a validation: a high-spp
Cycles render against spacefit's reference of the same filter (part means over the pixels whose centre
sees each part). Then rounds in turn, A B A B: spacefit and plain Mitsuba sweep spp in this process,
then Cycles in its own; each time is the median of ``forward_pareto.REPEATS`` renders after a first one
(Cycles: after its syncing render, with persistent data). Errors are ``studyio.relative_rmse`` against
spacefit's reference of the same filter (``forward_pareto.view_reference``) and, for Cycles, also
against its own high-spp render, so that a mismatch of models is not counted as noise. Times at equal
error are interpolated log-log (``forward_pareto.time_at_error``) and compared within each round.
Writes ``validation.csv``, ``sweep.csv``, ``equal_error.csv`` and ``cycles.png`` to ``--out``.

Run: ``make peers`` then ``.venv/bin/python experiments/cycles_peer.py [--full] [--rounds N] [--out experiments/results/cycles]``.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import tempfile
from pathlib import Path

import matplotlib
import numpy as np

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from forward_pareto import (  # noqa: E402
    REFERENCE_SEED, REPEATS, TARGET_ERRORS, VIEWS, label_view_axes, time_at_error, timed, view_reference)
from studyio import machine, relative_rmse, save_figure, write_csv  # noqa: E402

from spacefit.rendering.backend import dr  # noqa: E402
from spacefit.rendering.cycles import THREADS, export_view  # noqa: E402
from spacefit.rendering.exr import read_exr  # noqa: E402
from spacefit.rendering.renderer import Renderer  # noqa: E402
from spacefit.scene.assembly import assemble  # noqa: E402
from spacefit.scene.toml import load_scene  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
PEER_PYTHON = ROOT / ".venv-peers" / "bin" / "python"
CYCLES_SCRIPT = Path(__file__).resolve().parent / "cycles_render.py"
# (spp swept, rounds, spacefit's reference spp, Cycles' reference spp)
REDUCED = ([1, 4, 16], 1, 256, 256)
FULL = ([1, 2, 4, 8, 16, 32, 64], 3, 1024, 1024)
# plain Mitsuba: the whole film, the independent sampler (the yardstick of forward_pareto.METHODS)
PLAIN = "mitsuba film, independent"
# The comparisons: filter -> (spacefit's methods: name -> (whole film?, sampler; None: the default),
# Cycles' method: (name, render only spacefit's window as a render border?)).
COMPARISONS = {
    "box": ({"spacefit": (False, None)}, ("cycles, window", True)),
    "tent": ({"spacefit": (False, None), PLAIN: (True, "independent")}, ("cycles", False)),
}
# What each comparison is called in equal_error.csv and the README.
KIND = {"box": "like for like", "tent": "pipeline"}


def render_cycles(scene_dir: Path, out: Path, spps: list[int], repeats: int, seed: int,
                  window: bool = False) -> tuple[dict, dict[int, np.ndarray]]:
    """Run ``cycles_render.py`` in ``.venv-peers`` (``window``: spacefit's window only): its timings.json
    and the first image of each spp."""
    if not PEER_PYTHON.exists():
        raise SystemExit(f"{PEER_PYTHON} is missing: run `make peers` first (bpy 5.0.1 in a venv of its own).")
    with open(out / "cycles.log", "a") as log:
        # bpy's Python imports spacefit.rendering.cycles (numpy only) from this checkout
        subprocess.run([str(PEER_PYTHON), str(CYCLES_SCRIPT), str(scene_dir), "--out", str(out), "--spp", *map(str, spps),
                        "--repeats", str(repeats), "--seed", str(seed), *(["--window"] if window else [])], check=True, stdout=log,
                       stderr=subprocess.STDOUT, env={**os.environ, "PYTHONPATH": str(ROOT)})
    timings = json.loads((out / "timings.json").read_text())
    return timings, {spp: read_exr(out / f"cycles_{spp}.exr")[..., :3] for spp in spps}


def validation_rows(view: str, renderer: Renderer, spacefit_ref: np.ndarray, cycles_ref: np.ndarray) -> list[dict[str, object]]:
    """Per part (pixels whose centre sees it) and for the whole target: both renderers' mean radiance and their ratio."""
    parts = renderer.part_image()
    ours, theirs = parts.table(spacefit_ref), parts.table(cycles_ref)
    return [{"view": view, "part": name, "pixels": int(ours.pixels.sel(region=name)),
             "spacefit_mean": round(float(ours.mean_radiance.sel(region=name)), 6),
             "cycles_mean": round(float(theirs.mean_radiance.sel(region=name)), 6),
             "cycles_over_spacefit": round(float(theirs.mean_radiance.sel(region=name) / ours.mean_radiance.sel(region=name)), 5)}
            for name in ours.region.values.tolist()]


def run_view(view: str, extra: list[str], full: bool, rounds: int | None) -> tuple[list[dict], list[dict], list[dict]]:
    """Validation, sweep and equal-error rows of one view (see the module docstring)."""
    spps, default_rounds, reference_spp, cycles_reference_spp = FULL if full else REDUCED
    validation, sweep, equal = [], [], []
    for pixel_filter, (methods, (cycles_method, window)) in COMPARISONS.items():
        base = ["render.deterministic=false", f'render.filter="{pixel_filter}"', *extra]
        spacefit_ref = view_reference([f'render.filter="{pixel_filter}"', *extra], reference_spp)
        renderers = {name: Renderer(assemble(load_scene(None, [*base, *([f'render.sampler="{sampler}"'] if sampler else [])])), crop=not film)
                     for name, (film, sampler) in methods.items()}
        ours = renderers["spacefit"]
        with tempfile.TemporaryDirectory() as tmp:
            scene_dir, cycles_out = Path(tmp) / "scene", Path(tmp) / "cycles"
            cycles_out.mkdir()
            export_view(ours.assembly, scene_dir)
            _, ref_images = render_cycles(scene_dir, cycles_out, [cycles_reference_spp], 1, REFERENCE_SEED, window)
            cycles_ref = ref_images[cycles_reference_spp]
            rows = validation_rows(view, ours, spacefit_ref, cycles_ref)
            rows.append({"view": view, "part": "rel_rmse(cycles_ref, spacefit_ref)", "pixels": "", "spacefit_mean": "", "cycles_mean": "",
                         "cycles_over_spacefit": round(relative_rmse(cycles_ref, spacefit_ref), 5)})
            validation += [{"filter": pixel_filter, **row} for row in rows]
            runs = []
            for r in range(rounds or default_rounds):
                load = os.getloadavg()[0]
                for spp in spps:
                    for name, renderer in renderers.items():
                        time_s, image = timed(renderer, spp)
                        error = round(relative_rmse(image, spacefit_ref), 5)  # Mitsuba's own reference is spacefit's
                        runs.append({"view": view, "filter": pixel_filter, "round": r, "method": name, "spp": spp,
                                     "sampler": renderer.assembly.scene.render.sampler, "time_s": round(time_s, 5),
                                     "rel_rmse": error, "rel_rmse_own_ref": error, "threads": dr.thread_count(), "load_1min": round(load, 2)})
                timings, images = render_cycles(scene_dir, cycles_out, spps, REPEATS, 1 + r * REPEATS, window)
                load = os.getloadavg()[0]
                runs += [{"view": view, "filter": pixel_filter, "round": r, "method": cycles_method, "spp": spp,
                          "sampler": timings["sampling_pattern"], "time_s": round(statistics.median(timings["renders"][str(spp)]), 5),
                          "rel_rmse": round(relative_rmse(images[spp], spacefit_ref), 5),
                          "rel_rmse_own_ref": round(relative_rmse(images[spp], cycles_ref), 5),
                          "threads": timings["threads"], "load_1min": round(load, 2)} for spp in spps]
                print(f"{view}, {pixel_filter}, round {r}, {cycles_method}: build {timings['build_s']:.2f} s, first render "
                      f"{timings['first_render_s']:.2f} s, {timings['sampling_pattern']}, Blender {timings['blender']}", flush=True)
        sweep += runs
        equal += equal_error_rows(view, pixel_filter, runs, cycles_method)
    return validation, sweep, equal


def _time_at(rows: list[dict], method: str, target: float, key: str = "rel_rmse") -> float:
    """``forward_pareto.time_at_error`` of one method's rows, its error read from column ``key``."""
    return time_at_error([{"rel_rmse": row[key], "time_s": row["time_s"]} for row in rows if row["method"] == method], target)


def equal_error_rows(view: str, pixel_filter: str, sweep: list[dict], cycles_method: str) -> list[dict]:
    """Per round and target error: the times of spacefit, Cycles (against spacefit's reference and its own)
    and plain Mitsuba where timed, at that error, and spacefit's time over each."""
    rows = []
    for r in sorted({row["round"] for row in sweep}):
        runs = [row for row in sweep if row["round"] == r]
        for target in TARGET_ERRORS:
            # plain Mitsuba is timed in the pipeline comparison only (NaN in the other: every row has the same columns)
            t = {"spacefit": _time_at(runs, "spacefit", target), "cycles": _time_at(runs, cycles_method, target),
                 "cycles_own_ref": _time_at(runs, cycles_method, target, "rel_rmse_own_ref"), "plain": _time_at(runs, PLAIN, target)}
            rows.append({"view": view, "comparison": KIND[pixel_filter], "filter": pixel_filter, "cycles": cycles_method, "round": r,
                         "rel_rmse": target, **{f"{k}_s": round(v, 5) for k, v in t.items()},
                         **{f"spacefit_over_{k}": round(t["spacefit"] / t[k], 4) for k in t if k != "spacefit"}})
    return rows


def plot(path: Path, sweep: list[dict], reference_spp: int) -> None:
    """Error against time per method (median time, mean error over rounds), one panel per view."""
    fig, axes = plt.subplots(1, len(VIEWS), figsize=(11, 4.5))
    curves = [("box", "spacefit", "rel_rmse", "spacefit, box (like for like)", "o-"),
              ("box", "cycles, window", "rel_rmse", "Cycles, box, spacefit's window (like for like)", "v-"),
              ("tent", "spacefit", "rel_rmse", "spacefit, tent (pipeline; correlates neighbours)", "o--"),
              ("tent", "cycles", "rel_rmse", "Cycles, Gaussian, whole film (pipeline)", "D--"),
              ("tent", PLAIN, "rel_rmse", "plain Mitsuba (film, independent, tent)", "s:")]
    for ax, view in zip(axes, VIEWS):
        for pixel_filter, method, key, label, style in curves:
            rows = [r for r in sweep if r["view"] == view and r["filter"] == pixel_filter and r["method"] == method]
            spps = sorted({r["spp"] for r in rows})
            t = [statistics.median(r["time_s"] for r in rows if r["spp"] == s) for s in spps]
            e = [statistics.mean(r[key] for r in rows if r["spp"] == s) for s in spps]
            ax.plot(t, e, style, ms=4, label=label)
    label_view_axes(axes, reference_spp, THREADS)
    save_figure(fig, path)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", type=Path, default=Path("experiments/results/cycles"))
    p.add_argument("--full", action="store_true", help="spp 1-64, 3 rounds, 1024 spp references (about 25 min)")
    p.add_argument("--rounds", type=int, help="rounds of the sweep (default: 1, or 3 with --full)")
    args = p.parse_args()
    dr.set_thread_count(THREADS)
    args.out.mkdir(parents=True, exist_ok=True)
    print(f"{machine()}, load {os.getloadavg()}")
    validation, sweep, summary = [], [], []
    for view, extra in VIEWS.items():
        v, s, e = run_view(view, extra, args.full, args.rounds)
        validation, sweep, summary = validation + v, sweep + s, summary + e
        for row in v + e:
            print(row)
    write_csv(args.out / "validation.csv", validation)
    write_csv(args.out / "sweep.csv", sweep)
    write_csv(args.out / "equal_error.csv", summary)
    plot(args.out / "cycles.png", sweep, (FULL if args.full else REDUCED)[2])


if __name__ == "__main__":
    main()
