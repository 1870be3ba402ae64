"""The Oren-Nayar material (Oren & Nayar 1994, qualitative model): its JAX BRDF against the paper's
form in angles and its limits, Mitsuba's plugin against it, a rendered plate against the closed form,
a Jacobian column in sigma against finite differences, and fits of sigma to a BRDF table and an image."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import pixel_directions, small_scene, write_plate_obj

import spacefit as sf
from spacefit.errors import InputError
from spacefit.fitting.brdf_table import simulate_brdf_table
from spacefit.fitting.observations.brdf import fit_brdf_table, fitted_material
from spacefit.materials import Lambert, OrenNayar, make_material
from spacefit.materials.brdf import brdf
from spacefit.rendering.derivatives import render_chain
from spacefit.rendering.renderer import render

E = 5.0  # sun irradiance, W m^-2


def directions(n: int, seed: int, upper: bool = False) -> np.ndarray:
    v = np.random.default_rng(seed).normal(size=(n, 3))
    v[:, 2] = np.where(np.abs(v[:, 2]) < 0.05, np.copysign(0.05, v[:, 2]), v[:, 2])
    if upper:
        v[:, 2] = np.abs(v[:, 2])
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def paper(wi: np.ndarray, wo: np.ndarray, kd: float, sigma: float) -> np.ndarray:
    """Oren & Nayar 1994 eq. 30 written in the paper's angles (front-side directions)."""
    ti, to = np.arccos(wi[:, 2]), np.arccos(wo[:, 2])
    dphi = np.arctan2(wi[:, 1], wi[:, 0]) - np.arctan2(wo[:, 1], wo[:, 0])
    a = 1 - 0.5 * sigma**2 / (sigma**2 + 0.33)
    b = 0.45 * sigma**2 / (sigma**2 + 0.09)
    alpha, beta = np.maximum(ti, to), np.minimum(ti, to)
    return kd / np.pi * (a + b * np.maximum(0.0, np.cos(dphi)) * np.sin(alpha) * np.tan(beta))


@pytest.fixture(autouse=True)
def x64():
    with jax.enable_x64(True):
        yield


@pytest.mark.parametrize("sigma", [0.1, 0.5, 1.2])
def test_brdf_is_the_papers_form_and_reciprocal(sigma):
    wi, wo = directions(2000, 1, upper=True), directions(2000, 2, upper=True)
    m = OrenNayar(0.6, sigma)
    ours = np.asarray(brdf(m, wi, wo))
    np.testing.assert_allclose(ours, paper(wi, wo, 0.6, sigma), rtol=1e-12)
    np.testing.assert_allclose(ours, np.asarray(brdf(m, wo, wi)), rtol=1e-12)
    assert np.all(ours >= 0.6 * (1 - 0.5 * sigma**2 / (sigma**2 + 0.33)) / np.pi * (1 - 1e-12))  # at least A kd / pi


def test_sigma_0_is_lambert_exactly_and_the_back_shades_as_the_front():
    wi, wo = directions(2000, 3), directions(2000, 4)
    np.testing.assert_array_equal(np.asarray(brdf(OrenNayar(0.37, 0.0), wi, wo)), np.asarray(brdf(Lambert(0.37), wi, wo)))
    m = OrenNayar(0.5, 0.8)
    flip = np.array([1.0, 1.0, -1.0])
    np.testing.assert_allclose(np.asarray(brdf(m, wi * flip, wo * flip)), np.asarray(brdf(m, wi, wo)), rtol=1e-12)


@pytest.mark.parametrize("sigma", [0.3, 0.8, 1.5])
def test_directional_albedo_is_below_kd(sigma):
    """int f_r cos(theta_o) d omega_o by a midpoint rule over the hemisphere, at incidences 0 to 85 deg:
    at most kd (no energy made), and A kd at normal incidence, where the B term vanishes."""
    kd = 0.8
    t = (np.arange(200) + 0.5) * (np.pi / 2) / 200
    p = (np.arange(400) + 0.5) * 2 * np.pi / 400
    T, P = np.meshgrid(t, p, indexing="ij")
    wo = np.stack([np.sin(T) * np.cos(P), np.sin(T) * np.sin(P), np.cos(T)], axis=-1).reshape(-1, 3)
    weight = (np.cos(T) * np.sin(T)).ravel() * (np.pi / 2 / 200) * (2 * np.pi / 400)
    albedo = []
    for theta_i in np.radians([0.0, 30.0, 60.0, 85.0]):
        wi = np.broadcast_to([np.sin(theta_i), 0.0, np.cos(theta_i)], wo.shape)
        albedo.append(float(np.sum(np.asarray(brdf(OrenNayar(kd, sigma), wi, wo)) * weight)))
    assert max(albedo) < kd
    a = 1 - 0.5 * sigma**2 / (sigma**2 + 0.33)
    assert albedo[0] == pytest.approx(a * kd, rel=1e-4)


def test_fields_are_checked():
    with pytest.raises(InputError, match="sigma"):
        OrenNayar(0.5, np.pi / 2)
    with pytest.raises(InputError, match="kd"):
        OrenNayar(1.2, 0.3)
    assert sf.OrenNayar is OrenNayar and make_material("oren_nayar", {"kd": 0.2, "sigma": 0.4}) == OrenNayar(0.2, 0.4)


def plate_scene(tmp_path, sigma: float, **render):
    """A plate under a sun 50 deg from its normal, seen 37 deg off the normal from the sun's side
    (backscatter, where the B term is largest)."""
    th = np.radians(50.0)
    return small_scene(write_plate_obj(tmp_path / "plate.obj", size=8.0), {"material": "oren_nayar", "kd": 0.5, "sigma": sigma},
                       sun={"direction": [-np.sin(th), 0.0, -np.cos(th)], "irradiance_w_m2": E},
                       camera={"position_m": [6.0, 0.0, 8.0], "look_at_m": [0.0, 0.0, 0.0], "up": [0.0, 0.0, 1.0]},
                       render={"spp": 16, **render})


@pytest.mark.parametrize("sigma", [0.0, 0.6, 1.2])
def test_rendered_plate_matches_the_closed_form(tmp_path, sigma):
    scene = plate_scene(tmp_path, sigma)
    img = render(scene)
    wo = -pixel_directions(scene)
    th = np.radians(50.0)
    wi = np.broadcast_to([np.sin(th), 0.0, np.cos(th)], wo.shape)
    expected = paper(wi.reshape(-1, 3), wo.reshape(-1, 3), 0.5, sigma).reshape(wo.shape[:2]) * E * np.cos(th)
    assert np.mean(img[4:-4, 4:-4]) == pytest.approx(np.mean(expected[4:-4, 4:-4]), rel=0.01)
    lambert = 0.5 * E * np.cos(th) / np.pi
    assert abs(np.mean(expected[4:-4, 4:-4]) / lambert - 1.0) > (0.05 if sigma > 0 else -1.0)  # rough: not Lambert's


def cosine(a, b):
    a, b = np.ravel(a), np.ravel(b)
    return float(a @ b / (np.linalg.norm(a) * np.linalg.norm(b)))


def test_jacobian_column_in_sigma_matches_finite_differences(tmp_path):
    names = ["parts.plate.sigma", "parts.plate.kd"]
    chain = render_chain(plate_scene(tmp_path, 0.6, resolution=[16, 16]), names, spp=64, spp_grad=64)
    x0 = jnp.array([0.6, 0.5])
    J = np.asarray(jax.jacfwd(chain.forward(seed=1, seed_grad=2))(x0))
    for j, name in enumerate(names):
        e = np.zeros(2)
        e[j] = 0.01 * float(x0[j])
        fd = (chain.primal(x0 + e, 1) - chain.primal(x0 - e, 1)) / (2 * e[j])
        assert np.linalg.norm(fd) > 0, name
        assert cosine(J[..., j], fd) >= 0.98, name
        assert np.linalg.norm(J[..., j]) == pytest.approx(np.linalg.norm(fd), rel=0.05), name


def test_a_simulated_table_is_fitted_back_within_1_percent():
    truth = OrenNayar(0.42, 0.7)
    table = simulate_brdf_table(truth, np.arange(0.0, 80.0, 10.0), np.arange(0.0, 85.0, 7.0), (0.0, 45.0, 90.0, 180.0),
                                relative_error=0.01, seed=3)
    fit = fit_brdf_table(table, "oren_nayar", part="sample")
    kd, sigma = fit.values["parts.sample.kd"], fit.values["parts.sample.sigma"]
    assert list(fit.names) == ["parts.sample.kd", "parts.sample.sigma"]
    assert kd == pytest.approx(0.42, rel=0.01) and sigma == pytest.approx(0.7, rel=0.01)
    assert fitted_material("oren_nayar", fit) == OrenNayar(kd, sigma)


def test_image_fit_recovers_a_parts_sigma(tmp_path):
    reference = render(plate_scene(tmp_path, 0.9, resolution=[16, 16], seed=7))
    start = plate_scene(tmp_path, 0.3, resolution=[16, 16])
    result = sf.fit(sf.Observation(start, reference), ["parts.plate.sigma"], max_steps=20)
    assert result.values["parts.plate.sigma"] == pytest.approx(0.9, rel=0.02)
