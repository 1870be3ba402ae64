"""Light curves as observations: the readers and their geometry, the Earth's shadow, flat plates
against closed forms and against the renderer, a specular plate's glint, and a fit of a simulated
two-plate light curve."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from helpers import small_scene, write_plate_obj

import spacefit as sf
from spacefit.errors import InputError
from spacefit.geometry.frames import attitude_matrix
from spacefit.materials import Conductor, DiffuseConductor, Lambert, material_table
from spacefit.studies.lightcurve_observations import LightCurveObservations, magnitude_of
from spacefit.studies.observing import EARTH_RADIUS_M, Site, in_earth_shadow, read_light_curve
from spacefit.studies.plate_fit import fit_plates
from spacefit.studies.plates import Plate, plates_irradiance, predict_magnitudes

DATA = Path(__file__).resolve().parents[1] / "data" / "starlink-v1p5"
MOUNT_LEMMON = Site(32.4434, -110.7881, 2791.0)


@pytest.fixture(scope="module")
def pomenis() -> LightCurveObservations:
    """The Starlink observations, read once (astropy's sun for 1,173 times takes seconds)."""
    return read_light_curve(DATA / "pomenis_observations.csv", site=MOUNT_LEMMON)


def test_pomenis_observations_and_their_geometry(pomenis):
    """1,173 magnitudes; one satellite in the Earth's shadow (the Pomenis point every published model
    clips); the nadir-sun frame puts the sun in its y-z plane on the +y side and the observer below."""
    obs = pomenis
    assert len(obs) == 1173 and obs.band == "AB532" and obs.magnitude_sigma is None
    assert int(obs.in_shadow.sum()) == 1
    np.testing.assert_allclose(np.linalg.norm(obs.sun, axis=1), 1.0)
    np.testing.assert_allclose(obs.sun[:, 0], 0.0, atol=1e-12)
    assert np.all(obs.sun[:, 1] > 0) and np.all(obs.observer[:, 2] < 0)
    # the first row, 448.44 km up at 32.874 deg altitude: (R + h)^2 = R^2 + d^2 + 2 R d sin(alt)
    d, R, h, alt = obs.range_m[0], EARTH_RADIUS_M, 448.4444346e3, math.radians(32.87386184)
    assert R**2 + d**2 + 2 * R * d * math.sin(alt) == pytest.approx((R + h) ** 2, rel=1e-12) and d == pytest.approx(769.7e3, rel=1e-4)
    with pytest.raises(InputError, match="give the observer's `site`"):
        read_light_curve(DATA / "pomenis_observations.csv")


def test_earth_shadow_is_a_cylinder():
    sun = np.array([[1.0, 0.0, 0.0]] * 4)
    r = EARTH_RADIUS_M
    positions = np.array([[-2 * r, 0.99 * r, 0.0], [-2 * r, 1.01 * r, 0.0], [2 * r, 0.0, 0.0], [-1.1 * r, 0.0, 0.0]])
    assert in_earth_shadow(positions, sun).tolist() == [True, False, False, True]


def test_general_format_in_the_target_frame(tmp_path):
    path = tmp_path / "lc.csv"
    path.write_text("# a test\ntime_utc,magnitude,magnitude_sigma,sun_x,sun_y,sun_z,observer_x,observer_y,observer_z,range_m\n"
                    "2024-01-01T00:00:00,5.0,0.1,0,0,2,0,1,1,1e6\n")
    obs = read_light_curve(path, band="V")
    np.testing.assert_allclose(obs.sun[0], [0, 0, 1])
    np.testing.assert_allclose(obs.observer[0], [0, 2**-0.5, 2**-0.5])
    assert obs.magnitude_sigma.tolist() == [0.1] and not obs.in_shadow[0]
    with pytest.raises(InputError, match="give `band`"):
        read_light_curve(path)
    path.write_text("time_utc,magnitude,altitude_deg\n2024-01-01T00:00:00,5.0,3\n")
    with pytest.raises(InputError, match="has no geometry"):
        read_light_curve(path, band="V")
    path.write_text("time_utc,magnitude,sun_x,sun_y,sun_z,observer_x,observer_y,observer_z,range_m\nT,five,0,0,1,0,0,1,1\n")
    with pytest.raises(InputError, match="row 1's magnitude must be a number, got 'five'"):
        read_light_curve(path, band="V")
    path.write_text("time_utc,magnitude,sun_x,sun_y,sun_z,observer_x,observer_y,observer_z,range_m\n"
                    "2024-01-01T00:00:00,5.0,1e300,1e300,0,0,0,1,1e6\n")
    np.testing.assert_allclose(read_light_curve(path, band="V").sun[0], [2**-0.5, 2**-0.5, 0])  # no overflow to (0, 0, 0)
    path.write_text("time_utc,magnitude,altitude_deg,azimuth_deg,height_m\n2024-01-01 00:00:00,5.0,30,0,5e5\nyesterday,5.0,30,0,5e5\n")
    with pytest.warns(UserWarning, match="1 rows refused .*row 2: time_utc 'yesterday': not an ISO 8601 time"):
        assert len(read_light_curve(path, band="V", site=MOUNT_LEMMON)) == 1
    with pytest.raises(InputError, match="`site` must be an sf.Site"):
        read_light_curve(path, band="V", site=(32.4, -110.8))
    with pytest.raises(InputError, match=r"`site.latitude_deg` must be in \[-90, 90\] deg, got 100"):
        Site(100.0, 0.0)
    path.write_bytes(b"\xff\xfe garbage")
    with pytest.raises(InputError, match="is not a text file"):
        read_light_curve(path, band="V")


@pytest.fixture
def far_plate(tmp_path):
    """A 2 m x 2 m Lambert plate facing the camera 1 km away, 60 px across (box filter)."""
    return small_scene(write_plate_obj(tmp_path / "plate.obj"), {"material": "lambert", "kd": 0.5},
                       render={"spp": 4, "resolution": [80, 80], "filter": "box"},
                       camera={"position_m": [0.0, 0.0, 1000.0], "focal_length_mm": 3000.0, "pixel_pitch_mm": 0.1})


def test_flat_lambert_plate_follows_its_phase_function(far_plate):
    """E(a) = E_sun kd / pi A cos(a) / d^2 for a plate facing the observer, the sun at phase a: the
    rendered light curve within 1 %, the flat-plate model exactly."""
    phase = np.array([0.0, 30.0, 60.0, 80.0])
    lc = sf.light_curve(far_plate, phase_deg=phase, quiet=True)
    closed = 5.0 * 0.5 / math.pi * 4.0 * np.cos(np.radians(phase)) / 1000.0**2
    np.testing.assert_allclose(lc.irradiance_w_m2, closed, rtol=0.01)
    a = np.radians(phase)
    sun = np.stack([np.sin(a), np.zeros_like(a), np.cos(a)], axis=1)
    plates = plates_irradiance([Plate("plate", 4.0, (0, 0, 1), Lambert(0.5))], sun, np.tile([0.0, 0.0, 1.0], (4, 1)),
                               np.full(4, 1000.0), 5.0)
    np.testing.assert_allclose(np.asarray(plates), closed, rtol=1e-12)


def ggx_half_width(alpha: float) -> float:
    """The angle at which GGX's D(theta) falls to half of D(0): cos^4 (alpha^2 + tan^2)^2 = 2 alpha^4."""
    from scipy.optimize import brentq

    return brentq(lambda t: math.cos(t) ** 4 * (alpha**2 + math.tan(t) ** 2) ** 2 - 2 * alpha**4, 1e-9, 1.0)


def test_a_spinning_specular_plate_glints_when_and_as_long_as_geometry_says():
    """A GGX plate spinning about y at 2 deg/s, the sun 40 deg from the observer in the x-z plane:
    the glint peaks when the normal bisects them (psi 20 deg, t 10 s) and lasts (FWHM) the
    microfacet distribution's 2 theta_half / omega; E = E_sun A D G F / (4 d^2) and G, F barely change."""
    alpha, omega = 0.1, 2.0
    t = np.arange(0.0, 20.0, 0.01)
    psi = np.radians(omega * t)
    normals = np.stack([np.sin(psi), np.zeros_like(psi), np.cos(psi)], axis=1)
    # the plate turns; in its frame the sun and observer turn the other way
    world_sun, world_obs = np.array([math.sin(math.radians(40)), 0.0, math.cos(math.radians(40))]), np.array([0.0, 0.0, 1.0])
    frames = np.stack([np.stack([np.cos(psi), np.zeros_like(psi), -np.sin(psi)], 1), np.tile([0.0, 1.0, 0.0], (len(t), 1)), normals], 1)
    sun, obs = frames @ world_sun, frames @ world_obs
    e = np.asarray(plates_irradiance([Plate("plate", 1.0, (0, 0, 1), Conductor(1.5, 3.0, alpha, alpha))], sun, obs, np.ones(len(t)), 1.0))
    assert t[np.argmax(e)] == pytest.approx(10.0, abs=0.011)
    above = t[e >= e.max() / 2]
    assert above[-1] - above[0] == pytest.approx(2 * math.degrees(ggx_half_width(alpha)) / omega, rel=0.02)


@pytest.mark.parametrize("material", [Conductor(1.5, 3.0, 0.1, 0.1), DiffuseConductor(0.3, 1.5, 3.0, 0.1, 0.1)],
                         ids=["ggx", "diffuse+ggx"])
def test_rendered_glint_matches_the_flat_plate_model(tmp_path, material):
    """The renderer's integrated irradiance of a GGX plate (and of one with a diffuse term, which
    the renderer draws as a blend) turned about y equals the flat-plate model's within 2 % across
    the glint (the point-target limit the model assumes)."""
    scene = small_scene(write_plate_obj(tmp_path / "plate.obj"), material_table(material),
                        render={"spp": 8, "resolution": [48, 48], "filter": "box"},
                        camera={"position_m": [0.0, 0.0, 1000.0], "focal_length_mm": 2000.0, "pixel_pitch_mm": 0.1},
                        sun={"irradiance_w_m2": 5.0, "direction": [-math.sin(math.radians(40)), 0.0, -math.cos(math.radians(40))]})
    angles = np.array([-26.0, -20.0, -14.0])  # attitude_y turns +z towards -x
    lc = sf.light_curve(scene, attitude_deg=angles, axis="y", quiet=True)
    world_sun, world_obs = np.array([math.sin(math.radians(40)), 0.0, math.cos(math.radians(40))]), np.array([0.0, 0.0, 1.0])
    rotations = [attitude_matrix(np.radians([0.0, a, 0.0])) for a in angles]
    sun = np.array([r.T @ world_sun for r in rotations])
    obs = np.array([r.T @ world_obs for r in rotations])
    model = np.asarray(plates_irradiance([Plate("plate", 4.0, (0, 0, 1), material)], sun, obs,
                                         np.full(3, 1000.0), 5.0))
    assert np.argmax(model) == 1
    np.testing.assert_allclose(lc.irradiance_w_m2, model, rtol=0.02)


def test_a_simulated_two_plate_light_curve_is_fitted_back_within_its_errors():
    """Magnitudes with 0.05 mag noise at 200 geometries: the chassis's kd and the array's roughness
    come back within 3 standard errors, and chi^2 is within its expected range."""
    rng = np.random.default_rng(3)
    n = 200
    sun = np.stack([np.zeros(n), np.cos(np.radians(rng.uniform(5, 40, n))), -np.sin(np.radians(rng.uniform(5, 40, n)))], 1)
    sun /= np.linalg.norm(sun, axis=1, keepdims=True)
    obs = rng.normal(size=(n, 3)) * [0.5, 0.5, 0.3] - [0.0, 0.0, 1.0]
    obs /= np.linalg.norm(obs, axis=1, keepdims=True)
    truth = [Plate("chassis", 3.64, (0, 0, -1), Lambert(0.3)), Plate("array", 22.68, (0, 1, 0), Conductor(1.5, 0.0, 0.2, 0.2))]
    exact = LightCurveObservations(np.zeros(n), None, "AB532", sun, obs, np.full(n, 6e5), np.zeros(n, bool), None, "simulated")
    m = predict_magnitudes(truth, exact) + 0.05 * rng.standard_normal(n)
    data = LightCurveObservations(m, np.full(n, 0.05), "AB532", sun, obs, np.full(n, 6e5), np.zeros(n, bool), None, "simulated")
    start = [Plate("chassis", 3.64, (0, 0, -1), Lambert(0.1)), Plate("array", 22.68, (0, 1, 0), Conductor(1.5, 0.0, 0.4, 0.4))]
    fit = fit_plates(start, data, ["parts.chassis.kd", "parts.array.alpha"])
    assert fit.success and not fit.goodness.misfit, sf.format_result(fit)
    assert abs(fit.values["parts.chassis.kd"] - 0.3) < 3 * fit.stderr["parts.chassis.kd"]
    assert abs(fit.values["parts.array.alpha"] - 0.2) < 3 * fit.stderr["parts.array.alpha"]
    assert fit.stderr["parts.chassis.kd"] < 0.01 and np.isfinite(magnitude_of(np.array([1e-12]), "AB532", 1360.0)).all()
    with pytest.raises(InputError, match="`free` must be one of"):
        fit_plates(start, data, ["parts.panel.kd"])


def test_two_lambert_plates_agree_with_lumos_sat(pomenis):
    """lumos-sat's calculator (``experiments/starlink_lumos.py`` wrote its magnitudes) and spacefit's
    flat plates give the same light curve of the two-plate satellite, Lambertian (0.5), at every
    lit Pomenis observation: within 1 % (0.011 mag). This holds the geometry (site, sun, frame,
    ranges), the shadow and the AB conversion to the peer's."""
    rows = [line.split(",") for line in (Path(__file__).resolve().parents[1] / "experiments" / "results" / "starlink" /
                                          "lumos_lambert.csv").read_text().splitlines()[2:]]
    index, peer = np.array([int(r[0]) for r in rows]), np.array([float(r[1]) for r in rows])
    obs = pomenis
    plates = [Plate("chassis", 3.64, (0, 0, -1), Lambert(0.5)), Plate("array", 22.68, (0, 1, 0), Lambert(0.5))]
    ours = predict_magnitudes(plates, obs)
    assert np.isfinite(ours).sum() == len(index) == 1172 and np.all(np.isfinite(ours[index]))
    np.testing.assert_allclose(ours[index], peer, atol=2.5 * math.log10(1.01))


def test_a_plate_with_a_tabulated_brdf_agrees_with_lumos_sat(pomenis):
    """Issue 22 item 5: a flat plate with a tabulated (lab) BRDF against lumos-sat's calculator for
    the same plate: the chassis alone and the array alone, each with its measured table used as it
    is (sf.TabulatedBRDF; lumos-sat given a BRDF function of the same definition,
    ``experiments/starlink_lumos.py`` wrote its magnitudes), within 1 % at every lit Pomenis geometry."""
    from spacefit.materials.measured import read_brdf_table
    from spacefit.materials.tabulated import TabulatedBRDF

    rows = [line.split(",") for line in (Path(__file__).resolve().parents[1] / "experiments" / "results" / "starlink" /
                                          "lumos_tabulated.csv").read_text().splitlines()[2:]]
    peer = {"chassis": np.array([float(r[1]) for r in rows]), "array": np.array([float(r[2]) for r in rows])}
    for name, normal, area, table in (("chassis", (0, 0, -1), 3.64, "chassis"), ("array", (0, 1, 0), 22.68, "solar_array")):
        plate = Plate(name, area, normal, TabulatedBRDF.from_table(read_brdf_table(DATA / f"{table}_brdf.csv")))
        ours = predict_magnitudes([plate], pomenis)
        lit = np.isfinite(peer[name])
        assert lit.sum() > 300 and np.array_equal(np.isfinite(ours), lit), name
        np.testing.assert_allclose(ours[lit], peer[name][lit], atol=2.5 * math.log10(1.01), err_msg=name)


@pytest.mark.slow
def test_fit_plates_frees_the_attitude_and_a_tables_scale():
    """A simulated light curve (0.02 mag noise) of a tabulated chassis (its lab table scaled by 1.8)
    and a GGX array, the target turned 6 deg about z: fit_plates gives back the angle and the
    scale within 3 standard errors; fitted_plates turns the normals by the fitted angle and scales
    the table; a start outside the bounds given is refused, and so is a plate named ``target``."""
    from spacefit.materials.measured import read_brdf_table
    from spacefit.materials.tabulated import TabulatedBRDF
    from spacefit.geometry.frames import attitude_matrix

    rng = np.random.default_rng(3)
    n = 40
    elev = np.radians(rng.uniform(5, 40, n))
    sun = np.stack([np.zeros(n), np.cos(elev), -np.sin(elev)], 1)
    obs = rng.normal(size=(n, 3)) * [0.5, 0.5, 0.3] - [0.0, 0.0, 1.0]
    obs /= np.linalg.norm(obs, axis=1, keepdims=True)
    table = read_brdf_table(DATA / "chassis_brdf.csv")
    plates = [Plate("chassis", 3.64, (0, 0, -1), TabulatedBRDF.from_table(table)), Plate("array", 22.68, (0, 1, 0), Conductor(1.5, 0.0, 0.2, 0.2))]
    turn = attitude_matrix(np.radians([0.0, 0.0, 6.0]))
    truth = [Plate("chassis", 3.64, (0, 0, -1), TabulatedBRDF.from_table(table, 1.8)),
             Plate("array", 22.68, tuple(turn @ np.array([0.0, 1.0, 0.0])), plates[1].material)]
    exact = LightCurveObservations(np.zeros(n), None, "AB532", sun, obs, np.full(n, 6e5), np.zeros(n, bool), None, "simulated")
    m = predict_magnitudes(truth, exact) + 0.02 * rng.standard_normal(n)
    data = LightCurveObservations(m, np.full(n, 0.02), "AB532", sun, obs, np.full(n, 6e5), np.zeros(n, bool), None, "simulated")
    free = ["target.attitude_z_deg", "parts.chassis.scale"]
    fit = fit_plates(plates, data, free)
    assert fit.success and not fit.goodness.misfit, sf.format_result(fit)
    for name, true in zip(free, (6.0, 1.8)):
        assert abs(fit.values[name] - true) < 3 * fit.stderr[name], sf.format_result(fit)
    assert fit.stderr[free[0]] < 1.0 and fit.stderr[free[1]] < 0.1
    turned = sf.fitted_plates(plates, fit)
    np.testing.assert_allclose(turned[1].normal, truth[1].normal, atol=3 * math.radians(fit.stderr[free[0]]))
    assert turned[0].normal == (0.0, 0.0, -1.0) and turned[0].material.scale == pytest.approx(fit.values["parts.chassis.scale"])
    with pytest.raises(InputError, match="starts at 1, outside its bounds"):
        fit_plates(plates, data, ["parts.chassis.scale"], bounds={"parts.chassis.scale": (1.5, 3.0)})
    with pytest.raises(InputError, match="`bounds` must be one of"):
        fit_plates(plates, data, ["parts.chassis.scale"], bounds={"parts.array.eta": (1.0, 2.0)})
    with pytest.raises(InputError, match="must not have a plate named 'target'"):
        fit_plates([Plate("target", 1.0, (0, 0, 1), Lambert(0.3))], data, ["target.kd"])
