"""Parts built from primitives (box, plate, cylinder) in a scene file's part tables: radiance against
closed forms, silhouettes against their areas, and the errors naming key, value and range."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

import spacefit as sf
from spacefit.geometry.frames import attitude_matrix
from spacefit.scene.toml import scene_from_dict

E = 5.0
FOOTPRINT_M = 0.05  # pixel footprint at the target: pitch (mm) x distance / focal length (mm)
DISTANCE_M = 1000.0  # far: perspective changes a 3 m deep box's silhouette by < 0.2 %


def scene(parts: dict[str, Any], **sections: dict[str, Any]) -> sf.Scene:
    """A scene of primitive parts only (``target.mesh = "none"``), seen from +z, lit along the view."""
    data: dict[str, Any] = {
        "render": {"resolution": [128, 128], "spp": 1, "depth": 1, "seed": 3, "filter": "box"},
        "camera": {"position_m": [0.0, 0.0, DISTANCE_M], "look_at_m": [0.0, 0.0, 0.0], "focal_length_mm": 1000.0,
                   "pixel_pitch_mm": FOOTPRINT_M},
        "sun": {"irradiance_w_m2": E, "direction": [0.0, 0.0, -1.0]},
        "target": {"attitude_deg": [0.0, 0.0, 0.0], "mesh": "none"},
        "wrinkles": {"enabled": False},
        "parts": parts,
    }
    for key, value in sections.items():
        data[key] = {**data[key], **value}
    return scene_from_dict(data)


def silhouette_m2(image: np.ndarray) -> float:
    """Pixels that any sample hit, times the footprint: with a box filter and 1 sample per pixel a pixel
    is hit with probability its covered fraction, so the count estimates the area without bias."""
    return float(np.count_nonzero(image.max(axis=-1) > 0)) * FOOTPRINT_M**2


@pytest.mark.parametrize("theta_deg", [0.0, 50.0])
def test_lambert_plate_is_kd_E_cos_over_pi(theta_deg):
    kd, th = 0.5, np.radians(theta_deg)
    plate = {"plate": {"material": "white_paint", "kd": kd, "shape": "plate", "size_m": [10.0, 10.0]}}
    image = sf.render(scene(plate, render={"resolution": [32, 32], "spp": 16, "filter": "tent"},
                            sun={"direction": [np.sin(th), 0.0, -np.cos(th)]}))
    assert np.mean(image[4:-4, 4:-4]) == pytest.approx(kd * E * np.cos(th) / np.pi, rel=0.01)


@pytest.mark.parametrize("attitude_deg", [(0.0, 0.0, 0.0), (30.0, 40.0, 10.0)])
def test_box_silhouette_is_its_projected_area(attitude_deg):
    """A box's silhouette along d (part frame) is |d_x| s_y s_z + |d_y| s_x s_z + |d_z| s_x s_y."""
    size = np.array([1.0, 2.0, 3.0])
    box = {"bus": {"material": "white_paint", "shape": "box", "size_m": size.tolist(), "attitude_deg": list(attitude_deg)}}
    d = attitude_matrix(np.radians(attitude_deg)).T @ [0.0, 0.0, 1.0]  # the view direction in the part's frame
    expected = np.abs(d) @ [size[1] * size[2], size[0] * size[2], size[0] * size[1]]
    assert silhouette_m2(sf.render(scene(box))) == pytest.approx(expected, rel=0.02)


def test_cylinder_side_on_silhouette_is_2_r_length():
    cylinder = {"boom": {"material": "white_paint", "shape": "cylinder", "radius_m": 0.8, "length_m": 4.0,
                         "attitude_deg": [90.0, 0.0, 0.0]}}
    assert silhouette_m2(sf.render(scene(cylinder))) == pytest.approx(2 * 0.8 * 4.0, rel=0.02)


def test_primitive_round_trips_and_takes_new_values():
    parts = {"wing": {"material": "white_paint", "shape": "plate", "size_m": [2.0, 1.0], "position_m": [1.5, 0.0, 0.0]}}
    one = scene(parts)
    assert scene_from_dict(one.to_dict()) == one
    wider = one.with_values({"parts.wing.size_m": [3.0, 1.0]})
    assert wider.parts["wing"].shape.size_m == (3.0, 1.0) and wider.parts["wing"].shape.position_m == (1.5, 0.0, 0.0)


@pytest.mark.parametrize(("table", "message"), [
    ({"shape": "box", "size_m": [1.0, 0.0, 1.0]}, r"`parts.p.size_m \(y\)` must be in \(0, inf\] m, got 0"),
    ({"shape": "plate", "size_m": [1.0, -2.0]}, r"`parts.p.size_m \(y\)` must be in \(0, inf\] m, got -2"),
    ({"shape": "cylinder", "radius_m": -1.0, "length_m": 1.0}, r"`parts.p.radius_m` must be in \(0, inf\] m, got -1"),
    ({"shape": "sphere", "size_m": [1.0]}, r"`parts.p.shape` must be one of 'box', 'cylinder', 'plate'; got 'sphere'"),
    ({"shape": "box", "size_m": [1.0, 1.0, 1.0], "file": "p.obj"}, r"a `file` or a `shape`, not both"),
    ({"shape": "box"}, r"`parts.p.size_m` must be 3 lengths .*\(missing\)"),
    ({"shape": "plate", "size_m": [1.0, 1.0, 1.0]}, r"`parts.p.size_m` must be 2 lengths"),
    ({"shape": "cylinder", "radius_m": 1.0}, r"`parts.p.length_m` is missing"),
    ({"shape": "cylinder", "radius_m": 1.0, "length_m": 1.0, "size_m": [1.0]}, r"`parts.p.size_m` is not a size of a cylinder"),
    ({"size_m": [1.0, 1.0]}, r"`parts.p.shape` is missing"),
])
def test_errors_name_key_value_and_range(table, message):
    with pytest.raises(sf.InputError, match=message):
        scene({"p": {"material": "white_paint", **table}})


def test_no_mesh_part_without_shape_or_file():
    with pytest.raises(sf.InputError, match=r"'p' have no `file` and no `shape`.*the scene's parts: p"):
        sf.render(scene({"p": {"material": "white_paint"}}))


@pytest.mark.parametrize("name", ["box-wing", "starlink-v1p5"])
def test_shipped_primitive_scenes_render_every_part(name):
    """Each part is seen and lit: making it white (Lambert kd 0.9) changes the image."""
    one = sf.load_scene(Path(__file__).resolve().parents[1] / "data" / "scenes" / f"{name}.toml")
    image = sf.render(one)
    assert np.count_nonzero(image.max(axis=-1) > 0) > 0
    for part in one.parts:
        white = sf.render(one.with_values({f"parts.{part}.material": "lambert", f"parts.{part}.kd": 0.9}))
        assert np.abs(white - image).sum() > 0.01 * image.sum(), part
