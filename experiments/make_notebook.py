"""Build and execute ``experiments/walkthrough.ipynb``: the studies' results with charts inline.

The notebook uses only spacefit's public API and the files under ``experiments/results/`` (made by
the study scripts; a missing one is skipped with a note). Executing it here stores its outputs, so
it reads on GitHub without a kernel. Run: ``.venv/bin/python experiments/make_notebook.py``
(needs the ``notebook`` extra: ``pip install -e .[notebook]``).
"""

from __future__ import annotations

from pathlib import Path

import nbformat
from nbclient import NotebookClient

HERE = Path(__file__).resolve().parent

CELLS: list[tuple[str, str]] = [
    ("md", """# spacefit: results walkthrough

What spacefit simulates and fits, and what the studies in `experiments/` measured. Every figure
here is made by a script in `experiments/` (its name is given) or by the code in this notebook,
through spacefit's public API. Radiance is in W m^-2 sr^-1, lengths in metres."""),
    ("code", """import csv
import warnings
from pathlib import Path

import matplotlib.pyplot as plt
from IPython.display import Image, display

from spacefit import Observation, fit, identifiability
from spacefit.output import preview_scale, to_srgb8
from spacefit.rendering.renderer import render
from spacefit.rendering.exr import read_exr
from spacefit.scene.assembly import assemble
from spacefit.scene.toml import load_scene

ROOT = Path.cwd().parent if Path.cwd().name == "experiments" else Path.cwd()
RESULTS = ROOT / "experiments" / "results"


def show(path):
    path = RESULTS / path
    if path.exists():
        display(Image(filename=str(path)))
    else:
        print(f"{path} is missing: run the study script that makes it")


def table(path, keys=None):
    path = RESULTS / path
    if not path.exists():
        print(f"{path} is missing: run the study script that makes it")
        return
    rows = list(csv.DictReader(open(path)))
    keys = keys or list(rows[0])

    def cell(text):
        try:
            return f"{float(text):.4g}"
        except ValueError:
            return text[:14]

    print("  ".join(f"{k:>14s}" for k in keys))
    for row in rows:
        print("  ".join(f"{cell(row[k]):>14s}" for k in keys))"""),
    ("md", """## 1. The simulator

The thesis's scene (Table 4-2, its wrinkles' G read as micrometres) at a quarter of its resolution,
same field of view."""),
    ("code", """scene = load_scene(None, ["render.resolution=[150, 150]", "camera.pixel_pitch_mm=16"])
radiance = render(scene)
plt.figure(figsize=(4, 4))
plt.imshow(to_srgb8(radiance, preview_scale(radiance)))
plt.axis("off")
plt.title(f"max radiance {radiance.max():.3g} W m$^{{-2}}$ sr$^{{-1}}$");"""),
    ("md", """The thesis's sweeps of section 4.4 (`experiments/thesis_sweeps.py`), each sheet at one
exposure: attitudes, light level and range."""),
    ("code", """for name in ["attitude", "light_level", "distance"]:
    show(f"sweeps/{name}.png")"""),
    ("md", """## 2. Fitting materials

The synthetic panels case (its scene `spacefit/synthetic/panels.toml`, its reference `data/synthetic/panels/`), fitted from starts 50 % off with Levenberg-Marquardt."""),
    ("code", """obs = Observation(load_scene(ROOT / "spacefit" / "synthetic" / "panels.toml"),
                  read_exr(ROOT / "data" / "synthetic" / "panels" / "reference.exr"))
result = fit(obs, ["parts.panels.alpha_x", "parts.panels.alpha_y", "parts.legs.kd"],
             start={"parts.panels.alpha_x": 0.075, "parts.panels.alpha_y": 0.045, "parts.legs.kd": 0.25})
truth = {"parts.panels.alpha_x": 0.15, "parts.panels.alpha_y": 0.03, "parts.legs.kd": 0.5}
for name, value in result.values.items():
    print(f"{name:24s} {value:.4f} +/- {result.stderr[name]:.4f}   truth {truth[name]}")
print(result.status, result.warnings)
plt.semilogy([h["step"] for h in result.history], [h["loss"] for h in result.history], "o-")
plt.xlabel("step"); plt.ylabel("loss");"""),
    ("md", """## 3. D and G of the wrinkles

`experiments/dg_study.py`: the loss valley of constant rms height, the fits in (D, G) and in
(D, rms height) coordinates, and the standard errors against range."""),
    ("code", """show("dg_study/landscape.png")
table("dg_study/fits.csv", ["coordinates", "loss", "D", "G_rel_error", "se_D", "steps"])
show("dg_study/range.png")"""),
    ("md", """`experiments/identifiability.py`: at the thesis's optics and wrinkles (G = 10 m read literally), the standard error of
D and the smallest Fisher eigenvalue against range, for three image sizes."""),
    ("code", """show("identifiability/identifiability.png")
table("identifiability/identifiability.csv", ["range_m", "width_px", "pixel_m", "se_D", "se_G_rel", "corr_DG"])"""),
    ("md", """The same question asked of a single observation through the API: how well could one 64 px
reference of the wrinkles case determine D and G?"""),
    ("code", """obs = Observation(load_scene(ROOT / "spacefit" / "synthetic" / "wrinkles.toml"),
                  read_exr(ROOT / "data" / "synthetic" / "wrinkles" / "reference_noise2.exr"), sigma=0.00488)
with warnings.catch_warnings():
    warnings.filterwarnings("ignore", message=".*fold over")  # the wrinkles case folds 1.2 % of its faces (README, "Wrinkles")
    info = identifiability(obs, ["wrinkles.D", "wrinkles.G"], {"wrinkles.D": 2.4, "wrinkles.G": 0.04})
print(info.stderr, "correlation", round(float(info.correlation[0, 1]), 3))"""),
    ("md", """## 4. Level of detail

`experiments/lod_study.py`: displaced wrinkles against an effective (Beckmann) roughness on the flat
body, across range, pooled over four wrinkle seeds at 4096 spp. `bias_effective` is the error with
both models' Monte Carlo noise taken out, `bias_upper` adds two standard errors; the stated
tolerance is 0.15, met from 2.3 L per pixel on; `wrinkles.model = "auto"` switches at 3 L. `speedup_equal_noise` is what the geometry costs over what the effective model
costs at the geometry's noise."""),
    ("code", """show("lod/lod.png")
table("lod/lod.csv", ["range_m", "footprint_over_L", "bias_effective", "bias_upper", "noise_geometry",
                      "flux_ratio", "speedup_equal_noise", "auto_model"])"""),
    ("md", """`wrinkles.model = "auto"` (the default) makes that choice per part, and records it with its
reason; gentle wrinkles (rms slope 0.3) from 100 m and from 800 m, and the thesis's steep ones read
literally (G = 10 m, `data/scenes/thesis-literal.toml`, which also warns that the body folds over):"""),
    ("code", """gentle = ["wrinkles.L=0.4", "wrinkles.Ls=0.1", "wrinkles.D=2.4", "wrinkles.G=3e-4", "wrinkles.spacing_m=0.03",
          "camera.pixel_pitch_mm=18.75", "render.resolution=[128, 128]"]
literal = ROOT / "data" / "scenes" / "thesis-literal.toml"
for path, overrides in ((None, gentle + ["camera.position_m=[0, 0, 100]"]), (None, gentle + ["camera.position_m=[0, 0, 800]"]),
                        (literal, [])):
    choice = assemble(load_scene(path, overrides)).lod["body"]
    print(f"{choice.model:9s} {choice.reason}")"""),
    ("md", """## 5. Cost against accuracy, and where solvers fail

`experiments/forward_pareto.py`, `experiments/fit_cost.py` and `experiments/stability.py`."""),
    ("code", """show("forward/forward_pareto.png")
show("fit_cost/fit_cost.png")
show("stability/stability.png")"""),
]


def build(path: Path, cells: list[tuple[str, str]] = CELLS) -> None:
    """Write the notebook of ``cells`` (kind "md" or "code", source) and execute it in place (outputs stored)."""
    nb = nbformat.v4.new_notebook()
    nb.cells = [nbformat.v4.new_markdown_cell(src) if kind == "md" else nbformat.v4.new_code_cell(src) for kind, src in cells]
    NotebookClient(nb, timeout=600, kernel_name="python3", resources={"metadata": {"path": str(HERE)}}).execute()
    nbformat.write(nb, path)


if __name__ == "__main__":
    build(HERE / "walkthrough.ipynb")
    print(f"wrote {HERE / 'walkthrough.ipynb'}")
