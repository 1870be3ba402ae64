"""Issue 35's input slips, each refused in the user's terms before any work (one line naming the file,
row, column or key and what is allowed), with nothing written; the valid files beside them accepted."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
from astropy.io import fits

import spacefit as sf
from spacefit.cli import main

STARLINK = Path(__file__).resolve().parent.parent / "data" / "starlink-v1p5"


def test_a_fits_gain_of_zero_is_refused_naming_the_card(tmp_path):
    """GAIN is electrons per DN; the sensor's gain is its inverse, so 0 divided by zero (a traceback)."""
    path = tmp_path / "frame.fits"
    header = fits.Header({"EXPTIME": 0.01, "GAIN": 0.0, "RDNOISE": 2.0})
    fits.PrimaryHDU(np.full((8, 8), 100, np.uint16), header).writeto(path)
    with pytest.raises(sf.InputError, match=r"frame\.fits'.*GAIN = 0\.0 electrons per DN must be > 0"):
        sf.Observation.from_file(path, sf.default_scene().with_values({"render.resolution": [8, 8]}),
                                 sensor_defaults="illustrative")


@pytest.mark.parametrize("kind", ["missing", "folder"])
def test_a_brdf_table_that_is_not_a_file_is_an_input_error(tmp_path, kind):
    path = tmp_path / "table.csv"
    if kind == "folder":
        path.mkdir()
    words = "no BRDF table file" if kind == "missing" else "is a folder"
    with pytest.raises(sf.InputError, match=rf"`path`: .*{words}"):
        sf.read_brdf_table(path)


def test_a_brdf_value_past_what_a_goniometer_resolves_is_refused_naming_its_row(tmp_path):
    rows = ["theta_i_deg,phi_i_deg,theta_o_deg,phi_o_deg,brdf_sr", "10,180,10,0,0.05", "20,180,20,0,1e30", "30,180,30,0,0.04"]
    (tmp_path / "slip.csv").write_text("\n".join(rows) + "\n")
    with pytest.raises(sf.InputError, match=r"row 2 has 1e\+30 sr\^-1, above 100000 sr\^-1"):
        sf.read_brdf_table(tmp_path / "slip.csv")
    # the published tables peak at 8.0e3 (chassis) and 5.3e4 sr^-1 (solar array): read as they are
    assert sf.read_brdf_table(STARLINK / "solar_array_brdf.csv").value.max() == pytest.approx(53341.4)


def test_a_pass_read_from_none_is_an_input_error():
    with pytest.raises(sf.InputError, match=r"`path` must be a path"):
        sf.Pass.read(None)


@pytest.mark.parametrize("column, values, words", [
    ("file", (["a.exr", "b.exr", "a.exr"], [0.0, 10.0, 20.0]), r"frames 0 and 2 .* same file '.*a\.exr'"),
    ("time", (["a.exr", "b.exr", "c.exr"], [0.0, 10.0, 10.0]), r"frames 1 and 2 .* same time '10\.0'"),
])
def test_a_frame_listed_twice_is_refused(column, values, words):
    files, times = values
    with pytest.raises(sf.InputError, match=words):
        sf.Pass.from_columns({"file": files, "time": times})


def test_the_sun_given_as_a_direction_and_both_angles_is_refused_in_values_and_scene_files(tmp_path):
    both = {"sun.direction": [0.0, 0.0, -1.0], "sun.elevation_deg": 30.0, "sun.azimuth_deg": 10.0}
    with pytest.raises(sf.InputError, match=r"`sun\.direction` and both `sun\.elevation_deg` and `sun\.azimuth_deg`"):
        sf.default_scene().with_values(both)
    scene_file = tmp_path / "scene.toml"
    scene_file.write_text("[sun]\ndirection = [0.0, 0.0, -1.0]\nelevation_deg = 30.0\nazimuth_deg = 10.0\n")
    with pytest.raises(sf.InputError, match=r"`sun\.direction` and both"):
        sf.load_scene(scene_file)
    # a direction and one angle: the angle is set, the other kept from the direction (documented)
    sun = sf.default_scene().with_values({"sun.direction": [0.5, 0.0, -1.0], "sun.elevation_deg": 30.0}).sun.direction
    assert np.allclose(sun, [0.8660254037844387, 0.0, -0.5])


def test_an_exposure_past_a_day_is_refused():
    with pytest.raises(sf.InputError, match=r"`Sensor\.exposure_time_s` must be in \(0, 86400\] s, got 1e\+300"):
        sf.Sensor(exposure_time_s=1e300)


def test_out_a_dangling_link_exits_2_and_leaves_everything(tmp_path, capsys):
    (tmp_path / "out").symlink_to(tmp_path / "nowhere")
    before = sorted(os.listdir(tmp_path))
    assert main(["render", "--out", str(tmp_path / "out"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"spacefit: error: `--out` '{tmp_path / 'out'}' is a symbolic link to") and len(err.splitlines()) == 1
    assert sorted(os.listdir(tmp_path)) == before and not (tmp_path / "nowhere").exists()


@pytest.mark.parametrize("name", ["sun", "observer"])
def test_light_curve_directions_of_no_component_are_refused_by_name(name):
    """Rows of no component (shape (n, 0)) are refused as directions of the wrong shape, naming the argument (NumPy's
    reduction over an empty axis raised a ValueError; found by test_fuzz_long's new constructors)."""
    good = {"sun": np.array([[0.0, 0.0, 1.0]] * 2), "observer": np.array([[0.0, 0.6, 0.8]] * 2)}
    args = {**good, name: np.zeros((2, 0))}
    with pytest.raises(sf.InputError, match=f"`{name}` must be \\(2, 3\\) directions"):
        sf.LightCurveObservations(np.ones(2), None, "V", args["sun"], args["observer"], np.ones(2), np.zeros(2, bool), None, "x")
