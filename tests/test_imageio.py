"""Observation files: round trips of DN and sensor values, references' units and masks, and every refusal."""

from __future__ import annotations

import numpy as np
import pytest
import tifffile
from astropy.io import fits

from spacefit.errors import InputError
from spacefit.formation import observe
from spacefit.geometry.frames import Intrinsics
from spacefit.imageio import RowOrderWarning, format_sensor_sources, read_image, sensor_of, sidecar_path, write_observation
from spacefit.rendering.exr import write_exr
from spacefit.rendering.png import write_png
from spacefit.sensor import Sensor

SENSOR = Sensor(exposure_time_s=2e-3, gain_dn_per_electron=0.5, bias_dn=50.0, bit_depth=12, full_well_electrons=None, wavelength_m=(6e-7, 5.5e-7, 4.5e-7), psf_sigma_px=0.7)


@pytest.fixture(scope="module")
def dn() -> np.ndarray:
    intr = Intrinsics(7.0, 4e-3, 24, 16)
    radiance = np.linspace(0.0, 0.07, 24 * 16 * 3).reshape(16, 24, 3)  # up to about 3000 DN
    radiance[3, 4] = 0.5  # about 20,000 DN: saturates the 12-bit ADC (4095) there and in its nearest neighbours
    return observe(radiance, SENSOR, intr, seed=3)


@pytest.mark.parametrize("name", ["obs.fits", "obs.png", "obs.tiff"])
def test_round_trip_of_dn_and_sensor(tmp_path, dn, name):
    side = write_observation(tmp_path / name, dn, SENSOR, {"seed": 3})
    assert side == sidecar_path(tmp_path / name) and side.is_file()
    img = read_image(tmp_path / name)
    assert img.unit == "DN" and img.data.shape == dn.shape
    assert np.array_equal(img.data, dn.astype(float))
    assert sensor_of(img)[0] == SENSOR
    assert img.metadata["sidecar"]["metadata"] == {"seed": 3}
    # the simulation's illustrative defaults are named in the sidecar and in the sources
    assert "quantum_efficiency" in img.metadata["sidecar"]["sensor_defaults"] and "bias_dn" not in img.metadata["sidecar"]["sensor_defaults"]
    assert "illustrative default" in sensor_of(img)[1]["quantum_efficiency"] and "illustrative" not in sensor_of(img)[1]["bias_dn"]
    # saturated at the sensor's ADC maximum (not the 16-bit file's): exactly those values masked
    assert np.array_equal(~img.mask, dn >= 4095) and not img.mask[3, 4].any() and (~img.mask).sum() < 30


def test_fits_header_holds_every_sensor_value(tmp_path, dn):
    write_observation(tmp_path / "obs.fits", dn, SENSOR)
    sidecar_path(tmp_path / "obs.fits").unlink()  # the header alone must carry them
    img = read_image(tmp_path / "obs.fits")
    sensor, sources = sensor_of(img)
    assert sensor == SENSOR and sources["bias_dn"] == "header SPACEFIT SENSOR bias_dn"
    assert img.metadata["header"]["GAIN"] == pytest.approx(2.0) and img.metadata["header"]["RDNOISE"] == 5.0
    assert img.metadata["header"]["BUNIT"] == "adu" and img.metadata["saturation_dn"] == 4095
    assert (img.metadata["row_order"], img.metadata["row_order_source"]) == ("bottom-up", "header ROWORDER")
    with fits.open(tmp_path / "obs.fits") as f:
        # FITS rows run bottom-up and channels are the third axis
        assert f[0].data.shape == (3, 16, 24) and np.array_equal(f[0].data[1, -1], dn[0, :, 1])


def test_foreign_fits_radiance_and_saturate_keyword(tmp_path):
    rad = np.array([[1.0, 2.0], [3.0, 4.0]])
    fits.PrimaryHDU(rad, header=fits.Header([("BUNIT", "W m-2 sr-1"), ("EXPTIME", 0.5)])).writeto(tmp_path / "r.fits")
    with pytest.warns(RowOrderWarning, match="no ROWORDER and no celestial WCS"):
        img = read_image(tmp_path / "r.fits", unit="radiance")
    assert img.unit == "W m^-2 sr^-1" and np.array_equal(img.data[..., 0], rad[::-1]) and img.mask.all()
    assert img.metadata["sensor_found"]["exposure_time_s"] == (0.5, "header EXPTIME")
    fits.PrimaryHDU(np.array([[10, 900], [1000, 20]], dtype=np.int32), header=fits.Header([("SATURATE", 900)])).writeto(tmp_path / "d.fits")
    img = read_image(tmp_path / "d.fits")
    assert img.unit == "DN" and (~img.mask[..., 0]).tolist() == [[True, False], [False, True]]
    with pytest.raises(InputError, match="BUNIT = 'W m-2 sr-1' is W m\\^-2 sr\\^-1, but DN"):
        read_image(tmp_path / "r.fits", unit="DN")


def test_a_tile_compressed_fits_is_read_as_its_uncompressed_copy_and_its_truncation_refused(tmp_path):
    """A Rice-compressed 256 x 256 image (smaller on disk than the image it holds) reads as the same
    image written plain; the compressed file cut short is still refused as truncated."""
    dn = np.random.default_rng(3).integers(0, 4000, (256, 256)).astype(np.int16)
    header = fits.Header([("ROWORDER", "TOP-DOWN"), ("SATURATE", 4095)])
    fits.PrimaryHDU(dn, header=header).writeto(tmp_path / "plain.fits")
    fits.HDUList([fits.PrimaryHDU(), fits.CompImageHDU(dn, header=header, compression_type="RICE_1")]).writeto(tmp_path / "rice.fits")
    assert (tmp_path / "rice.fits").stat().st_size < dn.nbytes
    rice, plain = read_image(tmp_path / "rice.fits"), read_image(tmp_path / "plain.fits")
    assert rice.unit == plain.unit == "DN" and np.array_equal(rice.data, plain.data) and np.array_equal(rice.data[..., 0], dn)
    whole = (tmp_path / "rice.fits").read_bytes()
    (tmp_path / "cut.fits").write_bytes(whole[: len(whole) - 5000])
    with pytest.raises(InputError, match="^'[^']*cut.fits' is truncated: the header of HDU 1 promises data up to byte"):
        read_image(tmp_path / "cut.fits")


def test_exr_radiance_and_its_refusals(tmp_path):
    rad = np.full((4, 5, 3), 0.25, dtype=np.float32)
    write_exr(tmp_path / "ok.exr", rad)
    img = read_image(tmp_path / "ok.exr")
    assert img.unit == "W m^-2 sr^-1" and np.allclose(img.data, 0.25) and img.mask.all()
    bad = rad.copy()
    bad[0, 0, 1], bad[1, 2, 0], bad[1, 2, 2], bad[3, 3, 0] = -1.0, -2.0, -0.5, np.nan
    write_exr(tmp_path / "bad.exr", bad)
    with pytest.raises(InputError, match="1 pixels are NaN"):
        read_image(tmp_path / "bad.exr")
    bad[3, 3, 0] = 0.0
    write_exr(tmp_path / "bad.exr", bad)
    with pytest.raises(InputError, match="2 pixels have negative radiance"):
        read_image(tmp_path / "bad.exr")
    with pytest.raises(InputError, match="not DN"):
        read_image(tmp_path / "ok.exr", unit="DN")


def test_png_and_tiff_need_their_response(tmp_path):
    values = np.array([[0, 32768, 65535]], dtype=np.uint16)[..., None]
    write_png(tmp_path / "lin.png", values)
    tifffile.imwrite(tmp_path / "lin.tif", values[..., 0])
    for name in ("lin.png", "lin.tif"):
        with pytest.raises(InputError, match="unknown response; .*response='linear'"):
            read_image(tmp_path / name)
        img = read_image(tmp_path / name, response="linear")
        assert img.data[0, :, 0].tolist() == [0, 32768, 65535] and img.mask[0, :, 0].tolist() == [True, True, False]
    # sRGB: half code value is 21.4 % of full scale in light (IEC 61966-2-1)
    img = read_image(tmp_path / "lin.png", response="srgb")
    assert img.data[0, 1, 0] / 65535 == pytest.approx(((32768 / 65535 + 0.055) / 1.055) ** 2.4, rel=1e-6)
    assert img.data[0, 2, 0] == pytest.approx(65535)


def test_8_bit_png_is_refused_as_radiance_and_without_response(tmp_path):
    write_png(tmp_path / "preview.png", np.full((3, 3, 3), 200, dtype=np.uint8))
    with pytest.raises(InputError, match="is an 8-bit PNG: a display image; it holds digital numbers, not radiance"):
        read_image(tmp_path / "preview.png", unit="radiance")
    with pytest.raises(InputError, match="8-bit PNG of unknown response"):
        read_image(tmp_path / "preview.png")
    assert read_image(tmp_path / "preview.png", response="srgb").data.shape == (3, 3, 3)


def test_user_mask_and_alpha(tmp_path, dn):
    write_observation(tmp_path / "obs.tiff", dn, SENSOR)
    user = np.zeros((16, 24), dtype=np.uint8)
    user[:, :12] = 255
    write_png(tmp_path / "mask.png", user)
    img = read_image(tmp_path / "obs.tiff", mask=tmp_path / "mask.png")
    assert not img.mask[:, 12:].any() and np.array_equal(img.mask[:, :12], dn[:, :12] < 4095)
    with pytest.raises(InputError, match="`mask` is 5 x 4 px, the image 24 x 16 px"):
        read_image(tmp_path / "obs.tiff", mask=np.ones((4, 5)))
    rgba = np.zeros((2, 2, 4), dtype=np.uint16)
    rgba[0, 0, 3] = 65535
    write_png(tmp_path / "rgba.png", rgba)
    img = read_image(tmp_path / "rgba.png", response="linear")
    assert img.data.shape == (2, 2, 3) and img.mask[..., 0].tolist() == [[True, False], [False, False]]


def test_unknown_formats_and_bad_arguments(tmp_path, dn):
    (tmp_path / "x.jpg").write_bytes(b"\xff\xd8")
    with pytest.raises(InputError, match=r"unknown image format '.jpg'; supported: .exr, .fits, .fit, .fts, .png, .tif, .tiff"):
        read_image(tmp_path / "x.jpg")
    with pytest.raises(InputError, match="does not exist"):
        read_image(tmp_path / "missing.fits")
    with pytest.raises(InputError, match="supported: .fits"):
        write_observation(tmp_path / "obs.exr", dn, SENSOR)
    with pytest.raises(InputError, match="`response` must be one of 'linear', 'srgb'"):
        read_image(tmp_path / "x.jpg", response="gamma")
    with pytest.raises(InputError, match="holds 5000, above the sensor's 2\\^12 - 1 = 4095 DN"):
        write_observation(tmp_path / "o.fits", np.full((2, 2, 1), 5000, dtype=np.uint16), SENSOR)
    with pytest.raises(InputError, match="unsigned integers"):
        write_observation(tmp_path / "o.fits", np.ones((2, 2, 1)), SENSOR)


IMAGE = np.arange(12, dtype=np.uint16).reshape(3, 4) * 100 + 7  # top-down: row 0 is the image's top


def _write(path, rows: np.ndarray, **cards) -> None:
    fits.PrimaryHDU(rows, header=fits.Header(list(cards.items()))).writeto(path)


def test_fits_row_order_from_roworder_wcs_or_the_standard(tmp_path):
    """Bottom-up with and without ROWORDER, top-down with ROWORDER = 'TOP-DOWN', and a WCS's parity: all read to the same array."""
    _write(tmp_path / "plain.fits", IMAGE[::-1])
    _write(tmp_path / "up.fits", IMAGE[::-1], ROWORDER="BOTTOM-UP")
    _write(tmp_path / "down.fits", IMAGE, ROWORDER="TOP-DOWN")
    sky = dict(CTYPE1="RA---TAN", CTYPE2="DEC--TAN", CRVAL1=10.0, CRVAL2=20.0, CRPIX1=2.0, CRPIX2=2.0, CD1_2=0.0, CD2_1=0.0)
    _write(tmp_path / "sky_up.fits", IMAGE[::-1], CD1_1=-1e-4, CD2_2=1e-4, **sky)  # east left, north up: det < 0
    _write(tmp_path / "sky_down.fits", IMAGE, CD1_1=-1e-4, CD2_2=-1e-4, **sky)  # the same sky stored top-down: det > 0
    with pytest.warns(RowOrderWarning):
        plain = read_image(tmp_path / "plain.fits")
    assert plain.metadata["row_order_source"] == "FITS standard (no ROWORDER, no WCS)" and "first row = bottom" in plain.metadata["notes"][0]
    expected = {"up.fits": "header ROWORDER", "down.fits": "header ROWORDER", "sky_up.fits": "header WCS (parity of the sky)",
                "sky_down.fits": "header WCS (parity of the sky)"}
    for name, source in expected.items():
        img = read_image(tmp_path / name)
        assert np.array_equal(img.data[..., 0], IMAGE) and img.metadata["row_order_source"] == source and not img.metadata["notes"], name
    assert read_image(tmp_path / "down.fits").metadata["row_order"] == "top-down"
    # the override wins over what the file says
    flipped = read_image(tmp_path / "down.fits", row_order="bottom-up")
    assert np.array_equal(flipped.data[..., 0], IMAGE[::-1]) and flipped.metadata["row_order_source"] == "option/argument"
    _write(tmp_path / "odd.fits", IMAGE, ROWORDER="LEFT-RIGHT")
    with pytest.raises(InputError, match="ROWORDER = 'LEFT-RIGHT' is neither 'TOP-DOWN' nor 'BOTTOM-UP'"):
        read_image(tmp_path / "odd.fits")
    with pytest.raises(InputError, match="`row_order` must be one of 'bottom-up', 'top-down'; got 'upside-down'"):
        read_image(tmp_path / "down.fits", row_order="upside-down")


def test_foreign_header_is_mapped_field_by_field(tmp_path):
    """A header written by another program with plain keywords: each maps to its sensor field, with its source."""
    cards = dict(ROWORDER="TOP-DOWN", BUNIT="adu", EXPTIME=0.02, GAIN=2.5, RDNOISE=3.2, BIAS=100.0, SATURATE=60000.0,
                 RADSCALE=1234.5, PSFSIGMA=0.8, **{"DATE-OBS": "2026-03-04T05:06:07.5"})
    _write(tmp_path / "cam.fits", IMAGE, **cards)
    img = read_image(tmp_path / "cam.fits")
    assert img.unit == "DN" and img.metadata["date_obs"] == "2026-03-04T05:06:07.500"
    sensor, sources = sensor_of(img)
    assert sensor.gain_dn_per_electron == pytest.approx(0.4) and sources["gain_dn_per_electron"] == "header GAIN"
    assert (sensor.read_noise_electrons, sources["read_noise_electrons"]) == (3.2, "header RDNOISE")
    assert (sensor.bias_dn, sources["bias_dn"]) == (100.0, "header BIAS")
    assert (sensor.saturation_dn, sources["saturation_level_dn"]) == (60000.0, "header SATURATE")
    assert (sensor.radiometric_scale_dn_per_w_m2_sr, sources["radiometric_scale_dn_per_w_m2_sr"]) == (1234.5, "header RADSCALE")
    assert (sensor.psf_sigma_px, sources["psf_sigma_px"]) == (0.8, "header PSFSIGMA")
    assert img.metadata["sensor_found"]["exposure_time_s"] == (0.02, "header EXPTIME")
    # calibrated: no diffraction without an aperture, no vignetting, both by a stated rule
    assert not sensor.diffraction and not sensor.vignetted and sources["vignetting"].startswith("rule: off")
    assert set(sources) == {"gain_dn_per_electron", "bias_dn", "read_noise_electrons", "psf_sigma_px", "diffraction",
                            "radiometric_scale_dn_per_w_m2_sr", "saturation_level_dn", "vignetting"}
    table = format_sensor_sources(sensor, sources)
    assert "read_noise_electrons" in table and "(header RDNOISE)" in table and len(table.splitlines()) == 1 + len(sources)
    # aliases: READNOIS, RON, PEDESTAL; aliases that disagree are refused
    _write(tmp_path / "alias.fits", IMAGE, ROWORDER="TOP-DOWN", READNOIS=4.0, PEDESTAL=30.0)
    found = read_image(tmp_path / "alias.fits").metadata["sensor_found"]
    assert found["read_noise_electrons"] == (4.0, "header READNOIS") and found["bias_dn"] == (30.0, "header PEDESTAL")
    assert found["bit_depth"] == (16, "header BITPIX")
    _write(tmp_path / "both.fits", IMAGE, ROWORDER="TOP-DOWN", RDNOISE=4.0, RON=5.0)
    with pytest.raises(InputError, match="both.fits.: the FITS header gives read_noise_electrons 2 ways: RDNOISE = 4.0, RON = 5.0"):
        read_image(tmp_path / "both.fits")
    _write(tmp_path / "text.fits", IMAGE, ROWORDER="TOP-DOWN", GAIN="high")
    with pytest.raises(InputError, match="text.fits.: the FITS header's GAIN = 'high' is not a number"):
        read_image(tmp_path / "text.fits")


@pytest.mark.parametrize("suffix", ["png", "exr"])
def test_an_image_written_past_the_file_size_limit_is_an_os_error_naming_the_file(tmp_path, suffix):
    """Mitsuba reports a failed write as a RuntimeError; the writers raise the OSError of its cause, which the
    command line reports in one line (a render's preview PNG, written through Mitsuba since Pillow went, too)."""
    import errno
    import resource

    path = tmp_path / f"big.{suffix}"
    noise = np.random.default_rng(0).random((200, 200, 3))
    soft, hard = resource.getrlimit(resource.RLIMIT_FSIZE)
    resource.setrlimit(resource.RLIMIT_FSIZE, (4096, hard))  # Python ignores SIGXFSZ: the write fails with EFBIG
    try:
        with pytest.raises(OSError) as err:
            write_png(path, (noise * 255).astype(np.uint8)) if suffix == "png" else write_exr(path, noise.astype(np.float32))
    finally:
        resource.setrlimit(resource.RLIMIT_FSIZE, (soft, hard))
    assert err.value.errno == errno.EFBIG and err.value.filename == str(path), err.value


def test_the_egain_alias_is_read_as_the_gain(tmp_path):
    """EGAIN (electrons per DN), GAIN's alias, gives the gain as GAIN does, and names itself as the source."""
    _write(tmp_path / "egain.fits", IMAGE, ROWORDER="TOP-DOWN", BUNIT="adu", EGAIN=2.5, RDNOISE=3.2, BIAS=100.0, RADSCALE=1234.5, PSFSIGMA=0.8)
    sensor, sources = sensor_of(read_image(tmp_path / "egain.fits"))
    assert sensor.gain_dn_per_electron == pytest.approx(0.4) and sources["gain_dn_per_electron"] == "header EGAIN"
