"""The default wrinkles (G 1e-5 m) beside the thesis's literal reading (G 10 m), with their numbers.

For each reading, renders the thesis's view (Table 4-2: 600 px, 20 spp, 70 m) and a close view
(25 m, same optics), each cropped to the target, the wrinkles as displaced geometry, and saves one labelled PNG per reading into
``--out`` (``default.png``, ``thesis_literal.png``) with ``wrinkles.csv``: G (m), rms height (m),
rms slope (eq. 2-1 in closed form, :func:`spacefit.wm_rms_slope`) and the fraction of the body's
faces that fold over (:func:`spacefit.geometry.wrinkle.fold_fraction`).

Run: ``.venv/bin/python experiments/wrinkle_previews.py [--out experiments/results/wrinkles] [--size 600]``.
"""

from __future__ import annotations

import argparse
import warnings
from pathlib import Path

import matplotlib
from studyio import save_figure, write_csv
from thesis_sweeps import common_crop

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

import spacefit as sf  # noqa: E402
from spacefit.output import preview_scale, to_srgb8  # noqa: E402
from spacefit.rendering.renderer import Renderer  # noqa: E402
from spacefit.scene.assembly import assemble  # noqa: E402

LITERAL = Path(__file__).resolve().parents[1] / "data" / "scenes" / "thesis-literal.toml"
READINGS = [("default", None, "default: G = 1e-5 m (thesis's 10 read as um)"),
            ("thesis_literal", LITERAL, "thesis literal: G = 10 m")]
VIEWS = [("70 m (thesis)", 70.0), ("25 m", 25.0)]


def run_previews(out: Path, size: int = 600, spp: int = 20) -> list[dict[str, object]]:
    """Render both readings in both views; save one PNG per reading and wrinkles.csv into ``out``."""
    out.mkdir(parents=True, exist_ok=True)
    rows: list[dict[str, object]] = []
    for name, path, title in READINGS:
        base = [f"render.resolution=[{size}, {size}]", f"camera.pixel_pitch_mm={4.0 * 600 / size}", f"render.spp={spp}",
                "wrinkles.model='geometry'"]  # what "auto" takes at 600 px; small test sizes would take the effective roughness
        images, folds = [], 0.0
        for label, distance in VIEWS:
            with warnings.catch_warnings():
                warnings.filterwarnings("ignore", message=".*fold over")  # recorded in the CSV instead
                assembly = assemble(sf.load_scene(path, [*base, f"camera.position_m=[0, 0, {distance}]"]))
            folds = assembly.folds["body"]
            images.append((label, Renderer(assembly).render()))
        w = assembly.scene.wrinkles
        wm = {"gamma": w.gamma, "M": w.M, "L": w.L, "Ls": w.Ls}
        row = {"reading": name, "G_m": w.G, "rms_height_m": float(sf.wm_rms(w.D, w.G, **wm)),
               "rms_slope": float(sf.wm_rms_slope(w.D, w.G, **wm)), "fold_fraction": folds}
        rows.append(row)
        fig, axes = plt.subplots(1, len(images), figsize=(4.0 * len(images), 4.3), squeeze=False)
        for ax, (label, img) in zip(axes[0], images):
            ax.imshow(to_srgb8(img[common_crop([img])], preview_scale(img)))
            ax.set_title(label, fontsize=10)
            ax.set_xticks([])
            ax.set_yticks([])
        fig.suptitle(f"{title}\nrms height {1e3 * row['rms_height_m']:.3g} mm, rms slope {row['rms_slope']:.2g}, "
                     f"faces folded {100 * folds:.2g} %", fontsize=10)
        save_figure(fig, out / f"{name}.png")
    write_csv(out / "wrinkles.csv", rows)
    return rows


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", default="experiments/results/wrinkles")
    p.add_argument("--size", type=int, default=600, help="image width and height in px (600 = thesis)")
    p.add_argument("--spp", type=int, default=20)
    args = p.parse_args()
    for row in run_previews(Path(args.out), args.size, args.spp):
        print(row)


if __name__ == "__main__":
    main()
