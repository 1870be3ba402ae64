"""Build and execute ``experiments/pass.ipynb``: a simulated pass with per-frame attitude errors,
observed through a sensor, fitted on a local dask cluster; per-frame nuisances, residuals and the
materials with their errors, small (it runs in ``make docs``). Executing it here stores its outputs, so
it reads without a kernel.
Run: ``.venv/bin/python experiments/make_pass_notebook.py`` (needs the ``notebook`` extra).
"""

from __future__ import annotations

from pathlib import Path

import nbformat
from nbclient import NotebookClient

HERE = Path(__file__).resolve().parent

CELLS: list[tuple[str, str]] = [
    ("md", """# Fit a pass: frames, their poses and the materials

A telescope follows a target through a pass: each frame has its own time, sun, observer and a
slightly wrong target attitude. Here four frames of the panels case are simulated through a sensor
(DN with shot and read noise), each with the target turned by up to 0.3 deg about x and z off the
attitude its frame table states; the three materials are fitted jointly with each frame's two
attitude angles, on a local dask cluster. Radiance in W m^-2 sr^-1, angles in degrees."""),
    ("code", """import tempfile
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
from astropy.table import Table

import spacefit as sf

base = sf.load_case("panels").truth_scene.with_values({"render.resolution": [32, 32], "camera.pixel_pitch_mm": 75.0})
truth = {"parts.panels.alpha_x": 0.15, "parts.panels.alpha_y": 0.03, "parts.legs.kd": 0.5}
sensor = sf.Sensor(radiometric_scale_dn_per_w_m2_sr=500.0, gain_dn_per_electron=0.5, bias_dn=100.0, read_noise_electrons=5.0,
                   bit_depth=16, full_well_electrons=None, diffraction=False, psf_sigma_px=0.0)
errors = [{"target.attitude_x_deg": float(a), "target.attitude_z_deg": float(b)}
          for a, b in np.random.default_rng(3).uniform(-0.3, 0.3, (4, 2))]
folder = Path(tempfile.mkdtemp()) / "pass"
frames = sf.simulate_pass(base, sf.arc_pass(4), folder, errors=errors, sensor=sensor, spp=1024)
Table.read(folder / "frames.csv")"""),
    ("md", """The frames as the sensor saw them (DN), the observer crossing the panels' glint half-way:"""),
    ("code", """obs = [sf.Observation.from_file(f.file, s) for f, s in zip(frames.frames, frames.scenes(base))]
fig, axes = plt.subplots(1, 4, figsize=(8, 2.3))
for ax, o, f in zip(axes, obs, frames.frames):
    ax.imshow(o.reference[..., 0], cmap="gray")
    ax.set_title(f"t = {f.time_s:.0f} s", fontsize=8)
    ax.axis("off")"""),
    ("md", """The joint fit: materials shared (from 20 % off), each frame's attitude about x and z its own,
renders and Jacobian columns on a local cluster of two dask workers (`cluster=2`; the values are
the same bit for bit in this process)."""),
    ("code", """free = [*truth, *frames.per_frame(["target.attitude_x_deg", "target.attitude_z_deg"])]
start = {"parts.panels.alpha_x": 0.12, "parts.panels.alpha_y": 0.036, "parts.legs.kd": 0.42}
result = sf.fit(obs, free, start=start, render=sf.FitRender(spp=32), max_steps=12, cluster=2)
print(sf.format_result(result).split("\\n  nuisance")[0])"""),
    ("md", """The goodness of fit above is judged on the mean of two new renders at the fitted values, at more samples
than the fit's (k x, k a power of 2 up to 16, chosen so that their render noise adds at most a tenth to the expected
chi^2/dof), every fitted value counted, and with the references' own render noise in the expected range (they were
rendered at 1024 spp, which their FITS card `RENDSPP` records): docs/how-to/pass.md.

The materials against the truth, with their standard errors:"""),
    ("code", """for name, value in truth.items():
    fitted, se = result.values[name], result.stderr[name]
    print(f"{name:22s} truth {value:.4f}  fitted {fitted:.4f} +- {se:.4f}  ({100 * (fitted / value - 1):+.1f} %, {(fitted - value) / se:+.1f} sigma)")"""),
    ("md", """Each frame's attitude errors, fitted against the simulated ones, and each frame's goodness of fit
(`sf.frame_table`, `sf.plot_frames`; the fit's report writes them as `frames.csv` and `frames.png`):"""),
    ("code", """rows = sf.frame_table(result, frames)
t = [r["time_s"] for r in rows]
fig, axes = plt.subplots(1, 3, figsize=(12, 3))
for ax, name in zip(axes, ["target.attitude_x_deg", "target.attitude_z_deg"]):
    ax.errorbar(t, [r[name] for r in rows], yerr=[r[f"{name}.stderr"] for r in rows], fmt="o", label="fitted")
    ax.plot(t, [e[name] for e in errors], "x", ms=9, label="simulated")
    ax.set(xlabel="time [s]", ylabel=name)
    ax.legend()
axes[2].plot(t, [r["chi2_dof"] for r in rows], "o")
axes[2].set(xlabel="time [s]", ylabel="chi^2 / dof of the frame (incl. render noise)")
fig.tight_layout()
Table(rows)"""),
    ("md", """Per-frame residuals, reference - model (DN):"""),
    ("code", """fig, axes = plt.subplots(1, 4, figsize=(8, 2.3))
limit = max(np.nanmax(np.abs(r)) for r in result.residuals)
for ax, r, f in zip(axes, result.residuals, frames.frames):
    ax.imshow(r[..., 0], cmap="RdBu", vmin=-limit, vmax=limit)
    ax.set_title(f"t = {f.time_s:.0f} s", fontsize=8)
    ax.axis("off")"""),
]


def main() -> None:
    nb = nbformat.v4.new_notebook()
    nb.cells = [nbformat.v4.new_markdown_cell(src) if kind == "md" else nbformat.v4.new_code_cell(src) for kind, src in CELLS]
    NotebookClient(nb, timeout=3600, resources={"metadata": {"path": str(HERE)}}).execute()
    nbformat.write(nb, HERE / "pass.ipynb")
    print(f"wrote {HERE / 'pass.ipynb'}")


if __name__ == "__main__":
    main()
