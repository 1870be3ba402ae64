"""The public face: ``import spacefit as sf`` reaches every documented name (the API reference's table) and
leaves JAX's global configuration alone. The docs' Python examples run in tests/test_docs.py."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
import pytest
import xarray as xr
from helpers import small_scene, write_plate_obj

import spacefit as sf

DOCS = Path(__file__).resolve().parents[1] / "docs"


def api_reference_names() -> tuple[set[str], set[str]]:
    """The names in the first column of the API reference's table, and those its autosummary documents."""
    text = (DOCS / "reference" / "api.md").read_text()
    table = set(re.findall(r"^\| `sf\.(\w+)`", text, flags=re.MULTILINE))
    documented = set(re.findall(r"^   (\w+)$", text.split(".. autosummary::", 1)[1], flags=re.MULTILINE))
    return table, documented


def test_all_matches_the_api_reference():
    table, documented = api_reference_names()
    assert set(sf.__all__) == table
    assert set(sf.__all__) == documented
    for name in sf.__all__:
        assert getattr(sf, name) is not None, name


def test_import_leaves_jax_x64_as_it_was():
    """A fresh process: importing spacefit (and rendering) must not switch JAX's 64-bit mode."""
    code = ("import jax; before = jax.config.jax_enable_x64; import spacefit as sf; "
            "assert jax.config.jax_enable_x64 == before, 'import changed jax_enable_x64'; print(before)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "False"


def test_import_leaves_numpy_printing_as_it_was():
    """A fresh process: importing what reads observation files (colour-science sets NumPy's legacy
    printing at import) leaves NumPy's print options, and so every number written with str(), as they
    were: with legacy printing a float64 prints 12 digits, and files written through it lose precision."""
    code = ("import numpy as np; before = np.get_printoptions(); import spacefit as sf; sf.read_image; "
            "assert np.get_printoptions() == before, np.get_printoptions(); print(str(np.float64(1313793.1220847701)))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "1313793.1220847701"


def test_spacefit_gives_the_callers_mitsuba_variant_back(tmp_path):
    """Mitsuba has one global variant: after sf.render, a Renderer's methods and a render function's
    value and gradient, the caller's own variant is set again, and the caller's Mitsuba code runs in it;
    Mitsuba's log level is the caller's too."""
    import mitsuba as mi

    scene = plate_scene(tmp_path, 0.5)
    before = mi.variant()
    log_level = mi.logger().log_level()
    assert log_level != mi.LogLevel.Error
    try:
        for variant in ("scalar_rgb", "llvm_ad_rgb"):
            mi.set_variant(variant)
            image = sf.render(scene)
            assert mi.variant() == variant
            renderer = sf.Renderer(scene)
            renderer.set_values({"parts.plate.kd": 0.25})
            assert renderer.render() == pytest.approx(image / 2, rel=1e-5, abs=1e-7)
            assert renderer.part_image().names == ("plate",)
            assert mi.variant() == variant
            f = sf.render_function(scene, ["parts.plate.kd"])
            assert float(jax.grad(lambda x, f=f: f(x).sum())(jnp.array([0.5]))[0]) > 0
            assert mi.variant() == variant
            assert mi.load_dict({"type": "diffuse"}).variant_name() == variant
            assert mi.logger().log_level() == log_level  # nor Mitsuba's log level
    finally:
        mi.set_variant(before or "llvm_ad_rgb")


def test_variant_scopes_nest_and_overlap_across_threads(monkeypatch):
    """A nested scope of another variant gives its outer scope's back; a scope ending while another
    thread's is open switches nothing; the last one gives the caller's back, also after an error."""
    import threading

    import spacefit.rendering.backend as backend

    mi = backend.mi
    before = mi.variant()
    monkeypatch.setattr(backend, "resolve_variant", lambda requested: requested)  # any built variant, no GPU needed
    try:
        mi.set_variant("scalar_rgb")
        with backend.variant_scope("llvm_ad_rgb"):
            with backend.variant_scope("llvm_ad_mono"):
                assert mi.variant() == "llvm_ad_mono"
            assert mi.variant() == "llvm_ad_rgb"
        assert mi.variant() == "scalar_rgb"
        with pytest.raises(KeyError), backend.variant_scope("llvm_ad_rgb"):
            raise KeyError("inside")
        assert mi.variant() == "scalar_rgb"
        entered, release, seen = threading.Event(), threading.Event(), []

        def worker() -> None:
            with backend.variant_scope("llvm_ad_rgb"):
                entered.set()
                release.wait(60)
                seen.append(mi.variant())

        thread = threading.Thread(target=worker)
        with backend.variant_scope("llvm_ad_rgb"):
            thread.start()
            assert entered.wait(60)
        assert mi.variant() == "llvm_ad_rgb"  # the worker's scope is open: nothing switched
        release.set()
        thread.join()
        assert seen == ["llvm_ad_rgb"] and mi.variant() == "scalar_rgb"
    finally:
        mi.set_variant(before or "llvm_ad_rgb")


def plate_scene(tmp_path: Path, kd: float) -> sf.Scene:
    return small_scene(write_plate_obj(tmp_path / "plate.obj"), {"material": "white_paint", "kd": kd}, render={"spp": 8})


def test_a_render_asks_the_file_system_nothing(tmp_path, monkeypatch):
    """The system libLLVM is looked for once per process: every render's variant scope searched the
    file system for it again (4.5 ms of a 6 ms render of the default view at 1 spp)."""
    import glob

    renderer = sf.Renderer(plate_scene(tmp_path, 0.5))
    renderer.render()
    searches = []
    monkeypatch.setattr(glob, "glob", lambda *args, **kwargs: searches.append(args) or [])
    renderer.render()
    sf.render(renderer.assembly.scene)
    assert searches == []


def test_images_work_with_plain_optimistix_without_casts(tmp_path):
    """Recover a plate's albedo with optimistix directly on sf.render_function, in the caller's
    (default, 32-bit) JAX mode: no dtype casts, and the fit still runs inside spacefit's x64 scope."""
    assert not jax.config.jax_enable_x64
    truth = sf.render(plate_scene(tmp_path, 0.6))
    image = sf.render_function(plate_scene(tmp_path, 0.3), ["parts.plate.kd"])

    def residuals(x, args):
        return image(x) - truth

    solution = optx.least_squares(residuals, optx.LevenbergMarquardt(rtol=1e-4, atol=1e-6), jnp.array([0.3]), max_steps=20)
    assert solution.value.dtype == jnp.float32
    assert float(solution.value[0]) == pytest.approx(0.6, rel=0.02)
    assert not jax.config.jax_enable_x64


def test_jacobian_of_albedo_is_the_image_over_kd(tmp_path):
    """A Lambert image is linear in kd: d(image)/d(kd) = image / kd (independent seeds, so within noise)."""
    scene = plate_scene(tmp_path, 0.4)
    jac = sf.jacobian(scene, ["parts.plate.kd"], spp=64, spp_grad=64)
    column, expected = jac.columns["parts.plate.kd"], jac.image / 0.4
    lit = expected.max(axis=-1) > 0
    assert jac.at == {"parts.plate.kd": pytest.approx(0.4)}
    assert column[lit].mean() == pytest.approx(expected[lit].mean(), rel=0.01)
    assert np.all(column[~lit] == 0)


def test_scene_values_by_python_value():
    scene = sf.default_scene().with_values({"camera.position_m": np.array([0, 0, 50]), "parts.panels.alpha_x": np.float32(0.1),
                                            "render.spp": np.int64(4)})
    assert scene.camera.position_m == (0.0, 0.0, 50.0)
    assert scene.parts["panels"].material.alpha_x == pytest.approx(0.1)
    assert scene.render.spp == 4
    assert sf.load_scene(None, "render.spp=3").render.spp == 3  # one string is one override
    assert sf.load_scene(None, {"render.spp": 5}) == sf.default_scene().with_values({"render.spp": 5})
    with pytest.raises(sf.InputError, match="camera.positon_m"):
        scene.with_values({"camera.positon_m": [0, 0, 1]})


def test_part_image_and_table_match_the_parts_lit_pixels(tmp_path):
    """The part-ID image names the part at each pixel: on a scene of the panels case the lit pixels
    are target pixels, each part's mean is that of its own pixels, and space is -1."""
    scene = sf.load_case("panels").truth_scene.with_values({"render.resolution": [48, 48], "camera.pixel_pitch_mm": 50.0,
                                                           "render.spp": 4})
    renderer = sf.Renderer(scene)
    radiance, parts = renderer.render(), renderer.part_image()
    assert parts.names == ("body", "panels", "legs")
    assert parts.ids.shape == (48, 48)
    assert set(np.unique(parts.ids)) == {-1, 0, 1, 2}
    lit = radiance.max(axis=-1) > 0
    # only pixels on the silhouette, lit through the tent filter's 3 x 3 px footprint, may be lit and see space
    padded = np.pad(parts.ids >= 0, 1)
    near_target = np.any([padded[dy:dy + 48, dx:dx + 48] for dy in range(3) for dx in range(3)], axis=0)
    assert not np.any(lit & ~near_target)
    table = parts.table(radiance)
    grey = radiance.mean(axis=-1)
    assert isinstance(table, xr.Dataset) and list(table.region.values) == ["body", "panels", "legs", "target"]
    assert int(table.pixels.sel(region="legs")) == int((parts.ids == 2).sum())
    assert float(table.mean_radiance.sel(region="legs")) == pytest.approx(float(grey[parts.ids == 2].mean()))
    assert int(table.pixels.sel(region="target")) == int((parts.ids >= 0).sum())
    assert table.mean_radiance.attrs["units"] == "W m^-2 sr^-1" and "units" not in table.pixels.attrs  # no stray "1"
    # counting only some pixels: a NaN outside them (a masked reference) stays out of the means
    used = parts.ids != 2
    masked = parts.table(np.where(used[..., None], radiance, np.nan), used)
    assert int(masked.pixels.sel(region="legs")) == 0 and np.isnan(float(masked.mean_radiance.sel(region="legs")))
    assert float(masked.mean_radiance.sel(region="body")) == pytest.approx(float(table.mean_radiance.sel(region="body")))


def test_set_values_in_place_equals_a_reloaded_scene():
    """Sweeps change values in place: the same image as a scene loaded with those values."""
    base = sf.load_case("panels").truth_scene.with_values({"render.resolution": [32, 32], "camera.pixel_pitch_mm": 75.0,
                                                          "render.spp": 4})
    changed = {"parts.panels.alpha_x": 0.3, "parts.legs.kd": 0.7, "sun.elevation_deg": 60.0, "sun.azimuth_deg": -100.0}
    renderer = sf.Renderer(base)
    renderer.set_values(changed)
    reloaded = base.with_values({"parts.panels.alpha_x": 0.3, "parts.legs.kd": 0.7,
                                 "sun.direction": list(np.asarray(travel_direction(60.0, -100.0)))})
    assert np.allclose(renderer.render(), sf.render(reloaded), rtol=1e-5, atol=1e-7)
    with pytest.raises(sf.InputError, match="parts.panels.alpha_q"):
        renderer.set_values({"parts.panels.alpha_q": 0.1})


def travel_direction(elevation_deg: float, azimuth_deg: float) -> np.ndarray:
    el, az = np.radians(elevation_deg), np.radians(azimuth_deg)
    return -np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])



def test_a_former_name_warns_and_gives_its_replacement():
    """sf.TableFit, the table fits' result type before they became sf.fit's, is sf.FitResult, with a DeprecationWarning."""
    with pytest.warns(DeprecationWarning, match="sf.TableFit is deprecated"):
        assert sf.TableFit is sf.FitResult
    assert "TableFit" not in sf.__all__
