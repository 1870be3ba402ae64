"""Earthshine (spacefit/studies/earthshine.py): the lit Earth's irradiance at a target against closed
forms (a Lambert sphere's phase law, an overhead sun, the view factor of a uniformly bright sphere),
its quadrature against the converged sum, the light a plate reflects from it against the closed
form and against lumos-sat's calculator, and its gradient in a plate's BRDF."""

from __future__ import annotations

import csv
import dataclasses
import math
from pathlib import Path

import jax
import numpy as np
import pytest

import spacefit as sf
from spacefit.errors import InputError
from spacefit.studies.earthshine import EARTH_MEAN_RADIUS_M, VEGETATION, Earth, earthshine_irradiance, earthshine_sources
from spacefit.studies.observing import EARTH_RADIUS_M, in_earth_shadow
from spacefit.studies.plates import plates_irradiance

R = EARTH_MEAN_RADIUS_M
PEER = Path(__file__).resolve().parents[1] / "experiments" / "results" / "earthshine" / "lumos_earthshine.csv"
NADIR = np.array([0.0, 0.0, -1.0])


def above(height_m: float | np.ndarray) -> np.ndarray:
    """(n, 3) the Earth's centre seen from targets at ``height_m`` on the z axis (their frame: z up)."""
    height = np.atleast_1d(np.asarray(height_m, dtype=float))
    return np.stack([np.zeros_like(height), np.zeros_like(height), -(R + height)], axis=-1)


def sun_at(angle_deg: float) -> np.ndarray:
    """(1, 3) the sun at ``angle_deg`` from the zenith of a target on the z axis, in the y-z plane."""
    a = math.radians(angle_deg)
    return np.array([[0.0, math.sin(a), math.cos(a)]])


def reflection(plates: list[sf.Plate], values: dict | None = None):
    """The plates' reflection (m^2 sr^-1) as earthshine_irradiance takes it: the plate model's sun term per unit irradiance."""
    return lambda wi, wo: plates_irradiance(plates, wi, wo, np.ones(len(wi)), 1.0, values)


@pytest.mark.parametrize("phase_deg", [0.0, 40.0, 90.0, 130.0, 160.0])
def test_a_far_lambert_earth_follows_the_phase_law_of_a_lambert_sphere(phase_deg):
    """From far away (1e5 Earth radii) the Earth is a Lambert sphere: E = (2/3) A E_sun (R/d)^2 [sin a + (pi - a) cos a] / pi."""
    d, albedo, a = 1e5 * R, 0.3, math.radians(phase_deg)
    sources = earthshine_sources(above(d - R), sun_at(phase_deg), Earth(kd=albedo))
    expected = 2 / 3 * albedo * (R / d) ** 2 * (math.sin(a) + (math.pi - a) * math.cos(a)) / math.pi
    assert sources.irradiance(NADIR)[0] == pytest.approx(expected, rel=1e-3)


@pytest.mark.parametrize("height_m", [300e3, 550e3, 2000e3, 35786e3])
def test_the_visible_earth_has_the_view_factor_of_a_sphere(height_m):
    """Under an overhead sun all the visible cap is lit; seen uniformly bright its irradiance on a
    nadir plate is pi L (R / (R + h))^2 (the view factor of a sphere)."""
    sources = earthshine_sources(above(height_m), sun_at(0.0))
    facing = np.clip(sources.directions @ NADIR, 0.0, None)
    assert np.sum(sources.solid_angles * facing) == pytest.approx(math.pi * (R / (R + height_m)) ** 2, rel=1e-9)


@pytest.mark.parametrize("height_m", [300e3, 550e3, 2000e3])
def test_an_overhead_sun_lights_a_nadir_plate_as_the_closed_form_says(height_m):
    """A Lambert Earth of albedo A under an overhead sun: E / E_sun = 2 A x^2 [F(k) - F(q)] / (16 x^3),
    x = R / r, k = 1 - x^2, q = (1 - x)^2, F(y) = -(1 + x^2) k^2 / y - (1 + x^2) y - k^2 ln y + y^2 / 2
    (the integral of (A / pi) cos(gamma) over the cap in the plate's view, u = cos(gamma) substituted
    by y = D^2); the plate reflects E (rho / pi) A_p cos(theta_o) / d^2 towards an observer at d."""
    albedo, x = 0.3, R / (R + height_m)
    k, m, q = 1 - x**2, 1 + x**2, (1 - x) ** 2

    def F(y):
        return -m * k**2 / y - m * y - k**2 * math.log(y) + y**2 / 2

    expected = 2 * albedo * x**2 * (F(k) - F(q)) / (16 * x**3)
    sources = earthshine_sources(above(height_m), sun_at(0.0), Earth(kd=albedo))
    assert sources.irradiance(NADIR)[0] == pytest.approx(expected, rel=1e-6)
    rho, area, d, tilt = 0.5, 2.0, 900e3, math.radians(35.0)
    plate = sf.Plate("base", area, tuple(NADIR), sf.Lambert(rho))
    observer = np.array([[0.0, math.sin(tilt), -math.cos(tilt)]])
    reflected = earthshine_irradiance(reflection([plate]), sources, observer, np.array([d]), 1360.0)
    assert float(reflected[0]) == pytest.approx(1360.0 * expected * rho / math.pi * area * math.cos(tilt) / d**2, rel=1e-6)


def test_the_quadrature_is_converged_for_any_plate():
    """At random heights, suns and plate normals (the plate's horizon cutting the cap), the default
    nodes give the irradiance within 1e-3 of the target's Earthshine (that on a plate facing the
    Earth), against 4 times as many nodes per dimension, for a Lambert and the vegetation Earth."""
    rng = np.random.default_rng(7)
    n = 60
    earth_m, sun = above(rng.uniform(300e3, 2000e3, n)), rng.normal(size=(n, 3))
    normal = rng.normal(size=(n, 3))
    normal /= np.linalg.norm(normal, axis=-1, keepdims=True)
    for earth in (Earth(), VEGETATION):
        fine = earthshine_sources(earth_m, sun, earth, points=128)
        scale = fine.irradiance(NADIR)
        assert np.count_nonzero(scale) > n // 3  # most targets see the lit Earth
        error = np.abs(earthshine_sources(earth_m, sun, earth).irradiance(normal) - fine.irradiance(normal))
        assert np.all(error <= 1e-3 * scale)


def test_a_plate_reflects_earthshine_as_lumos_sat_computes_it():
    """lumos-sat 1.0.9's calculator (experiments/earthshine_lumos.py: its Earth of 6378 km, 601 x 601
    panels) on a Lambert plate, under a Lambert and the vegetation Phong Earth, at 550 km: within 0.5 %."""
    rows = list(csv.DictReader(line for line in PEER.read_text().splitlines() if not line.startswith("#")))
    assert len(rows) >= 5
    radius, height = 6378e3, 550e3
    for row in rows:
        a = math.radians(float(row["past_terminator_deg"]))
        to_observer = np.array([float(row[f"observer_{c}_m"]) for c in "xyz"]) - np.array([0.0, 0.0, radius + height])
        d = np.linalg.norm(to_observer)
        normal = tuple(float(row[f"normal_{c}"]) for c in "xyz")
        plate = sf.Plate("plate", 1.0, normal, sf.Lambert(0.5), tangent=(1.0, 0.0, 0.0) if abs(normal[0]) < 0.9 else (0.0, 1.0, 0.0))
        for name, earth in (("lambert", Earth(kd=0.3, radius_m=radius)), ("vegetation", dataclasses.replace(VEGETATION, radius_m=radius))):
            sources = earthshine_sources(np.array([[0.0, 0.0, -(radius + height)]]), np.array([[0.0, math.cos(a), -math.sin(a)]]), earth)
            ours = earthshine_irradiance(reflection([plate]), sources, to_observer[None] / d, np.array([d]), 1360.0)
            assert float(ours[0]) == pytest.approx(float(row[f"{name}_w_m2"]), rel=5e-3), (row, name)


def test_earthshine_is_differentiable_in_a_plates_brdf():
    """The gradient in a conductor plate's roughness against central finite differences."""
    plate = sf.Plate("panel", 3.0, (0.3, -0.2, -1.0), sf.Conductor(alpha_x=0.3, alpha_y=0.3, eta=1.4, k=0.1))
    sources = earthshine_sources(above([550e3, 800e3]), np.array([[0.0, 0.8, -0.3], [0.2, 0.9, 0.1]]), VEGETATION, points=16)
    observer = np.array([[0.1, -0.5, -0.8], [0.0, 0.3, -0.9]])
    range_m = np.array([1.2e6, 0.9e6])

    def total(alpha):
        values = {"panel": {"alpha_x": alpha, "alpha_y": alpha}}
        return earthshine_irradiance(reflection([plate], values), sources, observer, range_m).sum()

    with jax.enable_x64(True):
        grad = float(jax.grad(total)(0.3))
        h = 1e-5
        numeric = (float(total(0.3 + h)) - float(total(0.3 - h))) / (2 * h)
    assert grad != 0.0
    assert grad == pytest.approx(numeric, rel=1e-5)


def test_a_target_sees_the_lit_earth_exactly_where_it_is_out_of_its_shadow():
    """The lit cap leaves the target's view where the target enters the Earth's cylindrical shadow
    (both at 90 deg + arccos(R / r) from the sun): Earthshine is positive outside it, 0 inside."""
    height = 550e3
    edge = 90.0 + math.degrees(math.acos(EARTH_RADIUS_M / (EARTH_RADIUS_M + height)))
    angles = np.array([60.0, 100.0, edge - 0.5, edge + 0.5, 140.0, 180.0])
    sun = np.stack([np.zeros_like(angles), np.sin(np.radians(angles)), np.cos(np.radians(angles))], axis=-1)
    earth_m = np.tile([0.0, 0.0, -(EARTH_RADIUS_M + height)], (len(angles), 1))
    shine = earthshine_sources(earth_m, sun, Earth(radius_m=EARTH_RADIUS_M)).irradiance(NADIR)
    shadow = in_earth_shadow(-earth_m, sun)
    assert list(shadow) == [False] * 3 + [True] * 3
    assert np.all(shine[~shadow] > 0) and np.all(shine[shadow] == 0)
    assert np.all(np.diff(shine[~shadow]) < 0)  # dimmer towards the terminator


def test_mistakes_are_named():
    with pytest.raises(InputError, match="above the Earth"):
        earthshine_sources(above(-10e3), sun_at(0.0))
    with pytest.raises(InputError, match="kd \\+ earth.ks"):
        Earth(kd=0.8, ks=0.3)
    with pytest.raises(InputError, match="`sun`"):
        earthshine_sources(above([550e3, 600e3]), sun_at(0.0))
    sources = earthshine_sources(above(550e3), sun_at(0.0))
    with pytest.raises(InputError, match="`observer`"):
        earthshine_irradiance(reflection([sf.Plate("p", 1.0, (0, 0, -1), sf.Lambert(0.5))]), sources, np.ones((2, 3)), np.ones(2))
