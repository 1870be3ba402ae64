"""Rerun every sweep of thesis section 4.4 and save one labelled contact sheet per sweep (PNG).

Sweeps: six target attitudes, trace depth 2-5, light level 0.1-10 W m^-2, light directions, camera
distance 50-90 m, focal length 3000-9000 mm. Within a sheet all images share one exposure (that of
the thesis's default value), so brightness differences are real. A CSV beside the sheets lists
each image's mean and maximum radiance.

Run: ``.venv/bin/python experiments/thesis_sweeps.py [--out experiments/results/sweeps] [--size 600]``.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import matplotlib
import numpy as np
from studyio import save_figure, write_csv

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from spacefit.output import preview_scale, to_srgb8  # noqa: E402
from spacefit.progress import Progress  # noqa: E402
from spacefit.rendering.renderer import Renderer  # noqa: E402
from spacefit.scene.assembly import assemble  # noqa: E402
from spacefit.scene.toml import load_scene  # noqa: E402

# (sweep name, label of the value whose exposure the sheet uses, [(label, overrides), ...])
SWEEPS = [
    ("attitude", "[90,0,0]", [
        (f"[{a},{b},{c}]", [f"target.attitude_deg=[{a}, {b}, {c}]"])
        for a, b, c in [(0, 0, 90), (0, 0, 0), (0, 90, 0), (90, 0, 0), (0, 90, 90), (90, 0, 90)]
    ]),
    ("depth", "2", [(str(d), [f"render.depth={d}"]) for d in (2, 3, 4, 5)]),
    ("light_level", "5", [(f"{e:g}", [f"sun.irradiance_w_m2={e}"]) for e in (0.1, 0.5, 1.0, 5.0, 10.0)]),
    ("light_direction", "[0,0,-1]", [
        (f"[{x},{y},{z}]", [f"sun.direction=[{x}, {y}, {z}]"])
        for x, y, z in [(0, 0, -1), (1, 0, -1), (-1, 0, -1), (0, 1, -1), (0, -1, -1), (1, 1, -1)]
    ]),
    ("distance", "70", [(str(d), [f"camera.position_m=[0, 0, {d}]"]) for d in (50, 60, 70, 80, 90)]),
    ("focal_length", "7000", [(str(f), [f"camera.focal_length_mm={f}"]) for f in (3000, 5000, 7000, 9000)]),
]


def common_crop(images: list[np.ndarray], margin: float = 0.1) -> tuple[slice, slice]:
    """One square window holding every image's lit pixels, so sizes stay comparable across a sheet."""
    lit = np.any(np.stack([img.max(axis=-1) > 0 for img in images]), axis=0)
    rows, cols = np.nonzero(lit)
    h, w = lit.shape
    if rows.size == 0:
        return slice(0, h), slice(0, w)
    cy, cx = (rows.min() + rows.max()) / 2, (cols.min() + cols.max()) / 2
    half = (1 + margin) * max(rows.max() - rows.min(), cols.max() - cols.min()) / 2 + 2
    y0, x0 = int(max(cy - half, 0)), int(max(cx - half, 0))
    return slice(y0, int(min(cy + half, h))), slice(x0, int(min(cx + half, w)))


def contact_sheet(path: Path, title: str, unit: str, images: list[tuple[str, np.ndarray]], scale: float) -> None:
    """Save a one-row sheet of sRGB previews at a common exposure ``scale`` and crop, labelled by value."""
    crop = common_crop([img for _, img in images])
    fig, axes = plt.subplots(1, len(images), figsize=(2.6 * len(images), 3.0), squeeze=False)
    for ax, (label, img) in zip(axes[0], images):
        ax.imshow(to_srgb8(img[crop], scale))
        ax.set_title(f"{label} {unit}".strip(), fontsize=9)
        ax.set_xticks([])
        ax.set_yticks([])
    rows, cols = crop
    fig.suptitle(f"{title} (common exposure: white = {1 / scale:.3g} W m$^{{-2}}$ sr$^{{-1}}$; "
                 f"crop rows {rows.start}-{rows.stop}, cols {cols.start}-{cols.stop})", fontsize=10)
    save_figure(fig, path)


UNITS = {"attitude": "deg", "depth": "", "light_level": "W m^-2", "light_direction": "", "distance": "m", "focal_length": "mm"}


def run_sweeps(out: Path, size: int = 600, spp: int = 20, only: list[str] | None = None,
               overrides: list[str] | None = None) -> list[dict[str, object]]:
    """Render the sweeps, save a contact sheet per sweep and sweeps.csv into ``out``; return the rows."""
    out.mkdir(parents=True, exist_ok=True)
    # Keep the thesis's field of view at any size: pixel pitch scales inversely with the width.
    base = [f"render.resolution=[{size}, {size}]", f"camera.pixel_pitch_mm={4.0 * 600 / size}",
            f"render.spp={spp}", *(overrides or [])]
    sweeps = [s for s in SWEEPS if only is None or s[0] in only]
    rows: list[dict[str, object]] = []
    for name, reference, cases in sweeps:
        images = []
        progress = Progress(f"sweep {name}", delay=0.0)
        for i, (label, case) in enumerate(cases):
            img = Renderer(assemble(load_scene(None, base + case))).render()
            images.append((label, img))
            rows.append({"sweep": name, "value": label, "mean_radiance": float(img.mean()), "max_radiance": float(img.max())})
            progress(i + 1, len(cases))
        contact_sheet(out / f"{name}.png", name.replace("_", " "), UNITS[name], images, preview_scale(dict(images)[reference]))
    write_csv(out / "sweeps.csv", rows)
    return rows


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", default="experiments/results/sweeps")
    p.add_argument("--size", type=int, default=600, help="image width and height in px (600 = thesis)")
    p.add_argument("--spp", type=int, default=20)
    p.add_argument("--only", nargs="*", default=None, help="sweep names to run (default: all)")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE")
    args = p.parse_args()
    run_sweeps(Path(args.out), args.size, args.spp, args.only, args.overrides)
    print(f"wrote contact sheets and sweeps.csv to {args.out}")


if __name__ == "__main__":
    main()
