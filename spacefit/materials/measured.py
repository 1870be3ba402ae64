"""Measured BRDF tables (goniometer data) as they are read: :class:`BRDFTable` and :func:`read_brdf_table`.

The material models fitted to them are :mod:`spacefit.fitting.brdf_table`'s; a table used as it
is, a material of its own, is :class:`spacefit.materials.tabulated.TabulatedBRDF`.

Two file formats, both text with ``#`` comment lines, angles in degrees (radians inside), the BRDF
in sr^-1:

* the general format, a CSV file whose header names its columns: ``theta_i_deg, phi_i_deg,
  theta_o_deg, phi_o_deg, brdf_sr`` and optionally ``sigma_sr`` (each value's standard error).
  theta is the zenith angle from the surface normal (0 to 90), phi the azimuth in the surface's
  plane from its x axis (the tangent along which a conductor's ``alpha_x`` lies) towards y; ``_i``
  is the direction towards the light, ``_o`` towards the detector.
* the Scatterworks / lumos-sat format of the Starlink tables (Fankhauser, Askari & Tyson 2023, AJ
  166:59): five unnamed columns ``phi_i theta_i phi_o theta_o brdf`` with phi the zenith and theta
  the azimuth of the same two directions; a negative zenith is the direction on the far side of the
  normal (azimuth + 180 deg), as lumos-sat reads it (its ``spherical_to_unit``).

A direction (zenith z, azimuth a) is the unit vector (sin z cos a, sin z sin a, cos z) in the
surface's frame. Rows at or beyond grazing (|zenith| >= 90 deg, where the BRDF is undefined) are
dropped on reading, as are values at or below ``floor`` (an instrument's noise floor).
"""

from __future__ import annotations

import csv
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from spacefit.errors import InputError, check_array, check_range, check_type, quote, read_text_rows

GENERAL_COLUMNS = ("theta_i_deg", "phi_i_deg", "theta_o_deg", "phi_o_deg", "brdf_sr")

# The largest BRDF a table may hold (sr^-1): a goniometer's aperture of about 0.1 deg resolves a specular peak of
# at most about 1 / (pi 0.0017^2) ~ 1e5 sr^-1. A measured table can come close: the Starlink chassis's peaks at
# 8.0e3 sr^-1 and its solar array's at 5.3e4 (data/starlink-v1p5), so the limit is the resolvable one, not 1e3;
# it refuses unit slips (1e30).
MAX_BRDF_SR = 1e5


@dataclass(frozen=True)
class BRDFTable:
    """Measured BRDF values.

    Attributes:
        wi, wo: (n, 3) unit directions towards the light and the detector in the surface's frame.
        value: (n,) the BRDF, sr^-1.
        sigma: (n,) its standard errors, sr^-1, or None (not stated).
        source: where it came from (a path), for messages.

    Raises:
        InputError: directions that are not (n, 3) unit vectors, values or errors that are negative,
            not finite or of another length.

    Example:
        >>> import numpy as np, spacefit as sf
        >>> zenith = np.radians([10.0, 30.0, 50.0, 70.0])  # the light's; the detector looks down the normal
        >>> wi = np.stack([np.sin(zenith), 0 * zenith, np.cos(zenith)], axis=1)
        >>> wo = np.tile([0.0, 0.0, 1.0], (4, 1))
        >>> table = sf.BRDFTable(wi=wi, wo=wo, value=np.full(4, 0.3 / np.pi), sigma=np.full(4, 0.002), source="white paint")
        >>> len(table.value), table.source
        (4, 'white paint')
    """

    wi: np.ndarray
    wo: np.ndarray
    value: np.ndarray
    sigma: np.ndarray | None
    source: str

    def __post_init__(self) -> None:
        check_type("source", self.source, str, "a string")
        value = check_array("value", self.value).astype(float)
        if value.ndim != 1 or not np.all(np.isfinite(value)) or np.any(value < 0) or np.any(value > MAX_BRDF_SR):
            raise InputError(f"`value` must be a vector of finite BRDF values in [0, {MAX_BRDF_SR:g}] sr^-1, got {quote(self.value)}.")
        for name in ("wi", "wo"):
            w = check_array(name, getattr(self, name)).astype(float)
            if w.shape != (len(value), 3) or not np.all(np.isfinite(w)):
                raise InputError(f"`{name}` must be ({len(value)}, 3) finite directions (one per value), got shape {w.shape}.")
            with np.errstate(over="ignore"):
                norm = np.linalg.norm(w, axis=1)
            if not np.allclose(norm, 1.0, atol=1e-6):
                raise InputError(f"`{name}` must hold unit vectors, got lengths {quote(np.linalg.norm(w, axis=1))}.")
            object.__setattr__(self, name, w)
        object.__setattr__(self, "value", value)
        if self.sigma is not None:
            sigma = check_array("sigma", self.sigma).astype(float)
            if sigma.shape != value.shape or not np.all(np.isfinite(sigma) & (sigma > 0)):
                raise InputError(f"`sigma` must be None or {len(value)} positive finite errors (sr^-1), got {quote(self.sigma)}.")
            object.__setattr__(self, "sigma", sigma)

    def __len__(self) -> int:
        return len(self.value)


def unit_vectors(zenith_deg: np.ndarray, azimuth_deg: np.ndarray) -> np.ndarray:
    """(n, 3) unit vectors of zenith and azimuth angles (deg; a negative zenith is on the far side)."""
    z, a = np.radians(zenith_deg), np.radians(azimuth_deg)
    return np.stack([np.sin(z) * np.cos(a), np.sin(z) * np.sin(a), np.cos(z)], axis=-1)


def read_brdf_table(path: str | Path, *, floor: float = 0.0) -> BRDFTable:
    """Read a measured BRDF table, dropping rows at or beyond grazing (zenith >= 90 deg) and values at
    or below ``floor`` (sr^-1, an instrument's noise floor). Two text formats, ``#`` lines comments,
    angles in degrees, the BRDF in sr^-1:

    * the general format: a CSV file whose header names its columns ``theta_i_deg, phi_i_deg,
      theta_o_deg, phi_o_deg, brdf_sr`` and optionally ``sigma_sr`` (each value's standard error);
      theta is the zenith angle from the surface normal, phi the azimuth from the surface's x axis
      (a conductor's ``alpha_x`` tangent) towards y; ``_i`` towards the light, ``_o`` towards the
      detector;
    * the Scatterworks / lumos-sat format of the Starlink tables (Fankhauser, Askari & Tyson 2023,
      AJ 166:59): five unnamed columns ``phi_i theta_i phi_o theta_o brdf``, phi the zenith and
      theta the azimuth; a negative zenith is the direction on the far side of the normal.

    Args:
        path: the table's file.
        floor: values at or below it are dropped (sr^-1), >= 0.

    Returns:
        The :class:`BRDFTable`.

    Raises:
        InputError: an unreadable row, missing columns, a negative BRDF or error, nothing left.
        OSError: the file cannot be read.

    Example:
        >>> import spacefit as sf
        >>> with open("paint.csv", "w") as f:
        ...     print("theta_i_deg,phi_i_deg,theta_o_deg,phi_o_deg,brdf_sr,sigma_sr", file=f)
        ...     print("10,0,0,0,0.0955,0.002", file=f)
        ...     print("30,0,0,0,0.0955,0.002", file=f)
        >>> sf.read_brdf_table("paint.csv").value
        array([0.0955, 0.0955])
    """
    check_range("floor", floor, 0.0, unit="sr^-1")
    rows = read_text_rows("path", path, "BRDF table")
    path = Path(path)
    if not rows:
        raise InputError(f"BRDF table {path}: no data rows.")
    header = [h.strip() for h in rows[0].split(",")]
    if all(_is_number(h) for h in rows[0].replace(",", " ").split()):
        numbers = _numbers(path, rows, 5)
        wi, wo = unit_vectors(numbers[:, 0], numbers[:, 1]), unit_vectors(numbers[:, 2], numbers[:, 3])
        zenith = np.abs(numbers[:, [0, 2]])
        value, sigma = numbers[:, 4], None
    else:
        missing = [c for c in GENERAL_COLUMNS if c not in header]
        if missing:
            raise InputError(f"BRDF table {path}: the header {header} lacks {missing}; the general format's columns are "
                             f"{', '.join(GENERAL_COLUMNS)} (and optionally sigma_sr).")
        table = list(csv.DictReader(rows))
        names = [*GENERAL_COLUMNS, *(["sigma_sr"] if "sigma_sr" in header else [])]
        numbers = _numbers(path, [",".join(r[c] or "" for c in names) for r in table], len(names))
        wi, wo = unit_vectors(numbers[:, 0], numbers[:, 1]), unit_vectors(numbers[:, 2], numbers[:, 3])
        zenith = numbers[:, [0, 2]]
        if np.any((zenith < 0) | (zenith > 90)):
            raise InputError(f"BRDF table {path}: theta_i_deg and theta_o_deg must lie in [0, 90] deg (zenith from the normal).")
        value = numbers[:, 4]
        sigma = numbers[:, 5] if len(names) == 6 else None
        if sigma is not None and np.any(sigma <= 0):
            raise InputError(f"BRDF table {path}: sigma_sr must be positive, row {int(np.argmax(sigma <= 0)) + 1} has {sigma[sigma <= 0][0]:g}.")
    if np.any(value < 0):
        raise InputError(f"BRDF table {path}: a BRDF is never negative, row {int(np.argmax(value < 0)) + 1} has {value[value < 0][0]:g} sr^-1.")
    if np.any(value > MAX_BRDF_SR):
        row = int(np.argmax(value > MAX_BRDF_SR))
        raise InputError(f"BRDF table {path}: row {row + 1} has {value[row]:g} sr^-1, above {MAX_BRDF_SR:g} sr^-1, the sharpest "
                         "specular peak a goniometer resolves (a unit slip? the BRDF in sr^-1, not percent or 1/deg^2).")
    keep = np.all(zenith < 90.0, axis=1) & (value > floor)
    if not keep.any():
        raise InputError(f"BRDF table {path}: no value above the floor {floor:g} sr^-1 away from grazing.")
    return BRDFTable(wi[keep], wo[keep], value[keep], None if sigma is None else sigma[keep], str(path))


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _numbers(path: Path, rows: Sequence[str], columns: int) -> np.ndarray:
    if not rows:
        raise InputError(f"BRDF table {path}: no data rows.")
    out = []
    for i, row in enumerate(rows):
        fields = row.replace(",", " ").split()
        if len(fields) != columns or not all(_is_number(f) for f in fields):
            raise InputError(f"BRDF table {path}: data row {i + 1} must hold {columns} numbers, got {row.strip()!r}.")
        out.append([float(f) for f in fields])
    values = np.array(out, dtype=float)
    if not np.all(np.isfinite(values)):
        raise InputError(f"BRDF table {path}: every value must be finite.")
    return values
