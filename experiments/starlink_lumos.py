"""The peer for experiments/starlink.py: the published model, lumos-sat 1.0.9 (Fankhauser, Askari &
Tyson 2023), computed the same way on the same observations and the same splits (whole nights in 3
folds, date halves, the former random third).

Runs in its own environment (lumos-sat pins numpy 1.24 and astropy 5.2, which spacefit's do not
allow): ``python3 -m venv .venv-lumos && .venv-lumos/bin/pip install lumos-sat``, then
``.venv-lumos/bin/python experiments/starlink_lumos.py`` after ``experiments/starlink.py`` (whose
``geometry.csv`` gives each observation's sun altitude and azimuth, by astropy offline, the Earth's
shadow and the splits).

(a) lab tables, three ways: the paper's own lab model, a Binomial fit (Greynolds) to each table
    whose coefficients the package does not ship but the paper's repository does
    (``analysis/satellite_models/starlink_v1p5.py`` of Forrest-Fankhauser/satellite-optical-brightness,
    copied below; that file takes the areas as 3.65 and 22 m^2, here 3.64 and 22.68 as the data's
    description); lumos-sat's Phong model (Kd, Ks, n) fitted to each table by lumos-sat's own
    ``brdf.tools.fit`` (log space, values above the 1e-4 sr^-1 floor); and the tables used as they
    are, interpolated as ``sf.TabulatedBRDF`` does (:func:`tabulated`, written here again in numpy
    from its definition, on lumos-sat's own reading of the files).
(b) observations: the two surfaces' Phong parameters fitted to each split's training rows of the
    observed magnitudes (scipy least squares in magnitudes, as the paper's analysis, from the
    Phong fits to the tables), scored on its held-out rows; pooled over a split's folds and per fold.
Sun only (no Earthshine) unless ``--earthshine`` (lumos-sat's Earth mesh, a Lambertian Earth of
albedo 0.3, 51 x 51 panels). Writes ``experiments/results/starlink/lumos.json`` and
``lumos_lambert.csv``: lumos-sat's AB magnitude of each observation with both surfaces Lambertian
(albedo 0.5), sun only, and ``lumos_tabulated.csv``: the chassis alone and the array alone, each
with its tabulated lab BRDF, sun only, which tests/test_observed_lightcurves.py holds spacefit's
flat plates to.
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


CHASSIS, ARRAY = (3.64, np.array([0, 0, -1])), (22.68, np.array([0, 1, 0]))
# The paper's lab model: Binomial fits to the two tables (its repository's analysis/satellite_models/starlink_v1p5.py).
BINOMIAL_CHASSIS = lumos.brdf.library.BINOMIAL(np.array([[3.34, -98.085]]), np.array(
    [[-999.999, 867.538, 1000., 1000., -731.248, 618.552, -294.054, 269.248, -144.853, 75.196]]), d=3.0, l1=-5)
BINOMIAL_ARRAY = lumos.brdf.library.BINOMIAL(np.array([[0.534, -20.409]]), np.array(
    [[-527.765, 1000., -676.579, 430.596, -175.806, 57.879]]), d=3.0, l1=-3)


def signed_offset(i, n, o):
    """Harvey's signed offset of ``o`` from the specular direction of ``i`` about the normal ``n``, in
    direction cosines (sf.TabulatedBRDF's definition): beta = o's projection onto the surface,
    beta_0 = the mirror direction's, |beta - beta_0| signed by (beta - beta_0) . beta_0."""
    i, o = np.asarray(i, float), np.asarray(o, float)
    n = np.asarray(n, float).reshape((3,) + (1,) * (i.ndim - 1))
    beta = o - np.sum(o * n, axis=0) * n
    beta0 = -(i - np.sum(i * n, axis=0) * n)
    delta = beta - beta0
    d = np.sqrt(np.sum(delta**2, axis=0))
    return np.where(np.sum(delta * beta0, axis=0) < 0, -d, d)


def tabulated(path: Path):
    """A lumos-sat BRDF function of a measured in-plane table used as it is (sf.TabulatedBRDF's
    definition): ln f linear in the signed offset at each measured incidence, linear in the incident
    zenith between incidences, held at the end values beyond; rows at or beyond grazing and values
    <= 0 dropped (as sf.read_brdf_table)."""
    zi, ai, zo, ao, f = lumos.brdf.tools.read_brdf(str(path))
    keep = (np.abs(zi) < 90) & (np.abs(zo) < 90) & (f > 0)
    i = np.array(lumos.conversions.spherical_to_unit(np.radians(zi[keep]), np.radians(ai[keep])))
    o = np.array(lumos.conversions.spherical_to_unit(np.radians(zo[keep]), np.radians(ao[keep])))
    u, theta, log_f = signed_offset(i, (0, 0, 1), o), np.round(np.arccos(i[2]), 9), np.log(f[keep])
    grid = np.unique(theta)
    lines = []
    for t in grid:
        x, where = np.unique(u[theta == t], return_inverse=True)
        lines.append((x, np.bincount(where, log_f[theta == t]) / np.bincount(where)))

    def brdf(incident, normal, outgoing):
        i, o = np.array(incident, float), np.array(outgoing, float)
        i, o = np.broadcast_arrays(i.reshape(3, -1), o.reshape(3, -1))
        n = np.asarray(normal, float)
        cos_i, cos_o = n @ i, n @ o
        t = np.arccos(np.clip(cos_i, -1, 1))
        u = signed_offset(i, n, o)
        value = sum(np.interp(t, grid, np.eye(len(grid))[k]) * np.interp(u, x, y) for k, (x, y) in enumerate(lines))
        out = np.where((cos_i > 0) & (cos_o > 0), np.exp(value), 0.0)
        return out.reshape(np.shape(incident[0])) if np.ndim(incident[0]) else out.reshape(np.shape(outgoing[0]))

    return brdf


def magnitudes_of(surfaces, obs, geometry, rows, earthshine: bool) -> np.ndarray:
    """lumos-sat's AB magnitudes of ``surfaces`` at observations ``rows`` (inf where dark)."""
    out = np.full(len(rows), np.inf)
    for j, i in enumerate(rows):
        intensity = lumos.calculator.get_intensity_observer_frame(
            surfaces, obs["height_m"][i], obs["altitude"][i], obs["azimuth"][i], geometry["sun_alt"][i], geometry["sun_az"][i],
            include_earthshine=earthshine, earth_panel_density=51, earth_brdf=lumos.brdf.library.LAMBERTIAN(0.3))
        if intensity > 0:
            out[j] = lumos.conversions.intensity_to_ab_mag(intensity, clip=False)
    return out


def magnitudes(params, obs, geometry, rows, earthshine: bool) -> np.ndarray:
    """lumos-sat's AB magnitudes of the two Phong surfaces at observations ``rows`` (inf where dark)."""
    kd_c, ks_c, n_c, kd_a, ks_a, n_a = params
    surfaces = [lumos.geometry.Surface(*CHASSIS, lumos.brdf.library.PHONG(kd_c, ks_c, n_c)),
                lumos.geometry.Surface(*ARRAY, lumos.brdf.library.PHONG(kd_a, ks_a, n_a))]
    return magnitudes_of(surfaces, obs, geometry, rows, earthshine)


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
    geometry = {"sun_alt": np.array([float(r["sun_altitude_deg"]) for r in g]), "sun_az": np.array([float(r["sun_azimuth_deg"]) for r in g])}
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
    tables = {"chassis": tabulated(DATA / "chassis_brdf.csv"), "array": tabulated(DATA / "solar_array_brdf.csv")}
    if not args.earthshine:
        alone = {name: magnitudes_of([lumos.geometry.Surface(*plate, tables[name])], obs, geometry, np.arange(len(rows)), False)
                 for name, plate in (("chassis", CHASSIS), ("array", ARRAY))}
        with open(RESULTS / "lumos_tabulated.csv", "w", newline="") as f:
            w = csv.writer(f)
            w.writerow(["# lumos-sat 1.0.9: AB magnitude of one plate with its tabulated lab BRDF (sf.TabulatedBRDF's definition), "
                        "sun only, at the Pomenis observations (inf: dark); .venv-lumos/bin/python experiments/starlink_lumos.py"])
            w.writerow(["row", "chassis_ab_magnitude", "array_ab_magnitude"])
            for i in range(len(rows)):
                w.writerow([i, f"{alone['chassis'][i]:.6f}", f"{alone['array'][i]:.6f}"])
    everything = np.arange(len(rows))
    lab = []
    for surface in ("chassis", "solar_array"):
        popt = lumos.brdf.tools.fit(str(DATA / f"{surface}_brdf.csv"), lumos.brdf.library.PHONG,
                                    bounds=([0, 0, 0], [1, 1, 1e4]), p0=(0.1, 0.5, 50), log_space=True, clip=1e-4)
        lab.extend(float(p) for p in popt)
    out: dict = {"earthshine": args.earthshine, "lab_phong": lab, "splits": {}}
    lab_predictions = {"lab": magnitudes(lab, obs, geometry, everything, args.earthshine)}
    for name, chassis, array in (("lab_binomial", BINOMIAL_CHASSIS, BINOMIAL_ARRAY), ("lab_tabulated", tables["chassis"], tables["array"])):
        lab_predictions[name] = magnitudes_of([lumos.geometry.Surface(*CHASSIS, chassis), lumos.geometry.Surface(*ARRAY, array)], obs,
                                              geometry, everything, args.earthshine)
    lit = np.array([r["in_shadow"] == "0" for r in g])
    folds_of = {"night": [(f"fold {k}", np.array([r["night_fold"] == str(k) for r in g])) for k in range(3)],
                "date": [(f"date half {k}", np.array([r["date_half"] == str(k) for r in g])) for k in range(2)],
                "random": [("random third", np.array([r["random_held_out"] == "1" for r in g]))]}
    for kind, folds in folds_of.items():
        # fitted on the sun-only run and the whole-night splits alone: a fit is 100 s of CPU
        fit_here = not args.earthshine and kind != "random"
        record: dict = {"models": {m: {"folds": []} for m in (*lab_predictions, *(["fitted"] if fit_here else []))}}
        fitted_all = np.full(len(rows), np.nan)
        for fold, held in folds:
            for m, predicted in lab_predictions.items():
                record["models"][m]["folds"].append({"fold": fold, "held_out": scores(obs["magnitude"][held], predicted[held])})
            if not fit_here:
                continue
            train = np.flatnonzero(~held & lit)

            def residual(p, train=train):
                m = magnitudes(p, obs, geometry, train, False)
                return np.where(np.isfinite(m), obs["magnitude"][train] - m, 0.0)

            fit = scipy.optimize.least_squares(residual, lab, bounds=([0, 0, 0, 0, 0, 0], [1, 1, 1e4, 1, 1, 1e4]), x_scale="jac")
            fitted_all[held] = magnitudes(fit.x, obs, geometry, np.flatnonzero(held), args.earthshine)
            record["models"]["fitted"]["folds"].append({"fold": fold, "phong": fit.x.tolist(),
                                                         "held_out": scores(obs["magnitude"][held], fitted_all[held])})
        every = np.zeros(len(rows), dtype=bool)
        for _, held in folds:
            every |= held
        for m, predicted in (*lab_predictions.items(), *([("fitted", fitted_all)] if fit_here else [])):
            record["models"][m]["pooled"] = scores(obs["magnitude"][every], predicted[every])
        out["splits"][kind] = record
    name = "lumos_earthshine.json" if args.earthshine else "lumos.json"
    (RESULTS / name).write_text(json.dumps(out, indent=1))
    for kind, record in out["splits"].items():
        for m, r in record["models"].items():
            s = r["pooled"]
            folds = ", ".join(f"{f['held_out']['rms_mag']:.3f}" for f in r["folds"])
            print(f"lumos {kind:>6s} {m:>13s} pooled: n {s['n']}, R {s['pearson_r']:.3f}, RMS {s['rms_mag']:.3f} (folds {folds}), "
                  f"median {s['median_mag']:+.3f}, bias {s['bias_mag']:+.3f}")


if __name__ == "__main__":
    main()
