"""The main job end to end: reproducible renders, the output folder, and bad input before rendering."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest
from helpers import small_scene, write_plate_obj

from spacefit.cli import main
from spacefit.errors import InputError
from spacefit.rendering.renderer import Renderer
from spacefit.rendering.exr import read_exr
from spacefit.scene.assembly import assemble
from spacefit.scene.toml import load_scene

# A CI-sized version of the thesis's scene: same optics scaled to 64 px, coarse wrinkles, rendered as
# geometry (at 37.5 cm per pixel "auto" would take the default wrinkles' effective roughness).
SMALL = ["render.resolution=[64, 64]", "camera.pixel_pitch_mm=37.5", "render.spp=4", "wrinkles.spacing_m=0.15",
         "wrinkles.model='geometry'"]


@pytest.fixture(scope="module")
def small_renderer():
    return Renderer(assemble(load_scene(None, SMALL)))


def test_same_seed_same_image_other_seed_other_noise(small_renderer):
    a = small_renderer.render(seed=3)
    b = small_renderer.render(seed=3)
    c = small_renderer.render(seed=4)
    assert np.array_equal(a, b)
    assert not np.array_equal(a, c)
    assert a.shape == (64, 64, 3) and a.dtype == np.float32 and np.all(np.isfinite(a))
    assert a.max() > 0.0


def test_a_deterministic_render_is_the_render_wholly_on_one_thread_bit_for_bit(small_renderer, monkeypatch):
    """It traces its samples on all of Dr.Jit's threads and adds them into the film on one, in their order: the
    image of a render whose every kernel runs on one thread, over several passes and samplers."""
    from spacefit.rendering import sample_passes
    from spacefit.rendering.backend import dr

    monkeypatch.setattr(sample_passes, "MAX_SAMPLES_PER_PASS", 64 * 16)  # several passes
    threads = dr.thread_count()
    dr.set_thread_count(max(threads, 2))
    try:
        for scene in (small_renderer, Renderer(assemble(load_scene(None, SMALL + ["render.sampler='independent'"])))):
            spread = scene.render(seed=5, spp=16)
            with sample_passes.render_threads(True):
                assert dr.thread_count() == 1
                whole = scene.render(seed=5, spp=16)
            assert np.array_equal(spread, whole) and spread.max() > 0
    finally:
        dr.set_thread_count(threads)


def test_parallel_renders_agree_to_float_rounding():
    fast = Renderer(assemble(load_scene(None, SMALL + ["render.deterministic=false"])))
    a, b = fast.render(seed=3), fast.render(seed=3)
    assert np.allclose(a, b, rtol=1e-5, atol=1e-6 * a.max())


def test_cli_render_writes_the_folder_and_rerenders_identically(tmp_path):
    out = tmp_path / "run"
    args = ["render", "--out", str(out), "--quiet"] + [a for s in SMALL for a in ("--set", s)]
    assert main(args) == 0
    assert sorted(os.listdir(out)) == ["preview.png", "radiance.exr", "render.json", "scene.toml"]
    image = read_exr(out / "radiance.exr")
    sidecar = json.loads((out / "render.json").read_text())
    assert sidecar["seed"] == 0 and sidecar["scene"]["render"]["resolution"] == [64, 64]
    assert sidecar["versions"]["mitsuba"] and sidecar["triangles"]["body"] > 12
    table = sidecar["parts"]["table"]  # each part, then the whole target: pixels and mean radiance
    assert set(table) == {"body", "panels", "legs", "target"} and table["target"]["pixels"] == sum(
        table[p]["pixels"] for p in ("body", "panels", "legs")) > 0
    assert table["target"]["mean_radiance_w_m2_sr"] > 0
    again = tmp_path / "again"
    assert main(["render", str(out / "scene.toml"), "--out", str(again), "--quiet"]) == 0
    assert np.array_equal(read_exr(again / "radiance.exr"), image)


def test_export_wrinkled_body_stl(tmp_path):
    out = tmp_path / "body.stl"
    assert main(["export-stl", "--out", str(out), "--set", "wrinkles.spacing_m=0.2"]) == 0
    import trimesh

    body = trimesh.load(out)
    assert body.is_watertight and len(body.faces) > 12


def test_scene_command_writes_loadable_defaults(tmp_path):
    path = tmp_path / "scene.toml"
    assert main(["scene", "--out", str(path), "--set", "render.spp=8"]) == 0
    scene = load_scene(path)
    assert scene.render.spp == 8 and scene == load_scene(None, ["render.spp=8"])


def test_export_unknown_part(tmp_path, capsys):
    assert main(["export-stl", "--part", "antenna", "--out", str(tmp_path / "a.stl")]) == 2
    assert "body" in capsys.readouterr().err and not (tmp_path / "a.stl").exists()


@pytest.mark.parametrize(
    ("overrides", "message"),
    [
        (["camera.position_m=[0, 0, 0.1]"], "inside the target"),
        (["camera.attitude_deg=[180, 0, 0]"], "looks away"),
        (["camera.attitude_deg=[0, 60, 0]"], "field of view"),
        (["target.mesh='missing.obj'", "parts.body.material='mli_gold'"], "does not exist"),
        (["target.mesh='missing.obj'"], "`parts` must list the parts"),
        (["wrinkles.D=3.5"], "wrinkles.D"),
        (["render.resolution=[0, 10]"], "render.resolution"),
    ],
)
def test_bad_input_fails_before_rendering_and_leaves_nothing(tmp_path, capsys, overrides, message):
    out = tmp_path / "run"
    args = ["render", "--out", str(out), "--quiet"] + [a for s in SMALL + overrides for a in ("--set", s)]
    assert main(args) == 2
    assert message in capsys.readouterr().err
    assert not out.exists()


def test_unwritable_output_folder(capsys):
    # /proc refuses new files even to root, unlike permission bits
    assert main(["render", "--out", "/proc/spacefit-test/run", "--quiet"] + [a for s in SMALL for a in ("--set", s)]) == 2
    assert "not writable" in capsys.readouterr().err


def test_output_path_that_is_a_file(tmp_path, capsys):
    f = tmp_path / "file"
    f.write_text("x")
    assert main(["render", "--out", str(f), "--quiet"] + [a for s in SMALL for a in ("--set", s)]) == 2
    assert "not a folder" in capsys.readouterr().err
    assert f.read_text() == "x"


def test_error_inside_writing_removes_partial_output(tmp_path, monkeypatch):
    import spacefit.render_job as render_job

    def broken(path, image):
        raise OSError("disk full")

    monkeypatch.setattr(render_job, "write_exr", broken)
    out = tmp_path / "run"
    with pytest.raises(OSError):
        render_job.render_to_folder(load_scene(None, SMALL), out, quiet=True)
    assert not out.exists()


def test_a_failed_preview_leaves_nothing_though_the_exr_was_written_meanwhile(tmp_path, monkeypatch):
    """The EXR is written in a thread while the preview is encoded: an error in the preview waits for it, then
    removes the whole stage, and names the file."""
    import errno

    import spacefit.render_job as render_job

    def full(path, rgb8):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(path))

    monkeypatch.setattr(render_job, "write_png", full)
    out = tmp_path / "run"
    assert main(["render", "--out", str(out), "--quiet"] + [a for s in SMALL for a in ("--set", s)]) == 1
    assert not out.exists() and list(tmp_path.iterdir()) == []


def test_the_preview_encodes_every_pixel_as_the_whole_image_formula_does():
    """preview.png's tone map computes only the lit values (a target in black space): it must equal the formula
    applied to every value (clip, sRGB, round), for dark, negative, over-exposed and NaN-free images of any scale."""
    from spacefit.output import preview_scale, srgb_encode, to_srgb8

    rng = np.random.default_rng(3)
    for shape in [(64, 64, 3), (300, 7, 3), (1, 1, 3), (520, 3, 4)]:
        image = (rng.random(shape) * 3.0).astype(np.float32)
        image[rng.random(shape) < 0.6] = 0.0
        image[rng.random(shape) < 0.05] *= -1.0
        for scale in (preview_scale(image), 0.25, 40.0, -1.5):
            whole = np.round(srgb_encode(np.clip(image * scale, 0.0, 1.0)) * 255.0).astype(np.uint8)
            np.testing.assert_array_equal(to_srgb8(image, scale), whole)
        peak = image.max(axis=-1)
        lit = peak[peak > 0]
        assert preview_scale(image) == (1.0 / float(np.percentile(lit, 99.5)) if lit.size else 1.0)
    assert preview_scale(np.zeros((4, 4, 3), np.float32)) == 1.0


def test_the_render_folder_holds_what_the_writers_write_one_by_one(tmp_path):
    """write_render (the EXR in a thread, the preview's lit values only) against the plain writers called in turn
    on the whole-image tone map: the same four files, byte for byte."""
    from spacefit.output import PREVIEW_PERCENTILE, srgb_encode, write_json, write_render
    from spacefit.rendering.exr import write_exr
    from spacefit.rendering.png import write_png

    rng = np.random.default_rng(8)
    radiance = (rng.random((40, 56, 3)) * 5.0).astype(np.float32)
    radiance[rng.random((40, 56)) < 0.8] = 0.0
    sidecar = {"seed": 3, "versions": {"spacefit": "test"}}
    written = write_render(tmp_path / "folder", radiance, "[render]\nspp = 4\n", lambda: sidecar, write_exr, write_png)
    peak = radiance.max(axis=-1)
    scale = 1.0 / float(np.percentile(peak[peak > 0], PREVIEW_PERCENTILE))
    plain = tmp_path / "plain"
    plain.mkdir()
    write_exr(plain / "radiance.exr", radiance)
    write_png(plain / "preview.png", np.round(srgb_encode(np.clip(radiance * scale, 0.0, 1.0)) * 255.0).astype(np.uint8))
    (plain / "scene.toml").write_text("[render]\nspp = 4\n")
    write_json(plain / "render.json", {**sidecar, "preview": {"scale_sr_m2_per_W": scale, "percentile": PREVIEW_PERCENTILE,
                                                             "encoding": "sRGB IEC 61966-2-1"}})
    assert written == json.loads((plain / "render.json").read_text())
    names = ["preview.png", "radiance.exr", "render.json", "scene.toml"]
    assert sorted(os.listdir(tmp_path / "folder")) == names
    for name in names:
        assert (tmp_path / "folder" / name).read_bytes() == (plain / name).read_bytes(), name


def test_nan_override_is_rejected():
    with pytest.raises(InputError, match="finite"):
        load_scene(None, ["target.position_m=[0, nan, 0]"])


def test_render_crops_to_the_target_and_loses_no_light():
    """Only the window around the target's projected box is rendered; the whole film is black outside
    it. Matte parts, so that the totals compare without glint noise."""
    matte = ["parts.body.material='white_paint'", "parts.panels.material='white_paint'", "render.spp=256"]
    assembly = assemble(load_scene(None, SMALL + matte))
    cropped, full = Renderer(assembly), Renderer(assembly, crop=False)
    x0, y0, w, h = cropped.window
    assert full.window == (0, 0, 64, 64) and w * h < 0.5 * 64 * 64
    a, b = cropped.render(seed=1), full.render(seed=1)
    outside = np.ones((64, 64), dtype=bool)
    outside[y0:y0 + h, x0:x0 + w] = False
    assert a.shape == b.shape == (64, 64, 3)
    assert not a[outside].any() and not b[outside].any()
    assert a.sum() == pytest.approx(b.sum(), rel=0.01)


def test_part_image_of_the_window_equals_the_whole_films():
    """The part IDs come from one ray per pixel centre, whether the renderer traces a window or the film."""
    scene = load_scene(None, {"render.resolution": [128, 128], "camera.pixel_pitch_mm": 18.75, "render.spp": 1})
    windowed, film = Renderer(scene), Renderer(scene, crop=False)
    assert windowed.window[2] * windowed.window[3] < 0.2 * 128 * 128
    ids, expected = windowed.part_image().ids, film.part_image().ids
    assert set(np.unique(expected)) == {-1, 0, 1, 2}
    assert np.mean(ids == expected) > 0.999, np.mean(ids == expected)


def test_a_renders_pass_seeds_are_not_another_seeds():
    """Pass i of seed s is not pass 0 of seed s + i: renders of neighbouring seeds share no pass."""
    from spacefit.rendering.sample_passes import pass_seed

    for seed in (0, 1, 7, 1000):
        assert pass_seed(seed, 0) == seed
        assert {pass_seed(seed, i) for i in range(1, 8)}.isdisjoint({pass_seed(seed + i, 0) for i in range(1, 8)})


def test_a_target_no_pixel_sees_renders_black(tmp_path):
    """A plate just past the view's edge passes the view's check (its bounds reach into the view) but no pixel's
    samples reach its silhouette: the render is black, not Dr.Jit's error on an empty wavefront (found by
    test_fuzz_long's scene values)."""
    scene = small_scene(write_plate_obj(tmp_path / "plate.obj"), {"material": "white_paint", "kd": 0.5},
                        render={"resolution": [8, 8], "spp": 1})
    aside = scene.with_values({"camera.focal_length_mm": 25.0, "camera.look_at_m": [0.0, -1.0, 1.0],
                               "target.attitude_deg": [0.0, 0.0, 2.0]})
    renderer = Renderer(aside)
    assert not renderer.traced.any()
    image = renderer.render()
    assert image.shape == (8, 8, 3) and np.all(image == 0)
