"""The start-up savings: the disk cache of meshes, imports on first use, and the render's timings."""

from __future__ import annotations

import dataclasses
import json
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest

import spacefit as sf
from spacefit import cli
from spacefit.geometry import cache
from spacefit.output import srgb_decode, srgb_encode
from spacefit.scene import assembly as assembly_module
from spacefit.scene.assembly import assemble

# A wrinkled default scene small enough to refine in well under a second, rendered as geometry (at
# 37.5 cm per pixel "auto" would take the default wrinkles' effective roughness and refine nothing).
SMALL = {"wrinkles.spacing_m": 0.1, "render.resolution": [64, 64], "camera.pixel_pitch_mm": 37.5, "render.spp": 4,
         "wrinkles.model": "geometry"}
ROOT = Path(__file__).resolve().parents[1]


def _fresh(monkeypatch: pytest.MonkeyPatch, where: str | Path) -> sf.Scene:
    """Point the cache at ``where`` and forget the in-memory refinements, so the disk is consulted."""
    monkeypatch.setenv(cache.ENV, str(where))
    assembly_module._refinement.cache_clear()
    assembly_module._refined_faces.cache_clear()
    return sf.load_scene(None, SMALL)


def _assert_same(a, b) -> None:
    for name in a.parts:
        np.testing.assert_array_equal(a.scene_vertices[name], b.scene_vertices[name])
        np.testing.assert_array_equal(a.faces(name), b.faces(name))
    for name, ref in a.refinements.items():
        for field, value in dataclasses.asdict(ref).items():
            got = getattr(b.refinements[name], field)
            assert got.dtype == value.dtype, field
            np.testing.assert_array_equal(got, value)


def test_cached_meshes_equal_a_fresh_refinement(monkeypatch, tmp_path):
    fresh = assemble(_fresh(monkeypatch, cache.DISABLED))
    assert set(fresh.cache.values()) == {"off"}
    first = assemble(_fresh(monkeypatch, tmp_path))
    assert first.cache == {"lander": "miss", "body.refinement": "miss", "body.displaced": "miss", "body.faces": "miss"}
    second = assemble(_fresh(monkeypatch, tmp_path))
    # displaced vertices and their triangles cached: the refinement itself is read only when asked for
    assert second.cache == {"lander": "hit", "body.displaced": "hit", "body.faces": "hit"}
    _assert_same(fresh, first)
    _assert_same(fresh, second)
    for name, part in fresh.parts.items():
        np.testing.assert_array_equal(part.vertices, second.parts[name].vertices)
        assert (part.uv is None) == (second.parts[name].uv is None)
    # another height scale is another entry; the refinement is shared
    other = assemble(_fresh(monkeypatch, tmp_path).with_values({"wrinkles.G": 0.02}))
    assert other.cache["body.refinement"] == "hit" and other.cache["body.displaced"] == "miss"


@pytest.mark.parametrize("damage", ["truncate", "garbage", "tampered array"])
def test_a_damaged_entry_is_rebuilt_not_trusted(monkeypatch, tmp_path, damage):
    fresh = assemble(_fresh(monkeypatch, cache.DISABLED))
    assemble(_fresh(monkeypatch, tmp_path))
    entry = next(tmp_path.glob("displaced-*.npz"))
    if damage == "truncate":
        entry.write_bytes(entry.read_bytes()[: entry.stat().st_size // 2])
    elif damage == "garbage":
        entry.write_bytes(b"not a cache entry")
    else:  # a readable file whose array no longer matches its checksum
        with np.load(entry) as data:
            arrays = {k: data[k] for k in data.files}
        arrays["vertices"] = arrays["vertices"] + np.float32(1e-3)
        np.savez(entry, **arrays)
    rebuilt = assemble(_fresh(monkeypatch, tmp_path))
    assert rebuilt.cache["body.displaced"] == "miss"
    _assert_same(fresh, rebuilt)
    assert assemble(_fresh(monkeypatch, tmp_path)).cache["body.displaced"] == "hit"


def test_off_disables_the_cache_and_an_unwritable_folder_costs_only_time(monkeypatch, tmp_path):
    monkeypatch.setenv(cache.ENV, "off")
    assert cache.cache_dir() is None
    blocked = tmp_path / "file"
    blocked.write_text("a file where the cache folder would be")
    built = assemble(_fresh(monkeypatch, blocked / "cache"))
    assert set(built.cache.values()) == {"miss"}
    monkeypatch.delenv(cache.ENV)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert cache.cache_dir() == tmp_path / "xdg" / "spacefit"


def test_keys_change_with_every_input_and_concurrent_writers_leave_a_whole_entry(tmp_path):
    base = ("a", np.arange(3.0), 0.02)
    keys = {cache.cache_key("k", base), cache.cache_key("k", ("a", np.arange(3.0), 0.021)),
            cache.cache_key("k", ("a", np.arange(3.0, dtype=np.float32), 0.02)), cache.cache_key("j", base)}
    assert len(keys) == 4
    arrays = {"x": np.arange(200_000.0)}
    path = tmp_path / "k-entry.npz"
    writers = [threading.Thread(target=cache._write, args=(tmp_path, path, "key", arrays)) for _ in range(4)]
    for w in writers:
        w.start()
    for w in writers:
        w.join()
    np.testing.assert_array_equal(cache._read(path, "key")["x"], arrays["x"])
    assert cache._read(path, "other key") is None
    assert list(tmp_path.glob(".tmp-*")) == []


def test_a_flipped_bit_or_another_entry_s_valid_file_is_rebuilt_to_the_clean_arrays(monkeypatch, tmp_path):
    """Bit flips spread over an entry, and another input's whole entry copied under its name: each is
    rebuilt, and what is returned equals the clean build bit for bit."""
    monkeypatch.setenv(cache.ENV, str(tmp_path))
    builds = []

    def build(scale: float):
        builds.append(scale)
        return {"v": np.linspace(0.0, scale, 257), "f": np.arange(96, dtype=np.int64).reshape(32, 3)}

    clean, status = cache.cached("refinement", ("part", 1.0), lambda: build(1.0))
    assert status == "miss"
    (entry,) = tmp_path.glob("refinement-*.npz")
    intact = entry.read_bytes()
    statuses = []
    for n, at in enumerate(range(0, len(intact), len(intact) // 40)):
        entry.write_bytes(intact[:at] + bytes([intact[at] ^ (1 << (n % 8))]) + intact[at + 1:])
        arrays, status = cache.cached("refinement", ("part", 1.0), lambda: build(1.0))
        statuses.append(status)  # a "hit" only where the flip fell on what the zip format does not read back
        assert {k: a.tobytes() for k, a in arrays.items()} == {k: a.tobytes() for k, a in clean.items()}
        assert cache.cached("refinement", ("part", 1.0), lambda: build(1.0))[1] == "hit"
    assert statuses.count("miss") >= 30 and len(builds) == 1 + statuses.count("miss")
    cache.cached("refinement", ("part", 2.0), lambda: build(2.0))
    (other,) = set(tmp_path.glob("refinement-*.npz")) - {entry}
    entry.write_bytes(other.read_bytes())
    arrays, status = cache.cached("refinement", ("part", 1.0), lambda: build(1.0))
    assert status == "miss" and builds[-1] == 1.0
    np.testing.assert_array_equal(arrays["v"], clean["v"])


def test_every_public_name_resolves_and_is_listed():
    assert set(sf.__all__) <= set(dir(sf))
    assert set(sf._EXPORTS) == set(sf.__all__)  # every lazily imported name is public, and the reverse
    for name in sf.__all__:
        assert getattr(sf, name) is not None
    with pytest.raises(AttributeError):
        sf.no_such_name  # noqa: B018


def test_a_cached_render_imports_neither_jax_nor_the_fitting_or_plotting_stacks(tmp_path):
    script = (
        "import sys, spacefit, spacefit.cli, spacefit.render_job\n"
        "from spacefit.rendering.renderer import Renderer\n"
        f"Renderer(spacefit.load_scene(None, {SMALL!r})).render()\n"
        "heavy = ('jax', 'jaxtyping', 'optimistix', 'matplotlib', 'colour', 'trimesh', 'scipy')\n"
        "print(sorted(m for m in heavy if m in sys.modules))\n"
    )
    env = {"SPACEFIT_CACHE_DIR": str(tmp_path), "PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"}
    run = [subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True, check=True)
           for _ in range(2)]
    assert "jax" in run[0].stdout  # the first run refines and displaces the body
    assert run[1].stdout.strip() == "[]", run[1].stdout


# Modules `spacefit render` must not import once the mesh cache holds its meshes: the fitting, plotting, table,
# store and cluster stacks and the mesh builders (each a tenth of a second to seconds of start-up), Pillow (the
# preview is written through Mitsuba), importlib.metadata (the versions are read from their folders) and psutil (the
# lock's start time is read from /proc; psutil only checks a lock found held): 0.011 to 0.015 s each.
NOT_FOR_A_RENDER = ("jax", "jaxtyping", "optimistix", "equinox", "matplotlib", "colour", "trimesh", "scipy", "xarray",
                    "pandas", "astropy", "dask", "distributed", "zarr", "PIL", "importlib.metadata", "psutil")


def test_the_render_command_s_process_imports_none_of_the_stacks_it_does_not_need(tmp_path):
    """`spacefit render` as a process (cli.main, as the console script runs it), second run: its modules at exit."""
    overrides = [arg for key, value in SMALL.items() for arg in ("--set", f"{key}={json.dumps(value)}")]
    script = (
        "import sys, spacefit.cli\n"
        f"code = spacefit.cli.main(['render', '--out', {str(tmp_path / 'out')!r}, '--overwrite', '--quiet', *{overrides!r}])\n"
        f"print(code, sorted(m for m in {NOT_FOR_A_RENDER!r} if m in sys.modules))\n"
    )
    env = {"SPACEFIT_CACHE_DIR": str(tmp_path / "cache"), "PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"}
    runs = [subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True, check=True)
            for _ in range(2)]
    assert runs[0].stdout.startswith("0 ") and "jax" in runs[0].stdout  # the first run builds the meshes
    assert runs[1].stdout.strip() == "0 []", runs[1].stdout + runs[1].stderr


# Modules the fit command's stack must not import: colour-science (with pandas and Matplotlib's colour maps: 1.5-4 s;
# sRGB is written out in spacefit.output), optax (only Adam's), the store's and clusters' stacks, and astropy.wcs for a
# FITS observation whose header has no WCS (0.7 s).
NOT_FOR_A_FIT = ("colour", "pandas", "optax", "chex", "xarray", "zarr", "dask", "distributed", "tqdm", "astropy.wcs")


def test_the_fit_command_s_modules_import_none_of_the_stacks_a_default_fit_does_not_need(tmp_path):
    """What `spacefit fit` imports before it fits (cli.main's and _fit's modules, the files' readers, a FITS
    observation read with its ROWORDER) and what writing its report imports: none of NOT_FOR_A_FIT."""
    path = tmp_path / "obs.fits"
    script = ("import sys, numpy, spacefit.cli, spacefit.render_job, spacefit.pipeline, spacefit.scene.toml, spacefit.fitting.loop, "
              "spacefit.fitting.problem, spacefit.fitting.observation_files, spacefit.fitting.report, spacefit.imageio.reading\n"
              "from astropy.io import fits\n"
              f"fits.PrimaryHDU(numpy.zeros((4, 4), numpy.uint16), fits.Header({{'ROWORDER': 'TOP-DOWN'}})).writeto({str(path)!r})\n"
              f"spacefit.imageio.reading.read_image({str(path)!r})\n"
              f"print(sorted(m for m in {NOT_FOR_A_FIT!r} if m in sys.modules))\n")
    run = subprocess.run([sys.executable, "-c", script], env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"},
                         capture_output=True, text=True, check=True)
    assert run.stdout.strip() == "[]", run.stdout + run.stderr


def test_the_render_program_ends_at_once_with_its_folder_written_and_its_messages_out(tmp_path):
    """Run as the program, a render skips Python's shutdown (os._exit): its exit status, its messages (through pipes)
    and its four files are all there, and no lock or stage is left."""
    overrides = [arg for key, value in SMALL.items() for arg in ("--set", f"{key}={json.dumps(value)}")]
    env = {"SPACEFIT_CACHE_DIR": str(tmp_path / "cache"), "PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"}
    out = tmp_path / "out"
    run = subprocess.run([sys.executable, "-m", "spacefit.cli", "render", "--out", str(out), "--timings", *overrides],
                         env=env, capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    assert "total" in run.stderr and f"wrote {out / 'radiance.exr'}" in run.stderr
    assert sorted(p.name for p in out.iterdir()) == ["preview.png", "radiance.exr", "render.json", "scene.toml"]
    assert json.loads((out / "render.json").read_text())["scene"]["render"]["resolution"] == [64, 64]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cache", "out"]  # the lock beside the folder is gone
    # under a profiler the process exits as Python does, and the profiler writes its report
    profile = tmp_path / "render.prof"
    run = subprocess.run([sys.executable, "-m", "cProfile", "-o", str(profile), "-m", "spacefit.cli", "render", "--out",
                          str(out), "--overwrite", "--quiet", *overrides], env=env, capture_output=True, text=True)
    assert run.returncode == 0 and profile.stat().st_size > 0, run.stderr


def test_render_reports_where_the_time_went(monkeypatch, tmp_path, capsys):
    monkeypatch.setenv(cache.ENV, str(tmp_path / "cache"))
    overrides = [arg for key, value in SMALL.items() for arg in ("--set", f"{key}={json.dumps(value)}")]
    assert cli.main(["render", "--out", str(tmp_path / "out"), "--quiet", "--timings", *overrides]) == 0
    table = capsys.readouterr().err
    for stage in ("imports", "assemble", "load", "render", "part_ids", "write", "total"):
        assert stage in table
    assert "mesh cache: lander" in table and "kernels" in table
    sidecar = json.loads((tmp_path / "out" / "render.json").read_text())
    assert set(sidecar["timings_s"]) == {"imports", "assemble", "load", "render", "part_ids"}
    assert set(sidecar["mesh_cache"]) == {"lander", "body.refinement", "body.displaced", "body.faces"}  # a first run
    assert sidecar["kernels"]["launched"] >= 1


def test_package_versions_read_from_the_header_equal_importlib_metadata_s():
    """The sidecar's versions and the mesh cache's keys: every installed distribution's, and None for none."""
    from importlib import metadata

    from spacefit.versions import package_version

    names = {dist.metadata["Name"] for dist in metadata.distributions()}
    assert len(names) > 20
    assert {name: package_version(name) for name in names} == {name: metadata.version(name) for name in names}
    assert package_version("no-such-distribution-spacefit-test") is None


def test_srgb_encoding_and_decoding_equal_colour_science_s():
    with np.printoptions():  # colour-science sets NumPy's legacy printing when imported: later tests' str() keep 17 digits
        colour = pytest.importorskip("colour")
    x = np.concatenate([np.linspace(0.0, 0.01, 101), np.linspace(0.0, 1.0, 1001)])
    np.testing.assert_allclose(srgb_encode(x), colour.cctf_encoding(x, function="sRGB"), rtol=0, atol=1e-12)
    np.testing.assert_allclose(srgb_decode(x), colour.cctf_decoding(x, function="sRGB"), rtol=0, atol=1e-12)
    np.testing.assert_allclose(srgb_decode(srgb_encode(x)), x, rtol=0, atol=1e-12)


def test_a_refinement_held_in_memory_says_so_and_one_not_needed_is_not_read(monkeypatch, tmp_path):
    scene = _fresh(monkeypatch, tmp_path)
    assert assemble(scene).cache["body.refinement"] == "miss"
    again = assemble(scene)
    assert "body.refinement" not in again.cache and again.cache["body.faces"] == "memory"
    assert "body" in again.refinements and list(again.refinements) == ["body"] and "body.refinement" not in again.cache
    assert again.refinements["body"].faces.shape == again.faces("body").shape
    assert again.cache["body.refinement"] == "memory"
    np.testing.assert_array_equal(again.refinements["body"].faces, again.faces("body"))
