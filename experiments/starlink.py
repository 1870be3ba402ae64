"""The real case: Starlink v1.5 magnitudes observed from Mount Lemmon, predicted from the laboratory
BRDFs of its two surfaces and fitted to the observations, scored on whole nights held out (issues 22, 32).

Data: ``data/starlink-v1p5/`` (MIT licence, Fankhauser, Askari & Tyson 2023, AJ 166:59). The
satellite is the target description ``data/scenes/starlink-v1p5.toml`` as flat plates
(:func:`satellite`, :mod:`spacefit.studies.plates`): the chassis's nadir face, 3.64 m^2, facing -z,
and the solar array, 22.68 m^2, perpendicular to it and turned about z towards the sun (+y), in the
nadir-sun frame of :mod:`spacefit.studies.observing`; the sun by astropy, offline; the Earth's
shadow a cylinder; sun 1360 W m^-2; magnitudes AB at 532 nm (lumos-sat's).

Splits (:func:`splits`): the observations of one night (local evening date at Mount Lemmon,
UTC - 19 h) are never split. ``night``: the 79 nights in 3 folds (nights shuffled with seed 0, each
put in the fold with the fewest rows so far), each fold held out in turn and the scores pooled over
the three and given per fold; ``date``: the nights before the median date held out (the model fitted
to the later ones) and the reverse; ``random``: a random third of rows (seed 0), the former split,
kept for the record: its held-out rows have training rows of the same night minutes away.

Models, each scored on every split's held-out rows:
(a) lab tables alone: each surface's table (values above its 1e-4 sr^-1 floor) fitted with
    ``lambert+ggx`` (kd, eta, alpha; k = 0); and each table as it is (``sf.TabulatedBRDF``, extended
    off the plane of incidence by Harvey's direction cosines as the published Binomial model), with
    and without Earthshine (``sf.Earth()``, Lambert albedo 0.3). Nothing is fitted to observations.
(b) fitted to the training nights (Earthshine is left out of the fits: its share is small, see (a),
    and a fit with it took 4 min a fold): ``fitted``: the chassis's kd, eta (held >= 1) and alpha and the
    array's alpha, from (a)'s; ``attitude``: and the target's attitude about x (across the sun's
    plane); ``tables x 2``: the lab
    tables as they are with the two tables' factors fitted. (A design fit of the training nights, one
    light curve each with its own exposure scale ``image.scale@k``, took over 6 min a fold: left out;
    what per-night offsets would explain is measured from the residuals instead, below.)
Each fitted model's predictive interval per held-out observation (``sf.predict_design``): the
observations' error, which the data do not state, estimated from the training residuals over their
degrees of freedom (``sf.design_noise_mag``), with the parameters' covariance through the model's
Jacobian; its coverage is the fraction of held-out magnitudes within 1 sigma.

Scores, residual = observed - predicted (mag), over the observations with a finite prediction
(outside the Earth's shadow): Pearson R, RMS, median, bias (mean), coverage. Residuals of the best
by-night model binned by solar phase angle, by the sun's altitude at the site and by night (the
nights' mean residuals' spread against what the within-night scatter gives). Writes
``experiments/results/starlink/starlink.json`` and ``geometry.csv`` (per observation: sun altitude /
azimuth at the site, in shadow, night, night fold, date half, random held-out) that
``starlink_lumos.py``, the published model computed and fitted the same way, reads.

With ``--render-check N`` the two-part satellite is also rendered as a mesh (:func:`write_satellite_obj`)
with the lab materials at N observations and compared with the flat plates.

Run: ``PYTHONPATH=. .venv/bin/python experiments/starlink.py`` (about 5 min on 2 busy cores).
"""

from __future__ import annotations

import argparse
import csv
import json
import tempfile
import time
from pathlib import Path

import numpy as np

import spacefit as sf
from spacefit.fitting.observations.brdf import compare_brdf_models, fit_brdf_table, fitted_material
from spacefit.fitting.report import format_result
from spacefit.geometry.frames import attitude_matrix
from spacefit.materials import MaterialModel
from spacefit.materials.measured import read_brdf_table
from spacefit.materials.tabulated import TabulatedBRDF
from spacefit.studies.design import design_noise_mag, predict_design
from spacefit.studies.lightcurve_observations import LightCurveObservations
from spacefit.studies.observing import Site, read_light_curve, sun_directions_enu
from spacefit.studies.plate_fit import PlateLightCurve
from spacefit.studies.plates import Plate, predict_magnitudes

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "data" / "starlink-v1p5"
SCENE = ROOT / "data" / "scenes" / "starlink-v1p5.toml"
MOUNT_LEMMON = Site(32.4434, -110.7881, 2791.0)
# A night: the observations between one local noon and the next (Mount Lemmon keeps UTC - 7 h all year).
NIGHT_SHIFT = np.timedelta64(19, "h")
FOLDS = 3
# The relative error assumed for the lab tables' model comparison (the tables state none).
LAB_RELATIVE_ERROR = 0.1
SUN_IRRADIANCE = 1360.0
# The array's diffuse term and eta stay the lab's: kd freed runs to 0 (a bound), the array's light then
# all specular; eta freed is correlated -0.996 with alpha. The chassis's eta is held >= 1 (unbounded
# the fit stopped at 0.93, total reflection beyond 69 deg, in a worse minimum).
FREE = ["parts.chassis.kd", "parts.chassis.eta", "parts.chassis.alpha", "parts.solar_array.alpha"]
BOUNDS = {"parts.chassis.eta": (1.0, 100.0)}
ATTITUDE = "target.attitude_x_deg"
SCALES = ["parts.chassis.scale", "parts.solar_array.scale"]
# The observations' error from the training residuals: the half-width of their central 68 % (their
# tails are heavy: 1-sigma intervals of their rms held 88 % of a held-out fold's magnitudes).
NOISE_ESTIMATOR = "central68"


def satellite(chassis: MaterialModel, solar_array: MaterialModel) -> list[Plate]:
    """The target's plates, from the target description ``SCENE``: the chassis box's nadir face (its
    x by y size, normal -z) and the solar-array plate (its size, its normal +z turned by its attitude),
    with the given materials. The one place the plates come from: when
    ``spacefit.studies.target_plates.target_plates`` lands, this body becomes
    ``target_plates(sf.load_scene(SCENE), materials={"chassis": chassis, "solar_array": solar_array})``
    (keeping the nadir face alone of the chassis box, as the published model does)."""
    parts = sf.load_scene(SCENE).parts
    box, plate = parts["chassis"].shape, parts["solar_array"].shape
    normal = attitude_matrix(np.radians(plate.attitude_deg)) @ np.array([0.0, 0.0, 1.0])
    return [Plate("chassis", box.size_m[0] * box.size_m[1], (0.0, 0.0, -1.0), chassis),
            Plate("solar_array", plate.size_m[0] * plate.size_m[1], tuple(normal.tolist()), solar_array)]


def nights(obs: LightCurveObservations) -> np.ndarray:
    """Each observation's night: the local date of the evening it belongs to (datetime64[D])."""
    return (np.array(obs.time_utc, dtype="datetime64[s]") - NIGHT_SHIFT).astype("datetime64[D]")


def splits(obs: LightCurveObservations) -> dict[str, list[tuple[str, np.ndarray]]]:
    """Each split's held-out masks by name (module docstring): ``night`` 3 folds of whole nights,
    ``date`` the two halves of the nights by date, ``random`` a random third of rows."""
    night = nights(obs)
    days, counts = np.unique(night, return_counts=True)
    fold_of, rows = {}, np.zeros(FOLDS, dtype=int)
    for i in np.random.default_rng(0).permutation(len(days)):
        k = int(np.argmin(rows))
        fold_of[days[i]], rows[k] = k, rows[k] + counts[i]
    fold = np.array([fold_of[d] for d in night])
    cumulative = np.cumsum(counts)
    median_day = days[int(np.searchsorted(cumulative, cumulative[-1] / 2))]
    early = night < median_day
    random = np.zeros(len(obs), dtype=bool)
    random[np.random.default_rng(0).permutation(len(obs))[: len(obs) // 3]] = True
    return {"night": [(f"fold {k}", fold == k) for k in range(FOLDS)],
            "date": [(f"before {median_day}", early), (f"from {median_day}", ~early)],
            "random": [("random third", random)]}


def scores(observed: np.ndarray, predicted: np.ndarray, sigma: np.ndarray | None = None) -> dict[str, float]:
    """Pearson R, RMS, median and bias (mean) of observed - predicted where the prediction is finite,
    and with ``sigma`` the coverage: the fraction within 1 sigma."""
    ok = np.isfinite(predicted) & np.isfinite(observed)
    r = observed[ok] - predicted[ok]
    out = {"n": int(ok.sum()), "pearson_r": float(np.corrcoef(observed[ok], predicted[ok])[0, 1]),
           "rms_mag": float(np.sqrt(np.mean(r**2))), "median_mag": float(np.median(r)), "bias_mag": float(np.mean(r))}
    if sigma is not None:
        out["coverage"] = float(np.mean(np.abs(r) <= sigma[ok]))
        out["median_sigma_mag"] = float(np.median(sigma[ok]))
    return out


def lab_materials(out: dict) -> dict[str, MaterialModel]:
    """(a): each surface's table fitted with ``lambert+ggx``, k = 0 (and the models compared)."""
    lab = {}
    for surface in ("chassis", "solar_array"):
        table = read_brdf_table(DATA / f"{surface}_brdf.csv", floor=1e-4)
        comparison = compare_brdf_models(table, ("lambert", "ggx", "lambert+ggx", "lambert+beckmann"),
                                         relative_error=LAB_RELATIVE_ERROR, fixed={"k": 0.0})
        print(f"{surface}: {len(table)} values, models at {LAB_RELATIVE_ERROR:.0%} relative error\n{comparison.table()}")
        fit = fit_brdf_table(table, "lambert+ggx", fixed={"k": 0.0}, part=surface)  # errors from the residuals' scatter
        print(format_result(fit))
        lab[surface] = fitted_material("lambert+ggx", fit)
        out[f"lab_{surface}"] = {"comparison": comparison.table(), "fit": fit.to_dict(),
                                 "rms_ln": float(np.sqrt(np.mean(np.log(table.value / fit.renders[0]) ** 2)))}
    return lab


def fitted_model(name: str, lab: list[Plate], tables: list[Plate], obs: LightCurveObservations,
                 held: np.ndarray) -> tuple[np.ndarray, np.ndarray, dict]:
    """Model ``name`` of (b) fitted to the rows not ``held`` (and lit): its held-out magnitudes and
    predictive errors (nan where not predicted) and its fit's record."""
    train = obs.subset(~held & ~obs.in_shadow)
    test = obs.subset(held)
    plates, free, bounds = lab, [*FREE, ATTITUDE] if name == "attitude" else FREE, BOUNDS
    if name == "tables x 2":
        plates, free, bounds = tables, SCALES, {}
    curves = [PlateLightCurve(plates, train, SUN_IRRADIANCE, bounds)]
    result = sf.fit(curves, free, max_steps=100)
    noise = design_noise_mag(result, curves, estimator=NOISE_ESTIMATOR)
    magnitude, sigma = np.full(len(test), np.nan), np.full(len(test), np.nan)
    if (~test.in_shadow).any():
        p = predict_design(result, curves[0], test, noise_mag=noise)
        magnitude[p.rows], sigma[p.rows] = p.magnitude, p.sigma
    return magnitude, sigma, {"status": str(result.status), "values": result.values, "stderr": result.stderr, "noise_mag": noise,
                              "training_rows": len(train)}


FITTED = ("fitted", "attitude", "tables x 2")
# The former random split, kept for the record, is scored with these only (a fit is 10 to 40 s).
RANDOM_FITTED = ("fitted", "attitude")


def binned(residual: np.ndarray, by: np.ndarray, edges: np.ndarray) -> list[dict[str, float]]:
    """Count, mean and RMS of ``residual`` in bins of ``by``."""
    out = []
    for lo, hi in zip(edges[:-1], edges[1:]):
        r = residual[(by >= lo) & (by < hi) & np.isfinite(residual)]
        if len(r):
            out.append({"from": float(lo), "to": float(hi), "n": int(len(r)), "mean_mag": float(r.mean()),
                        "rms_mag": float(np.sqrt(np.mean(r**2)))})
    return out


def write_geometry(path: Path, obs: LightCurveObservations, split: dict[str, list[tuple[str, np.ndarray]]]) -> None:
    """Per observation: the sun's altitude and azimuth at the site, in shadow, night, night fold, date
    half (1: the later) and the random split's held-out row (what ``starlink_lumos.py`` reads)."""
    sun = sun_directions_enu(obs.time_utc, MOUNT_LEMMON)
    night = nights(obs)
    fold_of = np.zeros(len(obs), dtype=int)
    for k, (_, held) in enumerate(split["night"]):
        fold_of[held] = k
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["sun_altitude_deg", "sun_azimuth_deg", "in_shadow", "night", "night_fold", "date_half", "random_held_out"])
        for i in range(len(obs)):
            alt = np.degrees(np.arcsin(sun[i, 2]))
            az = np.degrees(np.arctan2(sun[i, 0], sun[i, 1])) % 360.0
            w.writerow([f"{alt:.6f}", f"{az:.6f}", int(obs.in_shadow[i]), str(night[i]), fold_of[i],
                        int(not split["date"][0][1][i]), int(split["random"][0][1][i])])


def write_satellite_obj(path: Path) -> Path:
    """The two-part satellite mesh: the chassis underside, a 3.64 m^2 square at x = -15 m facing -z,
    and the solar array, a 2.52 m x 9 m (22.68 m^2) rectangle facing +y at x = +15 m, where it
    neither shadows the chassis from a sun in the y-z plane nor often hides it."""
    c, w, h = 3.64**0.5 / 2, 2.52 / 2, 9.0 / 2
    path.write_text("o chassis\n"
                    f"v {-15 - c} {-c} 0\nv {-15 - c} {c} 0\nv {-15 + c} {c} 0\nv {-15 + c} {-c} 0\nf 1 2 3\nf 1 3 4\n"
                    "o solar_array\n"
                    f"v {15 - w} 0 {-h}\nv {15 + w} 0 {-h}\nv {15 + w} 0 {h}\nv {15 - w} 0 {h}\nf 5 6 7\nf 5 7 8\n")
    return path


def render_check(materials: dict, obs, rows: np.ndarray, folder: Path) -> dict:
    """Render the two-part mesh (``sf.light_curve``, 512 x 512 px of 1.25e-5 rad, 16 spp, box filter,
    8 km away, inside Mitsuba's default far clip of 10 km: the 30 m between the plates turn the view by
    3.8e-3 rad, which a sharp specular lobe feels) at observations ``rows``
    and compare its irradiance with the flat-plate model's; and
    check at the first whether the irradiance has converged in pixels and samples
    (``sf.light_curve_convergence``)."""
    from spacefit.materials import material_table
    from spacefit.scene.toml import scene_from_dict
    from spacefit.studies.plates import plates_irradiance

    mesh = write_satellite_obj(folder / "starlink_v1p5.obj")
    scene = scene_from_dict({
        "render": {"resolution": [512, 512], "spp": 16, "depth": 1, "seed": 1, "filter": "box"},
        "camera": {"position_m": [0.0, 0.0, -8000.0], "look_at_m": [0.0, 0.0, 0.0], "focal_length_mm": 8000.0,
                   "pixel_pitch_mm": 0.1},
        "sun": {"irradiance_w_m2": SUN_IRRADIANCE, "direction": [0.0, 0.0, -1.0]},
        "target": {"attitude_deg": [0.0, 0.0, 0.0], "position_m": [0.0, 0.0, 0.0], "mesh": str(mesh)},
        "wrinkles": {"enabled": False},
        "parts": {name: material_table(m) for name, m in materials.items()},
    })
    rendered, model = [], []
    for i in rows:
        lc = sf.light_curve(scene, attitude_deg=[0.0], sun=obs.sun[i].tolist(), observer=obs.observer[i].tolist(),
                            observer_range_m=float(obs.range_m[i]), quiet=True)
        rendered.append(float(lc.irradiance_w_m2[0]))
        model.append(float(plates_irradiance(satellite(materials["chassis"], materials["solar_array"]), obs.sun[i:i + 1],
                                             obs.observer[i:i + 1], obs.range_m[i:i + 1], SUN_IRRADIANCE)[0]))
    ratio = np.array(rendered) / np.array(model)
    first = rows[0]
    convergence = sf.light_curve_convergence(scene, tolerance=0.02, attitude_deg=[0.0], sun=obs.sun[first].tolist(),
                                             observer=obs.observer[first].tolist(), quiet=True)
    print(convergence.line())
    return {"rows": rows.tolist(), "rendered_w_m2": rendered, "plates_w_m2": model, "max_relative_difference": float(np.max(np.abs(ratio - 1))),
            "rms_relative_difference": float(np.sqrt(np.mean((ratio - 1) ** 2))), "convergence": convergence.line()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=ROOT / "experiments" / "results" / "starlink")
    parser.add_argument("--render-check", type=int, default=0, metavar="N",
                        help="render the two-part mesh at N observations with the lab materials and compare with the plates")
    args = parser.parse_args()
    t0 = time.time()
    out: dict = {"date_utc": time.strftime("%Y-%m-%d %H:%M", time.gmtime())}
    lab = lab_materials(out)
    obs = read_light_curve(DATA / "pomenis_observations.csv", site=MOUNT_LEMMON)
    lab_plates = satellite(lab["chassis"], lab["solar_array"])
    tables = satellite(*(TabulatedBRDF.from_table(read_brdf_table(DATA / f"{s}_brdf.csv")) for s in ("chassis", "solar_array")))
    lab_predictions = {"lab lambert+ggx": predict_magnitudes(lab_plates, obs, SUN_IRRADIANCE),
                       "lab tables": predict_magnitudes(tables, obs, SUN_IRRADIANCE),
                       "lab tables+earthshine": predict_magnitudes(tables, obs, SUN_IRRADIANCE, earth=sf.Earth())}
    split = splits(obs)
    night = nights(obs)
    out["observations"] = {"n": len(obs), "in_shadow": int(obs.in_shadow.sum()), "nights": int(len(np.unique(night))),
                           "observed_sd_mag": float(np.std(obs.magnitude))}
    out["splits"] = {}
    held_predictions: dict[str, dict[str, tuple[np.ndarray, np.ndarray]]] = {}
    for kind, folds in split.items():
        record: dict = {"folds": [name for name, _ in folds], "models": {}}
        models = RANDOM_FITTED if kind == "random" else FITTED
        pooled = {m: (np.full(len(obs), np.nan), np.full(len(obs), np.nan)) for m in models}
        for m in models:
            record["models"][m] = {"folds": []}
        for fold, held in folds:
            for m in models:
                t = time.time()
                magnitude, sigma, fit_record = fitted_model(m, lab_plates, tables, obs, held)
                pooled[m][0][held], pooled[m][1][held] = magnitude, sigma
                s = scores(obs.magnitude[held], magnitude, sigma)
                record["models"][m]["folds"].append({"fold": fold, "held_out": s, "fit": fit_record})
                print(f"{kind:>6s} {fold:>18s} {m:>20s}: n {s['n']}, R {s['pearson_r']:.3f}, RMS {s['rms_mag']:.3f}, "
                      f"bias {s['bias_mag']:+.3f}, coverage {s['coverage']:.2f} ({time.time() - t:.0f} s)")
            for m, predicted in lab_predictions.items():
                record["models"].setdefault(m, {"folds": []})["folds"].append({"fold": fold, "held_out": scores(obs.magnitude[held], predicted[held])})
        every = np.zeros(len(obs), dtype=bool)
        for _, held in folds:
            every |= held
        for m in models:
            record["models"][m]["pooled"] = scores(obs.magnitude[every], pooled[m][0][every], pooled[m][1][every])
        for m, predicted in lab_predictions.items():
            record["models"][m]["pooled"] = scores(obs.magnitude[every], predicted[every])
        out["splits"][kind] = record
        held_predictions[kind] = pooled
    best = min(FITTED, key=lambda m: out["splits"]["night"]["models"][m]["pooled"]["rms_mag"])
    residual = obs.magnitude - held_predictions["night"][best][0]
    phase = np.degrees(np.arccos(np.clip(np.sum(obs.sun * obs.observer, axis=1), -1.0, 1.0)))
    sun = sun_directions_enu(obs.time_utc, MOUNT_LEMMON)
    sun_altitude = np.degrees(np.arcsin(sun[:, 2]))
    per_night = [residual[(night == d) & np.isfinite(residual)] for d in np.unique(night)]
    per_night = [r for r in per_night if len(r)]
    means = np.array([r.mean() for r in per_night])
    within = np.sqrt(np.mean(np.concatenate([r - r.mean() for r in per_night]) ** 2))
    out["residuals"] = {"model": best, "by_phase_angle_deg": binned(residual, phase, np.arange(0, 181, 20.0)),
                        "by_sun_altitude_deg": binned(residual, sun_altitude, np.arange(-36, 1, 6.0)),
                        "nights": {"count": len(per_night), "mean_sd_mag": float(np.std(means, ddof=1)), "within_rms_mag": float(within),
                                   "expected_mean_sd_mag": float(within * np.sqrt(np.mean([1 / len(r) for r in per_night])))}}
    if args.render_check:
        with tempfile.TemporaryDirectory() as folder:
            rows = np.flatnonzero(~obs.in_shadow)[:: max(1, len(obs) // args.render_check)][: args.render_check]
            out["render_check"] = render_check(lab, obs, rows, Path(folder))
        print(f"rendered two-part mesh against the plates at {len(rows)} observations: max relative difference "
              f"{out['render_check']['max_relative_difference']:.2%}")
    out["wall_s"] = time.time() - t0
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "starlink.json").write_text(json.dumps(out, indent=1))
    write_geometry(args.out / "geometry.csv", obs, split)
    for kind, record in out["splits"].items():
        for m, r in record["models"].items():
            s = r["pooled"]
            folds = ", ".join(f"{f['held_out']['rms_mag']:.3f}" for f in r["folds"])
            cover = f", coverage {s['coverage']:.2f}" if "coverage" in s else ""
            print(f"{kind:>6s} {m:>22s} pooled: n {s['n']}, R {s['pearson_r']:.3f}, RMS {s['rms_mag']:.3f} (folds {folds}), "
                  f"bias {s['bias_mag']:+.3f}{cover}")
    print(f"residuals of {best} by night: {out['residuals']}")
    print(f"{out['observations']}; {out['wall_s']:.0f} s")


if __name__ == "__main__":
    main()
