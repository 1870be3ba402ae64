"""Forward cost against image error for the default scene (thesis Table 4-2): the Pareto front.

Sweeps samples per pixel, resolution (the thesis's field of view kept: pixel pitch 4 mm * 600 /
width) and trace depth. Image error is the relative RMSE over the reference's lit pixels
(``studyio.relative_rmse``) against a high-sample reference of the same resolution at the
deepest depth swept, rendered with another seed: at shallower depths it holds the bias of the
missing bounces as well as the noise. Wall time is the median of a few renders after a first
(compiling) render, with ``render.deterministic=false`` (all render threads; the CSV's ``threads``
column). Writes ``forward.csv`` and ``forward_pareto.png`` to ``--out``.

``--mask`` times spacefit's render, which traces only the pixels whose samples can reach the target's
silhouette (:attr:`Renderer.traced`), against Mitsuba's own loop over the window's box, in turn, in both
views (``mask_pairs.csv``); ``--mask-loop WAY VIEW`` renders one way 20 times, for a whole-process timer.

``--methods`` compares ways of spending a render's time at 600 px, depth 2, in the default view
(70 m, the target 5 % of the film) and a close one (25 m): plain Mitsuba (the whole film, the
``independent`` sampler) against spacefit's window around the target with each sampler of
``render.sampler``. For each it sweeps spp and interpolates (log-log) the time at which the error
reaches each target error; writes ``methods.csv``, ``equal_error.csv`` and ``methods.png``. Then it
renders plain Mitsuba and spacefit at spp of equal error (:data:`PAIR_SPP`) in turn and writes the
time ratios within each pair to ``equal_error_pairs.csv``.

Run: ``.venv/bin/python experiments/forward_pareto.py [--full] [--methods | --mask] [--out experiments/results/forward]``.
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections.abc import Sequence
from pathlib import Path

import matplotlib
import numpy as np

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from studyio import relative_rmse, save_figure, write_csv  # noqa: E402

from spacefit.progress import Progress  # noqa: E402

# Seed of the high-spp references: the synthetic cases' (spacefit/synthetic/*.toml), never a test render's.
REFERENCE_SEED = 7
from spacefit.rendering.renderer import Renderer  # noqa: E402
from spacefit.rendering.backend import dr  # noqa: E402
from spacefit.scene.assembly import assemble  # noqa: E402
from spacefit.scene.sampling import takes_sample_count  # noqa: E402
from spacefit.scene.toml import load_scene  # noqa: E402
from spacefit.studies.costs import pareto_front  # noqa: E402

# (widths px, spp values, depths, reference spp)
REDUCED = ([64, 128], [1, 2, 4, 8, 16], [1, 2, 3], 256)
FULL = ([150, 300, 600], [1, 2, 4, 8, 16, 32, 64], [1, 2, 3, 4, 5], 1024)
# Timed renders per configuration, after one untimed (compiling) render.
REPEATS = 3


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


# name -> (render the whole film?, sampler); the first is plain Mitsuba, the yardstick.
METHODS = {
    "mitsuba film, independent": (True, "independent"),
    "window, independent": (False, "independent"),
    "window, stratified": (False, "stratified"),
    "window, multijitter": (False, "multijitter"),
    "window, ldsampler": (False, "ldsampler"),
    "window, orthogonal": (False, "orthogonal"),
}
VIEWS = {"default (70 m)": [], "close (25 m)": ["camera.position_m=[0, 0, 25]"]}
# spp swept per method, each method at the counts its sampler takes (schema.takes_sample_count: the
# squares are valid for all but ldsampler, 4^k, and orthogonal, prime^2), and errors at which times are compared
METHOD_SPP = {"reduced": [4, 9, 16], "full": [4, 9, 16, 25, 36, 49, 64]}
TARGET_ERRORS = (0.4, 0.3, 0.2)


def view_reference(extra: list[str], spp: int) -> np.ndarray:
    """The error yardstick of a view of VIEWS (its ``extra`` overrides): spacefit's default render (the
    window, ``independent``) at ``spp`` with REFERENCE_SEED, all threads."""
    return Renderer(assemble(load_scene(None, ["render.deterministic=false", *extra]))).render(spp=spp, seed=REFERENCE_SEED)


def time_at_error(rows: list[dict[str, object]], target: float) -> float:
    """Wall time (s) at which a method's error reaches ``target``: log-log interpolation between the
    two spp that bracket it (NaN when none does)."""
    pts = sorted((float(r["rel_rmse"]), float(r["time_s"])) for r in rows)
    for (e0, t0), (e1, t1) in zip(pts, pts[1:]):
        if e0 <= target <= e1 and e1 > e0:
            w = np.log(target / e0) / np.log(e1 / e0)
            return float(np.exp(np.log(t0) + w * (np.log(t1) - np.log(t0))))
    return float("nan")


def run_methods(out: Path, full: bool) -> list[dict[str, object]]:
    """Time and error of every method of METHODS in both VIEWS; the methods take turns at each spp
    so that a drift in the machine's load falls on all of them alike."""
    spps = METHOD_SPP["full" if full else "reduced"]
    reference_spp = 1024 if full else 256
    out.mkdir(parents=True, exist_ok=True)
    rows, summary = [], []
    for view, extra in VIEWS.items():
        base = ["render.deterministic=false", *extra]
        reference = view_reference(extra, reference_spp)
        # render.spp 4 is valid for every sampler; each render passes its own spp
        renderers = {name: Renderer(assemble(load_scene(None, [*base, "render.spp=4", f'render.sampler="{sampler}"'])),
                                    crop=not film)
                     for name, (film, sampler) in METHODS.items()}
        view_rows = []
        for spp in spps:
            for name, renderer in renderers.items():
                if not takes_sample_count(METHODS[name][1], spp):
                    continue
                time_s, image = timed(renderer, spp)
                sampler = renderer.scene.sensors()[0].sampler()
                view_rows.append({"view": view, "method": name, "spp": spp, "samples_per_pixel": sampler.sample_count(),
                                  "time_s": round(time_s, 5), "rel_rmse": round(relative_rmse(image, reference), 5),
                                  "threads": dr.thread_count()})
        rows += view_rows
        for target in TARGET_ERRORS:
            times = {name: time_at_error([r for r in view_rows if r["method"] == name], target) for name in METHODS}
            plain = times[next(iter(METHODS))]
            summary += [{"view": view, "rel_rmse": target, "method": name, "time_s": round(t, 5),
                         "time_over_plain_mitsuba": round(t / plain, 3)} for name, t in times.items()]
    write_csv(out / "methods.csv", rows)
    write_csv(out / "equal_error.csv", summary)
    plot_methods(out / "methods.png", rows, reference_spp)
    return summary


# Equal-error pairs: (spp of plain Mitsuba, spp of spacefit's window with multijitter) that reached
# about the same error in the --methods sweep (0.31 / 0.30 at 70 m; 0.27 / 0.29 at 25 m).
PAIR_SPP = (32, 16)
PAIR_REPEATS = 7


def run_pairs(repeats: int = PAIR_REPEATS, reference_spp: int = 1024) -> list[dict[str, object]]:
    """Plain Mitsuba (whole film, independent, PAIR_SPP[0]) against spacefit (window, multijitter,
    PAIR_SPP[1]) in both VIEWS, rendered in turn ``repeats`` times: each pair's time ratio is taken
    within the pair, so that the machine's load drifting between renders cancels."""
    rows = []
    for view, extra in VIEWS.items():
        base = ["render.deterministic=false", *extra]
        reference = view_reference(extra, reference_spp)
        plain = Renderer(assemble(load_scene(None, base)), crop=False)
        ours = Renderer(assemble(load_scene(None, [*base, 'render.sampler="multijitter"'])))
        runs: dict[str, list[tuple[float, float]]] = {"plain": [], "spacefit": []}
        for renderer, spp in ((plain, PAIR_SPP[0]), (ours, PAIR_SPP[1])):
            renderer.render(spp=spp, seed=0)  # compile
        for seed in range(1, repeats + 1):
            for name, renderer, spp in (("plain", plain, PAIR_SPP[0]), ("spacefit", ours, PAIR_SPP[1])):
                t0 = time.perf_counter()
                image = renderer.render(spp=spp, seed=seed)
                runs[name].append((time.perf_counter() - t0, relative_rmse(image, reference)))
        rows.append({"view": view, "plain_spp": PAIR_SPP[0], "spacefit_spp": PAIR_SPP[1],
                     **pair_columns(runs, "spacefit", "plain")})
    return rows


def pair_columns(runs: dict[str, list[tuple[float, float]]], numerator: str, denominator: str) -> dict[str, float]:
    """A table row's columns for two renders timed in turn (``runs``: name -> (seconds, rel RMSE) per
    pair): each one's median time, the time ratio ``numerator / denominator`` pair by pair (median,
    min, max) and each one's mean error."""
    ratios = [n[0] / d[0] for n, d in zip(runs[numerator], runs[denominator])]
    return {**{f"{name}_s": round(statistics.median(t for t, _ in runs[name]), 4) for name in runs},
            "ratio_median": round(statistics.median(ratios), 3), "ratio_min": round(min(ratios), 3), "ratio_max": round(max(ratios), 3),
            **{f"{name}_rel_rmse": round(statistics.mean(e for _, e in runs[name]), 4) for name in runs}}


# spp of the mask's pairs, and renders per process of --mask-loop (about 5 s of rendering at 2 threads)
MASK_SPP = (16, 64)
MASK_LOOP_RENDERS = 20


def window_render(renderer: Renderer, spp: int, seed: int) -> np.ndarray:
    """The render spacefit did before its mask: Mitsuba's own loop over the whole film window (its box)."""
    from spacefit.rendering.backend import mi

    return renderer.to_film(np.asarray(mi.render(renderer.scene, seed=seed, spp=spp), dtype=np.float32))


def run_mask_pairs(repeats: int = PAIR_REPEATS, reference_spp: int = 1024) -> list[dict[str, object]]:
    """spacefit's render (the silhouette's mask, :attr:`Renderer.traced`) against Mitsuba's own loop over the
    window, the same scene, sampler (the default) and spp, rendered in turn ``repeats`` times per view and spp:
    both unbiased, so their errors agree and the time ratio is the one at equal error."""
    rows = []
    for view, extra in VIEWS.items():
        reference = view_reference(extra, reference_spp)
        renderer = Renderer(assemble(load_scene(None, ["render.deterministic=false", *extra])))
        for spp in MASK_SPP:
            renderer.render(spp=spp, seed=0), window_render(renderer, spp, 0)  # compile
            runs: dict[str, list[tuple[float, float]]] = {"mask": [], "window": []}
            for seed in range(1, repeats + 1):
                for name in runs:
                    t0 = time.perf_counter()
                    image = renderer.render(spp=spp, seed=seed) if name == "mask" else window_render(renderer, spp, seed)
                    runs[name].append((time.perf_counter() - t0, relative_rmse(image, reference)))
            rows.append({"view": view, "spp": spp, "sampler": renderer.assembly.scene.render.sampler,
                         "traced_share_of_window": round(float(renderer.traced.mean()), 4), **pair_columns(runs, "mask", "window")})
            print(rows[-1], flush=True)
    return rows


def mask_loop(way: str, view: str, spp: int = MASK_SPP[1]) -> None:
    """``MASK_LOOP_RENDERS`` renders of ``view`` the ``way`` given (``mask``: spacefit's; ``window``: Mitsuba's
    loop over the window), for a whole-process timer run in turn (A B A B) on both ways; prints its own time."""
    renderer = Renderer(assemble(load_scene(None, ["render.deterministic=false", *VIEWS[view]])))
    render = renderer.render if way == "mask" else lambda spp, seed: window_render(renderer, spp, seed)
    render(spp=spp, seed=0)
    t0 = time.perf_counter()
    for seed in range(1, MASK_LOOP_RENDERS + 1):
        render(spp=spp, seed=seed)
    print(f"{way}, {view}, {spp} spp: {(time.perf_counter() - t0) / MASK_LOOP_RENDERS:.4f} s per render")


def plot_methods(path: Path, rows: list[dict[str, object]], reference_spp: int) -> None:
    """Error against time per method, one panel per view."""
    fig, axes = plt.subplots(1, len(VIEWS), figsize=(11, 4.5))
    for ax, view in zip(axes, VIEWS):
        for name in METHODS:
            pts = sorted((r["time_s"], r["rel_rmse"], r["samples_per_pixel"]) for r in rows
                         if r["view"] == view and r["method"] == name)
            ax.plot([p[0] for p in pts], [p[1] for p in pts], "o-", ms=4, label=name)
    label_view_axes(axes, reference_spp, rows[0]["threads"])
    save_figure(fig, path)


def label_view_axes(axes: Sequence[object], reference_spp: int, threads: object) -> None:
    """Log-log error-against-time panels, one per view of VIEWS: scales, titles, labels, legend."""
    for ax, view in zip(axes, VIEWS):
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_title(f"{view}, 600 px, depth 2", fontsize=10)
        ax.set_xlabel(f"render wall time (s), median of {REPEATS}, {threads} threads")
    axes[0].set_ylabel(f"relative RMSE over lit pixels (reference {reference_spp} spp)")
    axes[0].legend(fontsize=7)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", default="experiments/results/forward")
    p.add_argument("--full", action="store_true", help="150/300/600 px, spp 1-64, depths 1-5, reference 1024 spp")
    p.add_argument("--methods", action="store_true", help="compare samplers and the window with plain Mitsuba instead")
    p.add_argument("--mask", action="store_true", help="time the silhouette's mask against the window's box, in turn")
    p.add_argument("--mask-loop", nargs=2, metavar=("WAY", "VIEW"), help="render one view 20 times, WAY mask or window")
    args = p.parse_args()
    if args.mask_loop:
        return mask_loop(*args.mask_loop)
    if args.mask:
        rows = run_mask_pairs() if args.full else run_mask_pairs(repeats=3, reference_spp=256)
        write_csv(Path(args.out) / "mask_pairs.csv", rows)
        return
    if args.methods:
        for row in run_methods(Path(args.out), args.full):
            print(row)
        pairs = run_pairs() if args.full else run_pairs(repeats=3, reference_spp=256)
        write_csv(Path(args.out) / "equal_error_pairs.csv", pairs)
        for row in pairs:
            print(row)
        return
    rows = run_forward(Path(args.out), args.full)
    front = pareto_front([(r["time_s"], r["rel_rmse"]) for r in rows])
    print(f"wrote {len(rows)} configurations to {args.out}; Pareto front:")
    for i in front:
        print(rows[i])


if __name__ == "__main__":
    main()
