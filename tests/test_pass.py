"""A pass: frame tables (CSV, ECSV, FITS, Python columns), each frame's scene equal to one built by
hand, per-frame pose Jacobian columns against finite differences, and the joint fit of a simulated
pass with per-frame attitude errors."""

from __future__ import annotations

import ast
import contextlib
import ctypes
import dataclasses
import os
import re
from pathlib import Path

import jax
import numpy as np
import pytest
from astropy.table import Table

import spacefit as sf
from spacefit.fitting.frames import FrameSpec, InProcess, Loaded, frame_jacobian, frame_part_image, frame_primal, run_frames, share_views
from spacefit.fitting import problem, residuals
from spacefit.fitting.problem import images_memory
from spacefit.precision import float64
from spacefit.rendering import memory
from spacefit.rendering.memory import describe_fit, fit_memory
from spacefit.rendering.logs import kernel_log
from spacefit.scene.assembly import assemble

# The panels case at 32 x 32 px (75 mm pixels: the 128 px field of view).
BASE = {"render.resolution": [32, 32], "camera.pixel_pitch_mm": 75.0}
TRUTH = {"parts.panels.alpha_x": 0.15, "parts.panels.alpha_y": 0.03, "parts.legs.kd": 0.5}
START = {"parts.panels.alpha_x": 0.12, "parts.panels.alpha_y": 0.036, "parts.legs.kd": 0.42}


def base_scene() -> sf.Scene:
    return sf.load_scene("spacefit/synthetic/panels.toml", BASE)


def pass_geometry(n: int) -> list[dict[str, object]]:
    """n frames of an observer sweeping 6 to 22 deg from the zenith round the target, the sun
    sinking from 80 deg elevation: each frame's scene values."""
    frames = []
    for k, theta in enumerate(np.linspace(6.0, 22.0, n)):
        phi = np.radians(40.0 + 50.0 * k / max(n - 1, 1))
        t = np.radians(theta)
        position = [25.0 * np.sin(t) * np.cos(phi), 25.0 * np.sin(t) * np.sin(phi), 25.0 * np.cos(t)]
        frames.append({"camera.position_m": [round(float(v), 6) for v in position], "sun.elevation_deg": 80.0 - 10.0 * k / max(n - 1, 1),
                       "sun.azimuth_deg": 200.0})
    return frames


def columns(frames: list[dict[str, object]], folder: str = "") -> dict[str, list[object]]:
    """Frame table columns of ``frames``: files f<k>.exr, ISO times 10 s apart, the camera by components."""
    out: dict[str, list[object]] = {"file": [f"{folder}f{k}.exr" for k in range(len(frames))],
                                    "time": [f"2026-11-25T12:00:{10 * k:02d}.5" for k in range(len(frames))]}
    for c, axis in enumerate("xyz"):
        out[f"camera.position_m.{axis}"] = [f["camera.position_m"][c] for f in frames]
    for key in ("sun.elevation_deg", "sun.azimuth_deg"):
        out[key] = [f[key] for f in frames]
    out["target.attitude_x_deg"] = [0.0] * len(frames)
    out["sensor.exposure_time_s"] = [1e-6 * (k + 1) for k in range(len(frames))]
    return out


def test_frame_tables_from_csv_ecsv_fits_and_lists_agree(tmp_path):
    frames = pass_geometry(3)
    cols = columns(frames)
    from_lists = sf.Pass.from_columns(cols, base_dir=tmp_path)
    Table(cols).write(tmp_path / "frames.csv")
    # ECSV and FITS hold the camera position as one column of 3 numbers per frame
    whole = {k: v for k, v in cols.items() if not k.startswith("camera.position_m.")}
    whole["camera.position_m"] = np.array([f["camera.position_m"] for f in frames])
    Table(whole).write(tmp_path / "frames.ecsv")
    Table(whole).write(tmp_path / "frames.fits")
    for name in ("frames.csv", "frames.ecsv", "frames.fits"):
        read = sf.Pass.read(tmp_path / name)
        assert len(read) == 3
        for a, b in zip(read.frames, from_lists.frames):
            assert a.file == tmp_path / b.file.name and a.time == b.time and a.sensor == b.sensor
            assert a.values.keys() == b.values.keys() and a.values["camera.position_m"] == pytest.approx(b.values["camera.position_m"], abs=1e-12)
            assert a.values["sun.elevation_deg"] == b.values["sun.elevation_deg"]
    assert from_lists.times_s == pytest.approx([0.0, 10.0, 20.0], abs=1e-9)
    assert from_lists.frames[2].sensor == {"exposure_time_s": 3e-6}
    seconds = sf.Pass.from_columns({**cols, "time": [100.0, 101.5, 103.0]})
    assert seconds.times_s.tolist() == [0.0, 1.5, 3.0]


def test_each_frames_scene_equals_one_built_by_hand(tmp_path):
    frames = pass_geometry(3)
    cols = columns(frames)
    cols["target.attitude_x_deg"] = [0.2, -0.1, 0.0]
    p = sf.Pass.from_columns(cols, base_dir=tmp_path)
    scenes = p.scenes(base_scene())
    for k, frame in enumerate(frames):
        x, y, z = map(float, frame["camera.position_m"])
        el, az = np.radians(frame["sun.elevation_deg"]), np.radians(200.0)
        toward_sun = [float(v) for v in (np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el))]
        by_hand = sf.load_scene("spacefit/synthetic/panels.toml", [
            "render.resolution=[32, 32]", "camera.pixel_pitch_mm=75.0", f"camera.position_m=[{x!r}, {y!r}, {z!r}]",
            f"sun.direction=[{-toward_sun[0]!r}, {-toward_sun[1]!r}, {-toward_sun[2]!r}]",
            f"target.attitude_deg=[{cols['target.attitude_x_deg'][k]!r}, 0.0, 0.0]"])
        ours, theirs = assemble(scenes[k]), assemble(by_hand)
        for axis in ("position", "right", "up", "forward"):  # the camera's frame, and the target's pose
            assert np.allclose(getattr(ours.camera, axis), getattr(theirs.camera, axis), rtol=0, atol=1e-12)
        assert np.allclose(ours.to_world, theirs.to_world, rtol=0, atol=1e-12)
        assert np.allclose(scenes[k].sun.direction, by_hand.sun.direction, rtol=0, atol=1e-12)
        assert scenes[k].target == by_hand.target and scenes[k].camera == by_hand.camera
        assert ours.intrinsics == theirs.intrinsics


def test_a_camera_posed_by_attitude_leaves_look_at():
    cols = {"file": ["a.exr"], "time": [0.0], "camera.position_m": [[0.0, 0.0, 25.0]], "camera.attitude_deg": [[0.0, 0.0, 10.0]]}
    scene = sf.Pass.from_columns(cols).scenes(base_scene())[0]
    assert scene.camera.look_at_m == () and scene.camera.attitude_deg == (0.0, 0.0, 10.0)


@pytest.mark.parametrize(("change", "message"), [
    ({"time": None}, "no `time` column"),
    ({"camera.position_m.z": None}, "needs all three components"),
    ({"time": ["2026-11-25T12:00:00", "noon", "2026-11-25T12:00:20"]}, "frame 1: `time` must be an ISO 8601"),
    ({"sun.elevation_deg": [80.0, 95.0, 70.0]}, "frame 1 (f1.exr): `sun.elevation_deg` must be in [-90, 90]"),
    ({"sun.elevaton_deg": [1.0, 2.0, 3.0]}, "sun.elevation_deg"),
    ({"file": ["f0.exr"]}, "one value per frame"),
])
def test_bad_frame_tables_are_refused_naming_the_column(change, message):
    cols = columns(pass_geometry(3))
    for key, value in change.items():
        if value is None:
            cols.pop(key)
        else:
            cols[key] = value
    with pytest.raises(sf.InputError) as err:
        sf.Pass.from_columns(cols).scenes(base_scene())
    assert message in str(err.value)


def test_per_frame_names_and_their_refusal():
    p = sf.Pass.from_columns(columns(pass_geometry(2)))
    assert p.per_frame(["target.attitude_x_deg", "image.scale"]) == [
        "target.attitude_x_deg@0", "target.attitude_x_deg@1", "image.scale@0", "image.scale@1"]
    with pytest.raises(sf.InputError, match="parts.legs.kd"):
        p.per_frame(["parts.legs.kd"])


def test_a_frames_pose_jacobian_column_matches_central_differences():
    """Frame 2's own attitude column, as the fit's batch computes it, against central differences of
    renders of that frame's scene with the attitude set in the scene file (1024 spp, common seed)."""
    scene = sf.Pass.from_columns(columns(pass_geometry(3))).scenes(base_scene())[2]
    spec = FrameSpec(scene, ("parts.legs.kd", "target.attitude_x_deg"), (0.0, 0.5), 256, 256, "prb")
    _, J = run_frames(InProcess(), frame_jacobian, [spec], [np.array([0.5, 0.0])], [1], [2])[0]
    h = 0.5
    up, down = (sf.render(scene.with_values({"target.attitude_x_deg": s * h, "render.spp": 1024, "render.seed": 11}))
                for s in (1, -1))
    fd = ((up - down) / (2 * h)).ravel()
    col = J[..., 1].ravel()
    assert np.dot(col, fd) / (np.linalg.norm(col) * np.linalg.norm(fd)) > 0.98
    assert np.linalg.norm(col) == pytest.approx(np.linalg.norm(fd), rel=0.1)


def tiny_frames(n: int, spp: int = 2, size: int = 12) -> list[FrameSpec]:
    """n frames of the arc at ``size`` x ``size`` px (12: tiny), each frame's attitude about x free."""
    base = sf.load_scene("spacefit/synthetic/panels.toml", {"render.resolution": [size, size], "camera.pixel_pitch_mm": 2400.0 / size})
    scenes = sf.Pass.from_columns({"file": [f"f{k}.exr" for k in range(n)], "time": list(range(n)), **columns_of(sf.arc_pass(n))}).scenes(base)
    return [FrameSpec(s, ("parts.legs.kd", "target.attitude_x_deg"), (0.0, 0.5), spp, spp, "prb", shared_view=True) for s in scenes]


def columns_of(frames: list[dict[str, object]]) -> dict[str, list[object]]:
    return {key: [f[key] for f in frames] for key in frames[0]}


def test_the_frames_of_a_pass_share_one_loaded_scene_and_render_as_on_their_own():
    """Two frames (own camera, sun and attitude) on one loaded scene: each frame's image, Jacobian and part
    image equal bit for bit those of the frame loaded alone, whatever frame rendered before."""
    specs = tiny_frames(2)
    x = np.array([0.5, 0.1])
    shared = Loaded()
    together = [frame_jacobian(s, s.key, x, 3, 4, shared) for s in specs]
    assert len(shared.stages) == 1 and len(shared.chains) == 2
    again = frame_jacobian(specs[0], specs[0].key, x, 3, 4, shared)  # after frame 1 set its own values
    alone = Loaded()
    image, J = frame_jacobian(specs[1], specs[1].key, x, 3, 4, alone)
    assert np.array_equal(together[1][0], image) and np.array_equal(together[1][1], J)
    assert np.array_equal(together[0][0], again[0]) and np.array_equal(together[0][1], again[1])
    assert not np.array_equal(together[0][0], together[1][0])  # the frames do differ
    assert [s.shared_view for s in share_views([dataclasses.replace(s, shared_view=False) for s in specs])] == [True, True]
    plain = dataclasses.replace(specs[0], shared_view=False)
    assert share_views([plain, plain]) == [plain, plain]  # observations of one scene keep their own, cropped
    for spec in specs[::-1]:
        assert np.array_equal(frame_part_image(spec, spec.key, shared).ids, frame_part_image(spec, spec.key, Loaded()).ids)


def test_a_pass_s_renders_trace_on_every_thread_and_equal_the_one_thread_renders_bit_for_bit(monkeypatch):
    """A batch of frames' images and Jacobians (a forward-mode and a finite-difference column) traces its samples on
    all of Dr.Jit's threads, and equals bit for bit the same batch with every kernel on one thread."""
    from spacefit.rendering import frozen
    from spacefit.rendering.backend import dr

    seen = []  # the threads each pass's samples were traced on (its first calls run in Python: unfrozen, recorded)

    def counted(samples):
        def traced(*args):
            seen.append(dr.thread_count())
            return samples(*args)
        return traced

    for name in ("camera_samples", "primal_state", "derivative_samples"):
        monkeypatch.setattr(frozen, name, counted(getattr(frozen, name)))
    specs, x = tiny_frames(2, spp=16, size=48), [np.array([0.5, 0.1])] * 2  # 36864 samples a pass: several blocks of work
    threads = dr.thread_count()
    dr.sync_thread()
    dr.set_thread_count(max(threads, 2))
    try:
        spread = run_frames(InProcess(), frame_jacobian, specs, x, [3, 3], [4, 4])
        dr.sync_thread()
        dr.set_thread_count(1)
        whole = run_frames(InProcess(), frame_jacobian, specs, x, [3, 3], [4, 4])
    finally:
        dr.sync_thread()
        dr.set_thread_count(threads)
    assert len(seen) > 4 and min(seen[:len(seen) // 2]) >= 2 and max(seen[len(seen) // 2:]) == 1
    for (image, J), (image_one, J_one) in zip(spread, whole):
        assert np.all(np.any(J != 0, axis=(0, 1, 2))) and image.max() > 0
        assert np.array_equal(image, image_one) and np.array_equal(J, J_one)


def test_a_caller_s_own_mitsuba_variant_changes_no_frame_and_is_kept():
    """With the caller's variant scalar_rgb, each frame's image, Jacobian and part image equal those
    rendered with spacefit's own variant set, bit for bit, and the caller's variant is set after each."""
    from spacefit.rendering.backend import mi

    specs = tiny_frames(2)
    x = np.array([0.5, 0.1])
    own = Loaded()
    expected = [(frame_jacobian(s, s.key, x, 3, 4, own), frame_part_image(s, s.key, own).ids) for s in specs]
    before = mi.variant()
    try:
        mi.set_variant("scalar_rgb")
        theirs = Loaded()
        for spec, ((image, J), ids) in zip(specs, expected):
            got_image, got_J = frame_jacobian(spec, spec.key, x, 3, 4, theirs)
            assert mi.variant() == "scalar_rgb"
            assert np.array_equal(frame_part_image(spec, spec.key, theirs).ids, ids) and mi.variant() == "scalar_rgb"
            assert np.array_equal(got_image, image) and np.array_equal(got_J, J)
    finally:
        mi.set_variant(before or "llvm_ad_rgb")


# JAX's event for one XLA compilation (jax.monitoring).
XLA_COMPILE = "/jax/core/compile/backend_compile_duration"


@contextlib.contextmanager
def xla_compilations():
    """A list of the XLA compilations made inside (one entry each)."""
    compiled: list[str] = []

    def listen(event: str, seconds: float, **_: object) -> None:
        if event == XLA_COMPILE:
            compiled.append(event)

    jax.monitoring.register_event_duration_secs_listener(listen)
    try:
        yield compiled
    finally:
        jax.monitoring.unregister_event_duration_listener(listen)


def test_the_frames_of_a_pass_compile_once_not_once_per_frame():
    """Three frames of a pass on one loaded scene: the first compiles its JAX programs and Dr.Jit
    kernels; the second and third (their own camera, sun and attitude: data, not code) compile
    neither for their images, Jacobians and part images, and render as each would alone."""
    specs = tiny_frames(3)
    x = np.array([0.5, 0.1])
    loaded = Loaded()
    frame_jacobian(specs[0], specs[0].key, x, 3, 4, loaded)
    frame_primal(specs[0], specs[0].key, x, 5, loaded)
    frame_part_image(specs[0], specs[0].key, loaded)
    with xla_compilations() as compiled, kernel_log() as kernels:
        together = [(frame_jacobian(s, s.key, x, 3, 4, loaded), frame_primal(s, s.key, x, 5, loaded)) for s in specs[1:]]
        parts = [frame_part_image(s, s.key, loaded) for s in specs[1:]]
    assert compiled == []
    assert kernels["launched"] > 0 and kernels["new"] == 0
    assert len(loaded.compiled) == 1  # one pair of programs (image, Jacobian) for the three frames
    (image, J), primal = together[1]
    alone = Loaded()
    assert np.array_equal(frame_jacobian(specs[2], specs[2].key, x, 3, 4, alone)[1], J)
    assert np.array_equal(frame_primal(specs[2], specs[2].key, x, 5, alone), primal)
    assert not np.array_equal(together[0][1], primal)  # the frames do differ
    assert np.array_equal(parts[1].ids, frame_part_image(specs[2], specs[2].key, alone).ids)


def test_a_frame_s_part_image_and_primal_render_share_their_scene_values_program():
    """A frame's part image sets its scene values from the program its primal renders take them from (one trace and one
    compilation per process, not two): its first primal render compiles no JAX program, and renders as alone."""
    spec = tiny_frames(1)[0]
    x = np.array([0.5, 0.1])
    loaded = Loaded()
    parts = frame_part_image(spec, spec.key, loaded)
    with xla_compilations() as compiled:
        primal = frame_primal(spec, spec.key, x, 5, loaded)
    assert compiled == []
    alone = Loaded()
    assert np.array_equal(frame_primal(spec, spec.key, x, 5, alone), primal)
    assert np.array_equal(frame_part_image(spec, spec.key, alone).ids, parts.ids) and np.any(parts.ids >= 0)


def test_a_process_keeps_at_most_max_scenes_loaded_dropping_the_least_recently_used():
    """Frames rendered at 1, 2 and 3 spp need three loaded scenes; with room for two, the least recently
    used one goes with its frames and compiled functions, and comes back (the same image) when asked again."""
    a, b, c = (tiny_frames(1, spp)[0] for spp in (1, 2, 3))
    loaded = Loaded(max_scenes=2)
    x = np.array([0.5, 0.0])
    first = frame_primal(a, a.key, x, 3, loaded)
    frame_primal(b, b.key, x, 3, loaded)
    frame_primal(a, a.key, x, 3, loaded)  # a is now the most recently used: b goes next
    frame_primal(c, c.key, x, 3, loaded)
    assert len(loaded.stages) == 2 and set(loaded.chains) == {a.key, c.key}
    assert {name[0] for name in loaded.compiled} == set(loaded.stages)
    frame_primal(b, b.key, x, 3, loaded)
    assert set(loaded.chains) == {b.key, c.key}
    assert np.array_equal(frame_primal(a, a.key, x, 3, loaded), first)
    assert set(loaded.chains) == {a.key, b.key}


@pytest.fixture(scope="module")
def small_pass(tmp_path_factory):
    """Three frames at 24 x 24 px (radiance at 64 spp) whose target is turned 0.2, -0.25 and 0.1 deg
    about x off the table's attitude; a fit of the legs' albedo and each frame's attitude, in this process."""
    folder = tmp_path_factory.mktemp("pass") / "frames"
    base = sf.load_scene("spacefit/synthetic/panels.toml", {"render.resolution": [24, 24], "camera.pixel_pitch_mm": 100.0})
    errors = [{"target.attitude_x_deg": e} for e in (0.2, -0.25, 0.1)]
    frames = sf.simulate_pass(base, sf.arc_pass(3), folder, errors=errors, spp=64)
    obs = [sf.Observation.from_file(f.file, s) for f, s in zip(frames.frames, frames.scenes(base))]
    free = ["parts.legs.kd", *frames.per_frame(["target.attitude_x_deg"])]
    options = {"start": {"parts.legs.kd": 0.4}, "render": sf.FitRender(spp=8), "max_steps": 6}
    return obs, free, options, sf.fit(obs, free, **options), folder


def test_a_reduced_pass_recovers_each_frames_attitude(small_pass):
    """The three-frame pass at 24 x 24 px, 8 spp: each frame's attitude within 0.05 deg, the legs'
    albedo within 3 of its standard errors, and a goodness of fit per frame."""
    _, _, _, result, _ = small_pass
    for k, error in enumerate((0.2, -0.25, 0.1)):
        assert abs(result.values[f"target.attitude_x_deg@{k}"] - error) < 0.05, k
    assert abs(result.values["parts.legs.kd"] - 0.5) < 3 * result.stderr["parts.legs.kd"]
    assert result.status.success and len(result.observation_goodness) == 3
    rows = sf.frame_table(result, sf.Pass.read(small_pass[4] / "frames.csv"))
    assert [r["time_s"] for r in rows] == [0.0, 10.0, 20.0]
    assert [r["target.attitude_x_deg"] for r in rows] == [result.values[f"target.attitude_x_deg@{k}"] for k in range(3)]


def test_the_pixel_grids_derivatives_are_each_frames_in_its_own_and_the_shared_values(small_pass, monkeypatch):
    """The pixel grid's changes of a pass with the blur shared and each frame's shift its own: the feedback's
    derivatives (forward mode) in each value are the central differences of the changes to the finer model, in the
    rows of every frame for the shared blur and of its own frame alone for a frame's shift; the three frames alike
    share their two programs, and the arrays their programs hold that are equal."""
    from spacefit.programs import AlikePrograms

    real_parse = ast.parse
    made: list[AlikePrograms] = []
    monkeypatch.setattr(residuals, "AlikePrograms", lambda share: made.append(AlikePrograms(share)) or made[-1])
    obs = small_pass[0]
    free = ["parts.legs.kd", "image.blur_sigma_px", *[f"image.shift_x_px@{k}" for k in range(3)]]
    s = problem.setup(obs, free, start={"parts.legs.kd": 0.5, "image.blur_sigma_px": 0.6}, render=sf.FitRender(spp=4))
    x, columns = np.asarray(s.x0, dtype=float), [1, 2, 3, 4]
    with jax.enable_x64(True):
        changes = s.problem.pixel_grid(x)
        each, _, derivatives = changes.settled(x, columns)
        np.testing.assert_allclose(each, changes.fine(x), rtol=1e-12, atol=1e-12)
        frame = np.repeat(np.arange(3), [ref.size for ref in s.problem.references])
        for i, j in enumerate(columns):
            h = np.zeros(len(x))
            h[j] = 1e-4
            central = (changes.fine(x + h) - changes.fine(x - h)).mean(axis=0) / 2e-4
            np.testing.assert_allclose(derivatives[i], central, rtol=0, atol=1e-5 * np.abs(central).max())
            touched = [bool(np.abs(derivatives[i][frame == k]).max() > 0) for k in range(3)]
            assert touched == ([True] * 3 if j == 1 else [k == j - 2 for k in range(3)]), j
        # the last evaluation (the grid step's): the same outputs, its renders dropped after, so nothing evaluates them again
        again = changes.settled(x, columns, last=True)
        np.testing.assert_array_equal(again[0], each)
        for i in range(len(columns)):
            np.testing.assert_array_equal(again[2][i], derivatives[i])
        with pytest.raises(RuntimeError, match="dropped by its last settled evaluation"):
            changes.fine(x)
        # settled's programs compiled ahead (the grid step's thread, beside the fixed point's iterations): the same bits;
        # and neither side parses Python with `ast` (CPython 3.11's parse trees are not safe across threads: the history,
        # "The report's modules imported on a thread")
        ahead = s.problem.pixel_grid(x)
        parsed: list[object] = []
        monkeypatch.setattr(ast, "parse", lambda *a, **k: parsed.append(a) or real_parse(*a, **k))
        ahead.ahead(x + 0.01, columns)  # values of the same shape: theirs are not used
        ahead.fine(x + 0.01)
        early = ahead.settled(x, columns, last=True)
        assert parsed == []
        np.testing.assert_array_equal(early[0], each)
        for i in range(len(columns)):
            np.testing.assert_array_equal(early[2][i], derivatives[i])
    assert len(made[0]._traced) == 6 and len(made[0]._programs) == 2  # each frame's two programs traced, compiled once
    settled_programs = [program for key, (program, *_) in made[1]._traced.items() if key[0].__name__ == "settled_changes"]
    assert len(settled_programs) == 3 and all(isinstance(program, jax.stages.Compiled) for program in settled_programs)
    # the arrays equal between frames (response matrices, frequency grids) held once, each frame's reference its own
    (_, first, _), (_, second, _) = list(made[0]._traced.values())[:2]
    shared = [a is b for a, b in zip(first, second)]
    assert shared == [bool(np.array_equal(a, b)) for a, b in zip(first, second)] and 0 < sum(shared) < len(shared)


@pytest.fixture(scope="module")
def client():
    from spacefit.executors import connect

    client, close = connect(2)
    yield client
    close()


def same_fit(a: sf.FitResult, b: sf.FitResult) -> None:
    """The guarantee of a fit on dask (docs/reference/passes.md, "Fits on dask"): the in-process fit's
    status, its values within 1e-3 of their standard errors, the same steps taken (every step's loss
    within 1e-9 relative: the workers' JAX sums may round apart, seen at 1e-11 in one trial step)."""
    assert a.status is b.status
    for name, value in b.values.items():
        assert abs(a.values[name] - value) <= 1e-3 * b.stderr[name], name
        assert a.stderr[name] == pytest.approx(b.stderr[name], rel=1e-3), name
    assert [h["accepted"] for h in a.history] == [h["accepted"] for h in b.history]
    np.testing.assert_allclose([h["loss"] for h in a.history], [h["loss"] for h in b.history], rtol=1e-9)


@pytest.mark.slow
def test_a_pass_fits_the_same_on_dask_as_in_process(small_pass, client):
    obs, free, options, in_process, _ = small_pass
    same_fit(sf.fit(obs, free, cluster=client, **options), in_process)


@pytest.mark.slow
def test_a_worker_killed_mid_fit_changes_nothing(small_pass, client):
    import os
    import signal
    import threading

    obs, free, options, in_process, _ = small_pass
    pids = client.run(os.getpid)
    killed = []

    def kill_one_soon(entry: dict) -> None:
        if entry["step"] == 1:  # during the next step's renders
            threading.Timer(0.2, lambda: (os.kill(next(iter(pids.values())), signal.SIGKILL), killed.append(1))).start()

    result = sf.fit(obs, free, cluster=client, resume=sf.Resume(on_step=kill_one_soon), **options)
    assert killed
    assert set(client.run(os.getpid).values()) != set(pids.values())  # the nanny started a new worker
    same_fit(result, in_process)


def test_spacefit_fit_pass_writes_the_frames_table_and_plot(small_pass, tmp_path, capsys, monkeypatch):
    """It says its size first; with --large it runs on a machine whose available memory is below that."""
    from spacefit.cli import main

    monkeypatch.setattr(memory, "available_memory_bytes", lambda: 2**20)

    folder = small_pass[4]
    scene = tmp_path / "scene.toml"
    scene.write_text(sf.load_scene("spacefit/synthetic/panels.toml", {"render.resolution": [24, 24], "camera.pixel_pitch_mm": 100.0}).to_toml())
    out = tmp_path / "fit"
    code = main(["fit", "--pass", str(folder / "frames.csv"), "--scene", str(scene), "--free", "parts.legs.kd",
                 "--per-frame", "target.attitude_x_deg", "--start", "parts.legs.kd=0.4", "--spp", "4", "--max-steps", "2",
                 "--out", str(out), "--large"])
    assert code in (0, 3)  # converged, or not after two steps: the report is written either way
    # its size first: 3 frames of 24 x 24 px, each seeing the albedo and its own attitude, at 4 spp
    first = capsys.readouterr().err.splitlines()[0]
    assert first == f"{describe_fit(3, 24, 24, fit_memory(3, 24 * 24, 2, 4))} (estimate)"
    assert {"frames.csv", "frames.png", "fit.json"} <= {p.name for p in out.iterdir()}
    rows = (out / "frames.csv").read_text().splitlines()
    assert len(rows) == 4 and "target.attitude_x_deg" in rows[0] and "chi2_dof" in rows[0] and "time_s" in rows[0]
    assert rows[2].split(",")[3] == "10.0"  # frame 1, 10 s after the first
    # the folder reads back: its result, and its frames as sf.frame_table gives them from it
    result = sf.read_fit(out)
    assert result.names == ("parts.legs.kd", *(f"target.attitude_x_deg@{k}" for k in range(3)))
    again = sf.frame_table(result, sf.Pass.read(folder / "frames.csv"))
    read = sf.read_frame_table(out / "frames.csv")
    assert [list(row) for row in read] == [list(row) for row in again]
    for row, other in zip(read, again):
        assert all(row[k] == other[k] or (row[k] != row[k] and other[k] != other[k]) for k in row), (row, other)  # NaN as NaN


@pytest.mark.slow
def test_a_pass_fit_interrupted_and_resumed_ends_as_the_uninterrupted_one(small_pass, tmp_path, monkeypatch):
    """`spacefit fit --pass` stopped by Ctrl-C after its second step (exit 130, the checkpoint kept), then
    run with --resume: the uninterrupted fit's status and exit code (the checkpoint's history keeps the
    stop rule's record), its legs' albedo and each frame's attitude (within 0.3 of their standard
    errors, the noise-floor rule's resolution: the solver restarts from the best point) and the frame
    table. Before the history was kept, the resumed fit ran its 6 steps left (exit 3, the step limit)."""
    import json
    import os
    import signal

    from spacefit.cli import main
    from spacefit.pipeline import Checkpoint

    scene = tmp_path / "scene.toml"
    scene.write_text(sf.load_scene("spacefit/synthetic/panels.toml", {"render.resolution": [24, 24], "camera.pixel_pitch_mm": 100.0}).to_toml())

    def args(out: str, *extra: str) -> list[str]:
        return ["fit", "--pass", str(small_pass[4] / "frames.csv"), "--scene", str(scene), "--free", "parts.legs.kd",
                "--per-frame", "target.attitude_x_deg", "--start", "parts.legs.kd=0.4", "--spp", "4", "--max-steps", "8",
                "--out", str(tmp_path / out), "--quiet", *extra]

    whole = main(args("whole"))
    update = Checkpoint.update

    def stop_after_two(self: Checkpoint, entry: dict) -> None:
        update(self, entry)
        if self.steps == 2:
            os.kill(os.getpid(), signal.SIGINT)  # taken at the end of the step, as a Ctrl-C is

    with monkeypatch.context() as m:
        m.setattr(Checkpoint, "update", stop_after_two)
        assert main(args("stopped")) == 130
    assert (tmp_path / "stopped" / "checkpoint.json").exists()
    assert main(args("stopped", "--resume")) == whole == 0
    assert not (tmp_path / "stopped" / "checkpoint.json").exists()
    expected, got = (json.loads((tmp_path / out / "fit.json").read_text()) for out in ("whole", "stopped"))
    assert got["status"] == expected["status"]
    for name, value in expected["values"].items():
        assert abs(got["values"][name] - value) < 0.3 * expected["stderr"][name], name
    assert len((tmp_path / "stopped" / "frames.csv").read_text().splitlines()) == 4


@pytest.mark.parametrize(("args", "message"), [
    (["a.exr", "--pass", "frames.csv"], "one of the two"),
    (["a.exr", "--per-frame", "target.attitude_x_deg"], "`--per-frame` goes with `--pass`"),
    (["--pass", "frames.txt"], "extension must be one of"),
])
def test_bad_pass_arguments_exit_2_before_anything_is_written(tmp_path, capsys, args, message):
    from spacefit.cli import main

    code = main(["fit", *args, "--scene", "spacefit/synthetic/panels.toml", "--free", "parts.legs.kd", "--out", str(tmp_path / "out")])
    assert code == 2 and message in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


# A calibrated camera: 500 DN per W m^-2 sr^-1, 0.5 DN per electron (1000 electrons per W m^-2 sr^-1).
PASS_SENSOR = sf.Sensor(radiometric_scale_dn_per_w_m2_sr=500.0, gain_dn_per_electron=0.5, bias_dn=100.0, read_noise_electrons=5.0,
                        bit_depth=16, full_well_electrons=None, diffraction=False, psf_sigma_px=0.0)


@pytest.mark.slow
def test_a_six_frame_pass_with_attitude_errors_recovers_materials_and_each_attitude(tmp_path):
    """Six frames (32 x 32 px) of an observer crossing the panels' glint, observed through a sensor
    (references at 1024 spp), each frame's target turned by up to 0.3 deg about x off its table's
    attitude; the materials from 20 % off and each frame's attitude fitted at 32 spp."""
    base = base_scene()
    errors = [{"target.attitude_x_deg": float(a)} for a in np.random.default_rng(3).uniform(-0.3, 0.3, 6)]
    frames = sf.simulate_pass(base, sf.arc_pass(6), tmp_path / "pass", errors=errors, sensor=PASS_SENSOR, spp=1024)
    obs = [sf.Observation.from_file(f.file, s) for f, s in zip(frames.frames, frames.scenes(base))]
    free = [*TRUTH, *frames.per_frame(["target.attitude_x_deg"])]
    result = sf.fit(obs, free, start=START, render=sf.FitRender(spp=32), max_steps=20)
    for name, tolerance in (("parts.panels.alpha_x", 0.05), ("parts.panels.alpha_y", 0.05), ("parts.legs.kd", 0.03)):
        assert result.values[name] == pytest.approx(TRUTH[name], rel=tolerance), name
    for k, error in enumerate(errors):
        assert abs(result.values[f"target.attitude_x_deg@{k}"] - error["target.attitude_x_deg"]) < 0.05, k
    assert len(result.observation_goodness) == 6 and all(q.noise_known for q in result.observation_goodness)


@pytest.mark.parametrize(("cluster", "message"), [
    (0, "`cluster` must be an integer >= 1"), (True, "`cluster` must be None, a number"), (1.5, "`cluster` must be None, a number"),
])
def test_a_bad_cluster_is_refused_before_anything_runs(cluster, message):
    with pytest.raises(sf.InputError) as err:
        sf.fit([], ["parts.legs.kd"], cluster=cluster)
    assert message in str(err.value)


def test_observation_files_take_one_frame_entry_per_reference():
    with pytest.raises(sf.InputError, match="`times` must give one entry per reference"):
        sf.ObservationFiles(["a.exr", "b.exr"], ["s.toml"], times=["0"])
    files = sf.Pass.from_columns(columns(pass_geometry(2))).observation_files("s.toml", sensor_values={"bias_dn": 90.0})
    assert files.times == ("2026-11-25T12:00:00.5", "2026-11-25T12:00:10.5")
    assert files._sensor_values(1) == {"bias_dn": 90.0, "exposure_time_s": 2e-6}  # the frame's own value added to the option's


def test_frames_share_a_loaded_scene_across_target_poses_only_when_they_set_the_pose():
    """Two views of a pass whose target is turned differently, materials free: their loaded scenes
    differ (the pose is loaded, not set) unless the frames set the pose from their view (a light
    curve's points, ``view_pose``)."""
    from spacefit.fitting.frames import _stage

    base = sf.Scene().with_values({"render.resolution": [8, 8], "camera.pixel_pitch_mm": 300.0, "wrinkles.enabled": False})
    scenes = [base.with_values({"target.attitude_z_deg": a, "sun.elevation_deg": e}) for a, e in ((0.0, 30.0), (40.0, 50.0))]
    specs = [FrameSpec(s, ("parts.legs.kd",), (0.0,), None, None, "prb", shared_view=True) for s in scenes]
    stages = [_stage(spec, assemble(spec.scene)) for spec in specs]
    assert stages[0] != stages[1]
    posed = [dataclasses.replace(spec, view_pose=True) for spec in specs]
    assert _stage(posed[0], assemble(scenes[0])) == _stage(posed[1], assemble(scenes[1]))


def test_a_frames_cached_jacobian_is_keyed_by_its_seeds_too():
    """The last Jacobian of a frame is reused at the same values and seeds only: other seeds render anew."""
    from types import SimpleNamespace

    def function(spec, key, kind):
        return lambda x, seeds: (np.full((1, 1, 3), float(seeds[1])), np.full((1, 1, 3, 1), float(seeds[0])))  # image, Jacobian

    loaded, spec = SimpleNamespace(jacobians={}, function=function), SimpleNamespace(names=("parts.legs.kd",))
    x = np.array([0.3])
    assert frame_jacobian(spec, "k", x, 1, 2, loaded)[0][0, 0, 0] == 2.0
    assert frame_jacobian(spec, "k", x, 1001, 1002, loaded)[0][0, 0, 0] == 1002.0


def test_a_fits_memory_estimate_grows_linearly_with_frames_from_its_inputs(small_pass):
    """Each added frame adds the same bytes, more per pixel and per free column; a fit's estimate is
    made from its images' count and size, the columns each frame sees (the shared albedo and its own
    attitude: 2) and the fit's spp (None: the scene's)."""
    steps = np.diff([fit_memory(n, 64 * 64, 2, 4) for n in range(1, 6)])
    assert np.all(steps == steps[0]) and steps[0] > 0
    assert fit_memory(2, 128 * 128, 2, 4) - fit_memory(1, 128 * 128, 2, 4) > steps[0]
    assert fit_memory(2, 64 * 64, 3, 4) - fit_memory(1, 64 * 64, 3, 4) > steps[0]
    obs, free, _, _, _ = small_pass
    size, estimate = images_memory(obs, free, {"parts.legs.kd", "target.attitude_x_deg"}, None)
    assert estimate == fit_memory(3, 24 * 24, 2, obs[0].scene.render.spp)
    assert size == describe_fit(3, 24, 24, estimate)
    assert images_memory(obs, free[:1], {"parts.legs.kd"}, 8)[1] == fit_memory(3, 24 * 24, 1, 8)


BENCH_COLUMNS, BENCH_SPP = 9, 16  # experiments/bench_pass.py's pass: a frame's renderer sees the 4 shared values and its own 5


# the runs of experiments/bench_pass.py stored in experiments/results/pass_memory/ that the estimate's constants are fitted
# to (spacefit/rendering/memory.py): the code's own at 128 x 128 px, and at 64 x 64 px an earlier commit's, whose peaks the
# C heap's pages handed back between the phases can only lower (the others there: earlier code, higher peaks)
CALIBRATION = ("bench_pass_64px.txt", "bench_pass_128px_ad0af01.txt", "bench_pass_128px_2c682df.txt")


def bench_peaks() -> list[tuple[int, int, float]]:
    """(size in px, frames, peak MiB) of each run of ``experiments/bench_pass.py`` in :data:`CALIBRATION`."""
    out = []
    for path in (Path(__file__).parents[1] / "experiments" / "results" / "pass_memory" / name for name in CALIBRATION):
        text = path.read_text()
        size = int(re.search(r"commit \w+; (\d+) x \d+ px, 16 spp", text).group(1))
        out += [(size, int(n), float(peak)) for n, peak in re.findall(r"^ *(\d+) frames: .*, peak (\d+) MiB", text, re.M)]
    return out


def test_a_fits_memory_estimate_is_at_or_above_the_measured_peaks_of_the_bench_pass_within_a_fifth():
    """The estimate against issue 33's 64-parameter pass as measured (12, 24 and 48 frames at 64 px, 12 and 48 at 128 px,
    each in a fresh process): never below a peak, and at most a fifth above it (the peaks scatter with the allocator's
    state by some 15 %: docs/measurements/performance-history.md, "A regression in memory at 48 frames")."""
    peaks = bench_peaks()
    assert {(size, n) for size, n, _ in peaks} >= {(64, 12), (64, 24), (64, 48), (128, 12), (128, 48)}
    for size, n, peak in peaks:
        ratio = fit_memory(n, size * size, BENCH_COLUMNS, BENCH_SPP) / 2**20 / peak
        assert 1.0 <= ratio <= 1.2, (size, n, peak, ratio)


@pytest.mark.skipif(not hasattr(ctypes.CDLL(None), "malloc_trim"), reason="glibc's malloc_trim")
def test_the_freed_pages_a_fit_s_phases_leave_in_the_c_heap_are_handed_back_to_the_system():
    """64 MiB freed in 64 KiB blocks (below glibc's mmap threshold: kept in the heap, under a block still in use) stay
    resident until :func:`~spacefit.rendering.memory.release_freed_memory` hands them back."""
    libc = ctypes.CDLL(None)
    libc.malloc.restype, libc.free.argtypes = ctypes.c_void_p, [ctypes.c_void_p]
    resident = lambda: int(Path("/proc/self/statm").read_text().split()[1]) * os.sysconf("SC_PAGE_SIZE")  # noqa: E731
    blocks = [libc.malloc(1 << 16) for _ in range(1024)]
    for block in blocks:
        ctypes.memset(block, 1, 1 << 16)
    above = libc.malloc(1 << 16)
    for block in blocks:
        libc.free(block)
    held = resident()
    memory.release_freed_memory()
    handed_back = held - resident()
    libc.free(above)
    assert handed_back >= 60 * 2**20


def test_a_pass_s_render_batch_hands_the_freed_heap_back_before_and_after_and_a_single_image_s_does_not(monkeypatch):
    """Several frames' renders (a pass's): the C heap's freed pages handed back before the batch (what the solver's step
    freed) and after it (what the renders freed); one frame's renders (a single image's fit, whose CPU is the concern):
    never. The frames' results are the function's, in order."""
    calls = []
    monkeypatch.setattr("spacefit.fitting.frames.release_freed_memory", lambda: calls.append("released"))
    fn = lambda spec, key, value, loaded=None: calls.append(value) or 2 * value  # noqa: E731
    specs = tiny_frames(2)
    assert run_frames(InProcess(), fn, specs, [1, 2]) == [2, 4]
    assert calls == ["released", 1, 2, "released"]
    calls.clear()
    assert run_frames(InProcess(), fn, specs[:1], [3]) == [6]
    assert calls == [3]


def test_a_fit_too_large_for_the_machine_is_refused_with_its_estimate_and_nothing_written(small_pass, tmp_path, monkeypatch, capsys):
    from spacefit.cli import main

    obs, free, options, _, folder = small_pass
    monkeypatch.setattr(memory, "available_memory_bytes", lambda: 2**20)
    estimate = fit_memory(3, 24 * 24, 2, 8)
    message = (f"a fit of 3 frames of 24 x 24 px needs about {estimate / 2**30:.2f} GiB of memory (estimate) and this machine has "
               "0.00 GiB available; fit fewer frames or fewer pixels, or pass allow_large=True (--large) to run it.")
    with pytest.raises(sf.InputError) as error:
        sf.fit(obs, free, **options)
    assert str(error.value) == message
    assert images_memory(obs, free, {"parts.legs.kd", "target.attitude_x_deg"}, 8, allow_large=True)[1] == estimate
    monkeypatch.setattr(problem, "LARGE_FIT_BYTES", estimate - 1)  # a large fit says its size before it starts
    with pytest.warns(UserWarning, match=re.escape(f"{describe_fit(3, 24, 24, estimate)} (estimate).")):
        problem.setup(obs, free, render=sf.FitRender(spp=8), allow_large=True)
    scene = tmp_path / "scene.toml"
    scene.write_text(obs[0].scene.to_toml())
    code = main(["fit", "--pass", str(folder / "frames.csv"), "--scene", str(scene), "--free", "parts.legs.kd",
                 "--per-frame", "target.attitude_x_deg", "--spp", "8", "--out", str(tmp_path / "fit")])
    assert code == 2 and capsys.readouterr().err.strip() == f"spacefit: error: {message}"
    assert [p.name for p in tmp_path.iterdir()] == ["scene.toml"]


@pytest.mark.slow
@float64
def test_a_pass_s_covariance_streamed_a_direction_at_a_time_equals_it_in_batches(monkeypatch):
    """The covariance's products of a three-frame pass (the legs' albedo and the blur shared, each frame's attitude
    and shift its own: 4 directions) applied one direction at a time (normal_equations.CHUNK_ELEMENTS below a
    vector's rows, as a long pass's are) equal those applied in one batch, to the float32 renders' rounding."""
    from spacefit.fitting import normal_equations
    from spacefit.fitting.uncertainty import covariance, linearise

    specs = tiny_frames(3)
    obs = [sf.Observation(spec.scene, sf.render(spec.scene.with_values({"render.spp": 4})), sigma=0.02) for spec in specs]
    free = ["parts.legs.kd", "image.blur_sigma_px", *sf.Pass.from_columns({"file": ["a", "b", "c"], "time": [0, 1, 2]}).per_frame(
        ["target.attitude_x_deg", "image.shift_x_px"])]
    s = problem.setup(obs, free, start={"parts.legs.kd": 0.4, "image.blur_sigma_px": 0.5}, render=sf.FitRender(spp=2))
    p = dataclasses.replace(s.problem, noise_known=True)
    lin = linearise(p, s.x0)
    assert normal_equations.chunk_for(lin.r.size) == normal_equations.MAX_CHUNK
    batched = covariance(p, s.x0, lin)
    monkeypatch.setattr(normal_equations, "CHUNK_ELEMENTS", lin.r.size - 1)
    assert normal_equations.chunk_for(lin.r.size) == 1
    cov, loss, fisher, correction = covariance(p, s.x0, linearise(p, s.x0))
    stderr = np.sqrt(np.diag(batched[0]))
    # the renders' float32 sums, J^T v, round one way or the other by the batch: up to 1.3e-6 of a covariance here
    assert np.all(np.abs(cov - batched[0]) <= 1e-5 * np.outer(stderr, stderr))
    assert np.all(np.abs(correction - batched[3]) <= 1e-5 * stderr)
    np.testing.assert_allclose(fisher, batched[2], rtol=1e-5)
    assert loss == batched[1]


@pytest.mark.slow
@float64
def test_a_pass_s_normal_equations_and_errors_apply_one_direction_per_kind_of_own_value():
    """Three frames, the legs' albedo and the blur shared, each frame's attitude and shift its own: J^T J of the
    solver's damped operator and every product of the covariance, applied to 2 + 2 directions
    (normal_equations.probes), equal those applied to the 8 columns one by one, in float64 as a fit's are
    (in JAX's 32-bit mode the correction's rounding alone reached 1.8e-6 of a standard error)."""
    import lineax as lx  # here: only this test builds the solver's operator itself

    from spacefit.fitting.normal_equations import gram
    from spacefit.fitting.uncertainty import covariance, linearise

    specs = tiny_frames(3)
    obs = [sf.Observation(spec.scene, sf.render(spec.scene.with_values({"render.spp": 4})), sigma=0.02) for spec in specs]
    free = ["parts.legs.kd", "image.blur_sigma_px", *sf.Pass.from_columns({"file": ["a", "b", "c"], "time": [0, 1, 2]}).per_frame(
        ["target.attitude_x_deg", "image.shift_x_px"])]
    s = problem.setup(obs, free, start={"parts.legs.kd": 0.4, "image.blur_sigma_px": 0.5}, render=sf.FitRender(spp=2))
    owners = residuals.column_owners(s.solver_params, s.problem.blocks)
    assert owners == (-1, -1, 0, 1, 2, 0, 1, 2)
    lin = linearise(s.problem, s.x0)
    alone = dataclasses.replace(lin, owners=None)
    damped = lx.FunctionLinearOperator(lambda v: (lin.J1(v), 0.3 * v), jax.ShapeDtypeStruct((len(free),), lin.x.dtype))
    # the renders' float32 sums, J^T v, round one way or the other: to 1e-9 of the largest entry here
    want = gram(damped)
    np.testing.assert_allclose(gram(damped, owners=owners), want, rtol=0.0, atol=1e-7 * np.abs(want).max())
    # the noise known: the information, the render noise's (a weight joining neighbouring pixels) and the Jacobian noise's products
    p = dataclasses.replace(s.problem, noise_known=True)
    (cov, loss, fisher, correction), want = covariance(p, s.x0, lin), covariance(p, s.x0, alone)
    stderr = np.sqrt(np.diag(want[0]))
    assert np.all(np.abs(cov - want[0]) <= 1e-6 * np.outer(stderr, stderr))
    assert np.all(np.abs(correction - want[3]) <= 1e-6 * stderr)
    np.testing.assert_allclose(fisher, want[2], rtol=1e-6)
    assert loss == want[1]
