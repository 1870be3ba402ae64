"""`spacefit fit` and `fit_to_folder`: the report folder, and every bad input refused before rendering."""

from __future__ import annotations

import gc
import json
import os
import subprocess
import sys
from pathlib import Path

import jax
import numpy as np
import pytest
from astropy.io import fits
from helpers import small_scene, write_sphere_obj

import spacefit as sf
from spacefit import cli
from spacefit.cli import AT_BOUND, MISFIT, NO_PROGRESS, NOT_CONVERGED, UNJUDGED, exit_code, main
from spacefit import FitResult
from spacefit.imageio import sidecar_path
from spacefit.rendering.png import write_png
from spacefit.scene.assembly import assemble
from spacefit.scene.toml import load_scene
from spacefit.pipeline import fit_to_folder
from spacefit.rendering.renderer import render
from spacefit.rendering.exr import read_exr, write_exr
from spacefit.fitting.compile_cache import ENV as JAX_CACHE_ENV, compile_cache_dir, use_compile_cache
from spacefit.geometry.cache import ENV as SPACEFIT_CACHE_ENV

TRUE_KD = 0.5
REPORT = ["comparison.png", "convergence.png", "fit.json", "fit.toml", "residuals.fits", "uncertainty.json"]


@pytest.fixture(scope="module")
def case(tmp_path_factory) -> Path:
    """A 32 x 32 Lambert sphere: references (kd 0.5, seed 7) from two sun directions, scenes starting at kd 0.3."""
    d = tmp_path_factory.mktemp("fit")
    mesh = write_sphere_obj(d / "sphere.obj", subdivisions=3)
    for name, sun in (("a", [0.3, 0.2, -1.0]), ("b", [-0.5, 0.0, -1.0])):
        sections = {"camera": {"pixel_pitch_mm": 0.5}, "sun": {"direction": sun}}
        truth = small_scene(mesh, {"material": "white_paint", "kd": TRUE_KD}, render={"spp": 4, "seed": 7}, **sections)
        write_exr(d / f"{name}.exr", render(truth))
        start = small_scene(mesh, {"material": "white_paint", "kd": 0.3}, render={"spp": 4}, **sections)
        (d / f"{name}.toml").write_text(start.to_toml())
    return d


# About 2000 DN on the lit sphere in 12 bits, no full well.
SENSOR = sf.Sensor(exposure_time_s=1e-6, gain_dn_per_electron=0.5, bias_dn=50.0, bit_depth=12, full_well_electrons=None)


@pytest.fixture(scope="module")
def dn_case(case) -> Path:
    """The sphere's reference a.exr observed by SENSOR: obs.fits (the sensor in its header and sidecar),
    bare.png (no sidecar: no sensor), sensor.json, and mask.png leaving out the left half."""
    dn = sf.observe(read_exr(case / "a.exr"), SENSOR, assemble(load_scene(case / "a.toml")).intrinsics, seed=3)
    sf.write_observation(case / "obs.fits", dn, SENSOR)
    sf.write_observation(case / "bare.png", dn, SENSOR)
    sidecar_path(case / "bare.png").unlink()
    (case / "sensor.json").write_text(json.dumps(SENSOR.to_dict()))
    mask = np.full((32, 32), 255, dtype=np.uint8)
    mask[:, :16] = 0
    write_png(case / "mask.png", mask)
    return case


def test_cli_fits_dn_with_its_sensor_and_records_it(dn_case, tmp_path):
    out = tmp_path / "run"
    code = main(_args(dn_case, out, "--spp", "2", reference="obs.fits"))
    assert sorted(os.listdir(out)) == REPORT
    report = json.loads((out / "fit.json").read_text())
    assert code == exit_code(sf.Status(report["status"])) and (code == 0) == report["success"]
    assert abs(report["values"]["parts.sphere.kd"] - TRUE_KD) < 0.03
    assert report["inputs"]["sensors"] == [SENSOR.to_dict()] and report["inputs"]["masks"] == []
    assert report["units"]["observations"] == ["DN"] and "fit_mean_dn" in report["parts"][0]["target"]


def test_cli_takes_a_sensor_file_a_response_and_a_mask(dn_case, tmp_path):
    out = tmp_path / "run"
    extra = ["--spp", "2", "--sensor", str(dn_case / "sensor.json"), "--response", "linear", "--mask", str(dn_case / "mask.png")]
    code = main(_args(dn_case, out, *extra, reference="bare.png"))
    assert sorted(os.listdir(out)) == REPORT
    report = json.loads((out / "fit.json").read_text())
    assert code == exit_code(sf.Status(report["status"])) and (code == 0) == report["success"]
    assert abs(report["values"]["parts.sphere.kd"] - TRUE_KD) < 0.03
    inputs = report["inputs"]
    assert inputs["sensors"] == [SENSOR.to_dict()] and inputs["sensor_file"] == str(dn_case / "sensor.json")
    assert inputs["masks"] == [str(dn_case / "mask.png")] and inputs["response"] == "linear"


@pytest.mark.parametrize(
    ("reference", "extra", "message"),
    [
        ("bare.png", ["--response", "linear"], "holds DN (digital numbers), and a fit of them needs 8 sensor value(s)"),
        ("bare.png", [], "of unknown response; say how its values encode light"),
        ("obs.fits", ["--sensor", "missing.json"], "sensor file 'missing.json' does not exist"),
        ("obs.fits", ["--sensor", "{case}/mask.png"], "must be .json or .toml, got '.png'"),
        ("obs.fits", ["--sensor", "{case}/bad_sensor.json"], "Did you mean 'bit_depth'?"),
        ("obs.fits", ["--mask", "missing.png"], "mask file 'missing.png' does not exist"),
        ("obs.fits", ["--mask", "{case}/mask.png", "--mask", "{case}/mask.png"], "got 2 masks for 1 references"),
        ("obs.fits", ["--mask", "{case}/small_mask.png"], "small_mask.png' is 8 x 8 px, the image 32 x 32 px"),
        ("obs.fits", ["--unit", "radiance"], "BUNIT = 'adu' is DN, but W m^-2 sr^-1 was asked for"),
        ("obs.fits", ["--sigma", "0.01"], "holds DN: its noise is its sensor's; leave `sigma` out"),
        ("a.exr", ["--sensor", "{case}/sensor.json"], "`sensor` describes the camera of a DN image"),
        ("a.exr", ["--response", "gamma"], "`response` must be one of 'linear', 'srgb'"),
    ],
)
def test_bad_observation_inputs_exit_2_and_leave_nothing(dn_case, tmp_path, capsys, reference, extra, message):
    (dn_case / "bad_sensor.json").write_text('{"bitdepth": 12}')
    write_png(dn_case / "small_mask.png", np.ones((8, 8), dtype=np.uint8))
    out = tmp_path / "run"
    extra = [e.replace("{case}", str(dn_case)) for e in extra]
    assert main(_args(dn_case, out, *extra, reference=reference)) == 2
    assert message in capsys.readouterr().err
    assert not out.exists()


def _args(case: Path, out: Path, *extra: str, reference: str = "a.exr") -> list[str]:
    return ["fit", str(case / reference), "--scene", str(case / "a.toml"), "--free", "parts.sphere.kd",
            "--out", str(out), "--max-steps", "3", "--quiet", *extra]


# `spacefit fit` as the program, with JAX's persistent-cache hits and its programs compiled or read back counted as they
# happen (on stderr: the fit ends the process at once, atexit handlers included).
COUNT_HITS = ("import runpy, sys\n"
              "from jax._src import monitoring\n"
              "monitoring.register_event_listener(lambda event, **kw: event.endswith('/cache_hits') and print('cache hit', file=sys.stderr))\n"
              "monitoring.register_event_duration_secs_listener(lambda event, s, **kw: event.endswith('/backend_compile_duration') and "
              "print('program', file=sys.stderr))\n"
              "sys.argv[0] = 'spacefit'\n"
              "runpy.run_module('spacefit.cli', run_name='__main__')\n")


@pytest.mark.slow  # two fit processes: 15-20 s on a quiet machine
def test_the_fit_program_ends_at_once_with_its_report_and_reads_jax_s_programs_from_the_disk(case, tmp_path):
    """Two `spacefit fit` processes sharing a JAX cache folder: the first writes the programs it compiled, the
    second reads them back, compiles none but the one compiled twice (no program calls back into Python for its
    renders: spacefit.fitting.outside; 5 did) and writes none; each ends at once (os._exit) with its report whole and its exit
    code the report's verdict, and leaves no lock or stage."""
    runs = []
    for k in range(2):
        out = tmp_path / f"run{k}"
        env = {**os.environ, JAX_CACHE_ENV: str(tmp_path / "jax"), "PYTHONPATH": os.pathsep.join(sys.path)}
        run = subprocess.run([sys.executable, "-c", COUNT_HITS, *_args(case, out, "--spp", "2")], env=env,
                             capture_output=True, text=True)
        report = json.loads((out / "fit.json").read_text())
        assert run.returncode == exit_code(sf.Status(report["status"])), run.stderr
        assert sorted(os.listdir(out)) == REPORT and "parts.sphere.kd" in run.stdout
        runs.append((run.stderr.count("cache hit"), sorted(p.name for p in (tmp_path / "jax").iterdir())))
    (first, written), (second, read) = runs
    assert run.stderr.count("program") <= second + 1  # the second process's programs from the disk (one may be compiled twice)
    assert len(written) >= 10 and read == written
    assert second >= first + len(written) - 1  # every program written is read back (one may be compiled twice in a process)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["jax", "run0", "run1"]


def test_the_program_s_modules_load_with_the_collector_off_and_are_frozen_out_of_its_scans():
    """Run as the program (``frozen``), what the command's imports leave is frozen (gc.freeze: a fit's 350 000 objects,
    which every full collection scanned) and the collector is on again after them, its youngest generation collected
    every PROGRAM_GC_YOUNG new objects, an import that fails included; main called in a process of its own (a test's, a
    notebook's) leaves the collector as it is."""
    assert gc.isenabled()
    frozen, thresholds = gc.get_freeze_count(), gc.get_threshold()
    try:
        cli._load("json", frozen=False)
        assert gc.get_freeze_count() == frozen and gc.isenabled() and gc.get_threshold() == thresholds
        cli._load("json", frozen=True)
        assert gc.get_freeze_count() > frozen and gc.isenabled()
        assert gc.get_threshold() == (cli.PROGRAM_GC_YOUNG, *thresholds[1:])
        gc.set_threshold(*thresholds)
        with pytest.raises(ModuleNotFoundError):
            cli._load("spacefit.no_such_module", frozen=True)
        assert gc.isenabled() and gc.get_threshold()[0] == cli.PROGRAM_GC_YOUNG
    finally:
        gc.unfreeze()
        gc.enable()
        gc.set_threshold(*thresholds)


def test_jax_s_cache_folder_follows_the_environment_and_a_folder_the_process_chose(monkeypatch, tmp_path):
    before = jax.config.jax_compilation_cache_dir  # the suite's own folder, once an earlier test has fitted
    jax.config.update("jax_compilation_cache_dir", None)
    try:
        monkeypatch.delenv(JAX_CACHE_ENV, raising=False)
        monkeypatch.setenv(SPACEFIT_CACHE_ENV, str(tmp_path))
        assert compile_cache_dir() == tmp_path / "jax"
        monkeypatch.setenv(SPACEFIT_CACHE_ENV, "off")
        assert compile_cache_dir() is None
        monkeypatch.setenv(JAX_CACHE_ENV, str(tmp_path / "mine"))
        assert compile_cache_dir() == tmp_path / "mine"
        monkeypatch.setenv(JAX_CACHE_ENV, "OFF")
        assert compile_cache_dir() is None and use_compile_cache() is None
        jax.config.update("jax_compilation_cache_dir", str(tmp_path / "chosen"))  # e.g. JAX_COMPILATION_CACHE_DIR
        monkeypatch.setenv(JAX_CACHE_ENV, str(tmp_path / "mine"))
        assert use_compile_cache() == tmp_path / "chosen" and jax.config.jax_compilation_cache_dir == str(tmp_path / "chosen")
    finally:
        jax.config.update("jax_compilation_cache_dir", before)


def test_cli_fit_writes_the_report(case, tmp_path, capsys):
    out = tmp_path / "run"
    code = main(_args(case, out, "--spp", "2"))
    assert sorted(os.listdir(out)) == REPORT
    report = json.loads((out / "fit.json").read_text())
    assert code == exit_code(sf.Status(report["status"])) and (code == 0) == report["success"]
    assert report["names"] == ["parts.sphere.kd"] and report["solver"] == "lm"
    assert abs(report["values"]["parts.sphere.kd"] - TRUE_KD) < 0.01
    assert len(report["history"]) == report["steps"] and report["inputs"]["options"]["render"]["spp"] == 2
    assert report["timings_s"]["solve"] > 0 and isinstance(report["success"], bool)
    printed = capsys.readouterr().out
    assert "parts.sphere.kd = " in printed and "+/-" in printed and "(start 0.3)" in printed


def test_cli_fit_that_does_not_converge_exits_3_with_its_report(case, tmp_path, capsys):
    out = tmp_path / "run"
    assert main(_args(case, out, "--spp", "2", "--max-steps", "2")) == NOT_CONVERGED
    assert sorted(os.listdir(out)) == REPORT and json.loads((out / "fit.json").read_text())["success"] is False
    assert "did not converge" in capsys.readouterr().err


def test_overwrite_replaces_a_previous_fit_whole_and_keeps_other_files(case, tmp_path):
    # a pass's fit before it (frames.csv, frames.png) and an older spacefit's residuals.png: none of them is this fit's
    out = tmp_path / "run"
    out.mkdir()
    (out / "fit.json").write_text('{"versions": {"spacefit": "0.1"}}')
    for name in ("frames.csv", "frames.png", "residuals.png", "comparison.png"):
        (out / name).write_text("an earlier fit's")
    assert main(_args(case, out, "--spp", "2")) == 2  # refused without --overwrite, nothing changed
    assert sorted(os.listdir(out)) == ["comparison.png", "fit.json", "frames.csv", "frames.png", "residuals.png"]
    code = main(_args(case, out, "--spp", "2", "--overwrite"))
    assert sorted(os.listdir(out)) == REPORT and (out / "comparison.png").read_bytes()[:4] == b"\x89PNG"
    assert code == exit_code(sf.Status(json.loads((out / "fit.json").read_text())["status"]))


def test_fit_to_folder_returns_the_result(case, tmp_path):
    refs = [case / "a.exr", case / "b.exr"]
    result = fit_to_folder(sf.ObservationFiles(refs, [case / "a.toml", case / "b.toml"]), ["parts.sphere.kd"], tmp_path / "run",
                           sf.FitOptions(max_steps=3, solver="gn"), quiet=True)
    assert isinstance(result, FitResult) and result.solver == "gn"
    assert abs(result.values["parts.sphere.kd"] - TRUE_KD) < 0.01
    assert len(result.renders) == 2 and result.renders[0].shape == (32, 32, 3)
    assert sorted(os.listdir(tmp_path / "run")) == REPORT
    # residuals.fits: reference - model per observation, in the reference's unit, top row first
    with fits.open(tmp_path / "run" / "residuals.fits") as hdus:
        assert [h.name for h in hdus[1:]] == ["OBS0", "OBS1"] and hdus["OBS1"].header["ROWORDER"] == "TOP-DOWN"
        residual = np.moveaxis(hdus["OBS1"].data, 0, -1)
    reference = read_exr(case / "b.exr")
    lit = np.argwhere(reference[..., 0] > 0)[0]
    assert residual[tuple(lit)] == pytest.approx(reference[tuple(lit)] - result.renders[1][tuple(lit)], rel=1e-6)
    assert np.allclose(residual, result.residuals[1], equal_nan=True)


@pytest.mark.parametrize("reference, extra", [("a.exr", ["--set", "sun.direction=[0, 0, 1]"]), ("obs.fits", ["--max-steps", "1"])])
def test_cli_fit_that_makes_no_progress_exits_4_and_says_so(dn_case, tmp_path, capsys, reference, extra):
    """The sun behind the sphere (kd changes no pixel), or a fit stopped after evaluating its start:
    no step lowers the loss, and the start is returned exactly (with a sensor too: no noise-bias
    correction moves a fit that never moved)."""
    out = tmp_path / "run"
    assert main(_args(dn_case, out, "--spp", "2", *extra, reference=reference)) == NO_PROGRESS
    report = json.loads((out / "fit.json").read_text())
    assert report["success"] is False and report["status"] == sf.Status.NO_PROGRESS.value
    assert report["values"] == report["start"]
    assert capsys.readouterr().out.startswith("failed: no step lowered the loss")


def test_exit_codes_are_distinct():
    codes = {status: exit_code(status) for status in sf.Status}
    assert codes[sf.Status.CONVERGED] == codes[sf.Status.NOISE_FLOOR] == 0
    assert (codes[sf.Status.NO_PROGRESS], codes[sf.Status.MISFIT], codes[sf.Status.AT_BOUND], codes[sf.Status.UNJUDGED]) == (
        NO_PROGRESS, MISFIT, AT_BOUND, UNJUDGED)
    assert codes[sf.Status.MAX_STEPS] == codes[sf.Status.NONFINITE] == NOT_CONVERGED
    assert len({NOT_CONVERGED, NO_PROGRESS, MISFIT, AT_BOUND, UNJUDGED, 0, 1, 2, 7, 8, 130, 143}) == 12


def test_error_while_writing_the_report_leaves_nothing(case, tmp_path, monkeypatch):
    import spacefit.fitting.report as report

    def broken(result):
        raise OSError("disk full")

    monkeypatch.setattr(report, "plot_convergence", broken)
    with pytest.raises(OSError, match="disk full"):
        fit_to_folder(sf.ObservationFiles([case / "a.exr"], [case / "a.toml"]), ["parts.sphere.kd"], tmp_path / "run",
                      sf.FitOptions(max_steps=1), quiet=True)
    assert not (tmp_path / "run").exists()


def _write_bad_reference(folder: Path, kind: str, reference: Path) -> Path:
    """A reference that is ``missing``, ``unreadable`` (not OpenEXR) or holds a ``nan`` pixel."""
    path = folder / f"{kind}.exr"
    if kind == "unreadable":
        path.write_text("not an image")
    elif kind == "nan":
        image = read_exr(reference)
        image[5, 5, 0] = np.nan
        write_exr(path, image)
    return path


@pytest.mark.parametrize(
    ("kind", "message"),
    [("missing", "does not exist"), ("unreadable", "could not be read as OpenEXR"), ("nan", "nan.exr': 1 pixels are NaN or infinite")],
)
def test_bad_reference_exits_2_and_leaves_nothing(case, tmp_path, capsys, kind, message):
    out = tmp_path / "run"
    reference = _write_bad_reference(tmp_path, kind, case / "a.exr")
    assert main(_args(case, out, reference=str(reference))) == 2
    assert message in capsys.readouterr().err
    assert not out.exists()


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--resolution", "16", "16"], "reference 0 has shape (32, 32, 3)"),
        (["--free", "parts.sphere.alpha_x"], "`free` must be one of"),
        (["--set", "parts.sphere.kd=0.4"], "`parts.sphere.kd` is both free and fixed by the override 'parts.sphere"),
        (["--set", "parts.sphere.alpha_x=0.1", "--free", "parts.sphere.alpha"], "`parts.sphere.alpha` is both free"),
        (["--set", "wrinkles.G=0.1", "--free", "wrinkles.rms_m"], "`wrinkles.rms_m` is both free"),
        (["--start", "parts.sphere.kd=1.5"], "`parts.sphere.kd` must be in [0, 1], got 1.5."),  # as a scene file's
        (["--start", "parts.sphere.kd=1"], "start of `parts.sphere.kd` must be inside (0, 1)"),  # a fit's open range
        (["--set", "sun.elevation_deg=30", "--free", "sun.elevation_deg"], "`sun.elevation_deg` is both free"),
        (["--start", "parts.sphere.kd=abc"], "`--start parts.sphere.kd` must be a number"),
        (["--start", "kd"], "`--start` takes NAME=VALUE"),
        (["--solver", "newton"], "`solver` must be one of"),
        (["--stop", "never"], "`stop` must be one of"),
        (["--scene", "b.toml", "--scene", "b.toml"], "3 scenes for 1 references"),
    ],
)
def test_bad_option_exits_2_and_leaves_nothing(case, tmp_path, capsys, extra, message):
    out = tmp_path / "run"
    assert main(_args(case, out, *extra)) == 2
    assert message in capsys.readouterr().err
    assert not out.exists()


def test_unwritable_output_folder(case, capsys):
    # /proc refuses new files even to root, unlike permission bits
    assert main(_args(case, Path("/proc/spacefit-test/fit"))) == 2
    assert "not writable" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("given", "message"),
    [
        ({"references": []}, "`references` must name at least one reference image"),
        ({"scenes": ["a.toml", "b.toml"]}, "give one scene for all references or one per reference; got 2 scenes for 3 references"),
        ({"masks": ["m.png", "m.png"]}, "got 2 masks for 3 references"),
        ({"resolution": (32,)}, r"`resolution` must be \(width, height\) px"),
        ({"sigma": 0.0}, r"`sigma` must be in \(0, inf\] W m\^-2 sr\^-1, got 0"),
        ({"unit": "kelvin"}, "`unit` must be one of"),
        ({"response": "gamma"}, "`response` must be one of 'linear', 'srgb'"),
        ({"row_order": "sideways"}, "`row_order` must be one of"),
        ({"sensor_defaults": "typical"}, "`sensor_defaults` must be one of"),
    ],
)
def test_observation_files_refuse_bad_input_on_construction(given, message):
    with pytest.raises(sf.InputError, match=message):
        sf.ObservationFiles(**{"references": ["a.exr", "b.exr", "c.exr"], "scenes": ["a.toml"], **given})


@pytest.mark.parametrize(
    ("given", "message"),
    [({"solver": "newton"}, "newton"), ({"max_steps": 0}, "`max_steps` must be an integer >= 1, got 0"),
     ({"stop": "never"}, "`stop` must be one of 'noise', 'tolerance'")],
)
def test_fit_options_refuse_bad_input_on_construction(given, message):
    with pytest.raises(sf.InputError, match=message):
        sf.FitOptions(**given)


def test_observation_files_load_and_record(case):
    files = sf.ObservationFiles([case / "a.exr", case / "b.exr"], case / "a.toml", resolution=[32, 32])
    assert files.scenes == (case / "a.toml",) and files.resolution == (32, 32) and files.masks == ()
    observations = files.load()
    assert [obs.scene.render.resolution for obs in observations] == [(32, 32), (32, 32)]
    np.testing.assert_array_equal(observations[1].reference, read_exr(case / "b.exr"))
    record = files.record(observations)
    assert record["references"] == [str(case / "a.exr"), str(case / "b.exr")] and record["scene_files"] == [str(case / "a.toml")]
    assert record["overrides"] == ["render.resolution=[32, 32]"] and record["scenes"] == [observations[0].scene.to_dict()]
    assert record["sensors"] == [None, None] and record["sigma"] is None and record["masks"] == []


def test_checkpoint_resumes_with_another_solver_and_refuses_another_loss(tmp_path):
    """What a resume may change is how the fit solves (solver, steps, start, stop), not what it fits."""
    from spacefit.pipeline import Checkpoint

    def inputs(options: sf.FitOptions) -> dict:
        return {"free": ["parts.sphere.kd"], "options": options.to_dict()}

    first = Checkpoint(tmp_path / "checkpoint.json", inputs(sf.FitOptions(solver="adam", render=sf.FitRender(spp=2))))
    first.update({"loss": 2.0, "values": {"parts.sphere.kd": 0.3}})
    first.update({"loss": 1.0, "values": {"parts.sphere.kd": 0.4}})
    first.update({"loss": 1.5, "values": {"parts.sphere.kd": 0.35}})
    again = Checkpoint(tmp_path / "checkpoint.json", inputs(sf.FitOptions(solver="lm", max_steps=10, render=sf.FitRender(spp=2))))
    # the file is written at every step, with the history: the resumed solve goes on after the 3rd from the best point
    assert again.resume(10) == {"start": {"parts.sphere.kd": 0.4}, "max_steps": 7} and again.steps == 3
    assert [h["loss"] for h in again.history] == [2.0, 1.0, 1.5]
    for other in (sf.FitOptions(loss="stats", render=sf.FitRender(spp=2)), sf.FitOptions(render=sf.FitRender(spp=4))):
        with pytest.raises(sf.InputError, match="was made with other options"):
            Checkpoint(tmp_path / "checkpoint.json", inputs(other)).resume(10)


def test_a_pixel_grid_step_past_its_black_sky_is_flagged_with_the_fits_own_values_and_errors(case, tmp_path, capsys, monkeypatch):
    """The sphere blurred by 1 px, its blur free: the pixel grid's fixed point tries the blur 3 px wider (its iterations
    forced there), past the black sky the finer models were sized for at the result (its reach and 1 px). The fit ends
    UNSTEPPED (exit 3, not "did not converge") with its whole report: its values the solve's (with the render noise's
    correction alone, no pixel-grid step), standard errors, a warning naming the values tried and their reach, and
    fit.json recording them."""
    from scipy.ndimage import gaussian_filter

    from spacefit.fitting import pixel_grid

    write_exr(tmp_path / "blurred.exr", gaussian_filter(read_exr(case / "a.exr"), (1.0, 1.0, 0.0)))
    out = tmp_path / "run"
    real = pixel_grid.anderson
    push = np.array([0.0, 3.0])  # the blur, px
    monkeypatch.setattr(pixel_grid, "anderson", lambda g, scale, *rest: real(lambda y: g(y + push), scale, *rest))
    assert main(["fit", str(tmp_path / "blurred.exr"), "--scene", str(case / "a.toml"), "--free", "parts.sphere.kd,image.blur_sigma_px",
                 "--max-steps", "8", "--spp", "4", "--quiet", "--out", str(out)]) == NOT_CONVERGED
    assert sorted(os.listdir(out)) == REPORT
    printed = capsys.readouterr()
    assert printed.out.startswith(f"{sf.Status.UNSTEPPED} (lm on the pixel loss")
    assert printed.err == f"spacefit: {sf.Status.UNSTEPPED}; its report is in {out}\n"
    report = json.loads((out / "fit.json").read_text())
    assert report["status"] == sf.Status.UNSTEPPED.value and report["success"] is False
    extras = report["extras"]
    assert not {"pixel_grid_error", "pixel_grid_short", "pixel_grid_remainder"} & set(extras)
    solved = [h for h in report["history"] if h["accepted"]][-1]["values"]
    for name, value in report["values"].items():
        assert value == pytest.approx(solved[name] + extras["noise_bias_correction"][name], rel=1e-12, abs=1e-15)
        assert 0 < report["stderr"][name] < 0.05 * value
    blur = report["values"]["image.blur_sigma_px"]
    assert abs(blur - 1.0) < 0.05
    past = extras["pixel_grid_past_black_sky"]
    assert past["values"] == {"image.blur_sigma_px": [pytest.approx(blur), pytest.approx(blur + 3.0)]}
    assert past["reach_px"] == [[pytest.approx(5 * blur), pytest.approx(5 * (blur + 3.0))]]
    assert [w for w in report["warnings"] if "black sky" in w and "not stepped" not in w] == [
        f"the pixel grid's step to the model made at 4x was not taken: its fixed point's iterations tried image.blur_sigma_px "
        f"{blur + 3.0:.4g} ({blur:.4g} at the result); there image 0's reach {5 * (blur + 3.0):.3g} px ({5 * blur:.3g} px at the "
        "result): past the black sky its finer models were sized for (the reach at the result and 1 px; the reach is 5 sigma of the "
        "blur and the larger shift). The values and their standard errors are the fit's on the pixel grid, without the step, and "
        "carry neither the grid's model error nor a bound on it; fit at a finer resolution, or with the blur fixed."]
