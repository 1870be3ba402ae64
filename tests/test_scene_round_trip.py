"""A scene's TOML text is the scene: ``scene_from_dict(tomllib.loads(scene.to_toml()))`` equals it, parts
in their order, for every shipped scene and for scenes changed in Python (the built-in lander with
parts removed, other materials, primitives, tabulated materials), and a sweep, whose workers
receive that text, gives each region the numbers of a direct render of the scene."""

from __future__ import annotations

import dataclasses
import re
import tomllib
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, reject, settings
from hypothesis import strategies as st

from helpers import write_sphere_obj

import spacefit as sf
from spacefit.geometry.articulation import AxisAngle, Fixed
from spacefit.geometry.primitives import Primitive
from spacefit.materials import PRESETS, Conductor, Lambert, TabulatedBRDF
from spacefit.materials.measured import read_brdf_table
from spacefit.scene.parameters import parameter, scene_value, scene_with_values
from spacefit.scene.target import DEFAULT_PRESETS, PartSettings, TargetSettings
from spacefit.scene.toml import load_scene, scene_from_dict
from spacefit.studies import worker
from spacefit.studies.worker import Task

ROOT = Path(__file__).resolve().parents[1]
CHASSIS = ROOT / "data" / "starlink-v1p5" / "chassis_brdf.csv"
LANDER = tuple(DEFAULT_PRESETS)


def through_toml(scene: sf.Scene) -> sf.Scene:
    """The scene a sweep's worker reads from the scene's TOML text."""
    return scene_from_dict(tomllib.loads(scene.to_toml()))


def assert_same(scene: sf.Scene) -> None:
    back = through_toml(scene)
    assert back == scene
    assert list(back.parts) == list(scene.parts)  # the regions' order of a sweep's store and of its workers


def lander(parts: dict[str, PartSettings], **sections: object) -> sf.Scene:
    s = sf.default_scene()
    return dataclasses.replace(s, parts=parts, wrinkles=dataclasses.replace(s.wrinkles, enabled=False), **sections)


@pytest.mark.parametrize("path", sorted((ROOT / "data" / "scenes").glob("*.toml")), ids=lambda p: p.stem)
def test_shipped_scene_files_round_trip(path, tmp_path):
    scene = load_scene(path)
    assert_same(scene)
    (tmp_path / "scene.toml").write_text(scene.to_toml())
    assert load_scene(tmp_path / "scene.toml") == scene


@pytest.mark.parametrize("name", sf.case_names())
def test_default_scene_and_synthetic_cases_round_trip(name):
    assert_same(sf.default_scene())
    assert_same(sf.load_case(name).truth_scene)


def test_a_lander_without_a_part_is_written_as_such():
    s = sf.default_scene()
    scene = lander({"panels": s.parts["panels"], "legs": s.parts["legs"]})
    assert 'body = false' in scene.to_toml()
    back = through_toml(scene)
    assert list(back.parts) == ["panels", "legs"] and back == scene
    cell = "<td style='text-align:left'>{}</td>"
    assert "".join(map(cell.format, ("parts", "body", "False"))) in scene._repr_html_()  # the notebook's table says so too


def test_removing_a_part_in_a_file_names_the_lander_parts():
    assert list(scene_from_dict({"wrinkles": {"enabled": False}, "parts": {"body": False}}).parts) == ["panels", "legs"]
    with pytest.raises(sf.InputError, match=r"^`parts.wing = false` removes a part of the built-in lander \(body, panels, legs\); 'wing' is not one\.$"):
        scene_from_dict({"parts": {"wing": False}})
    box = {"material": "white_paint", "shape": "box", "size_m": [1.0, 1.0, 1.0]}
    with pytest.raises(sf.InputError, match=r"'body' is not one \(`target.mesh` is not \"builtin\"\)\.$"):
        scene_from_dict({"target": {"mesh": "none"}, "parts": {"box": box, "body": False}})
    with pytest.raises(sf.InputError, match="`parts` must name at least one part"):
        scene_from_dict({"wrinkles": {"enabled": False}, "parts": dict.fromkeys(LANDER, False)})


def test_the_lander_parts_are_held_in_the_order_a_file_reads_them():
    s = sf.default_scene()
    box = PartSettings(Lambert(0.3), shape=Primitive("box", (1.0, 1.0, 1.0), position_m=(0.0, 0.0, 2.0)))
    scene = lander({"box": box, "legs": s.parts["legs"], "body": s.parts["body"]})
    assert list(scene.parts) == ["body", "legs", "box"]
    assert_same(scene)


def test_relative_files_are_the_same_files_wherever_the_text_is_read(tmp_path, monkeypatch):
    (tmp_path / "tables").mkdir()
    (tmp_path / "tables" / "chassis.csv").write_text(CHASSIS.read_text())
    write_sphere_obj(tmp_path / "ball.obj", subdivisions=1)
    (tmp_path / "q.csv").write_text("time_utc,qw,qx,qy,qz\n2024-03-01T04:00:00,1,0,0,0\n2024-03-01T04:01:00,0.6,0,0.8,0\n")
    monkeypatch.chdir(tmp_path)
    s = sf.default_scene()
    scene = lander({"body": s.parts["body"], "ball": PartSettings(TabulatedBRDF(source="tables/chassis.csv", scale=2.0), file="ball.obj")},
                   target=TargetSettings(attitude="table", quaternions="q.csv", time_utc="2024-03-01T04:00:30"))
    ball = scene.parts["ball"]
    assert ball.file == str(tmp_path / "ball.obj") and ball.material.source == str(tmp_path / "tables" / "chassis.csv")
    assert scene.target.quaternions == str(tmp_path / "q.csv")
    (tmp_path / "elsewhere").mkdir()
    (tmp_path / "elsewhere" / "scene.toml").write_text(scene.to_toml())
    back = load_scene(tmp_path / "elsewhere" / "scene.toml")
    assert back == scene and back.mesh_files() == [str(tmp_path / "ball.obj")]


def test_tables_differ_by_source_scale_and_values_and_one_a_file_cannot_state_is_refused():
    table = TabulatedBRDF(source=str(CHASSIS))
    assert table == TabulatedBRDF(source=str(CHASSIS)) != TabulatedBRDF(source=str(CHASSIS), scale=2.0)
    assert table != TabulatedBRDF(source=str(CHASSIS.with_name("solar_array_brdf.csv")))
    floored = TabulatedBRDF.from_table(read_brdf_table(CHASSIS, floor=0.5))
    assert (floored.source, floored.scale) == (table.source, table.scale) and floored != table
    s = sf.default_scene()
    scene = lander({**s.parts, "body": PartSettings(floored)})
    with pytest.raises(sf.InputError, match=rf"^`parts.body` cannot be written to a scene file, which states its source = '{re.escape(str(CHASSIS))}', "
                                            r"scale = 1.0: these give another table \(a table read with a floor"):
        scene.to_toml()
    made = TabulatedBRDF(table.incidence_rad, table.offset, table.log_value, "a table made in Python")
    with pytest.raises(sf.InputError, match=r"^`parts.body` cannot be written .*: these cannot be read \(.*no BRDF table file 'a table made in Python'"):
        lander({**s.parts, "body": PartSettings(made)}).to_toml()


materials = st.one_of(
    st.sampled_from(sorted(PRESETS)).map(lambda name: PRESETS[name]),
    st.floats(0.0, 1.0).map(Lambert),
    st.tuples(st.floats(0.1, 5.0), st.floats(0.0, 5.0), st.floats(1e-3, 1.0), st.floats(1e-3, 1.0)).map(lambda a: Conductor(*a)),
    st.floats(0.1, 10.0).map(lambda scale: TabulatedBRDF(source=str(CHASSIS), scale=scale)),
)
turns = st.one_of(st.just(Fixed()), st.tuples(st.floats(-360.0, 360.0), st.floats(-2.0, 2.0)).map(
    lambda a: AxisAngle((0.0, 1.0, 0.0), a[0], (0.0, a[1], 0.0))))
shapes = st.one_of(
    st.tuples(st.floats(0.1, 3.0), st.floats(0.1, 3.0), st.floats(0.1, 3.0)).map(lambda size: Primitive("box", size)),
    st.tuples(st.floats(0.1, 3.0), st.floats(0.1, 3.0)).map(lambda size: Primitive("cylinder", radius_m=size[0], length_m=size[1])),
)


@settings(max_examples=40, deadline=None, database=None)
@given(st.permutations(LANDER), st.integers(0, 3), st.lists(materials, min_size=5, max_size=5), st.lists(st.tuples(shapes, turns), max_size=2),
       st.sampled_from(["builtin", "", "none"]), st.floats(1.0, 20.0), st.integers(0, 2**31 - 1))
def test_scenes_changed_in_python_round_trip(order, removed, mats, own, mesh, elevation_deg, seed):
    """Lander parts removed and reordered, materials replaced, primitives added (turned or not), on
    the lander or without a mesh; values set by name on top."""
    kept = order[removed:] if mesh != "none" else ()
    parts = {name: PartSettings(m) for name, m in zip(kept, mats)}
    parts |= {f"own{i}": PartSettings(mats[-1 - i], shape=shape, articulation=turn) for i, (shape, turn) in enumerate(own)}
    if not parts:
        parts = {"plate": PartSettings(mats[0], shape=Primitive("plate", (1.0, 2.0)))}
    scene = lander(parts, target=TargetSettings(mesh=mesh))
    assert_same(scene.with_values({"sun.elevation_deg": elevation_deg, "render.seed": seed}))


SCENES = {"default": sf.default_scene(), **{p.stem: load_scene(p) for p in sorted((ROOT / "data" / "scenes").glob("*.toml"))}}


@settings(max_examples=40, deadline=None, database=None)
@given(st.sampled_from(sorted(SCENES)), st.data())
def test_registered_values_set_in_python_round_trip(name, data):
    """Any registered parameters of a shipped scene (materials, sun, pose, wrinkles) set in Python,
    each within its bounds near its value, survive the TOML text."""
    scene = SCENES[name]
    values = {}
    for key in data.draw(st.lists(st.sampled_from(sf.available_parameters(scene)), min_size=1, max_size=4, unique=True)):
        bounds, start = parameter(key).bounds, scene_value(scene, key)
        near = st.floats(max(bounds.lo, start - 1.0 - abs(start)), min(bounds.hi, start + 1.0 + abs(start)))
        values[key] = data.draw(near.filter(bounds.contains), label=key)
    try:
        changed = scene_with_values(scene, values)
    except sf.InputError:  # values that join to a scene refused as a whole (a camera that misses the target...)
        reject()
    assert_same(changed)


def small_lander() -> sf.Scene:
    """The lander from above without its body: its panels and legs, 32 x 32 px."""
    s = sf.default_scene()
    return lander({"panels": s.parts["panels"], "legs": s.parts["legs"]},
                  render=dataclasses.replace(s.render, resolution=(32, 32), spp=4),
                  camera=dataclasses.replace(s.camera, fov_deg=7.0),
                  target=dataclasses.replace(s.target, attitude_deg=(0.0, 0.0, 0.0)))


def test_a_sweep_of_a_lander_without_a_part_gives_a_direct_render_s_numbers():
    scene = small_lander()
    ds = sf.sweep(scene, {"render.seed": [3]}, images=True, quiet=True).load()
    assert list(ds.region.values) == ["panels", "legs", "target"]
    point = scene.with_values({"render.seed": 3})
    renderer = sf.Renderer(point)
    image = renderer.render()
    np.testing.assert_allclose(ds.radiance.sel({"render.seed": 3}).values, image, rtol=1e-5, atol=1e-7)
    pixels, means = renderer.part_image().means(image)
    assert pixels[0] > 0 and pixels[1] > 0 and pixels[2] == pixels[0] + pixels[1]  # no body in view
    np.testing.assert_array_equal(ds.pixels.sel({"render.seed": 3}).values, pixels)
    np.testing.assert_allclose(ds.mean_radiance.sel({"render.seed": 3}).values, means, rtol=1e-6)


def test_a_render_of_other_regions_than_the_sweep_s_is_refused():
    scene = small_lander()
    with pytest.raises(sf.InputError, match=r"^the rendered scene's regions \(panels, legs, target\) are not the sweep's "
                                            r"\(body, panels, legs, target\)"):
        worker.run_task(Task(scene.to_toml(), ("body", "panels", "legs", "target")))
