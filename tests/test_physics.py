"""Renders against analytic radiance: Lambert (thesis eq. 2-10), anisotropic GGX and Beckmann (Walter 2007)."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import pixel_directions, small_scene, write_plate_obj, write_sphere_obj

from spacefit.rendering.renderer import render

E = 5.0  # sun irradiance, W m^-2


def unit(v):
    v = np.asarray(v, float)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


@pytest.mark.parametrize(("theta_deg", "passes"), [(0.0, 1), (40.0, 1), (70.0, 1), (40.0, 4)])
def test_lambert_plate_matches_kd_E_cos_over_pi(tmp_path, monkeypatch, theta_deg, passes):
    """Also with the samples split into passes (as big renders are), which must not bias."""
    import spacefit.rendering.sample_passes as sample_passes

    monkeypatch.setattr(sample_passes, "MAX_SAMPLES_PER_PASS", sample_passes.MAX_SAMPLES_PER_PASS if passes == 1 else 32 * 32 * 4)
    kd = 0.5
    th = np.radians(theta_deg)
    sun = [np.sin(th), 0.0, -np.cos(th)]
    scene = small_scene(write_plate_obj(tmp_path / "plate.obj", size=4.0), {"material": "white_paint", "kd": kd},
                        sun={"direction": sun, "irradiance_w_m2": E})
    img = render(scene)
    inner = img[4:-4, 4:-4]
    expected = kd * E * np.cos(th) / np.pi
    assert np.mean(inner) == pytest.approx(expected, rel=0.01)


def test_lambert_sphere_matches_kd_E_cos_over_pi(tmp_path):
    kd = 0.3
    scene = small_scene(write_sphere_obj(tmp_path / "sphere.obj", radius=1.0), {"material": "white_paint", "kd": kd},
                        render={"resolution": [64, 64], "spp": 64},
                        camera={"position_m": [0.0, 0.0, 20.0], "focal_length_mm": 100.0, "pixel_pitch_mm": 0.05},
                        sun={"direction": unit([1.0, 0.0, -1.0]).tolist(), "irradiance_w_m2": E})
    img = render(scene)[..., 0]
    d = pixel_directions(scene)
    origin = np.array([0.0, 0.0, 20.0])
    # ray-sphere intersection per pixel centre; keep pixels well inside the silhouette
    b = d @ origin
    disc = b**2 - (origin @ origin - 1.0)
    hit = disc > 0.05  # away from the grazing rim
    t = -b - np.sqrt(np.where(hit, disc, 0.0))
    n = origin + t[..., None] * d
    cos_i = np.clip(n @ -unit([1.0, 0.0, -1.0]), 0.0, None)
    expected = kd * E * cos_i / np.pi
    # compare where the expected radiance varies slowly (exclude terminator and rim pixels)
    mask = hit & (cos_i > 0.2)
    assert mask.sum() > 300
    assert np.mean(img[mask]) == pytest.approx(np.mean(expected[mask]), rel=0.01)


def fresnel_conductor(cos_i, eta, k):
    """Unpolarised Fresnel reflectance of a conductor eta + i k (exact; pbrt-v3 FrConductor)."""
    c2 = cos_i**2
    s2 = 1.0 - c2
    t0 = eta**2 - k**2 - s2
    a2b2 = np.sqrt(t0**2 + 4 * eta**2 * k**2)
    t1 = a2b2 + c2
    a = np.sqrt(0.5 * (a2b2 + t0))
    t2 = 2 * cos_i * a
    rs = (t1 - t2) / (t1 + t2)
    t3 = c2 * a2b2 + s2**2
    t4 = t2 * s2
    rp = rs * (t3 - t4) / (t3 + t4)
    return 0.5 * (rp + rs)


def microfacet_walter(wi, wo, ax, ay, eta, k, distribution):
    """Walter et al. 2007 microfacet BRDF, anisotropic GGX or Beckmann, separable Smith G (Beckmann's
    Lambda by Walter's rational approximation, eq. 27), in the local frame."""
    h = unit(wi + wo)
    slope2 = (h[..., 0] / ax) ** 2 + (h[..., 1] / ay) ** 2  # tan^2 of h, scaled per axis, times cos^2
    if distribution == "ggx":
        D = 1.0 / (np.pi * ax * ay * (slope2 + h[..., 2] ** 2) ** 2)
    else:
        D = np.exp(-slope2 / h[..., 2] ** 2) / (np.pi * ax * ay * h[..., 2] ** 4)

    def lam(w):
        tan_alpha2 = (ax**2 * w[..., 0] ** 2 + ay**2 * w[..., 1] ** 2) / w[..., 2] ** 2
        if distribution == "ggx":
            return 0.5 * (-1.0 + np.sqrt(1.0 + tan_alpha2))
        a = 1.0 / np.sqrt(tan_alpha2)
        return np.where(a < 1.6, (1.0 - 1.259 * a + 0.396 * a**2) / (3.535 * a + 2.181 * a**2), 0.0)

    G = 1.0 / (1.0 + lam(wi)) / (1.0 + lam(wo))
    F = fresnel_conductor(np.sum(wi * h, axis=-1), eta, k)
    return D * G * F / (4.0 * wi[..., 2] * wo[..., 2])


@pytest.mark.parametrize(
    ("sun_dir", "ax", "ay", "distribution"),
    [
        ([0.5, 0.0, -1.0], 0.3, 0.1, "ggx"),   # light tilted along alpha_x
        ([0.0, 0.5, -1.0], 0.3, 0.1, "ggx"),   # the same tilt along alpha_y: different radiance
        ([0.3, -0.4, -1.0], 0.08, 0.05, "ggx"),  # the thesis's panel roughness
        ([0.5, 0.0, -1.0], 0.45, 0.3, "beckmann"),  # the level of detail's effective roughness
    ],
)
def test_anisotropic_microfacet_plate_matches_walter_2007(tmp_path, sun_dir, ax, ay, distribution):
    eta, k = 2.05, 0.055
    scene = small_scene(
        write_plate_obj(tmp_path / "plate.obj", size=4.0),
        {"material": "panel_thesis", "alpha_x": ax, "alpha_y": ay, "eta": eta, "k": k, "distribution": distribution},
        render={"spp": 256},
        camera={"position_m": [1.0, 0.5, 10.0], "look_at_m": [0.0, 0.0, 0.0], "up": [0.0, 1.0, 0.0],
                "focal_length_mm": 200.0, "pixel_pitch_mm": 0.1},
        sun={"direction": unit(sun_dir).tolist(), "irradiance_w_m2": E},
    )
    img = render(scene)[..., 0]
    wo = -pixel_directions(scene)  # plate frame = world frame here: x tangent, y bitangent, z normal
    wi = np.broadcast_to(-unit(sun_dir), wo.shape)
    expected = microfacet_walter(wi, wo, ax, ay, eta, k, distribution) * E * wi[..., 2]
    assert np.mean(img[2:-2, 2:-2]) == pytest.approx(np.mean(expected[2:-2, 2:-2]), rel=0.02)
