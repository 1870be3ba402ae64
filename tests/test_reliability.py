"""Nothing lost, nothing silently wrong: bad input, output folders, interruptions and resources.

Each class of mistake is a table of cases run through the command line (in process through
``main``, and in a subprocess where only a real process shows it: tracebacks, signals) and the
Python API, asserting the exit code, that the message names the argument, that no traceback
reaches the user, and the output folder's exact content before and after.
"""

from __future__ import annotations

import json
import os
import signal
import stat
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from helpers import small_scene, write_plate_obj, write_sphere_fit_case

import spacefit as sf
from spacefit.cli import INTERRUPTED, TERMINATED, main
from spacefit.output import STAGE_PREFIX, write_json

RENDER_FILES = ["preview.png", "radiance.exr", "render.json", "scene.toml"]
FIT_FILES = ["comparison.png", "convergence.png", "fit.json", "fit.toml", "residuals.fits", "uncertainty.json"]


def listing(folder: Path) -> list[str]:
    return sorted(os.listdir(folder)) if folder.exists() else []


@pytest.fixture(scope="module")
def plate_toml(tmp_path_factory) -> Path:
    """A tiny scene file: a 16 x 16 px Lambert plate."""
    d = tmp_path_factory.mktemp("plate")
    scene = small_scene(write_plate_obj(d / "plate.obj"), {"material": "white_paint", "kd": 0.5},
                        render={"resolution": [16, 16], "spp": 2})
    (d / "scene.toml").write_text("# the user's own comments\n" + scene.to_toml())
    return d / "scene.toml"


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--set", "sun.irradiance_w_m2=1e39"], r"sun\.irradiance_w_m2.*1e\+20"),
        (["--set", "sun.direction=[0, 0, 0]"], r"sun\.direction.*zero"),
        (["--set", "camera.position_m=[0, 0, 1e39]"], r"camera\.position_m.*100000 m"),
        (["--set", "target.position_m=[0, 0, -1e300]"], r"target\.position_m"),
        (["--set", "parts.plate.kd=true"], r"kd.*boolean"),
        (["--set", "wrinkles.enabled=true", "--set", "wrinkles.parts=['plate']", "--set", "wrinkles.M=100000000"],
         r"wrinkles\.M.*at most 64"),
        (["--set", "wrinkles.enabled=true", "--set", "wrinkles.parts=['plate']", "--set", "wrinkles.gamma=1.0000001"],
         r"wrinkles\.gamma.*at most 64"),
        (["--set", "wrinkles.enabled=true", "--set", "wrinkles.parts=['plate']", "--set", "wrinkles.Ls=1e-300"],
         r"wrinkles\.Ls"),
        (["--set", "wrinkles.enabled=true", "--set", "wrinkles.parts=['plate']", "--set", "wrinkles.spacing_m=1e-5"],
         r"wrinkles\.spacing_m.*at least"),
        (["--set", "render.variant='scalar_rgb'"], r"render\.variant"),
        (["--set", "camera.up=" + "[" * 3000 + "]" * 3000], r"camera\.up"),
        (["--set", "camera.position_m=[" + ", ".join(["1"] * 100000) + "]"], r"camera\.position_m"),
    ],
)
def test_bad_render_input_exits_2_naming_it_and_writes_nothing(plate_toml, tmp_path, capsys, extra, message):
    out = tmp_path / "out"
    assert main(["render", str(plate_toml), "--out", str(out), "--quiet", *extra]) == 2
    err = capsys.readouterr().err
    assert err.startswith("spacefit: error: ") and "Traceback" not in err
    assert len(err) < 2500, "a long value must be shortened in the message"
    import re

    assert re.search(message, err), err
    assert not out.exists()


@pytest.mark.parametrize(
    ("make", "args", "message"),
    [
        (lambda d: None, ["--out", ""], "empty"),
        (lambda d: (d / "out").mkdir() or (d / "out" / "mine.txt").write_text("x"), ["--out", "{d}/out"], "did not write"),
        (lambda d: None, ["{d}/folder_scene", "--out", "{d}/out"], "is a folder"),
    ],
)
def test_output_folder_refusals(tmp_path, capsys, make, args, message):
    (tmp_path / "folder_scene").mkdir()
    make(tmp_path)
    before = {p: p.read_bytes() for p in tmp_path.rglob("*") if p.is_file()}
    assert main(["render", *[a.format(d=tmp_path) for a in args], "--quiet"]) == 2
    assert message in capsys.readouterr().err
    assert {p: p.read_bytes() for p in tmp_path.rglob("*") if p.is_file()} == before


def test_the_input_scene_is_never_written_over(plate_toml, tmp_path, capsys):
    folder = tmp_path / "work"
    folder.mkdir()
    scene = folder / "scene.toml"
    scene.write_bytes(plate_toml.read_bytes())
    assert main(["render", str(scene), "--out", str(folder), "--quiet"]) == 2
    assert "input" in capsys.readouterr().err
    assert scene.read_bytes() == plate_toml.read_bytes() and listing(folder) == ["scene.toml"]
    assert main(["scene", str(scene), "--out", str(scene), "--overwrite"]) == 2
    assert scene.read_bytes() == plate_toml.read_bytes()


def test_a_scene_written_over_a_pipe_or_a_folder_is_refused_and_leaves_it_as_it_was(tmp_path, capsys):
    """`spacefit scene --out X --overwrite` moves a whole new file into place: over a device (run as root, it had
    turned /dev/null into a regular file), a pipe or a folder that would replace it; they are refused instead."""
    pipe, folder = tmp_path / "pipe", tmp_path / "folder"
    os.mkfifo(pipe)
    folder.mkdir()
    (folder / "kept.txt").write_text("mine")
    for target in (pipe, folder):
        assert main(["scene", "--out", str(target), "--overwrite"]) == 2
        err = capsys.readouterr().err
        assert err.startswith("spacefit: error: ") and "is not a regular file" in err and str(target) in err, err
    assert stat.S_ISFIFO(os.stat(pipe).st_mode) and listing(folder) == ["kept.txt"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["folder", "pipe"]  # no stage left


def test_a_previous_render_is_replaced_only_with_overwrite(plate_toml, tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["render", str(plate_toml), "--out", str(out), "--quiet"]) == 0
    assert listing(out) == RENDER_FILES
    first = (out / "radiance.exr").read_bytes()
    assert main(["render", str(plate_toml), "--out", str(out), "--quiet", "--set", "parts.plate.kd=0.9"]) == 2
    assert "--overwrite" in capsys.readouterr().err and (out / "radiance.exr").read_bytes() == first
    assert main(["render", str(plate_toml), "--out", str(out), "--quiet", "--overwrite", "--set", "parts.plate.kd=0.9"]) == 0
    assert listing(out) == RENDER_FILES and (out / "radiance.exr").read_bytes() != first


def test_export_stl_refuses_another_extension_and_existing_files(tmp_path, capsys):
    assert main(["export-stl", "--out", str(tmp_path / "body.obj")]) == 2
    assert ".stl" in capsys.readouterr().err and listing(tmp_path) == []
    (tmp_path / "body.stl").write_text("mine")
    assert main(["export-stl", "--out", str(tmp_path / "body.stl")]) == 2
    assert (tmp_path / "body.stl").read_text() == "mine"


def test_a_render_too_big_for_the_memory_is_refused_before_it_starts(plate_toml, tmp_path, capsys, monkeypatch):
    """The estimate (film and wavefront) against the memory available; here a machine with 1 GiB free."""
    import spacefit.rendering.memory as memory

    monkeypatch.setattr(memory, "available_memory_bytes", lambda: 1 << 30)
    assert main(["render", str(plate_toml), "--out", str(tmp_path / "out"), "--set", "render.resolution=[4096, 4096]"]) == 2
    err = capsys.readouterr().err
    needs = float(err.split("needs about ")[1].split(" GiB")[0])
    assert 1.25 <= needs < 2.0 and "this machine has 1.0 GiB available" in err  # the film alone is 1.25 GiB
    assert listing(tmp_path) == []


def test_a_fit_render_too_big_for_the_memory_is_refused_before_jax(plate_toml, monkeypatch):
    """A fit's renders are one wavefront (not split into passes): its samples count, naming `spp`
    (`fit --spp 1e8` failed inside JAX; 1e8 is now past render.spp's range, and this is within it)."""
    import spacefit.rendering.memory as memory

    monkeypatch.setattr(memory, "available_memory_bytes", lambda: 1 << 28)
    scene = sf.load_scene(plate_toml)
    with pytest.raises(sf.InputError, match=r"16 x 16 px render at 65536 spp needs about 1\.0 GiB .* or `spp`"):
        sf.jacobian(scene, ["parts.plate.kd"], spp=65536)
    assert sf.jacobian(scene, ["parts.plate.kd"], spp=4).image.shape == (16, 16, 3)


def test_strict_json_writes_non_finite_numbers_as_null(tmp_path):
    write_json(tmp_path / "a.json", {"x": float("nan"), "y": [1.0, float("inf")], "z": np.float32(2.5)})
    data = json.loads((tmp_path / "a.json").read_text(), parse_constant=lambda c: pytest.fail(f"bare {c}"))
    assert data["x"] is None and data["y"] == [1.0, None] and data["z"] == 2.5 and "nonfinite_as_null" in data


def test_black_render_says_why(tmp_path):
    mesh = write_plate_obj(tmp_path / "plate.obj")
    behind = small_scene(mesh, {"material": "white_paint", "kd": 0.5}, sun={"direction": [0.0, 0.0, 1.0]},
                         render={"resolution": [16, 16], "spp": 2})
    with pytest.warns(UserWarning, match="sun is behind the target"):
        _, sidecar = sf.render_to_folder(behind, tmp_path / "out", quiet=True)
    assert sidecar["warnings"] and "phase angle" in sidecar["warnings"][0]


def test_truncated_stl_and_scene_files_are_named(tmp_path):
    stl = tmp_path / "part.stl"
    stl.write_bytes(b"\0" * 80 + (12).to_bytes(4, "little") + b"\0" * 100)
    scene = {"target": {"mesh": str(stl)}, "wrinkles": {"enabled": False}, "parts": {"part": {"material": "white_paint"}}}
    with pytest.raises(sf.InputError, match=r"not a whole binary STL: 184 bytes .* 684 bytes"):
        sf.render(_scene_from(scene, tmp_path))
    bom = tmp_path / "bom.toml"
    bom.write_text("\ufeff[render]\nspp = 3\n", encoding="utf-8")
    assert sf.load_scene(bom).render.spp == 3


def _scene_from(data: dict, folder: Path) -> sf.Scene:
    path = folder / "scene.toml"
    import tomli_w

    path.write_text(tomli_w.dumps(data))
    return sf.load_scene(path)


@pytest.mark.parametrize(
    ("call", "error", "message"),
    [
        (lambda: sf.render("scene.toml"), TypeError, "Scene"),
        (lambda: sf.Renderer(42), TypeError, "Scene"),
        (lambda: sf.load_scene(3.5), TypeError, "path"),
        (lambda: sf.default_scene().with_values(["render.spp=3"]), TypeError, "mapping"),
        (lambda: sf.default_scene().with_values({"render.spp": "many"}), ValueError, "render.spp"),
        (lambda: sf.Observation(sf.default_scene(), np.ones((4, 4, 3), complex)), TypeError, "complex"),
        (lambda: sf.fit([object()], ["parts.legs.kd"]), TypeError, r"observations\[0\]"),
        (lambda: sf.fit(sf.Observation(sf.default_scene(), -np.ones((600, 600, 3))), ["parts.legs.kd"]), ValueError,
         "360000 pixels with negative"),
        (lambda: sf.jacobian(sf.default_scene(), ["parts.legs.kd"], spp=1.5), ValueError, "spp"),
        # issue 20: each raised something other than sf.InputError
        (lambda: sf.fit(None, ["parts.legs.kd"]), TypeError, "`observations` must be an sf.Observation"),
        (lambda: sf.fit(_observation(), "parts.legs.kd"), TypeError, "`free` must be a list of names"),
        (lambda: sf.fit(_observation(), ["parts.legs.kd"], start=[0.3]), TypeError, "`start` must be a mapping"),
        (lambda: sf.fit(_observation(), ["parts.legs.kd"], start={"parts.legs.kd": "a"}), TypeError, "`parts.legs.kd` must be a number"),
        (lambda: sf.FitRender(seed=-1), ValueError, r"`seed` must be an integer in \[0, 2147483647\].*32-bit"),
        (lambda: sf.FitRender(spp=10**8), ValueError, r"`spp` must be an integer in \[1, 65536\]"),
        (lambda: sf.Observation(sf.default_scene(), np.ones((600, 600, 3)), sigma=np.ones((3, 5))), ValueError,
         r"`Observation.sigma` has shape \(3, 5\)"),
        (lambda: sf.Observation(sf.default_scene(), [[1.0, 2.0], [3.0]]), TypeError, "`Observation.reference` must be an array"),
        (lambda: sf.observe(np.ones((4, 4, 3)), sf.Sensor(), sf.Intrinsics(0.05, 5e-5, 4, 4), -1), ValueError,
         "`seed` must be an integer >= 0, got -1"),
        (lambda: sf.Intrinsics(0.05, -5e-5, 4, 4), ValueError, "`Intrinsics.pixel_pitch`"),
        (lambda: sf.sensitivity(sf.default_scene(), ["parts.legs.kd"], seeds=None), TypeError, "`seeds` must be an integer"),
        (lambda: sf.light_curve(sf.default_scene(), phase_deg="x"), TypeError, "`phase_deg` must be a list of numbers"),
        # derived quantities that passed the checks and failed inside Mitsuba
        (lambda: sf.default_scene().with_values({"camera.focal_length_mm": 1e-200}), ValueError,
         "`camera.focal_length_mm`, `camera.pixel_pitch_mm` and `render.resolution` give a horizontal field of view of 180 deg"),
        (lambda: sf.default_scene().with_values({"camera.focal_length_mm": 1e9}), ValueError, "gives pixels of 4e-09 rad; at least 1e-06"),
        (lambda: sf.Renderer(sf.default_scene()).render(seed=-1), ValueError, r"`seed` must be an integer in \[0, 2147483647\]"),
        (lambda: sf.jacobian(sf.default_scene(), ["parts.legs.kd"], at={"parts.legs.kd": "x"}), TypeError, "`parts.legs.kd` must be a number"),
        (lambda: sf.write_exr("image.png", np.ones((4, 4, 3))), ValueError, r"`path` must end in \.exr"),
        (lambda: sf.read_image(None), TypeError, "`path` must be a path"),
        # found by tests/test_fuzz.py
        (lambda: sf.default_scene().with_values({"parts.legs.file": "a\0"}), ValueError, "`parts.legs.file` must not hold a NUL"),
        (lambda: sf.default_scene().with_values({"camera.attitude_deg": {}}), ValueError, r"`camera.attitude_deg` = \{\} sets nothing"),
    ],
)
def test_api_mistakes_raise_input_errors(call, error, message):
    with pytest.raises(sf.InputError, match=message) as info:
        call()
    assert isinstance(info.value, error)


def _observation() -> sf.Observation:
    return sf.Observation(sf.default_scene(), np.ones((600, 600, 3)))


def test_a_wide_camera_renders_or_is_refused_naming_its_keys(tmp_path):
    """A field of view up to MAX_FOV_DEG renders; past it the keys that make it are named, before Mitsuba."""
    from spacefit.scene.sections import MAX_FOV_DEG

    scene = small_scene(write_plate_obj(tmp_path / "plate.obj"), {"material": "white_paint", "kd": 0.5},
                        render={"resolution": [16, 16], "spp": 1}, camera={"position_m": [0.0, 0.0, 0.2]})
    half_width_mm = 8 * scene.camera.pixel_pitch_mm
    focal = {fov: half_width_mm / np.tan(np.radians(fov) / 2) for fov in (170.0, MAX_FOV_DEG - 0.01, MAX_FOV_DEG + 0.01)}
    for fov in (170.0, MAX_FOV_DEG - 0.01):
        image = sf.render(scene.with_values({"camera.focal_length_mm": focal[fov]}))
        assert np.all(np.isfinite(image)) and image.max() > 0
    with pytest.raises(sf.InputError, match=r"`camera.focal_length_mm`.*horizontal field of view of 179.01 deg.*at most 179 deg"):
        scene.with_values({"camera.focal_length_mm": focal[MAX_FOV_DEG + 0.01]})
    with pytest.raises(sf.InputError, match=r"vertical field of view"):
        scene.with_values({"camera.focal_length_mm": focal[170.0], "render.resolution": [16, 320]})


def test_a_far_camera_is_not_clipped_and_a_near_one_is_refused(tmp_path):
    """Mitsuba's default far clip (1e4 m) rendered a target seen from 20 km black; the same view at 2 km and
    20 km (focal length scaled with the distance) gives the same image. Nearer than the near clip is refused."""
    scene = small_scene(write_plate_obj(tmp_path / "plate.obj"), {"material": "white_paint", "kd": 0.5},
                        render={"resolution": [8, 8], "spp": 4}, camera={"look_at_m": [], "pixel_pitch_mm": 0.5})
    images = [sf.render(scene.with_values({"camera.position_m": [0.0, 0.0, z], "camera.focal_length_mm": 5.0 * z}))
              for z in (2e3, 2e4)]
    assert images[1].mean() > 0 and np.allclose(images[0], images[1], rtol=1e-3)
    with pytest.raises(sf.InputError, match="near clipping plane at 0.01 m"):
        sf.render(scene.with_values({"camera.position_m": [0.0, 0.0, 0.005]}))


def test_a_huge_or_tiny_up_vector_renders_as_a_unit_one(tmp_path):
    """`camera.up` = [0, 1e300, 0] passed the checks and made Mitsuba refuse a scaled camera (found by tests/test_fuzz.py)."""
    scene = small_scene(write_plate_obj(tmp_path / "plate.obj"), {"material": "white_paint", "kd": 0.5},
                        render={"resolution": [8, 8], "spp": 1})
    image = sf.render(scene)
    for up in ([0.0, 1e300, 0.0], [0.0, 1e-300, 0.0]):
        assert np.array_equal(sf.render(scene.with_values({"camera.up": up})), image)


def test_numpy_and_jax_scalars_are_numbers():
    import jax.numpy as jnp

    scene = sf.default_scene().with_values({"camera.focal_length_mm": np.float32(2.3e3), "render.spp": np.int64(16),
                                            "parts.legs.kd": jnp.float32(0.3)})
    assert scene.render.spp == 16 and scene.camera.focal_length_mm == pytest.approx(2300.0)
    assert sf.Conductor(eta=np.float64(2.0), k=jnp.asarray(0.1), alpha_x=np.float32(0.1), alpha_y=0.1).alpha_x == pytest.approx(0.1)


def test_stale_stage_of_a_dead_process_is_removed(plate_toml, tmp_path):
    out = tmp_path / "out"
    assert main(["render", str(plate_toml), "--out", str(out), "--quiet"]) == 0
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    stale = out / f"{STAGE_PREFIX}{dead.stdout.strip()}-abc"
    stale.mkdir()
    (stale / "radiance.exr").write_text("half")
    with pytest.warns(UserWarning, match="staging folder left by an interrupted"):
        assert main(["render", str(plate_toml), "--out", str(out), "--quiet", "--overwrite"]) == 0
    assert listing(out) == RENDER_FILES


# Interruptions, in real processes: the signal arrives while the command works.

def spacefit_process(args: list[str]) -> subprocess.Popen:
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    return subprocess.Popen([sys.executable, "-m", "spacefit.cli", *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env=env)


@pytest.fixture(scope="module")
def fit_case(tmp_path_factory) -> Path:
    """A Lambert sphere: a reference at kd 0.5 and a scene starting at kd 0.2, slow enough to interrupt."""
    return write_sphere_fit_case(tmp_path_factory.mktemp("fitcase"), subdivisions=3, size=48, spp=16)


def fit_args(case: Path, out: Path, *extra: str) -> list[str]:
    return ["fit", str(case / "ref.exr"), "--scene", str(case / "scene.toml"), "--free", "parts.sphere.kd",
            "--out", str(out), "--solver", "adam", "--max-steps", "40", *extra]


def wait_for(path: Path, process: subprocess.Popen, timeout: float = 240.0) -> None:
    t0 = time.time()
    while not path.exists():
        assert process.poll() is None, process.communicate()
        assert time.time() - t0 < timeout, "timed out"
        time.sleep(0.2)


@pytest.mark.parametrize(("sig", "code"), [(signal.SIGINT, INTERRUPTED), (signal.SIGTERM, TERMINATED)])
def test_interrupted_fit_reports_its_best_point_and_resumes(fit_case, tmp_path, sig, code):
    out = tmp_path / "run"
    p = spacefit_process(fit_args(fit_case, out))
    wait_for(out / "checkpoint.json", p)
    time.sleep(1.0)
    p.send_signal(sig)
    _, err = p.communicate(timeout=240)
    assert p.returncode == code, err
    assert "Traceback" not in err and "interrupted" in err
    assert listing(out) == sorted([*FIT_FILES, "checkpoint.json"])
    report = json.loads((out / "fit.json").read_text())
    assert report["status"].startswith({signal.SIGINT: "stopped: interrupted", signal.SIGTERM: "stopped: terminated"}[sig])
    checkpoint = json.loads((out / "checkpoint.json").read_text())
    assert report["values"] == pytest.approx(checkpoint["best"]["values"])  # the interruption waits for the step's end
    # resumed, it ends where an uninterrupted fit ends (kd 0.5, within the fit's accuracy); --max-steps
    # counts the steps before the interruption, so the budget is the first run's plus 20
    steps = checkpoint["steps"]
    assert main([*fit_args(fit_case, out), "--resume", "--quiet", "--solver", "lm", "--max-steps", str(steps + 20)]) == 0
    assert listing(out) == FIT_FILES
    assert json.loads((out / "fit.json").read_text())["values"]["parts.sphere.kd"] == pytest.approx(0.5, abs=0.01)


def test_resume_refuses_other_inputs(fit_case, tmp_path, capsys):
    out = tmp_path / "run"
    out.mkdir()
    write_json(out / "checkpoint.json", {"inputs": {"free": ["parts.sphere.kd"], "sigma": 9.0}, "best": {"loss": 1.0, "values": {}},
                                         "steps": 1, "versions": {"spacefit": "0.1.0"}})
    assert main([*fit_args(fit_case, out), "--resume", "--quiet"]) == 2
    assert "other" in capsys.readouterr().err


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM, signal.SIGKILL])
def test_interrupted_render_leaves_nothing_half_written(tmp_path, sig):
    """A render stopped at any point leaves the folder as it was: absent, or a previous result."""
    out = tmp_path / "out"
    p = spacefit_process(["render", "--out", str(out), "--set", "render.spp=64", "--set", "render.resolution=[300, 300]",
                          "--set", "camera.pixel_pitch_mm=8"])
    time.sleep(4.0)  # imports and set-up take about 3 s: the signal lands in the assembly, the render or the writing
    p.send_signal(sig)
    _, err = p.communicate(timeout=240)
    if p.returncode == 0:  # finished before the signal: a whole result
        assert listing(out) == RENDER_FILES
        return
    assert "Traceback" not in err
    if sig != signal.SIGKILL:
        assert p.returncode == {signal.SIGINT: INTERRUPTED, signal.SIGTERM: TERMINATED}[sig], err
    leftovers = [n for n in listing(out) if not n.startswith(STAGE_PREFIX)]
    assert leftovers in ([], RENDER_FILES)
