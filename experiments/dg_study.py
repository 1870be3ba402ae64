"""How to recover D and G: Jacobian methods, loss landscape, coordinates and losses, and range.

On the wrinkles case (experiments/cases.py), writes to ``--out`` (default experiments/results/dg_study):

1. ``jacobian.csv``: cosine of each method's Jacobian column in D and in G (at fixed G, D) with a
   reference column (central differences, common random numbers, 4x the samples, another seed),
   and its time: forward-mode ``prb``, ``direct_projective``, ``prb_projective``, and the finite
   differences with common random numbers that spacefit uses.
2. ``landscape.png`` / ``landscape.csv``: the pixel-L2 loss over a (D, G) grid around the truth with
   the curve of constant rms height: the valley along which D and G trade off.
3. ``fits.csv``: Levenberg-Marquardt from the case's start in (D, G) and in (D, rms height)
   coordinates, with the pixel, pyramid and statistics losses.
4. ``range.csv`` / ``range.png``: standard errors of D and G at the truth against camera range.

Run: ``.venv/bin/python experiments/dg_study.py [--quick]`` (quick: fewer points, for a check).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import matplotlib
import numpy as np
from studyio import save_figure, write_csv

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from spacefit import Observation, fit, identifiability  # noqa: E402
import spacefit as sf  # noqa: E402
from spacefit.geometry.wm import wm_rms  # noqa: E402
from spacefit.progress import Progress  # noqa: E402
from spacefit.rendering.derivatives import render_chain  # noqa: E402
from spacefit.scene.assembly import assemble  # noqa: E402

NAMES = ["wrinkles.D", "wrinkles.G"]
WRINKLES = sf.load_case("wrinkles")


def cosine(a: np.ndarray, b: np.ndarray) -> float:
    a, b = np.ravel(a), np.ravel(b)
    return float(a @ b / (np.linalg.norm(a) * np.linalg.norm(b)))


def jacobian_methods(out: Path, spp: int) -> list[dict[str, object]]:
    scene = WRINKLES.truth_scene.with_values({"render.spp": spp})
    assembly = assemble(scene)
    x0 = jnp.array([WRINKLES.truth[n] for n in NAMES])
    reference = render_chain(assembly, NAMES, spp=4 * spp)
    steps = reference.fd_steps
    ref = []
    for j in range(len(NAMES)):
        e = np.zeros(len(NAMES))
        e[j] = steps[j]
        ref.append((reference.primal(x0 + e, 99) - reference.primal(x0 - e, 99)) / (2 * steps[j]))
    rows = []
    for method in ("fd", "prb", "direct_projective", "prb_projective"):
        render = render_chain(assembly, NAMES, spp=spp, integrator="prb" if method == "fd" else method,
                              fd_steps=steps if method == "fd" else np.zeros(len(NAMES))).forward(1, 2)
        t0 = time.perf_counter()
        J = np.asarray(jax.jacfwd(render)(x0))
        elapsed = time.perf_counter() - t0
        rows.append({"method": method, "spp": spp, "time_s": round(elapsed, 2),
                     **{f"cos_{n.split('.')[1]}": round(cosine(J[..., j], ref[j]), 4) for j, n in enumerate(NAMES)}})
        print(rows[-1], flush=True)
    write_csv(out / "jacobian.csv", rows)
    return rows


def landscape(out: Path, n: int) -> None:
    reference, _ = WRINKLES.reference()
    w = WRINKLES.scene().wrinkles
    Ds = np.linspace(2.3, 2.5, n)
    Gs = np.geomspace(0.02, 0.08, n)
    scene = WRINKLES.scene()
    render = render_chain(scene, NAMES).forward(1, 2)
    loss = np.zeros((n, n))
    progress = Progress("landscape", delay=0.0)
    for i, D in enumerate(Ds):
        for j, G in enumerate(Gs):
            loss[i, j] = 0.5 * float(jnp.sum((render(jnp.array([D, G])) - reference) ** 2))
        progress(i + 1, n)
    write_csv(out / "landscape.csv", [{"D": D, "G": G, "loss": loss[i, j]} for i, D in enumerate(Ds) for j, G in enumerate(Gs)])
    fig, ax = plt.subplots(figsize=(5.5, 4.5))
    c = ax.contourf(Gs, Ds, np.log10(loss), levels=20, cmap="viridis")
    fig.colorbar(c, label="log10 pixel-L2 loss")
    rms = float(wm_rms(WRINKLES.truth["wrinkles.D"], WRINKLES.truth["wrinkles.G"], gamma=w.gamma, M=w.M, L=w.L, Ls=w.Ls))
    rms_grid = np.array([[float(wm_rms(D, G, gamma=w.gamma, M=w.M, L=w.L, Ls=w.Ls)) for G in Gs] for D in Ds])
    ax.contour(Gs, Ds, rms_grid, levels=[rms], colors="white", linestyles="--")
    ax.plot(WRINKLES.truth["wrinkles.G"], WRINKLES.truth["wrinkles.D"], "r+", ms=12, label="truth")
    ax.set_xscale("log")
    ax.set_xlabel("G (m)")
    ax.set_ylabel("D")
    ax.set_title(f"pixel-L2 loss; dashed: rms height {rms * 100:.1f} cm")
    ax.legend(loc="upper right")
    save_figure(fig, out / "landscape.png")


def fits(out: Path, max_steps: int) -> None:
    reference, _ = WRINKLES.reference()
    rows = []
    for coordinates in ("G", "rms"):
        for loss in ("pixel", "pyramid", "stats"):
            r = fit(Observation(WRINKLES.scene(), reference), NAMES, start=WRINKLES.start, loss=loss,
                    wrinkle_coordinates=coordinates, max_steps=max_steps)
            rows.append({"coordinates": coordinates, "loss": loss, "D": round(r.values["wrinkles.D"], 4),
                         "G_rel_error": round(r.values["wrinkles.G"] / WRINKLES.truth["wrinkles.G"] - 1, 4),
                         "se_D": round(r.stderr["wrinkles.D"], 4), "se_G": r.stderr["wrinkles.G"],
                         "corr_DG": round(float(r.correlation[0, 1]), 3), "steps": r.steps,
                         "time_s": round(r.wall_time_s, 1), "status": r.status})
            print(rows[-1], flush=True)
    write_csv(out / "fits.csv", rows)


def ranges(out: Path, distances: list[float]) -> None:
    rows = []
    for d in distances:
        # the same viewing direction, farther away
        position = np.array([3.0, -4.0, 10.0]) / np.linalg.norm([3.0, -4.0, 10.0]) * d
        case = WRINKLES.with_values({"camera.position_m": list(position)})
        image, sigma = case.reference(2)
        info = identifiability(Observation(case.scene(), image, sigma), NAMES, WRINKLES.truth)
        camera = case.scene().camera
        rows.append({"range_m": d, "pixel_m": round(d * camera.pixel_pitch_mm / camera.focal_length_mm, 4),
                     "se_D": info.stderr["wrinkles.D"], "se_G_rel": info.stderr["wrinkles.G"] / WRINKLES.truth["wrinkles.G"],
                     "corr_DG": float(info.correlation[0, 1])})
        print(rows[-1], flush=True)
    write_csv(out / "range.csv", rows)
    fig, ax = plt.subplots(figsize=(5.5, 3.8))
    ax.semilogy([r["range_m"] for r in rows], [r["se_D"] for r in rows], "o-", label="standard error of D")
    ax.semilogy([r["range_m"] for r in rows], [r["se_G_rel"] for r in rows], "s-", label="relative s.e. of G")
    ax.axhline(0.02, color="grey", ls=":", label="0.02")
    ax.set_xlabel("camera range (m)")
    ax.legend()
    ax.set_title("wrinkles case, 64 x 64 px, 2 % noise")
    save_figure(fig, out / "range.png")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", default="experiments/results/dg_study")
    p.add_argument("--quick", action="store_true")
    p.add_argument("--only", nargs="*", default=["jacobian", "landscape", "fits", "range"])
    args = p.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    if "jacobian" in args.only:
        jacobian_methods(out, spp=16 if args.quick else 64)
    if "landscape" in args.only:
        landscape(out, n=5 if args.quick else 13)
    if "fits" in args.only:
        fits(out, max_steps=5 if args.quick else 30)
    if "range" in args.only:
        ranges(out, [12.0, 30.0] if args.quick else [12.0, 20.0, 30.0, 45.0, 60.0, 90.0])


if __name__ == "__main__":
    main()
