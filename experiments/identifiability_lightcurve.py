"""What a light curve can tell (issue 22): each material parameter's expected standard error from one
resolved image, from a resolved pass (the images at every geometry of a pass) and from the light
curve over the same geometries, at stated noise levels, without fitting.

The target is the "materials" case's lander (panels alpha_x, alpha_y, eta; body alpha; legs kd),
tumbling through a pass of 8 attitudes (about x from -60 to 60 deg and about z from 0 to 315 deg,
:data:`ATTITUDES`), rendered at 32 x 32 px. For each
geometry the Jacobian of the image with respect to the parameters (:func:`spacefit.jacobian`,
forward mode, 64 spp); the standard errors are sqrt(diag((J^T J / sigma^2)^-1)) (the Fisher
information of Gaussian noise):

* image: the image at attitude 0 with per-value noise sigma = 2 % of its brightest value;
* pass: the images at every attitude, the same noise;
* light curve: each attitude's irradiance (the image's sum of radiance x pixel solid angle), noise
  1 % of it (0.011 mag).

Writes ``identifiability_lightcurve.csv`` and ``.png`` to ``--out``. Run:
``PYTHONPATH=. .venv/bin/python experiments/identifiability_lightcurve.py`` (about 5 min on 2 busy cores).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import matplotlib
import numpy as np

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

import spacefit as sf  # noqa: E402
from spacefit.scene.assembly import assemble  # noqa: E402
from spacefit.scene.parameters import scene_value  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
# The pass: (attitude_x_deg, attitude_z_deg) at each geometry, the target tumbling through it.
ATTITUDES = [(0.0, 0.0), (30.0, 45.0), (60.0, 90.0), (30.0, 135.0), (0.0, 180.0), (-30.0, 225.0), (-60.0, 270.0), (-30.0, 315.0)]
IMAGE_NOISE = 0.02  # of the image's brightest value, per value
CURVE_NOISE = 0.01  # of each irradiance


def standard_errors(J: np.ndarray) -> np.ndarray:
    """sqrt(diag(F^-1)) of the Fisher information F = J^T J (J already divided by the noise); inf
    along directions F does not constrain."""
    eigval, eigvec = np.linalg.eigh(J.T @ J)
    tiny = eigval <= 1e-12 * eigval.max()
    cov = (eigvec[:, ~tiny] / eigval[~tiny]) @ eigvec[:, ~tiny].T
    se = np.sqrt(np.diag(cov))
    se[np.any(np.abs(eigvec[:, tiny]) > 1e-6, axis=1)] = np.inf
    return se


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=ROOT / "experiments" / "results" / "identifiability_lightcurve")
    args = parser.parse_args()
    case = sf.load_case("materials")
    free = list(case.free)
    scene = case.truth_scene.with_values({"render.resolution": [32, 32], "camera.pixel_pitch_mm": 75.0})
    omega = sf.pixel_solid_angles(assemble(scene).intrinsics)
    images, curve = [], []
    for a in ATTITUDES:
        jac = sf.jacobian(scene.with_values({"target.attitude_x_deg": a[0], "target.attitude_z_deg": a[1]}), free, spp=64, spp_grad=64)
        columns = np.stack([jac.columns[n] for n in free], axis=-1)  # (h, w, 3, n)
        images.append((jac.image, columns))
        e = float(np.sum(jac.image.mean(axis=-1) * omega))
        curve.append((e, np.einsum("hwcn,hw->n", columns, omega) / 3.0))
    sigma = IMAGE_NOISE * images[0][0].max()
    one = standard_errors(images[0][1].reshape(-1, len(free)) / sigma)
    whole = standard_errors(np.concatenate([c.reshape(-1, len(free)) / (IMAGE_NOISE * img.max()) for img, c in images]))
    light = standard_errors(np.stack([d / (CURVE_NOISE * e) for e, d in curve]))
    values = np.array([scene_value(case.truth_scene, n) for n in free])
    args.out.mkdir(parents=True, exist_ok=True)
    rows = [{"parameter": n, "value": float(v), "image_se": float(a), "pass_se": float(b), "light_curve_se": float(c)}
            for n, v, a, b, c in zip(free, values, one, whole, light)]
    (args.out / "identifiability_lightcurve.json").write_text(json.dumps(rows, indent=1))
    with open(args.out / "identifiability_lightcurve.csv", "w") as f:
        f.write("parameter,value,image_se,pass_se,light_curve_se\n")
        for r in rows:
            f.write(f"{r['parameter']},{r['value']:.6g},{r['image_se']:.4g},{r['pass_se']:.4g},{r['light_curve_se']:.4g}\n")
    fig, ax = plt.subplots(figsize=(8, 3.6), layout="constrained")
    x = np.arange(len(free))
    for k, (label, se) in enumerate((("one image (2 % noise)", one), ("the pass's 8 images", whole), ("light curve (1 %)", light))):
        rel = np.where(np.isfinite(se), se / np.abs(values), 1e3)
        ax.bar(x + (k - 1) * 0.27, rel, 0.27, label=label)
    ax.set_yscale("log")
    ax.axhline(0.1, color="k", lw=0.8, ls="--")
    ax.set_xticks(x, [n.replace("parts.", "") for n in free])
    ax.set_ylabel("expected standard error / value")
    ax.set_title("what a light curve can tell: the materials case's lander, 8 attitudes (1e3: undetermined)", fontsize=9)
    ax.legend(fontsize=8)
    fig.savefig(args.out / "identifiability_lightcurve.png", dpi=120)
    for r in rows:
        print(f"{r['parameter']:>22s} {r['value']:8.4g}  image {r['image_se']:9.3g}  pass {r['pass_se']:9.3g}  light curve {r['light_curve_se']:9.3g}")


if __name__ == "__main__":
    main()
