"""The sensor of a DN image and where each of its values came from: the file, a sensor file, the
options, the illustrative defaults (only when asked for by name), or a documented rule."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any

from spacefit.errors import InputError, check_choice, check_type
from spacefit.imageio.fits import FITS_SENSOR_KEY, HEADER_KEYWORDS
from spacefit.imageio.reading import ObservedImage
from spacefit.sensor import Sensor, check_fields, missing_for_measurement, used_fields

SENSOR_DEFAULTS = ("illustrative",)


def _ways(field: str) -> str:
    """The three ways to give a sensor field, for an error message."""
    keys = [*HEADER_KEYWORDS.get(field, ()), *(("BITPIX (integer data)",) if field == "bit_depth" else ()),
            f"HIERARCH {FITS_SENSOR_KEY} {field}"]
    return (f"header keyword {' / '.join(keys)}; sensor file key {field} (--sensor FILE); "
            f"option --sensor-value {field}=VALUE (Python: sensor={{{field!r}: ...}})")


def sensor_of(image: ObservedImage, sensor: Sensor | Mapping[str, Any] | None = None, *,
              sensor_file: Mapping[str, Any] | None = None, defaults: str | None = None) -> tuple[Sensor, dict[str, str]]:
    """The sensor that measured a DN image, and where each value it uses came from.

    ``sensor`` given as an :class:`Sensor` is taken whole. Otherwise the values are, each
    replacing the ones before: the illustrative defaults (only with ``defaults="illustrative"``),
    the file's (its integer type's bits, a spacefit sidecar, the FITS header's keywords,
    :data:`HEADER_KEYWORDS`), ``sensor_file`` (the fields of a sensor file,
    :func:`read_sensor_file`), and the mapping ``sensor`` (an option or argument).
    Without defaults, the values not given follow documented rules, not illustrative numbers: no
    full well (the ``SATURATE`` level or the ADC's range saturates); diffraction only when both the
    aperture and the wavelength are given; vignetting off for a calibrated camera (a radiometric
    scale), on otherwise.

    Returns:
        the sensor and, for each field it uses, its source:
        ``"header KEY"``, ``"spacefit sidecar"``, ``"sensor file"``, ``"option/argument"``,
        ``"default (illustrative)"`` or ``"rule: ..."``.
    Raises:
        InputError: a value a fit needs that no
            source gives, naming each and the three ways to give it.

    Args:
        image: a DN image (:func:`read_image`).
        sensor: a whole :class:`Sensor`, or fields replacing the file's; None: the file's.
        sensor_file: the fields of a sensor file (:func:`read_sensor_file`).
        defaults: ``"illustrative"`` to fill values no source gives with :class:`Sensor`'s defaults.

    Example:
        >>> import numpy as np, spacefit as sf
        >>> sensor, camera = sf.Sensor(), sf.Intrinsics(focal_length=0.05, pixel_pitch=1e-5, width=4, height=3)
        >>> _ = sf.write_observation("frame.fits", sf.observe(np.full((3, 4, 3), 1.0), sensor, camera, seed=0), sensor)
        >>> found, sources = sf.sensor_of(sf.read_image("frame.fits"), {"exposure_time_s": 0.002})
        >>> found.exposure_time_s, sources["exposure_time_s"]
        (0.002, 'option/argument')
    """
    check_type("image", image, ObservedImage, "an sf.ObservedImage (what sf.read_image returns)")
    if isinstance(sensor, Sensor):
        return sensor, {name: "option/argument" for name in used_fields(sensor)}
    if sensor is not None:
        check_fields(sensor, "the sensor values of --sensor-value (Python: sensor=)")
    if defaults is not None:
        check_choice("sensor_defaults", defaults, SENSOR_DEFAULTS)
    layers: list[tuple[Mapping[str, Any], str]] = []
    if defaults is not None:
        layers.append(({f.name: getattr(Sensor(), f.name) for f in dataclasses.fields(Sensor)}, "default (illustrative)"))
    found = image.metadata.get("sensor_found", {})
    layers += [({k: v[0] for k, v in found.items()}, ""), (sensor_file or {}, "sensor file"), (sensor or {}, "option/argument")]
    fields: dict[str, Any] = {}
    sources: dict[str, str] = {}
    for values, source in layers:
        fields.update(values)
        sources.update({k: source or found[k][1] for k in values})
    missing = missing_for_measurement(fields)
    if missing:
        names = "; ".join(f"{m}: {_ways(m.split()[0])}" for m in missing)
        raise InputError(f"{image.path!r} holds DN (digital numbers), and a fit of them needs {len(missing)} sensor value(s) that "
                         f"neither the file nor the options give: {names}. Or ask for the illustrative defaults by name: "
                         "sensor_defaults='illustrative' (--sensor-defaults illustrative).")
    optics = "aperture_diameter_m" in fields and "wavelength_m" in fields
    rules = {"full_well_electrons": (None, "rule: none given (the saturation level or the ADC's range saturates)"),
             "diffraction": (optics, "rule: " + ("on, the aperture and wavelength given" if optics else
                                                 "off, no aperture and wavelength given"))}
    for name, (value, source) in rules.items():
        if name not in fields:
            fields[name], sources[name] = value, source
    result = Sensor.from_dict(fields, f"the sensor of {image.path!r}")
    if "vignetting" not in fields:
        sources["vignetting"] = f"rule: {'off for a calibrated camera' if result.calibrated else 'on (cos^4) without a radiometric scale'}"
    return result, {name: sources[name] for name in used_fields(result)}


def format_sensor_sources(sensor: Sensor, sources: Mapping[str, str]) -> str:
    """The values of ``sensor`` that a fit uses with their sources (:func:`sensor_of`), one line each.

    Args:
        sensor: the sensor (:func:`sensor_of`'s first value).
        sources: field -> source (:func:`sensor_of`'s second value).

    Returns:
        A title line and one line per field: name, value and source.

    Example:
        >>> import spacefit as sf
        >>> print(sf.format_sensor_sources(sf.Sensor(), {"exposure_time_s": "sensor file"}))
        sensor values and their sources:
          exposure_time_s = 0.001  (sensor file)
    """
    width = max(map(len, sources), default=0)
    lines = [f"  {name:<{width}} = {getattr(sensor, name) if name != 'vignetting' else sensor.vignetted}  ({source})"
             for name, source in sources.items()]
    return "\n".join(["sensor values and their sources:", *lines])
