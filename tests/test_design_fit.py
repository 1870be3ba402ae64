"""Fit a design, not a satellite (spacefit/studies/design.py) and predictive intervals
(spacefit/fitting/prediction.py): two simulated satellites of one design (shared materials, each its
own attitude offset) fitted jointly recover the materials within their errors and each one's offset;
the predictive intervals of held-out simulated observations cover 68 +- 10 % of them; an unseen
member's interval carries the members' spread; bad inputs are refused by name."""

from __future__ import annotations

import numpy as np
import pytest

import spacefit as sf
from spacefit.errors import InputError
from spacefit.scene.names import Name
from spacefit.studies.design import DesignMember, design_noise_mag, fit_design, predict_design
from spacefit.studies.lightcurve_observations import LightCurveObservations, magnitude_of

HEIGHT_M = 550e3
TRUTH = {"parts.chassis.kd": 0.30, "parts.array.kd": 0.08, "parts.array.alpha": 0.15}
OFFSETS_DEG = (6.0, -9.0)  # each satellite's attitude about x
SIGMA_MAG = 0.1


def plates(chassis_kd: float, array_kd: float, array_alpha: float) -> list[sf.Plate]:
    """A Starlink-like satellite: a nadir-facing chassis and an array facing the sun's side (+y)."""
    return [sf.Plate("chassis", 3.64, (0.0, 0.0, -1.0), sf.Lambert(chassis_kd)),
            sf.Plate("array", 22.68, (0.0, 1.0, 0.0), sf.DiffuseConductor(array_kd, 1.5, 0.0, array_alpha, array_alpha))]


def geometry(n: int, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``n`` observations at dusk: the sun 5 to 40 deg below the target's horizontal towards +y
    (spread about z by up to 40 deg), lighting both plates, observers within 60 deg of nadir on the
    sun's side; their ranges (m)."""
    rng = np.random.default_rng(seed)
    el, az = np.radians(rng.uniform(-40, -5, n)), np.radians(90 + rng.uniform(-40, 40, n))
    sun = np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)], axis=1)
    tilt, turn = np.radians(rng.uniform(0, 60, n)), rng.uniform(0.1, np.pi - 0.1, n)
    observer = np.stack([np.sin(tilt) * np.cos(turn), np.sin(tilt) * np.sin(turn), -np.cos(tilt)], axis=1)
    return sun, observer, HEIGHT_M / np.cos(tilt)


def simulated(offset_deg: float, n: int, seed: int, sigma: bool = True) -> LightCurveObservations:
    """Magnitudes of the true design turned by ``offset_deg`` about x, with SIGMA_MAG noise."""
    sun, observer, range_m = geometry(n, seed)
    exact = LightCurveObservations(np.zeros(n), None, "AB532", sun, observer, range_m, np.zeros(n, bool), None, "simulated")
    turned = sf.PlateLightCurve(plates(*TRUTH.values()), exact).block(("target.attitude_x_deg",)).model(np.array([offset_deg]), 0)
    magnitude = magnitude_of(np.asarray(turned), "AB532", 1360.0) + SIGMA_MAG * np.random.default_rng(seed + 100).standard_normal(n)
    return LightCurveObservations(magnitude, np.full(n, SIGMA_MAG) if sigma else None, "AB532", sun, observer, range_m,
                                  np.zeros(n, bool), None, f"satellite {seed}")


START = plates(0.2, 0.12, 0.25)
FREE = list(TRUTH)
OWN = ["target.attitude_x_deg"]


@pytest.fixture(scope="module")
def design():
    curves = [sf.PlateLightCurve(START, simulated(offset, 60, seed)) for seed, offset in enumerate(OFFSETS_DEG)]
    return curves, fit_design(curves, FREE, OWN, max_steps=100)


def test_two_satellites_fitted_jointly_recover_the_shared_materials_and_each_ones_offset(design):
    _, result = design
    assert result.success, result.warnings
    for name, truth in TRUTH.items():
        assert abs(result.values[name] - truth) < 3 * result.stderr[name], (name, result.values[name], result.stderr[name])
    for k, offset in enumerate(OFFSETS_DEG):
        name = Name("target.attitude_x_deg", k)
        assert abs(result.values[name] - offset) < 3 * result.stderr[name], (name, result.values[name], result.stderr[name])
    # the two offsets are told apart: one shared attitude could not have fitted both satellites
    assert abs(result.values["target.attitude_x_deg@0"] - result.values["target.attitude_x_deg@1"]) > 10 * result.stderr["target.attitude_x_deg@0"]


def test_predictive_intervals_of_held_out_observations_cover_about_68_percent(design):
    curves, result = design
    inside, count = 0, 0
    for k, offset in enumerate(OFFSETS_DEG):
        held = simulated(offset, 200, 50 + k)
        p = predict_design(result, curves[k], held, member=k, own=OWN, members=2)
        assert p.noise == "stated" and np.all(p.sigma_parameters > 0) and np.allclose(p.sigma_noise, SIGMA_MAG)
        inside += p.coverage(held.magnitude[p.rows]) * len(p.rows)
        count += len(p.rows)
    assert 0.58 <= inside / count <= 0.78, inside / count


@pytest.mark.slow
def test_without_stated_errors_the_noise_is_estimated_from_the_training_residuals():
    curves = [sf.PlateLightCurve(START, simulated(offset, 60, seed, sigma=False)) for seed, offset in enumerate(OFFSETS_DEG)]
    result = fit_design(curves, FREE, OWN, max_steps=100)
    noise = design_noise_mag(result, curves, OWN)
    assert 0.08 < noise < 0.12, noise
    # for normal residuals the half-width of their central 68 % is their rms
    assert abs(design_noise_mag(result, curves, OWN, "central68") / noise - 1) < 0.2
    with pytest.raises(InputError, match="`estimator`"):
        design_noise_mag(result, curves, OWN, "mad")
    held = simulated(OFFSETS_DEG[0], 400, 77, sigma=False)
    p = predict_design(result, curves[0], held, member=0, own=OWN, members=2, noise_mag=noise)
    assert p.noise == "training residuals"
    assert 0.58 <= p.coverage(held.magnitude[p.rows]) <= 0.78
    with pytest.raises(InputError, match="noise"):
        predict_design(result, curves[0], held, member=0, own=OWN, members=2)


def test_an_unseen_member_carries_the_members_spread(design):
    curves, result = design
    held = simulated(0.0, 50, 90)
    seen = predict_design(result, curves[0], held, member=0, own=OWN, members=2)
    unseen = predict_design(result, curves[0], held, own=OWN, members=2)
    # the unseen member's attitude is the two's mean, its variance their spread: wider everywhere it matters
    assert np.all(unseen.sigma_parameters >= seen.sigma_parameters - 1e-12)
    assert np.median(unseen.sigma_parameters) > 2 * np.median(seen.sigma_parameters)


def test_bad_design_inputs_are_refused_by_name(design):
    curves, result = design
    with pytest.raises(InputError, match="`own` names 'parts.nope.kd'"):
        DesignMember(curves[0], 0, ("parts.nope.kd",))
    with pytest.raises(InputError, match="both name"):
        fit_design(curves, [*FREE, "target.attitude_x_deg"], OWN)
    with pytest.raises(InputError, match="`curves`"):
        fit_design([], FREE)
    with pytest.raises(InputError, match="`member` must be from 0 to 1"):
        predict_design(result, curves[0], curves[0].observations, member=2, own=OWN, members=2)
    with pytest.raises(InputError, match="`members`"):
        predict_design(result, curves[0], curves[0].observations, own=OWN)
