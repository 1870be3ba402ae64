"""The real case: Starlink v1.5 magnitudes observed from Mount Lemmon, predicted from the laboratory
BRDFs of its two surfaces and fitted to the observations (issue 22).

Data: ``data/starlink-v1p5/`` (MIT licence, Fankhauser, Askari & Tyson 2023, AJ 166:59). The
satellite is two flat plates (:mod:`spacefit.studies.plates`): the chassis underside, 3.64 m^2,
facing nadir (-z), and the solar array, 22.68 m^2, perpendicular to it and turned about z towards
the sun (+y), in the nadir-sun frame of :mod:`spacefit.studies.observing`; the sun by astropy,
offline; the Earth's shadow a cylinder; sun 1360 W m^-2; magnitudes AB at 532 nm (lumos-sat's).

(a) lab tables: each surface's table (values above its 1e-4 sr^-1 floor, away from grazing) fitted
    with ``lambert+ggx`` (kd, eta, alpha; k = 0: a dielectric's Fresnel factor, eta and k not
    separable in these in-plane tables), then every observation predicted.
(b) observations: the chassis's kd, eta, alpha and the array's eta, alpha fitted to a random two
    thirds of the observations (seed 0), scored on the held-out third; the materials start from
    (a)'s, the array's kd stays (a)'s (freed, it ran to its bound 0).

Scores, residual = observed - predicted (mag), over the observations with a finite prediction
(outside the Earth's shadow): Pearson R, RMS, median, bias (mean). Writes
``experiments/results/starlink/starlink.json`` (figures, fits, split) and ``geometry.csv`` (per
observation: sun altitude / azimuth at the site, in shadow, held out) that ``starlink_lumos.py``,
the peer lumos-sat computed the same way, reads.

Run: ``PYTHONPATH=. .venv/bin/python experiments/starlink.py`` (about 2 min on 2 busy cores).
"""

from __future__ import annotations

import argparse
import csv
import json
import time
from pathlib import Path

import numpy as np

from spacefit.fitting.brdf_table import compare_brdf_models, fit_brdf_table, fitted_material, read_brdf_table
from spacefit.studies.observing import Site, read_light_curve, sun_directions_enu
from spacefit.studies.plates import Plate, fit_plates, fitted_plates, predict_magnitudes

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "data" / "starlink-v1p5"
MOUNT_LEMMON = Site(32.4434, -110.7881, 2791.0)
# The relative error assumed for the lab tables' model comparison (the tables state none).
LAB_RELATIVE_ERROR = 0.1
SUN_IRRADIANCE = 1360.0
# The array's diffuse term stays the lab's: freed, it runs to 0 (a bound), the array's light then all specular.
FREE = ["chassis.kd", "chassis.eta", "chassis.alpha", "array.eta", "array.alpha"]


def scores(observed: np.ndarray, predicted: np.ndarray) -> dict[str, float]:
    """Pearson R, RMS, median and bias (mean) of observed - predicted where the prediction is finite."""
    ok = np.isfinite(predicted) & np.isfinite(observed)
    r = observed[ok] - predicted[ok]
    return {"n": int(ok.sum()), "pearson_r": float(np.corrcoef(observed[ok], predicted[ok])[0, 1]),
            "rms_mag": float(np.sqrt(np.mean(r**2))), "median_mag": float(np.median(r)), "bias_mag": float(np.mean(r))}


def plates(chassis, array) -> list[Plate]:
    """The two-plate satellite (module docstring)."""
    return [Plate("chassis", 3.64, (0.0, 0.0, -1.0), chassis), Plate("array", 22.68, (0.0, 1.0, 0.0), array)]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=ROOT / "experiments" / "results" / "starlink")
    args = parser.parse_args()
    t0 = time.time()
    out: dict = {"date_utc": time.strftime("%Y-%m-%d %H:%M", time.gmtime())}
    lab = {}
    for surface in ("chassis", "solar_array"):
        table = read_brdf_table(DATA / f"{surface}_brdf.csv", floor=1e-4)
        comparison = compare_brdf_models(table, ("lambert", "ggx", "lambert+ggx", "lambert+beckmann"),
                                         relative_error=LAB_RELATIVE_ERROR, fixed={"k": 0.0})
        print(f"{surface}: {len(table)} values, models at {LAB_RELATIVE_ERROR:.0%} relative error\n{comparison.table()}")
        fit = fit_brdf_table(table, "lambert+ggx", fixed={"k": 0.0})  # errors from the residuals' scatter
        print(fit.report())
        lab[surface] = fitted_material("lambert+ggx", fit)
        out[f"lab_{surface}"] = {"comparison": comparison.table(), "fit": fit.to_dict(), "rms_ln": float(np.sqrt(np.mean(fit.residuals**2)))}
    obs = read_light_curve(DATA / "pomenis_observations.csv", site=MOUNT_LEMMON)
    satellite = plates(lab["chassis"], lab["solar_array"])
    predicted_lab = predict_magnitudes(satellite, obs, SUN_IRRADIANCE)
    rng = np.random.default_rng(0)
    held_out = np.zeros(len(obs), dtype=bool)
    held_out[rng.permutation(len(obs))[: len(obs) // 3]] = True
    out["observations"] = {"n": len(obs), "in_shadow": int(obs.in_shadow.sum()), "held_out": int(held_out.sum()),
                           "observed_sd_mag": float(np.std(obs.magnitude))}
    out["lab"] = {"all": scores(obs.magnitude, predicted_lab), "held_out": scores(obs.magnitude[held_out], predicted_lab[held_out])}
    fit = fit_plates(satellite, obs.subset(~held_out), FREE, sun_irradiance_w_m2=SUN_IRRADIANCE)
    print("fit to the observations (training two thirds):\n" + fit.report())
    predicted_fit = predict_magnitudes(fitted_plates(satellite, fit), obs, SUN_IRRADIANCE)
    out["fitted"] = {"fit": fit.to_dict(), "held_out": scores(obs.magnitude[held_out], predicted_fit[held_out]),
                     "in_sample": scores(obs.magnitude[~held_out], predicted_fit[~held_out])}
    out["wall_s"] = time.time() - t0
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "starlink.json").write_text(json.dumps(out, indent=1))
    sun = sun_directions_enu(obs.time_utc, MOUNT_LEMMON)
    with open(args.out / "geometry.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["sun_altitude_deg", "sun_azimuth_deg", "in_shadow", "held_out", "spacefit_lab_mag", "spacefit_fitted_mag"])
        for i in range(len(obs)):
            alt = np.degrees(np.arcsin(sun[i, 2]))
            az = np.degrees(np.arctan2(sun[i, 0], sun[i, 1])) % 360.0
            w.writerow([f"{alt:.6f}", f"{az:.6f}", int(obs.in_shadow[i]), int(held_out[i]), f"{predicted_lab[i]:.5f}",
                        f"{predicted_fit[i]:.5f}"])
    for name in ("lab", "fitted"):
        for part, s in out[name].items():
            if isinstance(s, dict) and "pearson_r" in s:
                print(f"{name:>7s} {part:>9s}: n {s['n']}, R {s['pearson_r']:.3f}, RMS {s['rms_mag']:.3f}, median {s['median_mag']:+.3f}, "
                      f"bias {s['bias_mag']:+.3f}")
    print(f"{out['observations']}; {out['wall_s']:.0f} s")


if __name__ == "__main__":
    main()
