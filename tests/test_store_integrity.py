"""Stores that cannot lie (issue 20): a done point is trusted only when its data match its checksum;
damaged chunks, truncated flags and deleted variables are recomputed on a rerun, and said; `sweep
--verify` counts them; input files changed during a sweep or before a fit's --resume are refused by
name; a sweep too large for the machine is refused before anything is allocated."""

from __future__ import annotations

import os
import shutil
import tracemalloc
from pathlib import Path

import pytest
import xarray as xr
from helpers import small_scene, write_sphere_obj
from test_sweep import sphere_scene

import spacefit as sf
from spacefit.cli import DAMAGED, UNFINISHED, main
from spacefit.studies import worker

AXES = {"parts.sphere.kd": [0.2, 0.5, 0.8], "render.seed": [1, 2]}  # 6 points; mean_radiance's chunk of (i, j) is "i.j.0"


def counting(monkeypatch) -> list:
    calls: list = []
    run = worker.run_task
    monkeypatch.setattr(worker, "run_task", lambda task: (calls.append(task), run(task))[1])
    return calls


@pytest.fixture
def finished(tmp_path) -> tuple[Path, Path]:
    """A finished store of AXES, and an untouched copy of it."""
    store = tmp_path / "store.zarr"
    sf.sweep(sphere_scene(tmp_path), AXES, store=store, quiet=True)
    shutil.copytree(store, tmp_path / "copy.zarr")
    return store, tmp_path / "copy.zarr"


def same_store(a: Path, b: Path) -> None:
    xr.testing.assert_identical(xr.open_zarr(a).load().drop_attrs(), xr.open_zarr(b).load().drop_attrs())


def test_damaged_chunks_behind_done_points_are_counted_and_recomputed(finished, tmp_path, monkeypatch, capsys):
    store, copy = finished
    report = sf.verify_store(store)
    assert (report.points, report.done, report.verified, report.failed, report.damaged) == (6, 6, 6, (), False)
    assert main(["sweep", str(store), "--verify"]) == 0
    assert capsys.readouterr().out.splitlines() == ["6 points: 6 done, 6 verified, 0 failed their checksum, 0 to compute"]

    chunk = store / "mean_radiance" / "1.0.0"
    chunk.write_bytes(chunk.read_bytes()[:7])  # truncated: no longer decodes
    (store / "irradiance" / "2.1.0").unlink()  # deleted: reads back as NaN
    report = sf.verify_store(store)
    assert report.failed == ((1, 0), (2, 1)) and (report.done, report.verified, report.missing) == (6, 4, 2)
    assert main(["sweep", str(store), "--verify"]) == DAMAGED
    assert "6 points: 6 done, 4 verified, 2 failed their checksum, 2 to compute" in capsys.readouterr().out

    calls = counting(monkeypatch)
    with pytest.warns(UserWarning, match=r"2 of 6 done points failed their checksum \(data chunk missing or damaged\) "
                                         "and are recomputed"):
        sf.sweep(sphere_scene(tmp_path), AXES, store=store, quiet=True)
    assert len(calls) == 2
    same_store(store, copy)
    assert main(["sweep", str(store), "--verify"]) == 0


def test_a_truncated_done_chunk_is_recomputed_not_a_traceback(finished, tmp_path, monkeypatch):
    store, copy = finished
    (store / "done" / "0.1").write_bytes(b"\x02\x01")
    report = sf.verify_store(store)
    assert report.failed == ((0, 1),) and report.damaged
    calls = counting(monkeypatch)
    with pytest.warns(UserWarning, match="1 of 6 done points failed"):
        sf.sweep(sphere_scene(tmp_path), AXES, store=store, quiet=True)
    assert len(calls) == 1
    same_store(store, copy)


@pytest.mark.parametrize("variable", ["pixels", "checksum", "done"])
def test_a_deleted_variable_is_recreated_and_its_points_recomputed(finished, tmp_path, monkeypatch, capsys, variable):
    store, copy = finished
    shutil.rmtree(store / variable)
    report = sf.verify_store(store)
    assert report.missing_variables == (variable,) and report.damaged and report.verified == 0
    assert main(["sweep", str(store), "--verify"]) == DAMAGED
    assert f"missing variables: {variable}" in capsys.readouterr().out
    calls = counting(monkeypatch)
    with pytest.warns(UserWarning, match=f"the variable.s. {variable} were missing and are recreated"):
        sf.sweep(sphere_scene(tmp_path), AXES, store=store, quiet=True)
    assert len(calls) == 6
    same_store(store, copy)
    assert sf.verify_store(store).verified == 6


def test_verify_says_unfinished_and_refuses_what_is_not_a_store(finished, tmp_path, capsys):
    import zarr

    store, _ = finished
    zarr.open_group(str(store), mode="r+", zarr_format=2)["done"][2, 0] = False
    assert main(["sweep", str(store), "--verify"]) == UNFINISHED
    assert "6 points: 5 done, 5 verified, 0 failed their checksum, 1 to compute" in capsys.readouterr().out
    (tmp_path / "other").mkdir()
    assert main(["sweep", str(tmp_path / "other"), "--verify"]) == 2
    assert "is not a spacefit sweep store" in capsys.readouterr().err
    assert main(["sweep", str(tmp_path / "sweep.toml")]) == 2
    assert "`--out` STORE is required" in capsys.readouterr().err


def test_a_mesh_edited_while_a_reloading_sweep_runs_is_refused(tmp_path, monkeypatch):
    """The camera's position reloads the scene at each point; the mesh is replaced during the second
    point's render: that point is not marked done, and the file is named."""
    mesh = tmp_path / "sphere.obj"
    axes = {"camera.position_m": [[0.0, 0.0, 10.0], [0.0, 0.0, 11.0], [0.0, 0.0, 12.0]]}
    scene = sphere_scene(tmp_path)
    original = mesh.read_bytes()
    calls, run = [], worker.run_task

    def edit_during_second(task):
        calls.append(task)
        if len(calls) == 2:
            write_sphere_obj(mesh, subdivisions=3)
        return run(task)

    monkeypatch.setattr(worker, "run_task", edit_during_second)
    store = tmp_path / "store.zarr"
    with pytest.raises(sf.InputError, match=r"'.*sphere\.obj' changed while the sweep ran .* the point rendered after "
                                            "the change is not marked done"):
        sf.sweep(scene, axes, store=store, quiet=True)
    assert list(xr.open_zarr(store).done.values) == [True, False, False]
    # the new mesh is another sweep; with the old one back, the store is finished as if never disturbed
    with pytest.raises(sf.InputError, match="other arguments"):
        sf.sweep(scene, axes, store=store, quiet=True)
    monkeypatch.setattr(worker, "run_task", run)
    mesh.write_bytes(original)
    finished = sf.sweep(scene, axes, store=store, quiet=True).load()
    xr.testing.assert_identical(finished.drop_attrs(), sf.sweep(scene, axes, quiet=True).load().drop_attrs())


def test_an_edit_that_keeps_the_file_status_is_caught_at_the_end(tmp_path, monkeypatch):
    """Same size, same inode, modification time put back: only the final SHA-256 sees it, and then
    no point of this run stays done."""
    mesh = tmp_path / "sphere.obj"
    scene = sphere_scene(tmp_path)
    calls, run = [], worker.run_task

    def edit_quietly(task):
        calls.append(task)
        if len(calls) == 1:
            st = os.stat(mesh)
            text = mesh.read_bytes()
            last = text.index(b"\n", text.index(b"v ")) - 1  # the last digit of the first vertex
            with open(mesh, "r+b") as f:
                f.seek(last)
                f.write(b"1" if text[last:last + 1] != b"1" else b"2")
            os.utime(mesh, ns=(st.st_atime_ns, st.st_mtime_ns))
        return run(task)

    monkeypatch.setattr(worker, "run_task", edit_quietly)
    store = tmp_path / "store.zarr"
    with pytest.raises(sf.InputError, match="the 2 points rendered in this run are not marked done"):
        sf.sweep(scene, {"parts.sphere.kd": [0.2, 0.5]}, store=store, quiet=True)
    assert not xr.open_zarr(store).done.values.any()


def test_a_sweep_of_a_billion_points_is_refused_before_allocating(tmp_path, monkeypatch, capsys):
    scene = sphere_scene(tmp_path)
    store = tmp_path / "big.zarr"
    grid = {"sun.elevation_deg": {"linspace": [10, 80, 1000]}, "sun.azimuth_deg": {"linspace": [0, 90, 1000]},
            "parts.sphere.kd": {"linspace": [0.1, 0.9, 1000]}}
    line = {"sun.elevation_deg": {"linspace": [10, 80, 1_000_000_000]}}
    tracemalloc.start()
    try:
        for axes in (grid, line):
            with pytest.raises(sf.InputError, match=r"a sweep of 1,000,000,000 points is more than 1,000,000 .*--large"):
                sf.sweep(scene, axes, store=store, quiet=True)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 20e6, peak  # a list of the points alone would be gigabytes
    assert not store.exists() and sorted(p.name for p in tmp_path.iterdir()) == ["sphere.obj"]
    # asked for, it is still refused where its index cannot fit in the memory
    import spacefit.rendering.memory as memory

    monkeypatch.setattr(memory, "available_memory_bytes", lambda: 1 << 30)
    with pytest.raises(sf.InputError, match=r"1,000,000,000 points needs about .* GiB of memory for its index"):
        sf.sweep(scene, grid, store=store, quiet=True, allow_large=True)
    assert not store.exists()
    # from the command line, one line and exit 2; --large gets past the count
    (tmp_path / "scene.toml").write_text(scene.to_toml())
    (tmp_path / "sweep.toml").write_text('scene = "scene.toml"\n[axes]\n"sun.elevation_deg" = {linspace = [10, 80, 2000000]}\n')
    capsys.readouterr()
    assert main(["sweep", str(tmp_path / "sweep.toml"), "--out", str(store), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert len(err.splitlines()) == 1 and "2,000,000 points is more than 1,000,000" in err and "store at most 38.1 GiB" in err
    (tmp_path / "sweep.toml").write_text('scene = "scene.toml"\n[axes]\n"sun.elevation_deg" = {linspace = [10, 80, 1000000000]}\n')
    assert main(["sweep", str(tmp_path / "sweep.toml"), "--out", str(store), "--quiet", "--large"]) == 2
    assert "of memory for its index alone and this machine has 1.0 GiB available" in capsys.readouterr().err
    assert not store.exists()


def test_the_estimate_is_printed_per_variable(tmp_path, capsys):
    sf.sweep(sphere_scene(tmp_path), AXES, store=tmp_path / "s.zarr")
    err = capsys.readouterr().err
    assert ("sweep of 6 points: store at most 120.0 KiB (mean_radiance 24.0 KiB, pixels 24.0 KiB, irradiance 24.0 KiB, "
            "checksum 24.0 KiB, done 24.0 KiB); index") in err


def kd_fit_files(folder: Path) -> Path:
    """A Lambert sphere's reference ``ref.exr`` (kd 0.5) and ``scene.toml`` (kd 0.2, 16 x 16 px) in ``folder``."""
    mesh = write_sphere_obj(folder / "sphere.obj", subdivisions=2)
    scene = small_scene(mesh, {"material": "white_paint", "kd": 0.2}, render={"resolution": [16, 16], "spp": 2})
    (folder / "scene.toml").write_text(scene.to_toml())
    sf.write_exr(folder / "ref.exr", sf.render(scene.with_values({"parts.sphere.kd": 0.5})))
    return folder / "ref.exr"


def test_a_reference_edited_before_resume_is_refused_by_name(tmp_path, monkeypatch, capsys):
    from spacefit.pipeline import Checkpoint

    reference = kd_fit_files(tmp_path)
    args = ["fit", str(reference), "--scene", str(tmp_path / "scene.toml"), "--free", "parts.sphere.kd", "--out",
            str(tmp_path / "fit"), "--solver", "adam", "--max-steps", "2", "--quiet"]
    monkeypatch.setattr(Checkpoint, "remove", lambda self: None)  # keep it, as an interrupted fit does
    assert main(args) not in (1, 2)  # a verdict: 0, or the fit's code for too few steps
    capsys.readouterr()
    monkeypatch.undo()
    assert main([*args, "--resume"]) not in (1, 2)  # the same files: resumed
    assert main([*args, "--resume"]) == 2  # the finished fit removed its checkpoint
    monkeypatch.setattr(Checkpoint, "remove", lambda self: None)
    assert main([*args, "--overwrite"]) not in (1, 2)
    image = sf.read_exr(reference)
    sf.write_exr(reference, image * 1.01)  # the same path, other contents
    capsys.readouterr()
    assert main([*args, "--resume"]) == 2
    err = capsys.readouterr().err
    assert "was made with other contents of" in err and "ref.exr" in err and "SHA-256" in err and "scene.toml" not in err


def test_a_store_written_before_checksums_is_recomputed_once(finished, tmp_path, monkeypatch):
    """An older spacefit's store: no `checksum` variable, in the files or in the consolidated metadata."""
    import zarr

    store, copy = finished
    shutil.rmtree(store / "checksum")
    zarr.consolidate_metadata(str(store), zarr_format=2)
    calls = counting(monkeypatch)
    with pytest.warns(UserWarning, match="checksum were missing and are recreated; the 6 done points are recomputed"):
        sf.sweep(sphere_scene(tmp_path), AXES, store=store, quiet=True)
    assert len(calls) == 6
    same_store(store, copy)


def test_a_reference_edited_while_the_fit_runs_is_refused_with_nothing_written(tmp_path, monkeypatch, capsys):
    from spacefit.fitting import loop

    reference = kd_fit_files(tmp_path)
    solve = loop.fit

    def edited_while_solving(*args, **kwargs):
        result = solve(*args, **kwargs)
        sf.write_exr(reference, sf.read_exr(reference) * 1.01)  # the same path, other contents, before the report
        return result

    monkeypatch.setattr(loop, "fit", edited_while_solving)
    out = tmp_path / "fit"
    assert main(["fit", str(reference), "--scene", str(tmp_path / "scene.toml"), "--free", "parts.sphere.kd", "--out", str(out),
                 "--solver", "adam", "--max-steps", "2", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "ref.exr" in err and "changed while the fit ran" in err
    assert not out.exists()


def test_damaged_or_deleted_coordinate_chunks_fail_verify_and_are_written_again(finished, tmp_path, monkeypatch, capsys):
    store, copy = finished
    kd = next((store / "parts.sphere.kd").glob("[0-9]*"))
    kd.write_bytes(bytes([kd.read_bytes()[0] ^ 1]) + kd.read_bytes()[1:])  # a flipped bit in the swept values
    (next((store / "render.seed").glob("[0-9]*"))).unlink()
    report = sf.verify_store(store)
    assert report.damaged and report.damaged_coordinates == ("parts.sphere.kd", "render.seed")
    assert main(["sweep", str(store), "--verify"]) == DAMAGED
    assert "damaged coordinates (chunks changed or missing): parts.sphere.kd, render.seed" in capsys.readouterr().out
    calls = counting(monkeypatch)
    with pytest.warns(UserWarning, match=r"the damaged coordinate\(s\) parts.sphere.kd, render.seed are written again"):
        sf.sweep(sphere_scene(tmp_path), AXES, store=store, quiet=True)
    assert calls == []  # the points' data were intact
    same_store(store, copy)
    assert not sf.verify_store(store).damaged


def test_two_points_chunks_swapped_with_their_checksums_fail_verify(finished, tmp_path, monkeypatch):
    store, copy = finished
    for variable in ("mean_radiance", "pixels", "irradiance", "checksum"):
        suffix = "" if variable == "checksum" else ".0"
        a, b = store / variable / f"0.0{suffix}", store / variable / f"2.1{suffix}"
        first, second = a.read_bytes(), b.read_bytes()
        a.write_bytes(second)
        b.write_bytes(first)
    report = sf.verify_store(store)
    assert report.failed == ((0, 0), (2, 1)) and report.verified == 4
    calls = counting(monkeypatch)
    with pytest.warns(UserWarning, match="2 of 6 done points failed their checksum"):
        sf.sweep(sphere_scene(tmp_path), AXES, store=store, quiet=True)
    assert len(calls) == 2
    same_store(store, copy)


@pytest.mark.parametrize(("name", "damage"), [
    ("mean_radiance/.zarray", lambda b: b"\xff\xfe" + b[2:]),  # not UTF-8
    ("pixels/.zattrs", lambda b: b[: len(b) // 2]),  # truncated JSON
    (".zattrs", lambda b: b"[]"),  # JSON, not an object
    (".zmetadata", lambda b: b""),
])
def test_a_damaged_metadata_file_is_a_one_line_error_naming_it(finished, tmp_path, capsys, name, damage):
    store, _ = finished
    path = store / name
    path.write_bytes(damage(path.read_bytes()))
    before = {p: p.read_bytes() for p in store.rglob("*") if p.is_file()}
    assert main(["sweep", str(store), "--verify"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and f"its metadata file {name!r} is damaged" in err and "Traceback" not in err
    with pytest.raises(sf.InputError, match=f"its metadata file {name!r} is damaged"):
        sf.sweep(sphere_scene(tmp_path), AXES, store=store, quiet=True)
    assert {p: p.read_bytes() for p in store.rglob("*") if p.is_file()} == before  # nothing written
