"""A measured BRDF table as a material of the path tracer (``material = "tabulated"``): Mitsuba's
``BSDF.eval`` of the plugin against the table at its own directions and against
:meth:`TabulatedBRDF.evaluate` at random directions, a rendered plate's flux against the flat-plate
model's, the Jacobian column of ``scale`` against central differences, and how a scene file names it."""

from __future__ import annotations

import math
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import small_scene, write_plate_obj

import spacefit as sf
from spacefit.errors import InputError
from spacefit.geometry.frames import attitude_matrix
from spacefit.materials import make_material, material_table, with_material_values
from spacefit.materials.measured import read_brdf_table
from spacefit.rendering.bsdf_eval import mitsuba_brdf
from spacefit.rendering.derivatives import render_chain
from spacefit.studies.plates import Plate, plates_irradiance

CHASSIS = Path(__file__).resolve().parents[1] / "data" / "starlink-v1p5" / "chassis_brdf.csv"
E = 5.0  # sun irradiance, W m^-2


@pytest.fixture(scope="module")
def chassis() -> sf.TabulatedBRDF:
    return sf.TabulatedBRDF(source=str(CHASSIS))


def by_mitsuba(material: sf.TabulatedBRDF, light: np.ndarray, detector: np.ndarray) -> np.ndarray:
    """f_r by the plugin's ``BSDF.eval``: the path tracer's ``si.wi`` is the detector's direction and
    ``wo`` the light's (radiance transport), so the table's light is passed as Mitsuba's ``wo``."""
    return mitsuba_brdf(material, detector, light)


def test_the_plugin_gives_the_table_back_at_its_own_directions(chassis):
    table = read_brdf_table(CHASSIS)
    f = by_mitsuba(chassis, table.wi, table.wo)
    np.testing.assert_allclose(f, table.value, rtol=0.01)
    assert np.ptp(np.log10(table.value)) > 2  # the peak and the diffuse floor: a constant could not pass


def test_the_plugin_evaluates_the_same_interpolation_at_random_directions(chassis):
    """Out of the plane of incidence, on both sides and between the measured incidences; opposite sides give 0."""
    rng = np.random.default_rng(5)
    v = rng.normal(size=(2, 4000, 3))
    v[..., 2] = np.where(np.abs(v[..., 2]) < 0.1, np.copysign(0.1, v[..., 2]), v[..., 2])
    v /= np.linalg.norm(v, axis=-1, keepdims=True)
    v = v.astype(np.float32).astype(float)
    light, detector = v[0], v[1] * np.sign(v[1, :, 2:] * v[0, :, 2:])  # same side
    with jax.enable_x64(True):
        expected = np.asarray(jax.jit(lambda a, b: chassis.evaluate(a, b, {"scale": 1.7}))(light, detector))
    scaled = with_material_values(chassis, {"scale": 1.7})
    np.testing.assert_allclose(by_mitsuba(scaled, light, detector), expected, rtol=0.01)
    assert np.ptp(np.log10(expected)) > 1
    assert np.all(by_mitsuba(chassis, light[:50], -detector[:50]) == 0.0)


def test_a_rendered_plate_gives_the_plate_models_flux(tmp_path, chassis):
    """The renderer's integrated irradiance of a tabulated plate turned about y (sun 40 deg from the
    observer) equals :func:`plates_irradiance` of the same plate within 1 %, through the specular
    peak and off it, in the point-target limit the model assumes: seen from 10 km (0.2 mrad across
    the plate; from 1 km, 2 mrad, the chassis's narrow peak at exact specularity came 4 % low)."""
    scene = small_scene(write_plate_obj(tmp_path / "plate.obj"), {"material": "tabulated", "source": str(CHASSIS)},
                        render={"spp": 8, "resolution": [48, 48], "filter": "box"},
                        camera={"position_m": [0.0, 0.0, 10000.0], "focal_length_mm": 20000.0, "pixel_pitch_mm": 0.1},
                        sun={"irradiance_w_m2": E, "direction": [-math.sin(math.radians(40)), 0.0, -math.cos(math.radians(40))]})
    angles = np.array([-30.0, -20.0, -5.0, 10.0])  # attitude_y turns +z towards -x
    lc = sf.light_curve(scene, attitude_deg=angles, axis="y", quiet=True)
    world_sun, world_obs = np.array([math.sin(math.radians(40)), 0.0, math.cos(math.radians(40))]), np.array([0.0, 0.0, 1.0])
    rotations = [attitude_matrix(np.radians([0.0, a, 0.0])) for a in angles]
    sun = np.array([r.T @ world_sun for r in rotations])
    obs = np.array([r.T @ world_obs for r in rotations])
    model = np.asarray(plates_irradiance([Plate("plate", 4.0, (0, 0, 1), chassis)], sun, obs, np.full(len(angles), 10000.0), E))
    assert np.max(model) / np.min(model) > 3  # the peak and off it
    np.testing.assert_allclose(lc.irradiance_w_m2, model, rtol=0.01)


def cosine(a, b):
    a, b = np.ravel(a), np.ravel(b)
    return float(a @ b / (np.linalg.norm(a) * np.linalg.norm(b)))


def test_jacobian_column_in_scale_matches_finite_differences(tmp_path):
    th = np.radians(50.0)
    scene = small_scene(write_plate_obj(tmp_path / "plate.obj", size=8.0), {"material": "tabulated", "source": str(CHASSIS), "scale": 0.8},
                        sun={"direction": [-np.sin(th), 0.0, -np.cos(th)], "irradiance_w_m2": E},
                        camera={"position_m": [6.0, 0.0, 8.0], "look_at_m": [0.0, 0.0, 0.0], "up": [0.0, 0.0, 1.0]},
                        render={"spp": 16, "resolution": [16, 16]})
    chain = render_chain(scene, ["parts.plate.scale"], spp=16, spp_grad=16)
    x0 = jnp.array([0.8])
    with jax.enable_x64(True):
        J = np.asarray(jax.jacfwd(chain.forward(seed=1, seed_grad=2))(x0))
    e = 0.01 * 0.8
    fd = (chain.primal(x0 + e, 1) - chain.primal(x0 - e, 1)) / (2 * e)
    assert np.linalg.norm(fd) > 0
    assert cosine(J[..., 0], fd) >= 0.98
    assert np.linalg.norm(J[..., 0]) == pytest.approx(np.linalg.norm(fd), rel=0.05)


def test_a_scene_file_names_the_table_beside_it(tmp_path):
    """``source`` relative to the scene file's folder; a written scene names the file, not the arrays;
    a tabulated part without a table is refused, naming the key."""
    (tmp_path / "tables").mkdir()
    (tmp_path / "tables" / "chassis.csv").write_text(CHASSIS.read_text())
    write_plate_obj(tmp_path / "plate.obj")
    (tmp_path / "scene.toml").write_text('[target]\nmesh = "plate.obj"\n[wrinkles]\nenabled = false\n'
                                         '[parts.plate]\nmaterial = "tabulated"\nsource = "tables/chassis.csv"\nscale = 0.5\n')
    part = sf.load_scene(tmp_path / "scene.toml").parts["plate"].material
    assert isinstance(part, sf.TabulatedBRDF) and part.scale == 0.5
    assert part.source == str((tmp_path / "tables" / "chassis.csv").resolve()) and len(part.incidence_rad) == 4
    assert material_table(part) == {"material": "tabulated", "source": part.source, "scale": 0.5}
    with pytest.raises(InputError, match=r"parts\.plate.*source"):
        make_material("tabulated", {"scale": 1.0}, where="parts.plate")


def test_another_source_reads_the_other_table(chassis):
    """Setting ``source`` to another file (an override, a sweep's axis) reads that file's table: the
    arrays read from the first are not kept; the same source keeps them, a new ``scale`` too."""
    array_file = CHASSIS.with_name("solar_array_brdf.csv")
    swapped = with_material_values(chassis, {"source": str(array_file)})
    fresh = sf.TabulatedBRDF(source=str(array_file))
    assert swapped.source == str(array_file)
    for k in range(len(fresh.incidence_rad)):
        np.testing.assert_array_equal(swapped.log_value[k], fresh.log_value[k])
    assert not np.array_equal(np.concatenate(swapped.log_value), np.concatenate(chassis.log_value))
    rescaled = with_material_values(chassis, {"source": chassis.source, "scale": 2.0})
    assert rescaled.scale == 2.0
    for k in range(len(chassis.incidence_rad)):
        np.testing.assert_array_equal(rescaled.log_value[k], chassis.log_value[k])
