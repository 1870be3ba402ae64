"""``spacefit fit-light-curve``: a light-curve file of magnitudes and each point's geometry as scene
values, fitted to a rendered target with the image fits' folder, progress, checkpoint, resume and
exit codes (issue 34 items 1 and 5)."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
from helpers import lander, observed, turning

import spacefit as sf
from spacefit.cli import MISFIT, main
from spacefit.pipeline import Checkpoint
from spacefit.scene.parameters import scene_value

FREE = ("parts.legs.kd",)
TRUTH = 0.2  # the lander's legs' albedo
SIGMA_MAG = 0.05


def write_curve(folder: Path, magnitude: np.ndarray, points: list[dict], sigma: float | None = SIGMA_MAG, name: str = "curve.csv") -> Path:
    """A point table: the magnitudes, their error, each point's attitude and its sun as a vector by components."""
    scene = lander(12, 64)
    rows = ["magnitude," + ("magnitude_sigma," if sigma else "") + "target.attitude_z_deg,sun.direction.x,sun.direction.y,sun.direction.z"]
    for m, p in zip(magnitude, points):
        sun = scene.with_values({"sun.elevation_deg": p["sun.elevation_deg"]}).sun.direction
        rows.append(",".join(repr(float(v)) for v in (m, *([sigma] if sigma else []), p["target.attitude_z_deg"], *sun)))
    (folder / name).write_text("\n".join(rows) + "\n")
    return folder / name


@pytest.fixture(scope="module")
def case(tmp_path_factory) -> Path:
    """Six points of the lander turning (12 x 12 px, 64 spp), its legs' albedo 0.2 observed with 0.05 mag noise."""
    folder = tmp_path_factory.mktemp("curve")
    scene, points = lander(12, 64), turning(6)
    (folder / "scene.toml").write_text(scene.to_toml())
    write_curve(folder, observed(scene, FREE, points, SIGMA_MAG), points)
    return folder


def args(case: Path, out: Path, *extra: str, curve: str = "curve.csv") -> list[str]:
    return ["fit-light-curve", str(case / curve), "--scene", str(case / "scene.toml"), "--free", ",".join(FREE),
            "--start", "parts.legs.kd=0.28", "--out", str(out), "--quiet", *extra]


@pytest.mark.slow
def test_a_light_curve_fitted_from_the_command_line_recovers_the_albedo(case, tmp_path, capsys):
    """The point table's sun given as a vector by components: the legs' albedo within 3 standard
    errors of the truth, exit 0 with a verdict within range, the report in the folder (35 s on 2 cores);
    the same curve with three points 0.5 mag brighter is a misfit, exit 5, its report written."""
    out = tmp_path / "fit"
    assert main(args(case, out)) == 0, capsys.readouterr()
    report = json.loads((out / "fit.json").read_text())
    assert report["success"] and report["status"].startswith("converged")
    kd, error = report["values"]["parts.legs.kd"], report["stderr"]["parts.legs.kd"]
    assert abs(kd - TRUTH) < 3 * error < 0.15, (kd, error)
    assert {"fit.json", "uncertainty.json", "convergence.png", "observation0.png"} <= {p.name for p in out.iterdir()}
    assert report["inputs"]["curve"] == str(case / "curve.csv") and report["inputs"]["free"] == list(FREE)
    assert "within the expected range" in capsys.readouterr().out

    wrong = tmp_path / "wrong"
    wrong.mkdir()
    (wrong / "scene.toml").write_text((case / "scene.toml").read_text())
    rows = (case / "curve.csv").read_text().splitlines()
    for i in (1, 3, 5):  # a glint the model does not have
        m, rest = rows[i].split(",", 1)
        rows[i] = f"{float(m) - 0.5!r},{rest}"
    (wrong / "curve.csv").write_text("\n".join(rows) + "\n")
    assert main(args(wrong, tmp_path / "misfit")) == MISFIT
    assert json.loads((tmp_path / "misfit" / "fit.json").read_text())["status"].startswith("misfit")


class Killed(BaseException):
    """Stands for SIGKILL: no clean-up runs (not an Exception, not a KeyboardInterrupt)."""


@pytest.mark.slow
def test_a_light_curve_fit_killed_mid_solve_resumes_to_the_uninterrupted_verdict(case, tmp_path, monkeypatch, capsys):
    """Killed after its second step (its checkpoint written), then run with --resume: the
    uninterrupted fit's status and exit code (0, not the step limit's 3: the checkpoint's history keeps
    the stop rule's record) and its albedo within 0.3 of its standard error (the solver restarts from
    the best point)."""
    whole = main(args(case, tmp_path / "whole", "--max-steps", "8"))
    expected = json.loads((tmp_path / "whole" / "fit.json").read_text())
    assert whole == 0 and expected["steps"] > 2
    update = Checkpoint.update

    def killed_after_two(self: Checkpoint, entry: dict) -> None:
        update(self, entry)
        if self.steps == 2:
            raise Killed

    with monkeypatch.context() as m:
        m.setattr(Checkpoint, "update", killed_after_two)
        with pytest.raises(Killed):
            main(args(case, tmp_path / "killed", "--max-steps", "8"))
    assert len(json.loads((tmp_path / "killed" / "checkpoint.json").read_text())["history"]) == 2
    capsys.readouterr()
    assert main(args(case, tmp_path / "killed", "--max-steps", "8", "--resume")) == whole
    got = json.loads((tmp_path / "killed" / "fit.json").read_text())
    assert (got["status"], got["success"]) == (expected["status"], expected["success"]), (got["history"], expected["history"])
    assert abs(got["values"]["parts.legs.kd"] - expected["values"]["parts.legs.kd"]) < 0.3 * expected["stderr"]["parts.legs.kd"]
    assert not (tmp_path / "killed" / "checkpoint.json").exists()


@pytest.fixture(scope="module")
def quick(tmp_path_factory) -> Path:
    """A scene and a point table of made-up magnitudes: nothing of these is rendered."""
    folder = tmp_path_factory.mktemp("quick")
    scene, points = lander(8, 4), turning(3)
    (folder / "scene.toml").write_text(scene.to_toml())
    write_curve(folder, np.array([10.0, 10.5, 11.0]), points)
    write_curve(folder, np.array([10.0, 10.5, 11.0]), points, sigma=None, name="nosigma.csv")
    lines = (folder / "curve.csv").read_text().splitlines()
    (folder / "extra.csv").write_text("\n".join([lines[0] + ",camera.focal_length_mm", *(f"{r},50" for r in lines[1:])]) + "\n")
    (folder / "nomagnitude.csv").write_text("\n".join(",".join(r.split(",")[1:]) for r in lines) + "\n")
    (folder / "text.csv").write_text("\n".join([lines[0], *(lines[1:2]), "bright," + lines[2].split(",", 1)[1]]) + "\n")
    (folder / "partial.csv").write_text("\n".join(",".join(r.split(",")[:-1]) for r in lines) + "\n")
    return folder


@pytest.mark.parametrize(("curve", "extra", "message"), [
    ("missing.csv", (), "light curve '.*missing.csv' does not exist"),
    ("extra.csv", (), "a point table has a `magnitude` column.*got also camera.focal_length_mm"),
    ("nomagnitude.csv", (), "got no magnitude"),
    ("text.csv", (), r"row 1's `magnitude` must be a finite number, got 'bright'"),
    ("partial.csv", (), r"gives sun.direction.x, sun.direction.y but not sun.direction.z"),
    ("curve.csv", ("--sigma-mag", "0.1"), "has a `magnitude_sigma` column: leave `sigma_mag` out"),
    ("nosigma.csv", ("--sigma-mag", "-1"), r"`sigma_mag` must be"),
    ("curve.csv", ("--site", "45,north"), "`--site` takes LAT,LON or LAT,LON,HEIGHT_M"),
    ("curve.csv", ("--band", "R"), "band"),
    ("curve.csv", ("--free", "parts.nose.kd"), "parts.nose.kd"),
    ("curve.csv", ("--free", "target.attitude_z_deg"), "target.attitude_z_deg"),
    ("curve.csv", ("--film-px", "0"), "`film_px` must be an integer >= 1, got 0"),
])
def test_bad_light_curve_inputs_exit_2_in_one_line_and_leave_nothing(quick, tmp_path, capsys, curve, extra, message):
    out = tmp_path / "out"
    given = args(quick, out, curve=curve)
    if extra[:1] == ("--free",):
        given[given.index("--free") + 1], extra = extra[1], ()
        given[given.index("--start"):given.index("--start") + 2] = []
    assert main([*given, *extra]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith("spacefit: error: "), err
    assert re.search(message, err), err
    assert not out.exists()


def test_light_curve_files_read_a_point_tables_scene_values(quick):
    """The sun given as components is each point's sun direction; the magnitudes and errors as written."""
    curve = sf.LightCurveFiles(quick / "curve.csv", quick / "scene.toml").load()
    scene = lander(8, 4)
    for point, p in zip(curve.points, turning(3)):
        assert point["target.attitude_z_deg"] == p["target.attitude_z_deg"]
        np.testing.assert_allclose(point["sun.direction"], scene.with_values({"sun.elevation_deg": p["sun.elevation_deg"]}).sun.direction)
    np.testing.assert_array_equal(curve.magnitude, [10.0, 10.5, 11.0])
    np.testing.assert_array_equal(curve.magnitude_sigma, [SIGMA_MAG] * 3)
    assert sf.LightCurveFiles(quick / "nosigma.csv", quick / "scene.toml").load().magnitude_sigma is None
    assert scene_value(curve.scene, "parts.legs.kd") == TRUTH


def test_a_point_tables_camera_is_a_vector_as_its_sun(tmp_path):
    """Each point's camera position and sun direction given as vectors by components: each point's
    scene has them, the camera's range differing from point to point."""
    scene = lander(8, 4)
    rows = ["magnitude,magnitude_sigma,camera.position_m.x,camera.position_m.y,camera.position_m.z,sun.direction.x,sun.direction.y,"
            "sun.direction.z", "10.0,0.05,0.0,10.0,70.0,0.0,-0.5,-1.0", "10.5,0.05,5.0,0.0,90.0,0.3,0.0,-1.0"]
    (tmp_path / "curve.csv").write_text("\n".join(rows) + "\n")
    (tmp_path / "scene.toml").write_text(scene.to_toml())
    curve = sf.LightCurveFiles(tmp_path / "curve.csv", tmp_path / "scene.toml").load()
    assert curve.geometry == ("camera.position_m", "sun.direction")
    assert [s.camera.position_m for s in curve.scenes] == [(0.0, 10.0, 70.0), (5.0, 0.0, 90.0)]
    sun = np.asarray(curve.scenes[1].sun.direction)
    np.testing.assert_allclose(sun / np.linalg.norm(sun), np.array([0.3, 0.0, -1.0]) / np.hypot(0.3, 1.0))


def test_light_curve_files_take_an_observers_file_in_the_targets_frame(quick, tmp_path):
    """An ECSV light curve of sun and observer directions in the target's frame (sf.write_light_curve):
    each lit observation a point at its geometry with the scene's camera, the one in the Earth's shadow
    left out, the magnitudes carried to the median range by the inverse square law; a given
    `sigma_mag` where the file states no errors."""
    sun = np.array([[0.0, 1.0, 1.0], [1.0, 0.0, 1.0], [0.0, 0.0, 1.0], [1.0, 1.0, 0.0]])
    observations = sf.LightCurveObservations(np.array([5.0, 5.5, 6.0, 7.0]), None, "V", sun, np.array([[0.0, 0.0, 1.0]] * 4),
                                             np.array([1e6, 2e6, 4e6, 1e6]), np.array([False, False, False, True]),
                                             np.array([f"2026-01-01T00:00:0{k}" for k in range(4)]), "test")
    path = sf.write_light_curve(observations, tmp_path / "curve.ecsv")
    curve = sf.LightCurveFiles(path, quick / "scene.toml", sigma_mag=0.02).load()
    assert len(curve.points) == 3 and set(curve.geometry) == {"target.attitude_x_deg", "target.attitude_y_deg", "target.attitude_z_deg",
                                                              "sun.elevation_deg", "sun.azimuth_deg"}
    np.testing.assert_allclose(curve.magnitude, [5.0 + 5 * np.log10(2.0), 5.5, 6.0 - 5 * np.log10(2.0)])
    np.testing.assert_array_equal(curve.magnitude_sigma, [0.02] * 3)
    assert curve.observer_range_m == 2e6
    with pytest.raises(sf.InputError, match="`sigma_mag` must be"):
        sf.LightCurveFiles(path, quick / "scene.toml", sigma_mag=-0.1)
