"""One vocabulary, checked everywhere: every entry point takes scene-file keys and parameter names,
refuses an out-of-range value with the message a scene file gets, and answers a typo with the
closest name at the depth where it went wrong. Scene sections check themselves on construction;
materials are objects from the moment a scene is read; a scene file reads back to an equal scene."""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest

import spacefit as sf
from spacefit.cli import main
from spacefit.materials import Conductor, Lambert
from spacefit.scene.parameters import check_names, scene_value

DATA = Path(__file__).resolve().parents[1] / "data"
SMALL = {"render.resolution": [24, 24], "render.spp": 1, "camera.pixel_pitch_mm": 100.0, "wrinkles.enabled": False}
# A bad value, the message every entry point gives for it (the scene file's).
BAD = [
    ({"parts.panels.alpha_x": 2.0}, "`parts.panels.alpha_x` must be in [0.0001, 1], got 2."),
    ({"parts.legs.kd": 1.5}, "`parts.legs.kd` must be in [0, 1], got 1.5."),
    ({"parts.legs.kd": -0.1}, "`parts.legs.kd` must be in [0, 1], got -0.1."),
    ({"sun.elevation_deg": 120.0}, "`sun.elevation_deg` must be in [-90, 90] deg, got 120."),
    ({"parts.panels.eta": math.nan}, "`parts.panels.eta` must be finite, got nan."),
]
TYPOS = [  # a typo at each depth, and the name suggested
    ("wrinkle.D", "wrinkles.D"),
    ("parts.panel.alpha_x", "parts.panels.alpha_x"),
    ("parts.panels.alpah_x", "parts.panels.alpha_x"),
    ("sun.elevation", "sun.elevation_deg"),
]


@pytest.fixture(scope="module")
def renderer():
    return sf.Renderer(sf.default_scene().with_values(SMALL))


def message(call) -> str:
    with pytest.raises(sf.InputError) as err:
        call()
    return str(err.value)


@pytest.mark.parametrize(("section", "kwargs", "text"), [
    (sf.RenderSettings, {"spp": -1}, "`render.spp` must be in [1, 65536], got -1."),
    (sf.CameraSettings, {"focal_length_mm": 0.0}, "`camera.focal_length_mm` must be in (0, inf] mm, got 0."),
    (sf.SunSettings, {"direction": (0, 0, 0)}, "`sun.direction` must not be the zero vector."),
    (sf.TargetSettings, {"position_m": (0, 0, 2e5)}, "`target.position_m` must lie within 100000 m"),
    (sf.WrinkleSettings, {"D": 3.5}, "`wrinkles.D` must be in (2, 3), got 3.5."),
])
def test_sections_check_themselves_on_construction(section, kwargs, text):
    assert text in message(lambda: section(**kwargs))


def test_a_scene_checks_what_joins_its_sections():
    assert "`render.spp` must be in [1, 65536], got -1." in message(lambda: sf.Scene(render=sf.RenderSettings(spp=-1)))
    assert "`wrinkles.parts` must be one of" in message(lambda: sf.Scene(wrinkles=sf.WrinkleSettings(parts=("hull",))))
    with pytest.raises(sf.InputError, match="must be a spacefit material"):
        sf.PartSettings("mli_gold")  # type: ignore[arg-type]
    scene = sf.Scene(camera=sf.CameraSettings(position_m=[0, 0, 50]))  # coerced as a scene file's list is
    assert scene.camera.position_m == (0.0, 0.0, 50.0) and scene == sf.default_scene().with_values({"camera.position_m": [0, 0, 50]})


def test_materials_are_objects_when_a_file_is_read(tmp_path):
    path = tmp_path / "scene.toml"
    path.write_text('[parts.body]\nmaterial = "mli_gold"\nalpha = 0.3\n[parts.legs]\nkd = 0.5\n')
    scene = sf.load_scene(path)
    assert scene.parts["body"].material == Conductor((0.143119, 0.374957, 1.44248), (3.98316, 2.38572, 1.60322), 0.3, 0.3)
    assert scene.parts["legs"].material == Lambert(0.5)
    path.write_text('[parts.body]\nmaterial = "lambert"\n')
    assert "`parts.body.kd` is missing" in message(lambda: sf.load_scene(path))


def test_an_override_of_a_tie_or_its_field_replaces_the_files_values_the_other_way(tmp_path):
    """``alpha`` given over a file's alpha_x and alpha_y sets both; ``alpha_x`` given over a file's
    ``alpha`` keeps the file's value for alpha_y; both given at once are refused."""
    written = tmp_path / "written.toml"
    written.write_text('[parts.body]\nmaterial = "conductor"\neta = 0.18\nk = 0.01\nalpha_x = 0.14\nalpha_y = 0.12\n')
    body = sf.load_scene(written, ["parts.body.alpha=0.2"]).parts["body"].material
    assert (body.alpha_x, body.alpha_y) == (0.2, 0.2)
    tied = tmp_path / "tied.toml"
    tied.write_text('[parts.body]\nmaterial = "conductor"\neta = 0.18\nk = 0.01\nalpha = 0.3\n')
    body = sf.load_scene(tied, ["parts.body.alpha_x=0.1"]).parts["body"].material
    assert (body.alpha_x, body.alpha_y) == (0.1, 0.3)
    with pytest.raises(sf.InputError, match=r"`parts.body.alpha` sets alpha_x and alpha_y; do not give them as well"):
        sf.load_scene(tied, ["parts.body.alpha_x=0.1", "parts.body.alpha=0.2"])


@pytest.mark.parametrize("path", sorted(DATA.glob("*/*.toml")), ids=lambda p: p.name)
def test_scene_files_read_back_to_an_equal_scene(tmp_path, path):
    if path.name == "cases.toml":
        pytest.skip("the cases' table, not a scene")
    rough = next(name for name, part in sf.load_scene(path).parts.items() if hasattr(part.material, "alpha_x"))
    scene = sf.load_scene(path, [f"parts.{rough}.alpha=0.2", "sun.elevation_deg=40", "sun.irradiance_w_m2='physical'"])
    copy = tmp_path / "copy.toml"
    copy.write_text(scene.to_toml())
    assert sf.load_scene(copy) == scene
    assert sf.load_scene(copy).to_toml() == scene.to_toml()


@pytest.mark.parametrize(("values", "text"), BAD, ids=lambda v: str(v)[:30])
def test_every_entry_point_refuses_a_bad_value_with_one_message(tmp_path, renderer, values, text):
    ((name, value),) = values.items()
    scene = sf.default_scene().with_values(SMALL)
    assert message(lambda: sf.load_scene(None, values)) == text
    assert message(lambda: scene.with_values(values)) == text
    assert message(lambda: renderer.set_values(values)) == text
    assert message(lambda: sf.sensitivity(scene, [name], at=values, quiet=True)) == text
    assert message(lambda: sf.sweep(scene, {name: [value]}, quiet=True)).endswith(text)
    reference = np.zeros((24, 24, 3), np.float32)
    assert message(lambda: sf.fit(sf.Observation(scene, reference), [name], start=values, max_steps=1)) == text
    assert main(["scene", "--out", str(tmp_path / "s.toml"), "--set", f"{name}={value}"]) == 2
    assert not (tmp_path / "s.toml").exists()


def test_set_values_refuses_before_setting_anything(renderer):
    before = renderer.current_scene
    with pytest.raises(sf.InputError, match=re.escape(BAD[1][1])):
        renderer.set_values({"parts.panels.alpha_x": 0.2, "parts.legs.kd": 1.5})
    assert renderer.current_scene is before
    assert "build a new Renderer" in message(lambda: renderer.set_values({"camera.focal_length_mm": 100.0}))


@pytest.mark.parametrize(("typo", "meant"), TYPOS)
def test_a_typo_at_any_depth_suggests_the_closest_name(renderer, typo, meant):
    scene = sf.default_scene().with_values(SMALL)
    hint = f"Did you mean `{meant}`?"
    assert hint in message(lambda: sf.load_scene(None, {typo: 1.0}))
    assert hint in message(lambda: scene.with_values({typo: 1.0}))
    assert hint in message(lambda: renderer.set_values({typo: 1.0}))
    if typo != "wrinkle.D":  # not a name of the scene's parameters at all: check_choice suggests among those
        assert meant in message(lambda: check_names(scene, [typo]))
    assert hint in message(lambda: sf.sweep(scene, {typo: [1.0]}, quiet=True))


def test_a_part_typo_says_it_is_not_a_part(tmp_path):
    text = message(lambda: sf.load_scene(None, ["parts.panel.alpha_x=0.1"]))
    assert "`panel` is not a part of the scene (parts: body, panels, legs). Did you mean `parts.panels.alpha_x`?" in text
    path = tmp_path / "scene.toml"
    path.write_text("[parts.panel]\nalpha_x = 0.1\n")
    assert "`panel` is not a part of the scene" in message(lambda: sf.load_scene(path))
    assert "`panel` is not a part of the scene" in message(lambda: check_names(sf.default_scene(), ["parts.panel.alpha_x"]))


def test_scene_keys_and_parameter_names_are_one_vocabulary(tmp_path, renderer):
    """``sun.elevation_deg`` and ``sun.direction`` set the same value wherever a value is set; a fit
    frees numbers, so a vector key is refused there with the parameters that spell it."""
    towards = np.array([math.cos(math.radians(30)), 0.0, math.sin(math.radians(30))])
    by_angle = sf.default_scene().with_values({"sun.elevation_deg": 30.0})
    by_key = sf.default_scene().with_values({"sun.direction": (-towards).tolist()})
    np.testing.assert_allclose(by_angle.sun.direction, by_key.sun.direction, atol=1e-15)
    path = tmp_path / "scene.toml"
    path.write_text("[sun]\nelevation_deg = 30\n")
    np.testing.assert_allclose(sf.load_scene(path).sun.direction, by_key.sun.direction, atol=1e-15)
    np.testing.assert_allclose(sf.load_scene(None, ["sun.elevation_deg=30"]).sun.direction, by_key.sun.direction, atol=1e-15)
    pose = sf.default_scene().with_values({"target.attitude_y_deg": 5.0, "target.position_m": [1.0, 2.0, 3.0]})
    assert pose.target.attitude_deg == (90.0, 5.0, 0.0) and pose.target.position_m == (1.0, 2.0, 3.0)
    assert "`image.scale` is a fit-only nuisance" in message(lambda: sf.default_scene().with_values({"image.scale": 2.0}))
    assert "give `sun.elevation_deg`, `sun.azimuth_deg`" in message(lambda: check_names(sf.default_scene(), ["sun.direction"]))
    renderer.set_values({"sun.direction": by_key.sun.direction})
    assert scene_value(renderer.current_scene, "sun.elevation_deg") == pytest.approx(30.0)


def test_setting_one_sun_angle_keeps_the_other(renderer):
    """The default sun is at the zenith; its azimuth reads 0 deg (stated), and setting the elevation
    alone turns it towards +x. Away from the zenith each angle keeps the other, in a scene and in a
    loaded renderer across calls."""
    scene = sf.default_scene()
    assert scene_value(scene, "sun.azimuth_deg") == 0.0
    assert scene_value(scene.with_values({"sun.elevation_deg": 90.0}), "sun.azimuth_deg") == 0.0
    tilted = scene.with_values({"sun.elevation_deg": 30.0})
    np.testing.assert_allclose(tilted.sun.direction, [-math.cos(math.radians(30)), 0.0, -0.5], atol=1e-15)
    turned = scene.with_values({"sun.elevation_deg": 30.0, "sun.azimuth_deg": 45.0}).with_values({"sun.elevation_deg": 60.0})
    assert scene_value(turned, "sun.azimuth_deg") == pytest.approx(45.0)
    assert scene_value(turned.with_values({"sun.azimuth_deg": -100.0}), "sun.elevation_deg") == pytest.approx(60.0)
    renderer.set_values({"sun.elevation_deg": 20.0, "sun.azimuth_deg": 70.0})
    renderer.set_values({"sun.elevation_deg": 50.0})
    assert scene_value(renderer.current_scene, "sun.azimuth_deg") == pytest.approx(70.0)
    renderer.set_values({"sun.azimuth_deg": -30.0})
    assert scene_value(renderer.current_scene, "sun.elevation_deg") == pytest.approx(50.0)
    image = renderer.render()
    reloaded = sf.render(renderer.assembly.scene.with_values({"sun.elevation_deg": 50.0, "sun.azimuth_deg": -30.0}))
    np.testing.assert_allclose(image, reloaded, rtol=1e-5, atol=1e-7)
