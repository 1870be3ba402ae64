"""Scene files: Table 4-2 defaults, TOML round trip, overrides, and a clear error for every bad value."""

from __future__ import annotations

import re

import pytest

from spacefit.errors import InputError
from spacefit.materials import Conductor, Lambert, make_material
from spacefit.scene.overrides import apply_overrides
from spacefit.scene.schema import Scene
from spacefit.scene.toml import load_scene, scene_from_dict


def test_defaults_are_table_4_2():
    """Table 4-2, and the thesis's wrinkles but G: 1e-5 m, its "10" read as micrometres (issue 13)."""
    s = Scene()
    assert s.render.resolution == (600, 600) and s.render.spp == 20 and s.render.depth == 2
    assert s.camera.pixel_pitch_mm == 4.0 and s.camera.focal_length_mm == 7000.0
    assert s.camera.position_m == (0.0, 0.0, 70.0) and s.camera.attitude_deg == (0.0, 0.0, 0.0)
    assert s.target.position_m == (0.0, 0.0, 0.0) and s.target.attitude_deg == (90.0, 0.0, 0.0)
    assert s.sun.irradiance_w_m2 == 5.0 and s.sun.direction == (0.0, 0.0, -1.0)
    w = s.wrinkles
    assert (w.D, w.G, w.gamma, w.M, w.L, w.Ls) == (2.3, 1e-5, 1.5, 5, 0.1, 5e-3)
    assert s.parts["panels"].material == Conductor(2.05, 0.055, 0.08, 0.05) == make_material("panel_thesis")
    assert s.parts["legs"].material == Lambert(0.2)
    body = s.parts["body"].material
    assert (body.eta, body.k) == (0.18, 0.01)


def test_toml_round_trip(tmp_path):
    s = load_scene(None, ["camera.focal_length_mm=5000", "parts.panels.alpha_x=0.1", "sun.irradiance_w_m2='physical'"])
    assert s.camera.focal_length_mm == 5000.0 and s.sun.irradiance_w_m2 == 1361.0
    path = tmp_path / "scene.toml"
    path.write_text(s.to_toml())
    assert load_scene(path) == s


def test_overrides_parse_toml_values():
    data = apply_overrides({}, ["render.resolution=[64, 48]", "target.mesh=lander.obj", "wrinkles.enabled=false"])
    assert data == {"render": {"resolution": [64, 48]}, "target": {"mesh": "lander.obj"}, "wrinkles": {"enabled": False}}


def test_unknown_keys_suggest_the_closest():
    with pytest.raises(InputError, match=r"`camera\.focal_length_mm`"):
        scene_from_dict({"camera": {"focal_lenght_mm": 5000}})
    with pytest.raises(InputError, match=r"Did you mean `wrinkles`"):
        scene_from_dict({"wrinkle": {}})
    with pytest.raises(InputError, match="alpha_x"):
        scene_from_dict({"parts": {"panels": {"material": "panel_thesis", "alpha_z": 0.1}}})


def test_unknown_material_lists_the_valid_ones():
    with pytest.raises(InputError, match="mli_gold.*Did you mean 'mli_gold'"):
        scene_from_dict({"parts": {"body": {"material": "mli_golden"}}})


@pytest.mark.parametrize(
    ("override", "names"),
    [
        ("wrinkles.D=2.0", "wrinkles.D"),
        ("wrinkles.D=3.0", "wrinkles.D"),
        ("wrinkles.D=nan", "wrinkles.D"),
        ("wrinkles.gamma=1.0", "wrinkles.gamma"),
        ("wrinkles.G=-1.0", "wrinkles.G"),
        ("wrinkles.spacing_m=0.0", "wrinkles.spacing_m"),
        ("parts.panels.alpha_x=0.0", "parts.panels.alpha_x` must be in [0.0001, 1], got 0"),
        ("parts.panels.alpha_y=-0.1", "parts.panels.alpha_y"),
        ("parts.panels.alpha=2", "parts.panels.alpha_x` must be in [0.0001, 1], got 2"),
        ("parts.legs.kd=1.5", "parts.legs.kd` must be in [0, 1], got 1.5"),
        ("parts.legs.kd=-0.1", "parts.legs.kd"),
        ("parts.body.eta=nan", "parts.body.eta` must be finite"),
        ("sun.elevation_deg=120", "sun.elevation_deg` must be in [-90, 90] deg, got 120"),
        ("render.resolution=[0, 600]", "render.resolution"),
        ("render.spp=0", "render.spp"),
        ("render.spp=2.5", "render.spp"),
        ("render.depth=0", "render.depth"),
        ("camera.focal_length_mm=-1", "camera.focal_length_mm"),
        ("camera.pixel_pitch_mm=inf", "camera.pixel_pitch_mm"),
        ("camera.position_m=[0, nan, 70]", "camera.position_m"),
        ("camera.position_m=[0, 70]", "camera.position_m"),
        ("sun.irradiance_w_m2=0", "sun.irradiance_w_m2"),
        ("sun.direction=[0, 0, 0]", "sun.direction"),
        ("render.variant='optix'", "render.variant"),
    ],
)
def test_bad_values_name_the_argument_and_range(override, names):
    with pytest.raises(InputError, match=re.escape(names)):
        load_scene(None, [override])


def test_malformed_toml(tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text("[camera\nfocal_length_mm = 1")
    with pytest.raises(InputError, match="not valid TOML"):
        load_scene(path)
    with pytest.raises(InputError, match="does not exist"):
        load_scene(tmp_path / "missing.toml")
