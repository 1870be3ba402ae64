"""Files and key languages spacefit did not write: FITS cubes and truncated copies, TIFF samples,
hand-written sensor files, sidecars and sweep files, masks, --set and --sensor-value. Each mistake
ends in sf.InputError (exit 2, one line naming the file or key, the value and what is allowed)
before any work, with nothing written in --out."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import tifffile
from astropy.io import fits
from helpers import small_scene, write_sphere_obj

import spacefit as sf
from spacefit.cli import main
from spacefit.fitting.observations.image import check_reference
from spacefit.fitting.problem import setup
from spacefit.imageio import read_image, sensor_of, sidecar_path
from spacefit.sensor import read_sensor_file
from spacefit.studies.axes import axis_lengths, parse_axes
from spacefit.studies.sweep import read_sweep_file

# A calibrated camera as an observatory's FITS header gives it (GAIN in electrons per DN).
CARDS = {"TELESCOP": "ground test", "OBJECT": "lander mock-up", "BUNIT": "adu", "ROWORDER": "TOP-DOWN", "RADSCALE": 4.0e4,
         "GAIN": 2.0, "RDNOISE": 3.0, "BIAS": 100.0, "PSFSIGMA": 0.5}


def _fits(path: Path, planes: np.ndarray, **cards) -> Path:
    """A FITS file as astropy writes it, with foreign header cards."""
    header = fits.Header()
    for key, value in {**CARDS, **cards}.items():
        header[key if len(key) <= 8 else f"HIERARCH {key}"] = value
    fits.PrimaryHDU(planes, header=header).writeto(path)
    return path


@pytest.fixture(scope="module")
def case(tmp_path_factory) -> Path:
    """A 32 x 32 sphere scene (scene.toml), a good DN observation of it (good.fits, from astropy) and a bad one of each kind."""
    d = tmp_path_factory.mktemp("inputs")
    mesh = write_sphere_obj(d / "sphere.obj", subdivisions=2)
    (d / "scene.toml").write_text(small_scene(mesh, {"material": "white_paint", "kd": 0.3}, render={"spp": 2}).to_toml())
    dn = np.full((32, 32), 300, dtype=np.uint16)
    _fits(d / "good.fits", dn)
    _fits(d / "cube.fits", np.stack([dn] * 5))
    whole = (d / "good.fits").read_bytes()
    (d / "truncated.fits").write_bytes(whole[: len(whole) - 1000])
    return d


def _fit(case: Path, out: Path, reference: str, *extra: str) -> list[str]:
    return ["fit", str(case / reference), "--scene", str(case / "scene.toml"), "--free", "parts.sphere.kd", "--out", str(out),
            "--max-steps", "1", "--quiet", *extra]


def _refused(argv: list[str], out: Path, capsys, *words: str) -> str:
    """Run the CLI; assert exit 2, one line naming every word, and nothing at ``out``."""
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("spacefit: error: "), err
    for word in words:
        assert word in err, (word, err)
    assert not out.exists()
    return err


def test_the_good_foreign_fits_is_read_with_its_header_sensor(case):
    image = read_image(case / "good.fits")
    sensor, sources = sensor_of(image)
    assert image.data.shape == (32, 32, 1) and sensor.gain_dn_per_electron == 0.5 and sources["bias_dn"] == "header BIAS"


def test_a_five_plane_fits_cube_is_refused_not_fitted_as_rgb(case, tmp_path, capsys):
    _refused(_fit(case, tmp_path / "run", "cube.fits"), tmp_path / "run", capsys,
             "cube.fits", "5 planes", "NAXIS3 = 5", "(5, 32, 32)", "1 plane (grey) or 3 (RGB)")
    _fits(tmp_path / "rgb.fits", np.full((3, 4, 5), 300, dtype=np.uint16))
    assert read_image(tmp_path / "rgb.fits").data.shape == (4, 5, 3)


def test_a_python_reference_of_other_than_1_or_3_channels_is_refused(case):
    scene = sf.load_scene(case / "scene.toml")
    with pytest.raises(sf.InputError, match=r"reference 0 has shape \(32, 32, 5\).*1 \(grey\) or 3 \(RGB\)"):
        check_reference(sf.Observation(scene, np.ones((32, 32, 5))), 0)


@pytest.mark.parametrize("reference", [[], np.ones(32)])
def test_a_reference_that_is_no_image_is_refused_by_the_fit_naming_its_shape(case, reference):
    """An empty list or a 1-D array passes `sf.Observation` (a real array) and is refused by the fit's set-up
    with the shape it has, not an AttributeError from the memory estimate made before (the slow fuzz test's find)."""
    scene = sf.load_scene(case / "scene.toml")
    with pytest.raises(sf.InputError, match=rf"reference 0 has shape \({len(reference)},\), but its scene renders \(height, width\) = \(32, 32\)"):
        setup(sf.Observation(scene, reference), ["parts.sphere.kd"])


def test_tiff_samples_an_unmarked_fourth_is_refused_an_unassociated_alpha_is_a_mask(tmp_path):
    rgba = np.full((4, 5, 4), 1000, dtype=np.uint16)
    rgba[0, 0, 3] = 0
    tifffile.imwrite(tmp_path / "four.tif", rgba, photometric="rgb", extrasamples=["unspecified"])
    with pytest.raises(sf.InputError, match=r"four.tif': TIFF image of 4 channels \(shape \(4, 5, 4\), channels last\); an image "
                                            r"holds 1 channel \(grey\) or 3 \(RGB\)"):
        read_image(tmp_path / "four.tif", response="linear")
    tifffile.imwrite(tmp_path / "alpha.tif", rgba, photometric="rgb", extrasamples=["unassalpha"])
    image = read_image(tmp_path / "alpha.tif", response="linear")
    assert image.data.shape == (4, 5, 3) and not image.mask[0, 0].any() and image.mask[1:].all()


def test_an_rgba_exr_is_refused_its_alpha_not_guessed(tmp_path):
    from spacefit.rendering.backend import mi  # an RGBA EXR as other renderers write it

    mi.Bitmap(np.ones((4, 5, 4), np.float32), pixel_format=mi.Bitmap.PixelFormat.RGBA).write(str(tmp_path / "rgba.exr"))
    with pytest.raises(sf.InputError, match=r"rgba.exr': EXR image of 4 channels \(shape \(4, 5, 4\), channels last\); an image "
                                            r"holds 1 channel \(grey\) or 3 \(RGB\); an alpha channel is read as a mask only in PNG"):
        read_image(tmp_path / "rgba.exr")


def test_a_truncated_fits_is_refused_with_the_bytes_it_lacks(case, tmp_path, capsys):
    size = (case / "truncated.fits").stat().st_size
    expected = 2880 + 32 * 32 * 2  # one header block, then the 16-bit data
    _refused(_fit(case, tmp_path / "run", "truncated.fits"), tmp_path / "run", capsys,
             "truncated.fits' is truncated", f"up to byte {expected}", f"holds {size} bytes")


def test_string_numbers_in_sensor_files_headers_and_options_are_refused(case, tmp_path, capsys):
    (tmp_path / "sensor.toml").write_text('gain_dn_per_electron = "2.0"\n')
    with pytest.raises(sf.InputError, match=r"sensor.toml': `gain_dn_per_electron` must be a number, not a string: got '2.0'"):
        read_sensor_file(tmp_path / "sensor.toml")
    _refused(_fit(case, tmp_path / "run", "good.fits", "--sensor", str(tmp_path / "sensor.toml")), tmp_path / "run", capsys,
             "sensor.toml", "gain_dn_per_electron", "'2.0'", "a number, not a string")
    _refused(_fit(case, tmp_path / "run", "good.fits", "--sensor-value", 'bias_dn="100"'), tmp_path / "run", capsys,
             "--sensor-value", "bias_dn", "'100'", "a number, not a string")
    _fits(tmp_path / "card.fits", np.full((32, 32), 300, dtype=np.uint16), **{"SPACEFIT SENSOR read_noise_electrons": "3"})
    with pytest.raises(sf.InputError, match=r"card.fits': the FITS header's HIERARCH SPACEFIT SENSOR cards: `read_noise_electrons` "
                                            r"must be a number, not a string: got '3'"):
        read_image(tmp_path / "card.fits")


@pytest.mark.parametrize(
    ("content", "message"),
    [
        ('{"sensor": {"bias_dn": 100', "sidecar '{path}' is not valid JSON: Expecting"),
        ("[1, 2, 3]", "sidecar '{path}' must hold a JSON object (unit, response, saturation_dn, sensor, ...), got [1, 2, 3]"),
        ('{"sensor": [0.5, 100]}', "sidecar '{path}', its sensor must be a table of sf.Sensor's fields, got [0.5, 100]"),
        ('{"sensor": {"gain_dn_per_electron": "0.5"}}', "`gain_dn_per_electron` must be a number, not a string: got '0.5'"),
        ('{"sensor": {"diffraction": "no"}}', "`diffraction` must be true or false, got 'no'"),
        ('{"response": "gamma"}', "response` must be one of 'linear', 'srgb'; got 'gamma'"),
    ],
)
def test_a_malformed_sidecar_is_refused_naming_it(case, tmp_path, capsys, content, message):
    reference = tmp_path / "obs.fits"
    reference.write_bytes((case / "good.fits").read_bytes())
    side = sidecar_path(reference)
    side.write_text(content)
    _refused(_fit(case, tmp_path / "run", str(reference)), tmp_path / "run", capsys, message.format(path=side))


def test_booleans_are_true_or_false_in_every_key_language(case, tmp_path, capsys):
    (tmp_path / "sweep.toml").write_text('images = "false"\n[axes]\n"sun.elevation_deg" = [10, 20]\n')
    _refused(["sweep", str(tmp_path / "sweep.toml"), "--out", str(tmp_path / "s.zarr")], tmp_path / "s.zarr", capsys,
             "sweep.toml': images` must be true or false, got 'false'")
    (tmp_path / "one.toml").write_text('derivatives = "parts.legs.kd"\n[axes]\n"sun.elevation_deg" = [10, 20]\n')
    with pytest.raises(sf.InputError, match="one.toml': `derivatives` must be a list of parameter names, got 'parts.legs.kd'"):
        read_sweep_file(tmp_path / "one.toml")
    with pytest.raises(sf.InputError, match="`images` must be true or false, got 'false'"):
        sf.sweep(sf.default_scene(), {"sun.elevation_deg": [10]}, images="false")
    (tmp_path / "scene.toml").write_text('[wrinkles]\nenabled = "false"\n')
    _refused(["render", str(tmp_path / "scene.toml"), "--out", str(tmp_path / "r")], tmp_path / "r", capsys,
             "`wrinkles.enabled` must be true or false, got 'false'")
    _refused(["render", "--set", "render.deterministic=yes", "--out", str(tmp_path / "r")], tmp_path / "r", capsys,
             "`render.deterministic` must be true or false, got 'yes'")
    (tmp_path / "sensor.json").write_text('{"vignetting": 0}')
    with pytest.raises(sf.InputError, match="sensor.json': `vignetting` must be true or false, got 0"):
        read_sensor_file(tmp_path / "sensor.json")


@pytest.mark.parametrize(
    ("line", "message"),
    [
        ('[render]\nspp = "64"', "`render.spp` must be an integer in [1, 65536], got '64'"),
        ('[sun]\nelevation_deg = "30"', "`sun.elevation_deg` must be a number, not a string: got '30'"),
        ('[parts.panels]\nalpha_x = "0.1"', "`parts.panels.alpha_x` must be a number, not a string: got '0.1'"),
    ],
)
def test_string_numbers_in_scene_files_are_refused(tmp_path, capsys, line, message):
    (tmp_path / "scene.toml").write_text(line + "\n")
    _refused(["render", str(tmp_path / "scene.toml"), "--out", str(tmp_path / "r")], tmp_path / "r", capsys, message)


@pytest.mark.parametrize(
    ("values", "message"),
    [
        (np.full((32, 32), np.nan), "1024 values are neither 0 (leave the pixel out) nor 1 (use it), e.g. nan"),
        (np.full((32, 32), 0.5), "1024 values are neither 0 (leave the pixel out) nor 1 (use it), e.g. 0.5"),
        (np.zeros((32, 32)), "leaves out all 1024 pixels: nothing would be fitted"),
        (np.ones((16, 32)), "is 32 x 16 px, the image 32 x 32 px"),
    ],
    ids=["nan", "half", "empty", "shape"],
)
def test_a_mask_must_be_binary_and_leave_something(case, tmp_path, capsys, values, message):
    fits.PrimaryHDU(values, header=fits.Header([("ROWORDER", "TOP-DOWN")])).writeto(tmp_path / "mask.fits")
    _refused(_fit(case, tmp_path / "run", "good.fits", "--mask", str(tmp_path / "mask.fits")), tmp_path / "run", capsys,
             f"mask file '{tmp_path / 'mask.fits'}'", message)


def test_a_mask_of_0_and_full_scale_or_1_is_read(case):
    mask = np.zeros((32, 32), dtype=np.uint8)
    mask[:, :10] = 255
    image = read_image(case / "good.fits", mask=mask)
    assert image.mask[:, :10].all() and not image.mask[:, 10:].any()
    assert read_image(case / "good.fits", mask=mask > 0).mask.sum() == 320


def test_arange_of_integers_gives_integers():
    axes = parse_axes(sf.default_scene(), {"render.seed": {"arange": [1, 4, 1]}, "sun.elevation_deg": {"arange": [10, 20, 2.5]}})
    assert axes[0].values == {"render.seed": [1, 2, 3]} and all(isinstance(v, int) for v in axes[0].values["render.seed"])
    assert axes[1].values == {"sun.elevation_deg": [10.0, 12.5, 15.0, 17.5]}
    with pytest.raises(sf.InputError, match=r"`axes\['render.spp'\].arange` must be a number, not a string: got '4'"):
        parse_axes(sf.default_scene(), {"render.spp": {"arange": [1, "4", 1]}})
    with pytest.raises(sf.InputError, match=r"`axes\['camera.attitude_deg'\]` must be a list of values, each a number, a string or"):
        parse_axes(sf.default_scene(), {"camera.attitude_deg": [(None, None, [])]})  # ragged (the slow fuzz test's find)


def test_linspace_of_integers_gives_integers_where_every_value_is_whole():
    axes = parse_axes(sf.default_scene(), {"render.spp": {"linspace": [4, 16, 4]},
                                           "sun.elevation_deg": {"linspace": [10, 20, 3]}})
    assert axes[0].values == {"render.spp": [4, 8, 12, 16]} and all(isinstance(v, int) for v in axes[0].values["render.spp"])
    assert axes[1].values == {"sun.elevation_deg": [10, 15, 20]}
    with pytest.raises(sf.InputError, match=r"render.spp"):
        parse_axes(sf.default_scene(), {"render.spp": {"linspace": [4, 17, 3]}})  # 10.5 is no whole count


def test_an_axis_table_without_scene_keys_counts_no_points():
    assert axis_lengths({"a": {"linspace": [0, 1, 5]}, "b": {"sun.elevation_deg": [1, 2], "sun.azimuth_deg": [3, 4]},
                         "c": {"linspace ": [0, 1, 5]}}) == [5, 2, 0]


def test_typos_get_the_closest_name_in_every_key_language(case, tmp_path, capsys):
    scene = sf.default_scene()
    (tmp_path / "sweep.toml").write_text('imags = true\n[axes]\n"sun.elevation_deg" = [10, 20]\n')
    with pytest.raises(sf.InputError, match="got 'imags'. Did you mean 'images'?"):
        read_sweep_file(tmp_path / "sweep.toml")
    with pytest.raises(sf.InputError, match=r"Did you mean `sun.elevation_deg`\?"):
        parse_axes(scene, {"sun.elevaton_deg": [10, 20]})
    with pytest.raises(sf.InputError, match=r"got \{'linspase': \[10, 20, 3\]\}. Did you mean \{linspace = "):
        parse_axes(scene, {"sun.elevation_deg": {"linspase": [10, 20, 3]}})
    with pytest.raises(sf.InputError, match="got 'parts.panels.alpha_xx'. Did you mean 'parts.panels.alpha_x'?"):
        sf.sweep(scene, {"sun.elevation_deg": [10]}, derivatives=["parts.panels.alpha_xx"])
    (tmp_path / "sensor.toml").write_text("bias = 100.0\n")
    with pytest.raises(sf.InputError, match="got 'bias'. Did you mean 'bias_dn'?"):
        read_sensor_file(tmp_path / "sensor.toml")
    _refused(_fit(case, tmp_path / "run", "good.fits", "--sensor-value", "read_noise=3"), tmp_path / "run", capsys,
             "--sensor-value", "got 'read_noise'. Did you mean 'read_noise_electrons'?")
    _fits(tmp_path / "card.fits", np.full((32, 32), 300, dtype=np.uint16), **{"SPACEFIT SENSOR bias_dm": 100.0})
    with pytest.raises(sf.InputError, match="HIERARCH SPACEFIT SENSOR cards: field` must be one of .* got 'bias_dm'. Did you mean 'bias_dn'?"):
        read_image(tmp_path / "card.fits")


def test_dn_below_the_sensors_bias_is_refused_in_dn_words_and_bias_subtracted_dn_is_kept(case):
    scene = sf.load_scene(case / "scene.toml")
    sensor = sf.Sensor(bias_dn=100.0, read_noise_electrons=3.0, gain_dn_per_electron=0.5, full_well_electrons=None)
    dn = np.full((32, 32, 1), 120.0)
    dn[0, :4] = -5.0
    with pytest.raises(sf.InputError) as err:
        check_reference(sf.Observation(scene, dn, sensor=sensor), 0)
    message = str(err.value)
    assert "4 pixels below 87.5 DN" in message and "bias (100 DN)" in message and "read noise (1.5 DN)" in message
    assert "radiance" not in message
    subtracted = sf.Sensor(bias_dn=0.0, read_noise_electrons=3.0, gain_dn_per_electron=0.5, full_well_electrons=None)
    noise = np.random.default_rng(1).normal(0.0, 1.5, (32, 32, 1))  # a dark, bias-subtracted frame: half its values below 0
    ref, used = check_reference(sf.Observation(scene, noise, sensor=subtracted), 0)
    assert used.all() and np.array_equal(ref, noise.astype(np.float32))


def test_a_frames_own_sensor_values_win_over_the_pass_wide_ones(tmp_path):
    """``frame_sensor_values`` replace ``sensor_values``' fields for their frame only."""
    files = sf.ObservationFiles([tmp_path / "a.fits", tmp_path / "b.fits"], [tmp_path / "scene.toml"],
                                sensor_values={"bias_dn": 100.0, "gain_dn_per_electron": 0.5},
                                frame_sensor_values=[{"bias_dn": 50.0}, {}])
    assert files._sensor_values(0) == {"bias_dn": 50.0, "gain_dn_per_electron": 0.5}
    assert files._sensor_values(1) == {"bias_dn": 100.0, "gain_dn_per_electron": 0.5}
