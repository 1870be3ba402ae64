"""Back faces are shaded as front faces, as in the thesis's renderer (pbrt-v3): Mitsuba's ``twosided``.

A plate wound away from the camera and the sun must render as the same plate wound towards them
(the mirrored geometry seen from its front), for a conductor and a Lambert material; and the thesis's
literal wrinkles (G = 10 m), whose folds put back faces in view, must not leave those pixels black.
"""

from __future__ import annotations

from pathlib import Path

import mitsuba as mi
import numpy as np
import pytest
from helpers import small_scene, write_plate_obj

import spacefit as sf
from spacefit.rendering.materials import bsdf_key
from spacefit.rendering.renderer import Renderer
from spacefit.scene.parameters import scene_with_values

LITERAL = Path(__file__).resolve().parents[1] / "data" / "scenes" / "thesis-literal.toml"


def flipped_plate(path: Path) -> Path:
    """The plate of :func:`write_plate_obj` with its faces wound the other way: its normal is -z."""
    text = write_plate_obj(path).read_text()
    return path if path.write_text(text.replace("f 1/1 2/2 3/3\nf 1/1 3/3 4/4", "f 1/1 3/3 2/2\nf 1/1 4/4 3/3")) else path


@pytest.mark.parametrize("material", [{"material": "panel_thesis"}, {"material": "white_paint"}])
def test_back_of_a_plate_renders_as_its_front(tmp_path, material):
    view = {"camera": {"position_m": [1.0, 0.5, 10.0], "look_at_m": [0.0, 0.0, 0.0]},
            "sun": {"direction": [0.3, 0.1, -1.0]}}
    front = sf.render(small_scene(write_plate_obj(tmp_path / "plate.obj"), material, **view))
    (tmp_path / "back").mkdir()
    back = sf.render(small_scene(flipped_plate(tmp_path / "back" / "plate.obj"), material, **view))
    assert front.mean() > 0
    assert np.allclose(back, front, rtol=1e-4, atol=1e-6)


def test_bsdf_key_names_the_twosided_bsdfs_parameters(tmp_path):
    """One home for the key: every part's BSDF parameter it names exists in the loaded scene."""
    scene = small_scene(write_plate_obj(tmp_path / "plate.obj"), {"material": "panel_thesis"})
    renderer = Renderer(scene)
    for field in ("alpha_u", "alpha_v", "eta", "k"):
        assert bsdf_key("plate", field) in renderer.params
    renderer.set_values({"parts.plate.alpha_x": 0.3})
    assert float(renderer.params[bsdf_key("plate", "alpha_u")][0]) == pytest.approx(0.3)


def test_literal_wrinkles_back_faces_in_view_are_lit():
    """At G = 10 m some camera rays hit the back of a face; they are shaded, not black: their mean
    radiance is of the order of the front faces' (a one-sided BSDF gives exactly 0)."""
    scene = sf.load_scene(LITERAL, {"render.resolution": [96, 96], "camera.pixel_pitch_mm": 17.5, "render.spp": 16})
    with pytest.warns(UserWarning, match="fold over"):
        renderer = Renderer(scene)
    image = renderer.render().mean(axis=-1)
    x0, y0, w, h = renderer.window
    index = np.arange(w * h)
    position = mi.Point2f((mi.Float(index % w) + 0.5) / w, (mi.Float(index // w) + 0.5) / h)
    ray, _ = renderer.scene.sensors()[0].sample_ray(0.0, 0.0, position, mi.Point2f(0.5))
    hit = renderer.scene.ray_intersect(ray)
    valid = np.asarray(hit.is_valid())
    back = valid & (np.einsum("ij,ij->j", np.asarray(ray.d), np.asarray(hit.n)) > 0)  # (3, n) each
    pixels = image[y0:y0 + h, x0:x0 + w].ravel()
    print(f"back faces: {back.sum() / valid.sum():.3f} of the target's rays; mean radiance back "
          f"{pixels[back].mean():.4g}, front {pixels[valid & ~back].mean():.4g} W m^-2 sr^-1")
    assert back.sum() > 0.01 * valid.sum()
    assert pixels[back].mean() > 0.2 * pixels[valid & ~back].mean()


@pytest.mark.parametrize(("material", "values"), [
    ({"material": "conductor", "eta": 1.5, "k": 1.0, "alpha_x": 0.2, "alpha_y": 0.1}, {"parts.plate.eta": 2.5, "parts.plate.alpha": 0.3}),
    ({"material": "diffuse_conductor", "kd": 0.2, "eta": 1.5, "k": 1.0, "alpha_x": 0.2, "alpha_y": 0.1},
     {"parts.plate.kd": 0.4, "parts.plate.alpha_y": 0.3}),
    ({"material": "lambert", "kd": 0.3}, {"parts.plate.kd": 0.6}),
    ({"material": "oren_nayar", "kd": 0.3, "sigma": 0.2}, {"parts.plate.kd": 0.5, "parts.plate.sigma": 1.0}),
], ids=["conductor", "diffuse_conductor", "lambert", "oren_nayar"])
def test_values_set_by_key_render_as_the_scene_with_them(tmp_path, material, values):
    """Each model's traverse keys and writes (spacefit/rendering/materials.py: a blend's halves doubled,
    ``reflectance`` as RGB) set what its BSDF dictionary would: the same image as the scene loaded with
    the values (same samples)."""
    view = {"camera": {"position_m": [3.0, 1.0, 9.0], "look_at_m": [0.0, 0.0, 0.0]}, "sun": {"direction": [-0.3, 0.1, -1.0]}}
    scene = small_scene(write_plate_obj(tmp_path / "plate.obj"), material, **view)
    renderer = Renderer(scene)
    before = renderer.render()
    renderer.set_values(values)
    after = renderer.render()
    assert not np.allclose(after, before, rtol=0.01)
    np.testing.assert_allclose(after, sf.render(scene_with_values(scene, values)), rtol=1e-5, atol=1e-7)
