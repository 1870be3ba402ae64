"""Sweeps: labelled Datasets, in-place reuse equal to reloads, a store that survives kill -9 and is
completed (not recomputed) by a rerun, refusals of mismatched reruns, and the command line."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
from helpers import small_scene, write_sphere_obj

import spacefit as sf
from spacefit.cli import main
from spacefit.studies import worker

AXES = {"sun.elevation_deg": [30.0, 50.0, 70.0, 90.0], "parts.sphere.kd": [0.2, 0.5], "render.seed": [1, 2, 3]}


def sphere_scene(tmp_path: Path) -> sf.Scene:
    return small_scene(write_sphere_obj(tmp_path / "sphere.obj", subdivisions=2), {"material": "white_paint"},
                       render={"spp": 4}, camera={"focal_length_mm": 5.0},  # the whole sphere, 20 px across
                       sun={"direction": [-0.5, 0.0, -0.75**0.5]})  # azimuth 0


def test_sweep_is_labelled_and_in_place_values_equal_reloaded_scenes(tmp_path):
    scene = sphere_scene(tmp_path)
    ds = sf.sweep(scene, AXES, images=True, quiet=True).load()
    assert ds.mean_radiance.dims == ("sun.elevation_deg", "parts.sphere.kd", "render.seed", "region")
    assert list(ds.region.values) == ["sphere", "target"]
    assert ds["sun.elevation_deg"].attrs["units"] == "deg" and ds.irradiance.attrs["units"] == "W m^-2"
    assert ds.attrs["seeds"] == [1, 2, 3] and ds.attrs["scene_toml"] == scene.to_toml()
    assert bool(ds.done.all())
    # a point rendered in place on the loaded scene is the image of the scene loaded at its values
    point = scene.with_values({"sun.direction": [-np.cos(np.radians(50.0)), 0.0, -np.sin(np.radians(50.0))],
                               "parts.sphere.kd": 0.5, "render.seed": 2})
    fresh = sf.render(point)
    stored = ds.radiance.sel({"sun.elevation_deg": 50.0, "parts.sphere.kd": 0.5, "render.seed": 2}).values
    np.testing.assert_allclose(stored, fresh, rtol=1e-5, atol=1e-7)
    # Lambert: the mean radiance is linear in kd
    ratio = ds.mean_radiance.sel({"parts.sphere.kd": 0.5}) / ds.mean_radiance.sel({"parts.sphere.kd": 0.2})
    np.testing.assert_allclose(ratio.values, 2.5, rtol=1e-5)


def test_zipped_axes_and_scene_keys(tmp_path):
    scene = sphere_scene(tmp_path)
    axes = {"sun": {"sun.elevation_deg": [40.0, 60.0], "sun.azimuth_deg": [0.0, 90.0]},
            "camera.position_m": [[0.0, 0.0, 10.0], [0.0, 0.0, 12.0]]}
    ds = sf.sweep(scene, axes, quiet=True).load()
    assert ds.mean_radiance.dims == ("sun", "camera.position_m", "region")
    assert list(ds["sun.azimuth_deg"].values) == [0.0, 90.0]
    pixels = ds.pixels.sel(region="target").values
    assert np.all(pixels[:, 0] > pixels[:, 1])  # farther camera, fewer pixels


def test_bad_axes_name_the_argument(tmp_path):
    scene = sphere_scene(tmp_path)
    with pytest.raises(sf.InputError, match="parts.sphere.kd"):
        sf.sweep(scene, {"parts.sphere.kd": [0.5, 1.5]}, quiet=True)
    with pytest.raises(sf.InputError, match="unknown scene key"):
        sf.sweep(scene, {"camera.postion_m": [[0, 0, 10]]}, quiet=True)
    with pytest.raises(sf.InputError, match="equal length"):
        sf.sweep(scene, {"z": {"sun.elevation_deg": [10, 20], "sun.azimuth_deg": [0]}}, quiet=True)
    # an integer past 64 bits (found by test_fuzz_long's studies: the store's coordinates overflowed), and nothing written
    with pytest.raises(sf.InputError, match=r"`axes\['wrinkles.gamma'\]` holds 18446744073709551616, an integer past 64 bits"):
        sf.sweep(scene, {"wrinkles.gamma": [2, 2**64]}, store=tmp_path / "store", quiet=True)
    assert not (tmp_path / "store").exists()


SCRIPT = """
import sys, time
sys.path.insert(0, {tests!r})
from pathlib import Path
import spacefit as sf
from spacefit.cli import main
from spacefit.studies import worker
from test_sweep import AXES, sphere_scene

run = worker.run_task
worker.run_task = lambda task: (time.sleep({sleep}), run(task))[1]  # slow points: a window to kill in
sf.sweep(sphere_scene(Path({tmp!r})), AXES, store={store!r}, quiet=True)
"""


def done_points(store: Path) -> int:
    return sum(1 for p in (store / "done").glob("*") if not p.name.startswith("."))


def test_sweep_killed_half_way_resumes_to_the_uninterrupted_result(tmp_path, monkeypatch):
    store = tmp_path / "store.zarr"
    total = 4 * 2 * 3
    code = SCRIPT.format(tests=str(Path(__file__).parent), tmp=str(tmp_path), store=str(store), sleep=0.15)
    proc = subprocess.Popen([sys.executable, "-c", code])
    deadline = time.time() + 120
    while done_points(store) < total // 3 and proc.poll() is None and time.time() < deadline:
        time.sleep(0.02) if store.exists() else time.sleep(0.2)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    finished = done_points(store)
    assert 0 < finished < total, finished
    before = xr.open_zarr(store).load()

    calls = []
    run = worker.run_task
    monkeypatch.setattr(worker, "run_task", lambda task: (calls.append(task), run(task))[1])
    resumed = sf.sweep(sphere_scene(tmp_path), AXES, store=store, quiet=True).load()
    assert len(calls) == total - int(before.done.sum())  # no finished point is computed again
    kept = before.done.values
    np.testing.assert_array_equal(resumed.mean_radiance.values[kept], before.mean_radiance.values[kept])

    monkeypatch.setattr(worker, "run_task", run)
    full = sf.sweep(sphere_scene(tmp_path), AXES, quiet=True).load()
    xr.testing.assert_identical(resumed.drop_attrs(), full.drop_attrs())

    calls.clear()
    monkeypatch.setattr(worker, "run_task", lambda task: (calls.append(task), run(task))[1])
    sf.sweep(sphere_scene(tmp_path), AXES, store=store, quiet=True)
    assert calls == []  # a finished store: nothing to do
    sf.sweep(sphere_scene(tmp_path), {**AXES, "sun.elevation_deg": [30, 50, 70, 90]}, store=store, quiet=True)
    assert calls == []  # the same numbers written as integers are the same sweep
    with pytest.raises(sf.InputError, match="other arguments"):
        sf.sweep(sphere_scene(tmp_path), {**AXES, "render.seed": [1, 2]}, store=store, quiet=True)


def test_sweep_command_line(tmp_path, capsys):
    mesh = write_sphere_obj(tmp_path / "sphere.obj", subdivisions=2)
    scene = small_scene(mesh, {"material": "white_paint"}, render={"spp": 4})
    (tmp_path / "scene.toml").write_text(scene.to_toml())
    (tmp_path / "sweep.toml").write_text(textwrap.dedent("""
        scene = "scene.toml"
        [axes]
        "sun.elevation_deg" = {linspace = [30, 90, 3]}
        [axes.pose]
        "target.attitude_z_deg" = [0, 45]
        "render.seed" = [1, 2]
        """))
    assert main(["sweep", str(tmp_path / "sweep.toml"), "--out", str(tmp_path / "s.zarr"), "--quiet"]) == 0
    ds = xr.open_zarr(tmp_path / "s.zarr")
    assert ds.mean_radiance.dims == ("sun.elevation_deg", "pose", "region") and bool(ds.done.all())
    capsys.readouterr()
    (tmp_path / "bad.toml").write_text('[axes]\n"sun.elevation_deg" = [95]\n')
    assert main(["sweep", str(tmp_path / "bad.toml"), "--out", str(tmp_path / "b.zarr")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("spacefit: error:") and "sun.elevation_deg" in err and len(err.splitlines()) == 1
    assert not (tmp_path / "b.zarr").exists()


def test_a_two_worker_dask_cluster_gives_the_in_process_dataset(tmp_path):
    """Workers keep their loaded scene, are restarted after 3 renders here, and give identical numbers."""
    scene = sphere_scene(tmp_path)
    axes = {"sun.elevation_deg": [30.0, 60.0, 90.0], "render.seed": [1, 2]}
    local = sf.sweep(scene, axes, quiet=True).load()
    distributed = sf.sweep(scene, axes, workers=2, max_renders_per_worker=3, store=tmp_path / "d.zarr", quiet=True).load()
    xr.testing.assert_identical(local.drop_attrs(), distributed.drop_attrs())
    assert local.attrs["spacefit_sweep"] == distributed.attrs["spacefit_sweep"]


@pytest.mark.parametrize(("signum", "code"), [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_ctrl_c_stops_the_command_line_sweep_cleanly(tmp_path, signum, code):
    mesh = write_sphere_obj(tmp_path / "sphere.obj", subdivisions=2)
    (tmp_path / "scene.toml").write_text(small_scene(mesh, {"material": "white_paint"}, render={"spp": 256}).to_toml())
    (tmp_path / "sweep.toml").write_text('scene = "scene.toml"\n[axes]\n"sun.elevation_deg" = {linspace = [10, 90, 400]}\n')
    store = tmp_path / "s.zarr"
    proc = subprocess.Popen([sys.executable, "-m", "spacefit.cli", "sweep", str(tmp_path / "sweep.toml"), "--out", str(store),
                             "--quiet"], stderr=subprocess.PIPE, text=True)
    deadline = time.time() + 120
    while (not store.exists() or done_points(store) < 2) and proc.poll() is None and time.time() < deadline:
        time.sleep(0.05)
    proc.send_signal(signum)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == code, err
    assert err.strip().splitlines() == [f"spacefit: interrupted; every finished point is in {store} (rerun the same command to finish)"]
    ds = xr.open_zarr(store)
    assert 2 <= int(ds.done.sum()) < 400
    finished = ds.done.values
    assert np.all(np.isfinite(ds.mean_radiance.values[finished]))


def test_an_edited_mesh_file_is_another_sweep(tmp_path):
    """The store's identity holds the mesh files' contents: the same scene file over an edited mesh
    at the same path is refused, not completed with the old results."""
    store = tmp_path / "store.zarr"
    axes = {"parts.sphere.kd": [0.2, 0.5]}
    sf.sweep(sphere_scene(tmp_path), axes, store=store, quiet=True)
    sf.sweep(sphere_scene(tmp_path), axes, store=store, quiet=True)  # the same file written again: the same sweep
    scene = sphere_scene(tmp_path)
    write_sphere_obj(tmp_path / "sphere.obj", subdivisions=3)
    with pytest.raises(sf.InputError, match=r"other arguments \(scene, mesh files"):
        sf.sweep(scene, axes, store=store, quiet=True)


@pytest.fixture(scope="module")
def thread_client():
    """A dask client of a one-worker cluster in this process (threads: starts in a fraction of a second), at a TCP address."""
    from distributed import Client, LocalCluster

    with LocalCluster(n_workers=1, threads_per_worker=1, processes=False, protocol="tcp", dashboard_address=None) as cluster:
        with Client(cluster) as client:
            yield client


def test_a_sweep_takes_a_client_its_address_or_none_as_a_fit_does(tmp_path, thread_client):
    from spacefit.executors import is_client

    scene = sphere_scene(tmp_path)
    axes = {"sun.elevation_deg": [30.0, 60.0]}
    here = sf.sweep(scene, axes, quiet=True).load()
    assert thread_client.scheduler.address.startswith("tcp://")
    for cluster in (thread_client, thread_client.scheduler.address):
        xr.testing.assert_identical(sf.sweep(scene, axes, cluster=cluster, quiet=True).load().drop_attrs(), here.drop_attrs())
    assert thread_client.status == "running"  # the caller's client is left open
    assert is_client(thread_client) and not is_client(thread_client.scheduler.address)


CLUSTER_WORDS = "must be None, a number of local workers, a scheduler address or a dask Client"
# Every public function with a `cluster=`, called with everything else valid enough to reach its check.
WITH_CLUSTER = {
    "fit": lambda cluster: sf.fit([], ["parts.legs.kd"], cluster=cluster),
    "sweep": lambda cluster: sf.sweep(sf.default_scene(), {"sun.elevation_deg": [30.0]}, cluster=cluster, quiet=True),
    "light_curve": lambda cluster: sf.light_curve(sf.default_scene(), phase_deg=[10.0], cluster=cluster, quiet=True),
    "fit_to_folder": lambda cluster: sf.fit_to_folder(sf.ObservationFiles(["missing.exr"], ["missing.toml"]), ["parts.legs.kd"],
                                                      "never-written", cluster=cluster),
    "compare_plates_to_render": lambda cluster: sf.compare_plates_to_render(sf.default_scene(), phase_deg=[10.0], cluster=cluster),
    "choose_light_curve_model": lambda cluster: sf.choose_light_curve_model(sf.default_scene(), None, cluster=cluster),
}


@pytest.mark.parametrize("name", WITH_CLUSTER)
@pytest.mark.parametrize(("cluster", "message"), [
    (1.5, f"^`cluster` {CLUSTER_WORDS}, got 1.5"), ("grid", "^`cluster` 'grid' must be SCHEME://HOST:PORT"),
    ("file:///tmp/x", "^`cluster` 'file:///tmp/x' has the scheme 'file'"), (0, "^`cluster` must be an integer >= 1"),
])
def test_every_cluster_argument_refuses_what_is_not_a_cluster_in_one_line(name, cluster, message, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(sf.InputError, match=message) as err:
        WITH_CLUSTER[name](cluster)
    assert len(str(err.value).splitlines()) == 1 and not (tmp_path / "never-written").exists()


def test_a_points_summaries_are_those_of_its_whole_film(tmp_path):
    """The summaries are taken over the rendered window only (black outside it): the same irradiance,
    pixels and mean radiance as over the whole film, which the stored image is."""
    scene = sphere_scene(tmp_path).with_values({"render.resolution": [64, 48]})
    ds = sf.sweep(scene, {"sun.elevation_deg": [30.0, 60.0], "render.seed": [1, 2]}, images=True, quiet=True).load()
    renderer = sf.Renderer(scene)
    assert renderer.window[2] * renderer.window[3] < 64 * 48  # the window is a part of the film
    parts, omega = renderer.part_image(), sf.pixel_solid_angles(renderer.assembly.intrinsics)
    for elevation in (30.0, 60.0):
        for seed in (1, 2):
            point = ds.sel({"sun.elevation_deg": elevation, "render.seed": seed})
            film = point.radiance.values
            whole = worker.summaries(film, parts, omega, list(point.region.values))
            np.testing.assert_allclose(point.irradiance.values, whole["irradiance"], rtol=1e-12)
            np.testing.assert_array_equal(point.pixels.values, whole["pixels"])
            np.testing.assert_allclose(point.mean_radiance.values, whole["mean_radiance"], rtol=1e-12)
