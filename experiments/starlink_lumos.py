"""The peer for experiments/starlink.py: the published model, lumos-sat 1.0.9 (Fankhauser, Askari &
Tyson 2023), computed the same way on the same observations and the same held-out third.

Runs in its own environment (lumos-sat pins numpy 1.24 and astropy 5.2, which spacefit's do not
allow): ``python3 -m venv .venv-lumos && .venv-lumos/bin/pip install lumos-sat``, then
``.venv-lumos/bin/python experiments/starlink_lumos.py`` after ``experiments/starlink.py`` (whose
``geometry.csv`` gives each observation's sun altitude and azimuth, by astropy offline, the Earth's
shadow and the split).

(a) lab tables: lumos-sat's Phong model (Kd, Ks, n) fitted to each table by lumos-sat's own
    ``brdf.tools.fit`` (log space, values above the 1e-4 sr^-1 floor). The paper's lab model is a
    Binomial fit whose coefficients are not published with the package; Phong is the model the
    package documents for fits.
(b) observations: the two surfaces' Phong parameters fitted to the training two thirds of the
    observed magnitudes (scipy least squares in magnitudes, as the paper's analysis), scored on
    the held-out third.
Sun only (no Earthshine) unless ``--earthshine`` (lumos-sat's Earth mesh, a Lambertian Earth of
albedo 0.3, 51 x 51 panels). Writes ``experiments/results/starlink/lumos.json`` and
``lumos_lambert.csv``: lumos-sat's AB magnitude of each observation with both surfaces Lambertian
(albedo 0.5), sun only, which tests/test_observed_lightcurves.py holds spacefit's flat plates to.
"""

from __future__ import annotations

import argparse
import csv
import json
from pathlib import Path

import numpy as np
import scipy.optimize

import lumos.brdf.library
import lumos.brdf.tools
import lumos.calculator
import lumos.conversions
import lumos.geometry

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "data" / "starlink-v1p5"
RESULTS = ROOT / "experiments" / "results" / "starlink"


def scores(observed: np.ndarray, predicted: np.ndarray) -> dict:
    """As experiments/starlink.py: residual = observed - predicted where the prediction is finite."""
    ok = np.isfinite(predicted) & np.isfinite(observed)
    r = observed[ok] - predicted[ok]
    return {"n": int(ok.sum()), "pearson_r": float(np.corrcoef(observed[ok], predicted[ok])[0, 1]),
            "rms_mag": float(np.sqrt(np.mean(r**2))), "median_mag": float(np.median(r)), "bias_mag": float(np.mean(r))}


def magnitudes(params, obs, geometry, rows, earthshine: bool) -> np.ndarray:
    """lumos-sat's AB magnitudes of the two Phong surfaces at observations ``rows`` (inf where dark)."""
    kd_c, ks_c, n_c, kd_a, ks_a, n_a = params
    surfaces = [lumos.geometry.Surface(3.64, np.array([0, 0, -1]), lumos.brdf.library.PHONG(kd_c, ks_c, n_c)),
                lumos.geometry.Surface(22.68, np.array([0, 1, 0]), lumos.brdf.library.PHONG(kd_a, ks_a, n_a))]
    out = np.full(len(rows), np.inf)
    for j, i in enumerate(rows):
        intensity = lumos.calculator.get_intensity_observer_frame(
            surfaces, obs["height_m"][i], obs["altitude"][i], obs["azimuth"][i], geometry["sun_alt"][i], geometry["sun_az"][i],
            include_earthshine=earthshine, earth_panel_density=51, earth_brdf=lumos.brdf.library.LAMBERTIAN(0.3))
        if intensity > 0:
            out[j] = lumos.conversions.intensity_to_ab_mag(intensity, clip=False)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--earthshine", action="store_true")
    args = parser.parse_args()
    lines = [line for line in (DATA / "pomenis_observations.csv").read_text().splitlines() if line.strip() and not line.startswith("#")]
    rows = list(csv.DictReader(lines))
    obs = {"height_m": np.array([float(r["satellite_height"]) * 1e3 for r in rows]),
           "altitude": np.array([float(r["satellite_altitude"]) for r in rows]),
           "azimuth": np.array([float(r["satellite_azimuth"]) for r in rows]),
           "magnitude": np.array([float(r["ab_magnitude"]) for r in rows])}
    g = list(csv.DictReader((RESULTS / "geometry.csv").read_text().splitlines()))
    geometry = {"sun_alt": np.array([float(r["sun_altitude_deg"]) for r in g]), "sun_az": np.array([float(r["sun_azimuth_deg"]) for r in g]),
                "held_out": np.array([r["held_out"] == "1" for r in g])}
    lambert = lumos.brdf.library.LAMBERTIAN(0.5)
    surfaces = [lumos.geometry.Surface(3.64, np.array([0, 0, -1]), lambert), lumos.geometry.Surface(22.68, np.array([0, 1, 0]), lambert)]
    with open(RESULTS / "lumos_lambert.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["# lumos-sat 1.0.9: AB magnitude of the Pomenis observations, chassis and array Lambertian (0.5), sun only"])
        w.writerow(["row", "ab_magnitude"])
        for i in range(len(rows)):
            intensity = lumos.calculator.get_intensity_observer_frame(
                surfaces, obs["height_m"][i], obs["altitude"][i], obs["azimuth"][i], geometry["sun_alt"][i], geometry["sun_az"][i],
                include_earthshine=False)
            if intensity > 0:
                w.writerow([i, f"{float(lumos.conversions.intensity_to_ab_mag(intensity, clip=False)):.6f}"])
    held = np.flatnonzero(geometry["held_out"])
    train = np.flatnonzero(~geometry["held_out"])
    everything = np.arange(len(rows))
    lab = []
    for surface in ("chassis", "solar_array"):
        popt = lumos.brdf.tools.fit(str(DATA / f"{surface}_brdf.csv"), lumos.brdf.library.PHONG,
                                    bounds=([0, 0, 0], [1, 1, 1e4]), p0=(0.1, 0.5, 50), log_space=True, clip=1e-4)
        lab.extend(float(p) for p in popt)
    out: dict = {"earthshine": args.earthshine, "lab_phong": lab}
    predicted = magnitudes(lab, obs, geometry, everything, args.earthshine)
    out["lab"] = {"all": scores(obs["magnitude"], predicted), "held_out": scores(obs["magnitude"][held], predicted[held])}

    def residual(p):
        m = magnitudes(p, obs, geometry, train, False)
        return np.where(np.isfinite(m), obs["magnitude"][train] - m, 0.0)

    fit = scipy.optimize.least_squares(residual, lab, bounds=([0, 0, 0, 0, 0, 0], [1, 1, 1e4, 1, 1, 1e4]), x_scale="jac")
    fitted = magnitudes(fit.x, obs, geometry, everything, args.earthshine)
    out["fitted_phong"] = fit.x.tolist()
    out["fitted"] = {"held_out": scores(obs["magnitude"][held], fitted[held]), "in_sample": scores(obs["magnitude"][train], fitted[train])}
    name = "lumos_earthshine.json" if args.earthshine else "lumos.json"
    (RESULTS / name).write_text(json.dumps(out, indent=1))
    for key in ("lab", "fitted"):
        for part, s in out[key].items():
            print(f"lumos {key:>7s} {part:>9s}: n {s['n']}, R {s['pearson_r']:.3f}, RMS {s['rms_mag']:.3f}, "
                  f"median {s['median_mag']:+.3f}, bias {s['bias_mag']:+.3f}")


if __name__ == "__main__":
    main()
