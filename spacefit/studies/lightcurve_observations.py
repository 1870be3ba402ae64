"""Measured brightness at known geometry: the observations a light-curve fit takes
(:class:`LightCurveObservations`, checked on construction), and magnitudes <-> irradiances.

The geometry is in the target's frame: unit directions from the target towards the sun and the
observer, the observer's range, and where known the Earth's centre (for Earthshine). A target in
the Earth's shadow is predicted dark, flagged (``in_shadow``) and left out of fits. Magnitudes are
apparent magnitudes in a band of :data:`~spacefit.studies.lightcurve.SUN_MAGNITUDES`:
m = m_sun - 2.5 log10(E / E_sun) (:func:`magnitude_of`, :func:`irradiance_of`). How files of
measured magnitudes are read and written is :mod:`spacefit.studies.observing`'s.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from spacefit.errors import InputError, check_array, check_choice, check_type, quote, unit_rows
from spacefit.studies.lightcurve import SUN_MAGNITUDES
from spacefit.studies.observation_files import RefusedRow
from spacefit.studies.orbit import EARTH_RADIUS_M


@dataclass(frozen=True)
class LightCurveObservations:
    """Measured brightness at known geometry.

    Attributes:
        magnitude, magnitude_sigma: apparent magnitudes in ``band`` and their errors (None: not stated).
        sun, observer: (n, 3) unit directions from the target towards the sun and the observer, in
            the target's frame.
        range_m: the observer's distance (m).
        in_shadow: (n,) the target in the Earth's shadow (predicted dark; left out of fits).
        time_utc: ISO times, or None.
        source: where they came from.
        refused: the file's rows not used, with the reason (:class:`RefusedRow`).
        earth_m: (n, 3) the Earth's centre seen from the target, in its frame (m; what Earthshine,
            :func:`earthshine_irradiance`, needs), or None where the file gives no position.

    Example:
        >>> import numpy as np, spacefit as sf
        >>> phase = np.radians([20.0, 40.0, 60.0])  # the sun overhead, the observer tilted away
        >>> curve = sf.LightCurveObservations(
        ...     magnitude=np.array([5.0, 5.2, 5.5]), magnitude_sigma=np.full(3, 0.05), band="V",
        ...     sun=np.tile([0.0, 0.0, 1.0], (3, 1)), observer=np.stack([np.sin(phase), 0 * phase, np.cos(phase)], axis=1),
        ...     range_m=np.full(3, 1.0e6), in_shadow=np.zeros(3, bool), time_utc=None, source="example")
        >>> curve.magnitude
        array([5. , 5.2, 5.5])
    """

    magnitude: np.ndarray
    magnitude_sigma: np.ndarray | None
    band: str
    sun: np.ndarray
    observer: np.ndarray
    range_m: np.ndarray
    in_shadow: np.ndarray
    time_utc: np.ndarray | None
    source: str
    refused: tuple[RefusedRow, ...] = ()
    earth_m: np.ndarray | None = None

    def __post_init__(self) -> None:
        check_type("source", self.source, str, "a string")
        check_choice("band", self.band, SUN_MAGNITUDES)
        magnitude = _finite("magnitude", self.magnitude, 1)
        n = len(magnitude)
        fields = {"magnitude": magnitude, "range_m": _finite("range_m", self.range_m, 1, n)}
        if np.any(fields["range_m"] <= 0):
            raise InputError(f"`range_m` must be positive, got {quote(self.range_m)}.")
        if self.magnitude_sigma is not None:
            fields["magnitude_sigma"] = _finite("magnitude_sigma", self.magnitude_sigma, 1, n)
            if np.any(fields["magnitude_sigma"] <= 0):
                raise InputError(f"`magnitude_sigma` must be None or positive, got {quote(self.magnitude_sigma)}.")
        for name in ("sun", "observer"):
            v = _finite(name, getattr(self, name), 2, n)
            # its shape first: rows of no component have no largest to scale by (unit_rows)
            if v.shape[1:] != (3,) or not np.all(np.isfinite(unit := unit_rows(v))):
                raise InputError(f"`{name}` must be ({n}, 3) directions, none (0, 0, 0), got {quote(getattr(self, name))}.")
            fields[name] = unit
        shadow = check_array("in_shadow", self.in_shadow, "a bool array")
        if shadow.shape != (n,):
            raise InputError(f"`in_shadow` must be {n} booleans, got shape {shadow.shape}.")
        if self.earth_m is not None:
            fields["earth_m"] = _finite("earth_m", self.earth_m, 2, n)
            if fields["earth_m"].shape[1:] != (3,) or np.any(np.linalg.norm(fields["earth_m"], axis=1) <= EARTH_RADIUS_M):
                raise InputError(f"`earth_m` must be None or ({n}, 3) positions of the Earth's centre, each farther than its "
                                 f"radius {EARTH_RADIUS_M:g} m, got {quote(self.earth_m)}.")
        if self.time_utc is not None:
            fields["time_utc"] = _times(self.time_utc, n)
        for name, value in fields.items():
            object.__setattr__(self, name, value)

    def __len__(self) -> int:
        return len(self.magnitude)

    def subset(self, rows: np.ndarray) -> "LightCurveObservations":
        """These observations at ``rows`` (indices or a boolean mask)."""
        pick = (lambda a: None if a is None else a[rows])
        return LightCurveObservations(self.magnitude[rows], pick(self.magnitude_sigma), self.band, self.sun[rows], self.observer[rows],
                                      self.range_m[rows], self.in_shadow[rows], pick(self.time_utc), self.source, self.refused,
                                      pick(self.earth_m))


def _times(value: object, n: int) -> np.ndarray:
    """``value`` as an array of ``n`` times (ISO 8601 strings as the files give them)."""
    try:
        times = np.asarray(value)
    except (TypeError, ValueError, RecursionError, OverflowError):  # ragged: [None, []]
        times = None
    if times is None or times.shape != (n,):
        raise InputError(f"`time_utc` must be None or {n} times, got {quote(value)}.")
    return times


def _finite(name: str, value: object, ndim: int, n: int | None = None) -> np.ndarray:
    """``value`` as a finite float array of ``ndim`` dimensions (the first of length ``n`` if given, else at least 1)."""
    arr = check_array(name, value).astype(float)
    if arr.ndim != ndim or len(arr) != (n if n is not None else max(len(arr), 1)) or not np.all(np.isfinite(arr)):
        count = f"{n}" if n is not None else "one or more"
        raise InputError(f"`{name}` must be {count} finite values{' (rows)' if ndim > 1 else ''}, got {quote(value)}.")
    return arr


def magnitude_of(irradiance_w_m2: np.ndarray, band: str, sun_irradiance_w_m2: float) -> np.ndarray:
    """Apparent magnitudes in ``band`` of irradiances at the observer (inf where dark)."""
    with np.errstate(divide="ignore"):
        return SUN_MAGNITUDES[check_choice("band", band, SUN_MAGNITUDES)] - 2.5 * np.log10(np.asarray(irradiance_w_m2) / sun_irradiance_w_m2)


def irradiance_of(magnitude: np.ndarray, band: str, sun_irradiance_w_m2: float) -> np.ndarray:
    """Irradiances at the observer (W m^-2) of apparent magnitudes in ``band``."""
    return sun_irradiance_w_m2 * 10.0 ** (-0.4 * (np.asarray(magnitude) - SUN_MAGNITUDES[check_choice("band", band, SUN_MAGNITUDES)]))


# d ln E / d m: a magnitude error's relative irradiance error.
LN_PER_MAGNITUDE = 0.4 * math.log(10.0)
