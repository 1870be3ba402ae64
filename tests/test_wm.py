"""The W-M height field of thesis eq. 2-1 (Yan & Komvopoulos 1998) and the roughness check of section 2.2."""

from __future__ import annotations

import math

import jax
import numpy as np
import pytest

import spacefit  # noqa: F401
from spacefit.errors import InputError
from spacefit.geometry.wm import (
    check_wm_params,
    profile_ra,
    wm_height,
    wm_n_max,
    wm_phases,
    wm_rms,
    wm_rms_slope,
    wm_section_ra,
)

THESIS = {"gamma": 1.5, "M": 5, "L": 0.1, "Ls": 5e-3}
GOOD = {"D": 2.3, "G": 1e-3, **THESIS}


@pytest.fixture(autouse=True)
def float64_mode():
    """jvp traces D and G from the test: float64 tracers, as in spacefit's own scoped callers."""
    with jax.enable_x64(True):
        yield


def eq_2_1(x, y, D, G, gamma, M, L, Ls, phases):
    """Eq. 2-1 as printed: polar coordinates and the double sum, one term at a time."""
    n_max = int(np.log(L / Ls) / np.log(gamma))
    r, theta = np.sqrt(x**2 + y**2), np.arctan2(y, x)
    total = np.zeros_like(x)
    for m in range(1, M + 1):
        for n in range(n_max + 1):
            phi = phases[m - 1, n]
            arg = 2 * np.pi * gamma**n * r / L * np.cos(theta - np.pi * m / M) + phi
            total += gamma ** ((D - 3) * n) * (np.cos(phi) - np.cos(arg))
    return L * (G / L) ** (D - 2) * np.sqrt(np.log(gamma) / M) * total


@pytest.fixture
def phases():
    return wm_phases(THESIS["M"], wm_n_max(THESIS["L"], THESIS["Ls"], THESIS["gamma"]), seed=3)


@pytest.fixture
def points():
    uv = np.random.default_rng(0).uniform(-0.3, 0.3, size=(500, 2))
    uv[0] = 0.0
    uv[1] = [-0.2, 0.0]  # negative x axis, where the polar angle jumps
    return uv


def test_heights_match_eq_2_1(phases, points):
    for D, G in [(2.3, 1e-3), (2.7, 10.0)]:
        got = np.asarray(wm_height(points, D, G, **THESIS, phases=phases))
        want = eq_2_1(points[:, 0], points[:, 1], D, G, **THESIS, phases=phases)
        assert got[0] == 0.0
        np.testing.assert_allclose(got, want, rtol=1e-10, atol=1e-10 * np.abs(want).max())


@pytest.mark.parametrize("which", ["D", "G"])
def test_derivatives_match_finite_differences(phases, points, which):
    base = {"D": 2.4, "G": 0.02}

    def heights(value):
        return wm_height(points, **{**base, which: value}, **THESIS, phases=phases)

    _, tangent = jax.jvp(heights, (base[which],), (1.0,))
    h = 1e-6
    central = (np.asarray(heights(base[which] + h)) - np.asarray(heights(base[which] - h))) / (2 * h)
    np.testing.assert_allclose(np.asarray(tangent), central, rtol=1e-6, atol=1e-8 * np.abs(central).max())


def test_heights_jit_and_grad(phases, points):
    f = jax.jit(lambda D, G: wm_height(points, D, G, **THESIS, phases=phases).sum())
    assert f(2.3, 0.01) == pytest.approx(float(wm_height(points, 2.3, 0.01, **THESIS, phases=phases).sum()))
    assert np.all(np.isfinite(jax.grad(f, argnums=(0, 1))(2.3, 0.01)))


def test_n_max_and_phases():
    assert wm_n_max(0.1, 5e-3, 1.5) == 7
    assert wm_n_max(0.1, 0.1 / 1.5**3, 1.5) == 3  # an exact power of gamma keeps its finest scale
    a, b = wm_phases(5, 7, seed=1), wm_phases(5, 7, seed=1)
    assert a.shape == (5, 8) and np.array_equal(a, b)
    assert not np.allclose(a, wm_phases(5, 7, seed=2))
    assert a.min() >= 0.0 and a.max() < 2 * np.pi


def test_ra_grows_with_g_at_fixed_d():
    ra = [wm_section_ra(2.3, G) for G in (1.0, 2.0, 5.0, 10.0)]
    assert all(lo < hi for lo, hi in zip(ra, ra[1:]))


def test_profile_ra_of_known_profiles():
    x = np.linspace(-1.0, 3.0, 4000)
    line = 0.7 * x - 2.0
    assert profile_ra(x, line) == pytest.approx(0.0, abs=1e-12)
    # Blocks of (+, -, -, +) have zero mean and zero correlation with x: the mean line is `line`.
    square = 0.25 * np.tile([1.0, -1.0, -1.0, 1.0], len(x) // 4)
    assert profile_ra(x, line + square) == pytest.approx(0.25, rel=1e-10)


@pytest.mark.parametrize(
    "name, value",
    [
        ("D", 2.0),
        ("D", 3.0),
        ("D", math.nan),
        ("G", 0.0),
        ("G", -1.0),
        ("gamma", 1.0),
        ("M", 0),
        ("M", 2.5),
        ("M", True),
        ("L", 0.0),
        ("L", -0.1),
        ("Ls", 0.1),
        ("Ls", 0.2),
        ("Ls", 0.0),
    ],
)
def test_bad_parameters_are_named(name, value):
    with pytest.raises(InputError, match=f"wrinkles\\.{name}`"):
        check_wm_params(**{**GOOD, name: value})


def test_good_parameters_pass():
    check_wm_params(**GOOD)
    check_wm_params(2.999, 10.0, 1.01, 1, 1.0, 0.999)


def test_rms_height_and_slope_match_a_sampled_surface():
    """The closed forms of the rms height and per-axis rms slope against one sampled realisation
    (8 m x 8 m, 20 L, 5 mm grid; gentle wrinkles: L 0.4 m, Ls 0.1 m)."""
    params = {"gamma": 1.5, "M": 5, "L": 0.4, "Ls": 0.1}
    D, G, h = 2.4, 3e-4, 0.005
    x = np.arange(0.0, 8.0, h)
    X, Y = np.meshgrid(x, x)
    phases = wm_phases(params["M"], wm_n_max(params["L"], params["Ls"], params["gamma"]), seed=1)
    z = np.asarray(wm_height(np.stack([X.ravel(), Y.ravel()], -1), D, G, phases=phases, **params)).reshape(X.shape)
    slope_y, slope_x = np.gradient(z, h)
    assert z.std() == pytest.approx(float(wm_rms(D, G, **params)), rel=0.02)
    for slope in (slope_x, slope_y):
        assert slope.std() == pytest.approx(float(wm_rms_slope(D, G, **params)), rel=0.02)
