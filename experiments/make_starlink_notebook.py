"""Build and execute ``experiments/starlink.ipynb``: the Starlink real case (issue 22) with its charts.

The notebook reads what ``experiments/starlink.py``, ``starlink_lumos.py`` and
``identifiability_lightcurve.py`` wrote under ``experiments/results/`` and refits the chassis's lab
table itself through the public API. Run: ``PYTHONPATH=. .venv/bin/python experiments/make_starlink_notebook.py``
(needs the ``notebook`` extra).
"""

from __future__ import annotations

from pathlib import Path

import nbformat
from nbclient import NotebookClient

HERE = Path(__file__).resolve().parent

CELLS: list[tuple[str, str]] = [
    ("md", """# Starlink v1.5: laboratory BRDFs and observed magnitudes

1,173 AB magnitudes of Starlink v1.5 satellites observed from Mount Lemmon and the laboratory BRDFs
of their two surfaces (Fankhauser, Askari & Tyson 2023, AJ 166:59; MIT licence, `data/starlink-v1p5/`).
The satellite is two flat plates, the chassis underside (3.64 m^2, nadir) and the solar array
(22.68 m^2, towards the sun). Made by `experiments/starlink.py` (spacefit) and
`experiments/starlink_lumos.py` (the published model, lumos-sat, computed the same way)."""),
    ("code", """import csv
import json
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
from IPython.display import Image, display

import spacefit as sf

ROOT = Path.cwd().parent if Path.cwd().name == "experiments" else Path.cwd()
RESULTS = ROOT / "experiments" / "results"
DATA = ROOT / "data" / "starlink-v1p5"
ours = json.loads((RESULTS / "starlink" / "starlink.json").read_text())
peer = json.loads((RESULTS / "starlink" / "lumos.json").read_text())"""),
    ("md", """## 1. A lab table and the model fitted to it

The chassis's table, in the plane of incidence, against `lambert+ggx` (k = 0) fitted in log space.
No model of `sf.BRDF_MODELS` fits it within an assumed 10 % error: the comparison's table."""),
    ("code", """table = sf.read_brdf_table(DATA / "chassis_brdf.csv", floor=1e-4)
fit = sf.fit_brdf_table(table, "lambert+ggx", fixed={"k": 0.0})
print(fit.report())
print(ours["lab_chassis"]["comparison"])
import jax.numpy as jnp
from spacefit.materials.brdf import brdf
model = np.asarray(brdf(sf.fitted_material("lambert+ggx", fit), jnp.asarray(table.wi), jnp.asarray(table.wo)))
zen_i = np.degrees(np.arccos(table.wi[:, 2]))
zen_o = np.degrees(np.arctan2(table.wo[:, 0], table.wo[:, 2]))
fig, ax = plt.subplots(figsize=(8, 4))
for z in sorted(set(np.round(zen_i, 1))):
    rows = np.isclose(zen_i, z, atol=0.1)
    line, = ax.semilogy(zen_o[rows], table.value[rows], ".", ms=3, label=f"lab, {z:g} deg in")
    ax.semilogy(zen_o[rows], model[rows], "-", color=line.get_color(), lw=1)
ax.set_xlabel("outgoing zenith in the plane of incidence (deg)")
ax.set_ylabel("BRDF (sr$^{-1}$)")
ax.legend(fontsize=8);"""),
    ("md", """## 2. Predicted against observed magnitudes

Residual = observed - predicted, over the observations outside the Earth's shadow; (b) is scored on
the held-out third."""),
    ("code", """print(f"{'model':>34s} {'scored on':>10s} {'R':>6s} {'RMS':>6s} {'median':>7s} {'bias':>7s}")
for name, result in (("spacefit", ours), ("lumos-sat (Phong)", peer)):
    for key, label in (("lab", "lab tables"), ("fitted", "fitted to observations")):
        for part, s in result[key].items():
            if "pearson_r" not in s:
                continue
            print(f"{name + ', ' + label:>34s} {part:>10s} {s['pearson_r']:6.3f} {s['rms_mag']:6.3f} {s['median_mag']:+7.3f} "
                  f"{s['bias_mag']:+7.3f}")
print(json.dumps(ours["fitted"]["fit"]["values"], indent=1), json.dumps(ours["fitted"]["fit"]["stderr"], indent=1))"""),
    ("code", """lines = [l for l in (DATA / "pomenis_observations.csv").read_text().splitlines() if l.strip() and not l.startswith("#")]
observed = np.array([float(r["ab_magnitude"]) for r in csv.DictReader(lines)])
geometry = list(csv.DictReader((RESULTS / "starlink" / "geometry.csv").read_text().splitlines()))
held = np.array([g["held_out"] == "1" for g in geometry])
fig, axes = plt.subplots(1, 2, figsize=(9, 4), sharey=True)
for ax, key, title in zip(axes, ("spacefit_lab_mag", "spacefit_fitted_mag"), ("from the lab tables", "fitted (held-out third)")):
    predicted = np.array([float(g[key]) for g in geometry])
    rows = np.isfinite(predicted) & (held if "fitted" in key else True)
    ax.plot(predicted[rows], observed[rows], ".", ms=3)
    lo, hi = np.nanmin(observed), np.nanmax(observed)
    ax.plot([lo, hi], [lo, hi], "k-", lw=0.8)
    ax.set_xlabel("predicted AB magnitude")
    ax.set_title(title)
axes[0].set_ylabel("observed AB magnitude");"""),
    ("md", """## 3. What a light curve can tell

`experiments/identifiability_lightcurve.py`: each material parameter's expected standard error
from one image, a pass of 8 images and the light curve over the same geometries."""),
    ("code", """display(Image(filename=str(RESULTS / "identifiability_lightcurve" / "identifiability_lightcurve.png")))"""),
]


def main() -> None:
    nb = nbformat.v4.new_notebook()
    nb.cells = [nbformat.v4.new_markdown_cell(text) if kind == "md" else nbformat.v4.new_code_cell(text) for kind, text in CELLS]
    NotebookClient(nb, timeout=600, kernel_name="python3", resources={"metadata": {"path": str(HERE.parent)}}).execute()
    nbformat.write(nb, HERE / "starlink.ipynb")
    print(f"wrote {HERE / 'starlink.ipynb'}")


if __name__ == "__main__":
    main()
