"""Build and execute ``experiments/walkthrough.ipynb``: what spacefit simulates and fits, every figure computed.

The notebook uses ``sf.`` names only and computes every figure it shows, at small sizes (it runs in
``make docs``, docs/tutorials/). Executing it here stores its outputs, so it reads on GitHub without
a kernel. Run: ``.venv/bin/python experiments/make_notebook.py`` (needs the ``notebook`` extra:
``pip install -e .[notebook]``).
"""

from __future__ import annotations

from pathlib import Path

import nbformat
from nbclient import NotebookClient

HERE = Path(__file__).resolve().parent

CELLS: list[tuple[str, str]] = [
    ("md", """# spacefit: a walkthrough

What spacefit simulates and fits, through its public API (`import spacefit as sf`), every figure
computed here at small sizes (the measured studies behind the numbers quoted are in the
documentation's validation and performance pages). Radiance is in W m^-2 sr^-1, lengths in metres,
angles in degrees at this edge."""),
    ("code", """import warnings

import matplotlib.pyplot as plt
import numpy as np

import spacefit as sf


def show(ax, radiance, title=""):
    \"\"\"A radiance image, linear, its 99.5th percentile of lit pixels white.\"\"\"
    lit = radiance[radiance > 0]
    ax.imshow(np.clip(radiance / (np.percentile(lit, 99.5) if lit.size else 1.0), 0, 1))
    ax.set_title(title, fontsize=9)
    ax.set_axis_off()"""),
    ("md", """## 1. The simulator

The thesis's scene (Table 4-2, its wrinkles' G read as micrometres), small: 96 x 96 px with the
same field of view per pixel scaled up, 8 samples per pixel."""),
    ("code", """scene = sf.load_scene(None, {"render.resolution": [96, 96], "camera.pixel_pitch_mm": 12.5, "render.spp": 8})
renderer = sf.Renderer(scene)
radiance = renderer.render()
fig, ax = plt.subplots(figsize=(4, 4))
show(ax, radiance, f"max radiance {radiance.max():.3g} W m$^{{-2}}$ sr$^{{-1}}$")
print(renderer.part_image().table(radiance))"""),
    ("md", """A sweep of the target's attitude (the thesis's section 4.4 sweeps attitude, light level and
range): `sf.sweep` renders every point on the loaded scene and returns a labelled xarray Dataset,
here with the images kept."""),
    ("code", """ds = sf.sweep(scene, {"target.attitude_z_deg": [0.0, 30.0, 60.0, 90.0]}, images=True, quiet=True)
print(ds)
fig, axes = plt.subplots(1, 4, figsize=(10, 2.8))
for ax, angle in zip(axes, ds["target.attitude_z_deg"].values):
    show(ax, np.asarray(ds.radiance.sel({"target.attitude_z_deg": angle})), f"attitude z {angle:g} deg")"""),
    ("md", """## 2. Fitting materials

The synthetic panels case (`sf.load_case("panels")`): its scene rendered with many samples stands
in for the observation, and three materials are fitted from starts 50 % off with
Levenberg-Marquardt."""),
    ("code", """case = sf.load_case("panels")
truth_scene = case.truth_scene.with_values({"render.resolution": [32, 32], "camera.pixel_pitch_mm": 75.0})
reference = sf.render(truth_scene.with_values({"render.spp": 256}))
result = sf.fit(sf.Observation(truth_scene, reference), case.free, start=case.start)
print(sf.format_result(result))
print("truth:", {name: case.truth[name] for name in case.free})
sf.plot_convergence(result).flat[0].figure"""),
    ("md", """## 3. D and G of the wrinkles

How well could one reference of the wrinkles case determine the fractal dimension D and the height
scale G? `sf.identifiability` predicts the standard errors and their correlation from the Fisher
information at the truth, without a fit."""),
    ("code", """case = sf.load_case("wrinkles")
scene = case.truth_scene.with_values({"render.resolution": [32, 32], "camera.pixel_pitch_mm": 2 * case.truth_scene.camera.pixel_pitch_mm,
                                      "render.spp": 16})
with warnings.catch_warnings():
    warnings.filterwarnings("ignore", message=".*fold over")  # steep wrinkles fold a few faces (user guide, "Wrinkles")
    reference = sf.render(scene.with_values({"render.spp": 64}))
    info = sf.identifiability(sf.Observation(scene, reference), ["wrinkles.D", "wrinkles.G"],
                              {"wrinkles.D": scene.wrinkles.D, "wrinkles.G": scene.wrinkles.G}, spp=16)
print(info.stderr, "correlation", round(float(info.correlation[0, 1]), 3))"""),
    ("md", """## 4. Level of detail

`wrinkles.model = "auto"` (the default) renders a wrinkled part as displaced geometry, or, where a
pixel covers many wrinkle wavelengths, as an effective (Beckmann) roughness, and records the choice
with its reason in the render's sidecar. Gentle wrinkles (rms slope 0.3) from 100 m and from 800 m:"""),
    ("code", """import tempfile
from pathlib import Path

gentle = {"wrinkles.L": 0.4, "wrinkles.Ls": 0.1, "wrinkles.D": 2.4, "wrinkles.G": 3e-4, "wrinkles.spacing_m": 0.03,
          "camera.pixel_pitch_mm": 37.5, "render.resolution": [64, 64], "render.spp": 4}
fig, axes = plt.subplots(1, 2, figsize=(6, 3))
with tempfile.TemporaryDirectory() as folder:
    for ax, range_m in zip(axes, (100, 800)):
        radiance, sidecar = sf.render_to_folder(sf.load_scene(None, {**gentle, "camera.position_m": [0, 0, range_m]}),
                                                Path(folder) / f"r{range_m}", quiet=True)
        choice = sidecar["wrinkle_model"]["body"]
        print(f"{range_m:4d} m: {choice['model']:9s} {choice['reason']}")
        show(ax, radiance, f"{range_m} m: {choice['model']}")"""),
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
