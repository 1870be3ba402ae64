"""
A BRDF table fit: the Starlink chassis
======================================

A laboratory BRDF table of the chassis of Starlink v1.5 satellites (Fankhauser, Askari & Tyson
2023, AJ 166:59; the table ships with spacefit's repository under ``data/starlink-v1p5/``), read by
``sf.read_brdf_table`` and fitted with a diffuse term plus a GGX microfacet lobe (``lambert+ggx``;
``k`` held at 0: a coated surface's eta and k are not separable in the plane of incidence). The fit
compares logarithms, since the table spans five decades from the specular peak to the diffuse floor.
"""

from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

import spacefit as sf

root = next(
    p
    for p in [Path.cwd(), *Path.cwd().parents]
    if (p / "data" / "starlink-v1p5").is_dir()
)
table = sf.read_brdf_table(
    root / "data" / "starlink-v1p5" / "chassis_brdf.csv", floor=1e-4
)
fit = sf.fit_brdf_table(table, "lambert+ggx", fixed={"k": 0.0}, part="chassis")
print(
    f"{len(table.value)} values; {fit.status.name.lower()} in {len(fit.history)} steps"
)
for name in fit.names:
    print(f"  {name:20s} = {fit.values[name]:.4g} +- {fit.stderr[name]:.2g}")

# %%
# Data (points) and the fitted model (lines) in the plane of incidence, one colour per
# incident zenith angle; the outgoing angle is signed, negative on the light's side.
incidence = np.round(np.degrees(np.arccos(table.wi[:, 2])), 1)
outgoing = np.degrees(np.arccos(table.wo[:, 2])) * np.sign(
    table.wo[:, 0] * -np.sign(table.wi[:, 0] + 1e-12)
)
model = np.asarray(
    fit.renders[0]
)  # the fitted model at each of the table's directions, sr^-1
fig, ax = plt.subplots(figsize=(8, 4.5), layout="constrained")
for i, zenith in enumerate(np.unique(incidence)):
    rows = np.flatnonzero(incidence == zenith)
    rows = rows[np.argsort(outgoing[rows])]
    ax.semilogy(
        outgoing[rows],
        table.value[rows],
        ".",
        color=f"C{i}",
        alpha=0.6,
        label=f"incidence {zenith:g} deg",
    )
    ax.semilogy(outgoing[rows], model[rows], "-", color=f"C{i}")
ax.set(
    xlabel="outgoing zenith angle (deg; negative: the light's side)",
    ylabel="BRDF (sr$^{-1}$)",
    title="Starlink v1.5 chassis: lab table (points) and the lambert+ggx fit (lines)",
)
ax.legend(fontsize=9)
ax.grid(alpha=0.3)
