"""Build and execute ``experiments/starlink.ipynb``: the Starlink real case with its charts, computed
with ``sf.`` names only from the data in ``data/starlink-v1p5/`` (it runs in ``make docs`` too).
Run: ``PYTHONPATH=. .venv/bin/python experiments/make_starlink_notebook.py`` (needs the ``notebook`` extra).
"""

from __future__ import annotations

from pathlib import Path

import nbformat
from nbclient import NotebookClient

HERE = Path(__file__).resolve().parent

CELLS: list[tuple[str, str]] = [
    ("md", """# Fit a light curve: Starlink v1.5, laboratory BRDFs and observed magnitudes

1,173 AB magnitudes of Starlink v1.5 satellites observed from Mount Lemmon and the laboratory BRDFs
of their two surfaces (Fankhauser, Askari & Tyson 2023, AJ 166:59; MIT licence, `data/starlink-v1p5/`).
The satellite is two flat plates, the chassis underside (3.64 m^2, nadir) and the solar array
(22.68 m^2, towards the sun). Everything below is computed here with `sf.` names (the full study,
with the published model lumos-sat beside it, is `experiments/starlink.py` and
`experiments/starlink_lumos.py`)."""),
    ("code", """from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

import spacefit as sf

ROOT = next(p for p in [Path.cwd(), *Path.cwd().parents] if (p / "data" / "starlink-v1p5").is_dir())
DATA = ROOT / "data" / "starlink-v1p5"
"""),
    ("md", """## 1. A lab table and the model fitted to it

Each surface's table against `lambert+ggx` (k = 0) fitted in log space at an assumed 10 % error;
`sf.compare_brdf_models` says which of the models fits within it. The model's values are the fit's
(`fit.renders[0]`, the table observation's predicted values)."""),
    ("code", """lab = {}
for surface in ("chassis", "solar_array"):
    table = sf.read_brdf_table(DATA / f"{surface}_brdf.csv", floor=1e-4)
    print(sf.compare_brdf_models(table, ("lambert", "ggx", "lambert+ggx"), relative_error=0.1, fixed={"k": 0.0}).table())
    fit = sf.fit_brdf_table(table, "lambert+ggx", relative_error=0.1, fixed={"k": 0.0})
    lab[surface] = sf.fitted_material("lambert+ggx", fit)
    if surface == "chassis":
        chassis_table, chassis_fit = table, fit

table, fit = chassis_table, chassis_fit
print(sf.format_result(fit))
model = fit.renders[0]
zen_i = np.degrees(np.arccos(table.wi[:, 2]))
zen_o = np.degrees(np.arctan2(table.wo[:, 0], table.wo[:, 2]))
fig, ax = plt.subplots(figsize=(8, 4))
for z in sorted(set(np.round(zen_i, 1))):
    rows = np.isclose(zen_i, z, atol=0.1)
    line, = ax.semilogy(zen_o[rows], table.value[rows], ".", ms=3, label=f"lab, {z:g} deg in")
    order = np.argsort(zen_o[rows])
    ax.semilogy(zen_o[rows][order], model[rows][order], "-", color=line.get_color(), lw=1)
ax.set_xlabel("outgoing zenith in the plane of incidence (deg)")
ax.set_ylabel("BRDF (sr$^{-1}$)")
ax.set_title("chassis: lab (dots) and lambert+ggx (lines)")
ax.legend(fontsize=7);"""),
    ("md", """## 2. Predicted against observed magnitudes

The observations with the sun by astropy (offline) and the Earth's shadow flagged; the magnitudes
the two plates predict with the lab materials, then with the materials fitted to two thirds of
the observations and scored on the held-out third. Residual = observed - predicted."""),
    ("code", """obs = sf.read_light_curve(DATA / "pomenis_observations.csv", site=sf.Site(32.4434, -110.7881, 2791.0))
plates = [sf.Plate("chassis", 3.64, (0.0, 0.0, -1.0), lab["chassis"]), sf.Plate("array", 22.68, (0.0, 1.0, 0.0), lab["solar_array"])]
held = np.zeros(len(obs), dtype=bool)
held[np.random.default_rng(0).permutation(len(obs))[: len(obs) // 3]] = True
predicted_lab = sf.predict_magnitudes(plates, obs)
fit = sf.fit_plates(plates, obs.subset(~held), ["parts.chassis.kd", "parts.chassis.eta", "parts.chassis.alpha", "parts.array.eta", "parts.array.alpha"])
print(sf.format_result(fit))
predicted_fit = sf.predict_magnitudes(sf.fitted_plates(plates, fit), obs)


def scores(rows, predicted):
    r = obs.magnitude[rows] - predicted[rows]
    r = r[np.isfinite(r)]
    return f"n {r.size}, RMS {np.sqrt(np.mean(r**2)):.3f} mag, median {np.median(r):+.3f} mag"


print("lab tables, all:     ", scores(~obs.in_shadow, predicted_lab))
print("fitted, held-out third:", scores(held & ~obs.in_shadow, predicted_fit))
fig, axes = plt.subplots(1, 2, figsize=(9, 4), sharey=True)
for ax, predicted, rows, title in ((axes[0], predicted_lab, ~obs.in_shadow, "from the lab tables"),
                                   (axes[1], predicted_fit, held & ~obs.in_shadow, "fitted (held-out third)")):
    rows = rows & np.isfinite(predicted)
    ax.plot(predicted[rows], obs.magnitude[rows], ".", ms=3)
    lo, hi = np.nanmin(obs.magnitude), np.nanmax(obs.magnitude)
    ax.plot([lo, hi], [lo, hi], "k-", lw=0.8)
    ax.set_xlabel("predicted AB magnitude")
    ax.set_title(title)
axes[0].set_ylabel("observed AB magnitude");"""),
]

def main() -> None:
    nb = nbformat.v4.new_notebook()
    nb.cells = [nbformat.v4.new_markdown_cell(text) if kind == "md" else nbformat.v4.new_code_cell(text) for kind, text in CELLS]
    NotebookClient(nb, timeout=600, kernel_name="python3", resources={"metadata": {"path": str(HERE.parent)}}).execute()
    nbformat.write(nb, HERE / "starlink.ipynb")
    print(f"wrote {HERE / 'starlink.ipynb'}")


if __name__ == "__main__":
    main()
