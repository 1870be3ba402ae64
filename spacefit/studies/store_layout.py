"""What a sweep's Zarr store holds: its variables, coordinates and chunks, as an empty Dataset.

Each point of the sweep's grid holds :func:`point_variables` (the region means, pixel counts and
irradiance; the image and the sensitivities where asked for), each variable one chunk per point,
beside the point's :data:`CHECKSUM` and its ``done`` flag (:func:`template`). The coordinates are the
axes' values (a zipped axis's keys and a vector's components beside them), the regions, and the
parameters' units; their digests (:func:`coordinate_digest`) are kept in the attribute
:data:`COORDINATES`. How a store is opened, written, verified and repaired is
:mod:`spacefit.studies.store`'s.
"""

from __future__ import annotations

import hashlib
from collections.abc import Mapping
from typing import Any

import numpy as np

from spacefit.scene.parameters import parameter
from spacefit.scene.schema import Scene
from spacefit.studies.axes import Axis, units
from spacefit.studies.sensitivity import SUMMARY_VARIABLES, normalisation
from spacefit.studies.worker import regions
from spacefit.units import RADIANCE_UNIT

CHECKSUM = "checksum"  # the variable of each point's checksum (one chunk per point)
COORDINATES = "spacefit_coordinates"  # the store's attribute of each coordinate's digest (coordinate_digest)


def _coords(axes: list[Axis]) -> dict[str, Any]:
    """Coordinates: a grid axis of scalars is indexed by its values; the keys of a zipped axis and
    vector values (a key's components along ``KEY[i]``) are coordinates beside it."""
    coords: dict[str, Any] = {}
    for axis in axes:
        for key, vals in axis.values.items():
            arr = np.asarray(vals)
            dims = (axis.name,) if arr.ndim == 1 else (axis.name, f"{key}[i]")
            coords[key] = (dims, arr, {"units": units(key)})
    return coords


def point_variables(scene: Scene, *, images: bool, derivatives: tuple[str, ...]) -> dict[str, tuple[Any, ...]]:
    """The variables of each point: name -> (extra dimensions, their sizes, dtype, fill, unit, description)."""
    n = len(regions(scene))
    out: dict[str, tuple[Any, ...]] = {
        "mean_radiance": (("region",), (n,), np.float64, np.nan, RADIANCE_UNIT,
                          "mean over the pixels whose centre sees the region of the RGB mean radiance"),
        "pixels": (("region",), (n,), np.int32, -1, "1", "pixels whose centre sees the region"),
        "irradiance": (("region",), (n,), np.float64, np.nan, "W m^-2",
                       "sum of radiance times pixel solid angle over the region's pixels (target: the whole image), at the pinhole"),
    }
    if images:
        w, h = scene.render.resolution
        out["radiance"] = (("y", "x", "channel"), (h, w, 3), np.float32, np.nan, RADIANCE_UNIT, "the rendered image")
    for name, (dtype, fill, unit, doc) in (SUMMARY_VARIABLES.items() if derivatives else ()):
        out[name] = (("parameter", "region"), (len(derivatives), n), dtype, fill, unit, doc)
    return out


def template(scene: Scene, axes: list[Axis], *, images: bool, derivatives: tuple[str, ...], attrs: Mapping[str, Any]) -> Any:
    """The store's empty Dataset (dask arrays, never computed): dimensions, coordinates, chunks of one point."""
    import dask.array as da  # here: dask and xarray take a second to import; only a sweep's store needs them
    import xarray as xr

    dims = tuple(a.name for a in axes)
    shape = tuple(a.size for a in axes)
    one = (1,) * len(dims)
    layout = point_variables(scene, images=images, derivatives=derivatives)
    variables: dict[str, Any] = {}
    for name, (extra, size, dtype, fill, unit, doc) in layout.items():
        data = da.full(shape + size, fill, dtype=dtype, chunks=one + size)
        variables[name] = (dims + extra, data, {"units": unit, "description": doc})
    variables[CHECKSUM] = (dims, da.zeros(shape, dtype=np.uint64, chunks=one), {
        "description": f"BLAKE2b (8 bytes, little-endian, keyed with the point's index as 'i,j,...') of the point's bytes of {', '.join(sorted(layout))} in this "
                       "order (C order, the stored dtypes), written after them and before done; 0: none",
        "variables": sorted(layout)})
    variables["done"] = (dims, da.zeros(shape, dtype=bool, chunks=one),
                         {"description": "the point is written, durably, and its checksum with it"})
    coords = {**_coords(axes), "region": np.array(regions(scene), dtype=object)}
    if images:
        coords["channel"] = np.array(["R", "G", "B"], dtype=object)
    if derivatives:
        coords["parameter"] = np.array(derivatives, dtype=object)
        coords["parameter_unit"] = ("parameter", np.array([parameter(n).unit for n in derivatives], dtype=object))
        coords["normalised_unit"] = ("parameter", np.array([normalisation(n, 1.0)[1] for n in derivatives], dtype=object))
    ds = xr.Dataset(variables, coords=coords)
    ds.attrs = {**attrs, COORDINATES: {name: coordinate_digest(ds[name].values) for name in sorted(ds.coords)}}
    return ds


def coordinate_digest(values: Any) -> str:
    """BLAKE2b (hex, 16 bytes) of a coordinate's values: numbers by dtype, shape and bytes; strings by
    their UTF-8 text, each ended by a NUL."""
    array = np.asarray(values)
    digest = hashlib.blake2b(digest_size=16)
    digest.update(f"{array.shape}|".encode())
    if array.dtype.kind in "OUST":
        for item in array.reshape(-1):
            digest.update(str(item).encode() + b"\0")
    else:
        digest.update(f"{array.dtype.str}|".encode())
        digest.update(np.ascontiguousarray(array).tobytes())
    return digest.hexdigest()
