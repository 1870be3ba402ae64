"""A saved fit read back: the :class:`~spacefit.fitting.result.FitResult` of a fit's folder (what
:func:`~spacefit.fitting.report.write_fit_report`, ``spacefit fit`` and
:func:`~spacefit.fitting.report.write_table_fit` write) or of its ``fit.json`` alone.

``fit.json`` gives the values, standard errors, correlation, status, warnings, goodness of fit,
per-part rows and history (:meth:`FitResult.from_dict`); beside it ``fit.toml`` gives the fitted
scene and ``residuals.fits`` the images' residuals. The renders and the observations are not saved:
a fit read back has none (its figures say so where they would show a render).
"""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np

from spacefit.errors import InputError, check_path
from spacefit.fitting.result import FitResult
from spacefit.scene.toml import load_scene


def read_fit(path: str | Path) -> FitResult:
    """The fit saved in ``path``: a fit's folder or its ``fit.json``. Beside ``fit.json``, ``fit.toml``
    gives :attr:`~FitResult.scene` (None, with a warning, where it no longer loads: a mesh moved) and
    ``residuals.fits`` the images' :attr:`~FitResult.residuals` (float32, as saved; a table's or a light
    curve's are not saved). ``renders`` and ``observations`` are empty.

    Raises:
        InputError: no such file or folder, a folder without ``fit.json``, or a ``fit.json`` that is not
            a fit's (not JSON, a field missing, an unknown status).

    Args:
        path: a fit's folder, or its ``fit.json``.

    Returns:
        The :class:`FitResult`.

    Example:
        >>> import numpy as np, spacefit as sf
        >>> zenith = np.radians([10.0, 30.0, 50.0, 70.0])
        >>> wi = np.stack([np.sin(zenith), 0 * zenith, np.cos(zenith)], axis=1)
        >>> table = sf.BRDFTable(wi=wi, wo=np.tile([0.0, 0.0, 1.0], (4, 1)), value=np.full(4, 0.3 / np.pi), sigma=np.full(4, 0.002), source="paint")
        >>> folder = sf.write_table_fit("paint-fit", sf.fit_brdf_table(table, "lambert"))
        >>> back = sf.read_fit(folder)
        >>> back.status.value, round(back.values["parts.sample.kd"], 3)
        ('converged', 0.3)
    """
    path = check_path("path", path)
    file = path / "fit.json" if path.is_dir() else path
    if not file.is_file():
        raise InputError(f"`path` {str(path)!r}: no fit.json there (give a fit's folder or its fit.json).")
    try:
        data = json.loads(file.read_text(encoding="utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as err:
        raise InputError(f"{str(file)!r} is not JSON: {err}.") from None
    if not isinstance(data, dict):
        raise InputError(f"{str(file)!r} holds a {type(data).__name__}, not a fit's summary.")
    result = FitResult.from_dict(data, where=repr(str(file)))
    folder = file.parent
    if (folder / "fit.toml").is_file():
        try:
            result.scene = load_scene(folder / "fit.toml")
        except InputError as err:
            warnings.warn(f"{str(folder / 'fit.toml')!r} does not load ({err}); the fit read back has no scene.", stacklevel=2)
    if (folder / "residuals.fits").is_file():
        result.residuals = _residuals(folder / "residuals.fits")
    return result


def _residuals(path: Path) -> list[np.ndarray]:
    """The images' residuals of ``residuals.fits`` (:func:`~spacefit.fitting.report.write_residuals`:
    extension ``OBS<k>`` for image k, (channels, height, width), top row first) as (height, width,
    channels), in image order."""
    from astropy.io import fits  # here: only a saved image fit's residuals need astropy's FITS reader (0.3 s)

    with fits.open(path) as hdus:
        images = {int(h.name[3:]): np.moveaxis(np.asarray(h.data, dtype=np.float32), 0, -1)
                  for h in hdus[1:] if h.name.startswith("OBS") and h.name[3:].isdigit()}
    return [images[k] for k in sorted(images)]
