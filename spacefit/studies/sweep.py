"""Sweeps: render a scene at every point of a grid of scene values into a labelled, resumable store.

A sweep's axes are scene values (``axes``): ``{"sun.elevation_deg": [10, 20, 30]}`` is one axis of
three points; several keys are a grid (every combination); a table of keys of equal length is one
zipped axis named by the table (``{"pose": {"sun.azimuth_deg": [...], "target.attitude_z_deg": [...]}}``);
``{"linspace": [start, stop, num]}`` or ``{"arange": [start, stop, step]}`` stand for lists. A key is a
registered parameter (``sf.available_parameters``: materials, sun angles, pose), set in place on the
loaded scene, ``render.seed`` / ``render.spp``, or any other scene-file key (``camera.position_m``...)
or the wrinkles' D, G or rms height, for which the scene is assembled and loaded again (the meshes
and the refinement from the caches, the displacement redone).

The result is an xarray Dataset whose dimensions are the axes, with coordinates in the keys' units
(``units`` attributes), and per point: ``mean_radiance``, ``pixels`` and ``irradiance`` of each part
and of the whole ``target`` (:func:`spacefit.studies.worker.summaries`), ``radiance`` images when
asked (one chunk per point), the derivatives when asked, and ``done``. It is written to a Zarr
store point by point, each point's ``done`` after its data: a sweep stopped in any way (Ctrl-C,
kill -9) keeps every finished point, and running it again with the same arguments computes only
the missing ones. A store of other arguments is refused, never mixed.
"""

from __future__ import annotations

import contextlib
import hashlib
import itertools
import json
import math
import os
import shutil
import sys
import tempfile
import warnings
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from spacefit import __version__
from spacefit.digests import Watch
from spacefit.errors import InputError, InputTypeError, check_choice, check_count, check_flag, check_name_list, check_range, closest, quote
from spacefit.interrupts import deferred_interrupts
from spacefit.locks import hold_lock
from spacefit.output import STAGE_PREFIX, check_writable, clean_stale_stages
from spacefit.progress import progress_bar
from spacefit.scene.schema import Scene
from spacefit.scene.sections import check_scene
from spacefit.scene.toml import load_scene, read_scene_dict
from spacefit.scene.parameters import GEOMETRY, MOVES_VERTICES, available, check_names, parameter, scene_with_values
from spacefit.executors import Cluster, check_cluster, cluster_of
from spacefit.studies.cluster import STALL_S, run_on_dask
from spacefit.studies.sensitivity import SUMMARY_VARIABLES, normalisation
from spacefit.studies import worker
from spacefit.studies.worker import Task, regions
from spacefit.units import RADIANCE_UNIT

RENDER_ARGUMENTS = ("render.seed", "render.spp")
# Scene keys a sweep cannot vary: they fix the shape of the store's images and part lists.
FIXED_KEYS = ("render.resolution", "target.mesh")
SUFFIX_UNITS = {"_m": "m", "_mm": "mm", "_deg": "deg", "_w_m2": "W m^-2", "_px": "px"}
CHECKSUM = "checksum"  # the variable of each point's checksum (one chunk per point)
VERIFY_BATCH_BYTES = 64 << 20  # a store is verified in reads of about this many bytes
# A sweep of more points is refused unless allow_large: a store holds a file per point and variable.
MAX_POINTS = 1_000_000
FILE_BLOCK_BYTES = 4096  # a chunk file takes at least a file-system block
# The index of points to compute, per point: the done flag, np.nonzero's int64 per axis, and a
# tuple in a list (sorted copy included): 72 bytes, plus 36 per axis (an int and its pointer).
INDEX_BYTES_PER_POINT, INDEX_BYTES_PER_POINT_AXIS = 73, 44
STORE_FORMAT = 2  # Zarr format 2: readable by every Zarr library (format 3 has no string type yet)
AxesSpec = Mapping[str, Any]


@dataclass(frozen=True)
class Axis:
    """One dimension of a sweep: its name and the values of each key along it (equal lengths)."""

    name: str
    values: dict[str, list[Any]]

    @property
    def size(self) -> int:
        """Number of points along the axis."""
        return len(next(iter(self.values.values())))


def units(key: str) -> str:
    """The unit of a swept key: the registry's for a parameter, else from the key's suffix ("1" if none)."""
    try:
        return parameter(key).unit
    except InputError:
        return _suffix_unit(key)


def _suffix_unit(key: str) -> str:
    return next((u for suffix, u in SUFFIX_UNITS.items() if key.endswith(suffix)), "1")


def _values(key: str, spec: Any) -> list[Any]:
    """A key's list of values from a list or a ``linspace`` / ``arange`` table."""
    if isinstance(spec, Mapping):
        rule = next(iter(spec)) if len(spec) == 1 else None
        if rule == "linspace" and isinstance(spec[rule], list) and len(spec[rule]) == 3:
            start, stop, num = spec["linspace"]
            check_count(f"axes[{key!r}].linspace num", num)
            values = np.linspace(check_range(f"axes[{key!r}].linspace start", start),
                                 check_range(f"axes[{key!r}].linspace stop", stop), int(num))
            whole = all(isinstance(v, int) and not isinstance(v, bool) for v in (start, stop))
            if whole and np.all(values == np.round(values)):  # integers stay integers (render.spp)
                return values.astype(int).tolist()
            return values.tolist()
        if rule == "arange" and isinstance(spec[rule], list) and len(spec[rule]) == 3:
            bounds = [check_range(f"axes[{key!r}].arange", v) for v in spec["arange"]]
            start, stop, step = bounds
            if not step or (stop - start) / step <= 0:
                raise InputError(f"`axes[{key!r}].arange` = {spec['arange']} gives no values; use [start, stop, step] "
                                 "with a step towards stop.")
            whole = all(isinstance(v, int) and not isinstance(v, bool) for v in spec["arange"])  # integers stay integers (render.seed)
            return np.arange(*(spec["arange"] if whole else bounds)).tolist()
        close = [c for c in (closest(str(k), ("linspace", "arange")) for k in spec) if c]
        hint = f" Did you mean {{{close[0]} = [start, stop, ...]}}?" if close else ""
        raise InputError(f"`axes[{key!r}]` must be a list of values, {{linspace = [start, stop, num]}} or "
                         f"{{arange = [start, stop, step]}}, got {quote(dict(spec))}.{hint}")
    if isinstance(spec, (str, bytes)) or not isinstance(spec, Sequence | np.ndarray) or len(spec) == 0:
        raise InputError(f"`axes[{key!r}]` must be a non-empty list of values, got {quote(spec)}.")
    return [np.asarray(v).tolist() for v in spec]


def _zipped(spec: Any) -> bool:
    """Whether an axis zips several scene keys: a table whose keys are scene keys (they have dots;
    ``linspace`` and ``arange`` have none)."""
    return isinstance(spec, Mapping) and any("." in str(k) for k in spec)


def parse_axes(scene: Scene, axes: AxesSpec) -> list[Axis]:
    """Check a sweep's axes against the scene (every key and value) and return them in order."""
    if not isinstance(axes, Mapping) or not axes:
        raise InputTypeError(f"`axes` must be a non-empty mapping of scene keys to lists of values, got {quote(axes)}.")
    parsed = []
    for name, spec in axes.items():
        values = {k: _values(k, v) for k, v in spec.items()} if _zipped(spec) else {name: _values(name, spec)}
        if not values:
            raise InputError(f"axis {name!r} zips no keys: give it a table of scene keys and their lists of values.")
        if len({len(v) for v in values.values()}) > 1:
            raise InputError(f"the zipped keys of axis {name!r} must have lists of equal length, got "
                             f"{ {k: len(v) for k, v in values.items()} }.")
        parsed.append(Axis(name, values))
    keys = [k for a in parsed for k in a.values]
    if len(set(keys)) != len(keys):
        raise InputError(f"`axes` names a key twice: {keys}.")
    for axis in parsed:
        for key, vals in axis.values.items():
            if key in FIXED_KEYS:
                raise InputError(f"`axes` may not sweep {key!r}: it fixes the store's images and parts; run one sweep per value.")
            for v in dict.fromkeys(map(json.dumps, vals)):  # every distinct value, checked as the scene would
                value = json.loads(v)
                try:
                    scene.with_values({key: value})
                except InputError as err:
                    raise type(err)(f"`axes[{key!r}]` holds {quote(value)}: {err}") from None
    return parsed


def _canonical(scene: Scene, axes: list[Axis], options: Mapping[str, Any], mesh_sha256: Mapping[str, str]) -> str:
    """The arguments that decide a store's contents, as JSON: a rerun must match them (numbers
    compared as floats, so that ``[30, 60]`` and ``[30.0, 60.0]`` are the same sweep), and so must
    the contents of the mesh files the scene reads (``mesh_sha256``: path -> SHA-256; an edited mesh
    at the same path is another sweep)."""
    axes_json = [[a.name, {k: _floats(v) for k, v in a.values.items()}] for a in axes]
    return json.dumps({"scene": scene.to_toml(), "axes": axes_json, "mesh_files": dict(mesh_sha256), **options},
                      sort_keys=True)


def _floats(value: Any) -> Any:
    """``value`` with every integer (not bool) as a float, lists kept."""
    if isinstance(value, list):
        return [_floats(v) for v in value]
    return float(value) if isinstance(value, int) and not isinstance(value, bool) else value


def in_place_names(scene: Scene) -> set[str]:
    """The registered parameters a sweep sets on the loaded scene: all but the wrinkles' D, G and rms
    height, whose points assemble the scene again (the refinement is kept, the displacement redone, and
    the level of detail's effective roughness follows them)."""
    return set(available(scene)) - set(GEOMETRY)


def tasks(scene: Scene, axes: list[Axis], *, images: bool, derivatives: tuple[str, ...], derivative_seeds: int
          ) -> Callable[[tuple[int, ...]], Task]:
    """The task of each point (its index along every axis)."""
    names = in_place_names(scene)
    in_place = [k for a in axes for k in a.values if k in names]
    crop = not any(k in MOVES_VERTICES for k in in_place)
    base = Task(scene.to_toml(), crop=crop, images=images, derivatives=derivatives, derivative_seeds=derivative_seeds)
    tomls: dict[str, str] = {}

    def task(index: tuple[int, ...]) -> Task:
        values = {k: vals[i] for a, i in zip(axes, index) for k, vals in a.values.items()}
        scene_keys = {k: v for k, v in values.items() if k not in names and k not in RENDER_ARGUMENTS}
        key = json.dumps(scene_keys, sort_keys=True)
        if key not in tomls:
            parameters = {k: v for k, v in scene_keys.items() if k in GEOMETRY}
            edited = scene.with_values({k: v for k, v in scene_keys.items() if k not in parameters})
            tomls[key] = scene_with_values(edited, parameters).to_toml() if scene_keys else base.scene_toml
        seed, spp = (values.get(k) for k in RENDER_ARGUMENTS)
        return replace(base, scene_toml=tomls[key], in_place=tuple((k, float(values[k])) for k in in_place),
                       spp=None if spp is None else int(spp), seed=None if seed is None else int(seed))

    return task


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
        "description": f"BLAKE2b (8 bytes, little-endian) of the point's bytes of {', '.join(sorted(layout))} in this "
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
    return xr.Dataset(variables, coords=coords, attrs=dict(attrs))


def open_store(store: str | Path | None, spec: str, make: Callable[[], Any], overwrite: bool) -> Any:
    """The Zarr group of the sweep ``spec``: created from ``make()`` when new (or ``overwrite``), reopened
    when it holds the same sweep; refused when it holds another one or other files."""
    import zarr  # here: only a sweep's store needs Zarr (slow to import)

    if store is None:
        memory = zarr.storage.MemoryStore()
        make().to_zarr(memory, compute=False, mode="w", zarr_format=STORE_FORMAT)
        return zarr.open_group(memory, mode="r+", zarr_format=STORE_FORMAT)
    if not str(store).strip():
        raise InputError("`store` must name a folder, got an empty string.")
    target = Path(store)
    if target.exists():
        old = _stored_spec(target)
        if old is None and (not target.is_dir() or any(target.iterdir())):
            raise InputError(f"`store` {str(target)!r} exists and is not a spacefit sweep store; choose a new folder.")
        if old is not None and old != spec and not overwrite:
            raise InputError(f"`store` {str(target)!r} holds a sweep with other arguments (scene, mesh files, axes or options); rerun "
                             "with the same ones to finish it, pass overwrite=True (--overwrite) to replace it, or choose a new store.")
        if old == spec and not overwrite:
            return zarr.open_group(str(target), mode="r+", zarr_format=STORE_FORMAT)
    # the empty store is made beside its place and moved there whole: a kill leaves no half store
    check_writable(target)
    target.parent.mkdir(parents=True, exist_ok=True)
    clean_stale_stages(target.parent, of=f"-{target.name}")  # this store's, left by a kill while it was made
    stage = Path(tempfile.mkdtemp(prefix=f"{STAGE_PREFIX}{os.getpid()}-", suffix=f"-{target.name}", dir=target.parent))
    try:
        make().to_zarr(str(stage / "store"), compute=False, mode="w", zarr_format=STORE_FORMAT)
        if target.exists():
            shutil.rmtree(target)
        os.replace(stage / "store", target)
    finally:
        shutil.rmtree(stage, ignore_errors=True)
    return zarr.open_group(str(target), mode="r+", zarr_format=STORE_FORMAT)


def _stored_spec(path: Path) -> str | None:
    """The arguments of the sweep stored at ``path``, or None if it is not a sweep store."""
    import zarr  # here: only a sweep's store needs Zarr (slow to import)

    try:
        return zarr.open_group(str(path), mode="r", zarr_format=STORE_FORMAT).attrs.get("spacefit_sweep")
    except Exception:  # noqa: BLE001  (any unreadable folder is "not a store")
        return None


def pending(done: np.ndarray, order: Sequence[int]) -> list[tuple[int, ...]]:
    """The indices of the points not yet done, grouped by the axes in ``order`` (slowest first)."""
    todo = [tuple(int(i) for i in idx) for idx in zip(*np.nonzero(~done))]
    return sorted(todo, key=lambda idx: tuple(idx[a] for a in order))


def point_checksum(values: Sequence[np.ndarray]) -> np.uint64:
    """The checksum of one point: BLAKE2b (8 bytes) of its variables' bytes, in the order given."""
    digest = hashlib.blake2b(digest_size=8)
    for value in values:
        digest.update(np.ascontiguousarray(value).tobytes())
    return np.uint64(int.from_bytes(digest.digest(), "little"))


def write_point(group: Any, index: tuple[int, ...], result: Mapping[str, np.ndarray], root: Path | None = None) -> None:
    """Write one point's variables, then the checksum of their bytes as read back from the store,
    flush them to the disk (``root``: the store's folder), then its ``done`` flag. Each is a chunk of
    its own, which Zarr writes whole to a temporary file and renames."""
    names = sorted(result)
    for name in names:
        group[name][index] = result[name]
    group[CHECKSUM][index] = point_checksum([np.asarray(group[name][index]) for name in names])
    if root is not None:
        _flush(root, index, {**{name: np.ndim(result[name]) for name in names}, CHECKSUM: 0})
    group["done"][index] = True


def _flush(root: Path, index: tuple[int, ...], extra_dims: Mapping[str, int]) -> None:
    """fsync the chunk files of the point ``index`` of each variable (with its number of dimensions
    beyond the axes) and their folders, so that a crash of the machine cannot undo them."""
    for name, extra in extra_dims.items():
        _fsync(root / name / ".".join(map(str, index + (0,) * extra)))  # Zarr 2's chunk key, "." separated
        _fsync(root / name)


def _fsync(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


@dataclass(frozen=True)
class StoreReport:
    """What :func:`verify_store` found: counts of points, the done points whose data failed their
    checksum (or whose flag is unreadable), and the variables missing from the store."""

    points: int
    done: int
    verified: int
    failed: tuple[tuple[int, ...], ...]
    missing_variables: tuple[str, ...]

    @property
    def missing(self) -> int:
        """Points not done (never computed, or failed)."""
        return self.points - self.verified

    @property
    def damaged(self) -> bool:
        """Some done point failed its checksum, or a variable is missing."""
        return bool(self.failed or self.missing_variables)

    def __str__(self) -> str:
        lines = [f"{self.points:,} points: {self.done:,} done, {self.verified:,} verified, {len(self.failed):,} failed "
                 f"their checksum, {self.missing:,} to compute"]
        if self.missing_variables:
            lines.append(f"missing variables: {', '.join(self.missing_variables)}")
        return "\n".join(lines)


def check_points(group: Any, root: Path) -> StoreReport:
    """Read back every done point of the store in folder ``root`` (``group``, opened without its
    consolidated metadata) in batches and compare its checksum; a missing chunk, an undecodable one
    or a missing variable fails the points it holds, never raises."""
    present = {p.parent.name for p in root.glob("*/.zarray")}
    names = list(group[CHECKSUM].attrs.get("variables", ())) if CHECKSUM in present else []
    missing = tuple(n for n in ["done", CHECKSUM, *names] if n not in present)
    shape = tuple(group["done"].shape if "done" in present else group.attrs.get("sweep_shape", ()))
    points, done_count, failed, verified = math.prod(shape) if shape else 0, 0, [], 0
    point_bytes = sum(math.prod(group[n].shape[len(shape):]) * group[n].dtype.itemsize for n in names if n in present)
    for slab in _slabs(shape, point_bytes + 9):
        done, unreadable = _read(group["done"], slab) if "done" in present else (None, None)
        if done is None or not (done.any() or unreadable.any()):
            continue
        done = done & ~unreadable
        done_count += int(done.sum() + unreadable.sum())
        bad = unreadable.copy()
        if missing:
            bad |= done
        else:
            stored, bad_sum = _read(group[CHECKSUM], slab)
            data = [_read(group[n], slab) for n in names]
            for local in zip(*np.nonzero(done)):
                ok = not bad_sum[local] and not any(b[local] for _, b in data)
                bad[local] = not (ok and stored[local] != 0 and point_checksum([v[local] for v, _ in data]) == stored[local])
        verified += int((done & ~bad).sum())
        start = tuple(s.start for s in slab)
        failed += [tuple(int(a + b) for a, b in zip(start, local)) for local in zip(*np.nonzero(bad))]
    return StoreReport(points, done_count, verified, tuple(failed), missing)


def _slabs(shape: tuple[int, ...], point_bytes: int) -> Iterator[tuple[slice, ...]]:
    """Blocks of the grid of points (C order) of at most VERIFY_BATCH_BYTES each (one point at least)."""
    budget, block = max(1, VERIFY_BATCH_BYTES // max(point_bytes, 1)), []
    for n in reversed(shape):
        take = max(1, min(n, budget))
        block.insert(0, take)
        budget = max(1, budget // take)
    for start in itertools.product(*(range(0, n, b) for n, b in zip(shape, block))):
        yield tuple(slice(a, min(a + b, n)) for a, b, n in zip(start, block, shape))


def _read(array: Any, slab: tuple[slice, ...]) -> tuple[np.ndarray, np.ndarray]:
    """The values of ``array`` over ``slab`` and which points' chunks could not be read (those read as
    zeros): one read for the slab, point by point only where it fails."""
    shape = tuple(s.stop - s.start for s in slab)
    try:
        return np.asarray(array[slab]), np.zeros(shape, dtype=bool)
    except Exception:  # noqa: BLE001  (a damaged chunk raises whatever its codec raises)
        values = np.zeros(shape + tuple(array.shape[len(slab):]), dtype=array.dtype)
        unreadable = np.zeros(shape, dtype=bool)
        for local in np.ndindex(shape):
            try:
                values[local] = array[tuple(s.start + i for s, i in zip(slab, local))]
            except Exception:  # noqa: BLE001
                unreadable[local] = True
        return values, unreadable


def verify_store(store: str | Path) -> StoreReport:
    """Check a sweep store without rendering: read back every done point and compare its checksum.

    Returns:
        A :class:`StoreReport`: counts of points done, verified, failed and to compute; ``damaged``
        when a done point failed or a variable is missing (a rerun of the sweep recomputes them).

    Raises:
        InputError: ``store`` is not a spacefit sweep store.
    """
    import zarr  # here: only a sweep's store needs Zarr (slow to import)

    path = Path(store)
    if _stored_spec(path) is None:
        raise InputError(f"`store` {str(store)!r} is not a spacefit sweep store (no folder with a sweep's attributes).")
    group = zarr.open_group(str(path), mode="r", zarr_format=STORE_FORMAT, use_consolidated=False)
    return check_points(group, path)


def repair(group: Any, root: Path, make: Callable[[], Any]) -> Any:
    """Verify the done points of a reopened store; recreate missing variables, clear the ``done``
    flag of the points that failed (so that they are computed again) and say how many. Returns the
    group to write to: ``group``, or the store opened again when variables were recreated."""
    import zarr  # here: only a sweep's store needs Zarr (slow to import)

    plain = zarr.open_group(str(root), mode="r", zarr_format=STORE_FORMAT, use_consolidated=False)
    report = check_points(plain, root)
    if report.missing_variables:
        make()[list(report.missing_variables)].to_zarr(str(root), mode="a", compute=False, zarr_format=STORE_FORMAT)
        group = zarr.open_group(str(root), mode="r+", zarr_format=STORE_FORMAT)  # its metadata now lists them
    for index in report.failed:
        group["done"][index] = False
    gone = ", ".join(report.missing_variables)
    if "done" in report.missing_variables:
        said = f"the variable(s) {gone} were missing and are recreated; every point is computed again"
    elif report.missing_variables:
        said = f"the variable(s) {gone} were missing and are recreated; the {report.done:,} done points are recomputed"
    else:
        said = (f"{len(report.failed):,} of {report.done:,} done points failed their checksum (data chunk missing or "
                "damaged) and are recomputed")
    if report.damaged:
        warnings.warn(f"store {str(root)!r}: {said}", stacklevel=3)
    return group


def axis_lengths(axes: AxesSpec) -> list[int]:
    """The number of points along each axis, from the specification alone (no list of values built);
    0 for an axis that :func:`parse_axes` will refuse."""
    if not isinstance(axes, Mapping):
        return [0]

    def length(spec: Any) -> int:
        if isinstance(spec, Mapping) and set(spec) == {"linspace"} and isinstance(spec["linspace"], Sequence):
            num = spec["linspace"][2] if len(spec["linspace"]) == 3 else 0
            return num if isinstance(num, int) and not isinstance(num, bool) and num > 0 else 0
        if isinstance(spec, Mapping) and set(spec) == {"arange"} and isinstance(spec["arange"], Sequence):
            try:
                start, stop, step = (float(v) for v in spec["arange"])
                return max(0, math.ceil((stop - start) / step))
            except (TypeError, ValueError, ZeroDivisionError, OverflowError):
                return 0
        if _zipped(spec):  # its keys' lengths are checked equal later
            return max((length(v) for v in spec.values()), default=0)
        if isinstance(spec, Mapping):
            return 0
        return len(spec) if isinstance(spec, Sequence | np.ndarray) and not isinstance(spec, str | bytes) else 0

    return [length(spec) for spec in axes.values()]


@dataclass(frozen=True)
class Estimate:
    """A sweep's size, known before anything is allocated: its points, the store's bytes on disk per
    variable (at most: uncompressed, and a file-system block per chunk at least) and the memory of
    its index of points to compute."""

    points: int
    store_bytes: dict[str, int]
    index_bytes: int

    @property
    def sizes(self) -> str:
        """The store's and the index's sizes, in words."""
        per = ", ".join(f"{name} {_size(b)}" for name, b in self.store_bytes.items())
        return f"store at most {_size(sum(self.store_bytes.values()))} ({per}); index {_size(self.index_bytes)} in memory"

    def __str__(self) -> str:
        return f"sweep of {self.points:,} points: {self.sizes}; time left: the progress bar's, from the renders measured"


def _size(n: float) -> str:
    for unit in ("B", "KiB", "MiB", "GiB", "TiB"):
        if n < 1024 or unit == "TiB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024
    return ""


def estimate(scene: Scene, axes: AxesSpec, *, images: bool, derivatives: tuple[str, ...]) -> Estimate:
    """The size of a sweep (:class:`Estimate`) from its axes' lengths and the scene (nothing allocated)."""
    lengths = axis_lengths(axes)
    points = math.prod(lengths)
    layout = point_variables(scene, images=images, derivatives=derivatives)
    chunk = {name: math.prod(size) * np.dtype(dtype).itemsize for name, (_, size, dtype, *_) in layout.items()}
    chunk |= {CHECKSUM: 8, "done": 1}
    store = {name: points * max(FILE_BLOCK_BYTES, b) for name, b in chunk.items()}
    return Estimate(points, store, points * (1 + INDEX_BYTES_PER_POINT_AXIS * len(lengths) + INDEX_BYTES_PER_POINT))


def check_estimate(found: Estimate, store: str | Path | None, *, allow_large: bool) -> None:
    """Refuse a sweep whose index (and store, when ``store`` is None: in memory) would not fit in the
    memory available; and unless ``allow_large``, one of more than :data:`MAX_POINTS` points or whose
    new store may not fit on its disk."""
    from spacefit.rendering.memory import available_memory_bytes  # deferred: Mitsuba (the sweep renders anyway)

    if found.points > MAX_POINTS and not allow_large:
        raise InputError(f"a sweep of {found.points:,} points is more than {MAX_POINTS:,} (a file per point and "
                         f"variable; {found.sizes}); split it, or pass allow_large=True (--large) to run it.")
    memory = available_memory_bytes()
    needs = found.index_bytes + (sum(found.store_bytes.values()) if store is None else 0)  # a store in memory
    if needs > memory:
        what = "its index alone" if store is not None else "its index and its store (in memory: give `store` a folder)"
        raise InputError(f"a sweep of {found.points:,} points needs about {_size(needs)} of memory for {what} and this "
                         f"machine has {_size(memory)} available; split it into smaller sweeps.")
    if allow_large:
        return
    if store is not None and not Path(store).exists():  # a new store (one to finish holds its points already)
        parent = next(p for p in Path(store).absolute().parents if p.exists())
        free = shutil.disk_usage(parent).free
        if sum(found.store_bytes.values()) > free:
            raise InputError(f"the store of this sweep may need up to {_size(sum(found.store_bytes.values()))} and "
                             f"{str(parent)!r} has {_size(free)} free ({found.sizes}); free some space, choose another "
                             "disk, or pass allow_large=True (--large) to run it (compression may make it fit).")


def sweep(
    scene: Scene,
    axes: AxesSpec,
    *,
    store: str | Path | None = None,
    images: bool = False,
    derivatives: Sequence[str] = (),
    derivative_seeds: int = 4,
    overwrite: bool = False,
    cluster: Cluster | None = None,
    max_renders_per_worker: int = 500,
    allow_large: bool = False,
    stall_s: float = STALL_S,
    quiet: bool = False,
    workers: int | None = None,
    scheduler: str | None = None,
) -> Any:
    """Render ``scene`` at every point of ``axes`` and return the results as a labelled xarray Dataset.

    Args:
        scene: the scene every point starts from.
        axes: the swept values (module docstring): key -> list, or axis name -> {key: list} (zipped).
        store: a Zarr folder written point by point (None: in memory). An existing store of the
            same sweep is completed, not recomputed. It is locked while the sweep runs
            (:mod:`spacefit.locks`): a store another process writes is refused, naming it.
        images: store each point's radiance image (W m^-2 sr^-1) too.
        derivatives: registered parameters whose derivatives of each region's mean radiance to
            store at every point, with their Monte Carlo standard errors (:func:`sf.sensitivity`).
        derivative_seeds: independent seeds of each derivative (>= 2).
        overwrite: replace a store that holds another sweep.
        cluster: where the points render (:mod:`spacefit.executors`): None, this process; an int N, a new
            local dask.distributed cluster of N worker processes; a scheduler address (``tcp://host:8786``);
            a ``distributed.Client`` (left open).
        max_renders_per_worker: restart a dask worker after this many renders (Mitsuba leaks).
        allow_large: run a sweep of more than :data:`MAX_POINTS` points, or whose store may not fit
            on its disk (:func:`check_estimate`; the size is printed first unless ``quiet``).
        stall_s: on dask, stop with :class:`~spacefit.executors.ClusterError` when no point
            finishes for this long (s); a point whose worker dies is retried twice, then named the same way.
        quiet: no size estimate, no progress bar.
        workers, scheduler: deprecated spellings of ``cluster`` (an int, an address).

    Returns:
        The Dataset, read back from the store (lazily: arrays load when used).

    Ctrl-C (or SIGTERM) stops after the point being rendered; every finished point stays in the
    store and KeyboardInterrupt is raised. A reopened store's done points are read back and their
    checksums compared first: those that fail are computed again (a warning says how many). The
    mesh files are checked before each point is marked done and hashed again at the end: a changed
    one raises InputError naming it, the points rendered after the change not marked done.
    """
    import xarray as xr  # here: only a sweep's store needs xarray (slow to import)

    check_scene(scene)
    check_count("derivative_seeds", derivative_seeds, 2, optional=False)
    check_count("max_renders_per_worker", max_renders_per_worker, optional=False)
    stall_s = check_range("stall_s", stall_s, 0.0, lo_open=True, unit="s")
    cluster = cluster_of(cluster, workers, scheduler)
    check_cluster(cluster)
    derivatives = check_name_list("derivatives", derivatives)
    if derivatives:
        check_names(scene, derivatives, "derivatives")
    images = check_flag("images", images)
    found = estimate(scene, axes, images=images, derivatives=derivatives)
    check_estimate(found, store, allow_large=allow_large)
    parsed = parse_axes(scene, axes)
    if not quiet:
        print(found, file=sys.stderr, flush=True)
    watch = Watch(scene.mesh_files())
    options = {"images": images, "derivatives": list(derivatives), "derivative_seeds": derivative_seeds}
    spec = _canonical(scene, parsed, options, watch.recorded)
    seeds = parsed_seeds(scene, parsed)
    attrs = {"spacefit_version": __version__, "scene_toml": scene.to_toml(), "seeds": seeds,
             "sweep_shape": [a.size for a in parsed],
             "spacefit_sweep": spec, "description": "spacefit sweep: radiance of each region at each point"}
    def make() -> Any:
        return template(scene, parsed, images=images, derivatives=derivatives, attrs=attrs)

    with contextlib.nullcontext() if store is None else hold_lock(store, "`store`"):  # one writer per store
        reopened = store is not None and Path(store).exists() and not overwrite  # else open_store makes a new one
        group = open_store(store, spec, make, overwrite)
        if reopened:
            group = repair(group, Path(store), make)
        task_of = tasks(scene, parsed, images=images, derivatives=derivatives, derivative_seeds=derivative_seeds)
        names = in_place_names(scene)
        # points that load another scene vary slowest, so that a scene is loaded once per value
        order = sorted(range(len(parsed)), key=lambda a: all(k in names or k in RENDER_ARGUMENTS for k in parsed[a].values))
        todo = pending(np.asarray(group["done"][...]), order)
        total = math.prod(a.size for a in parsed)
        run_points(todo, task_of, group, total=total, cluster=cluster,
                   max_renders_per_worker=max_renders_per_worker, stall_s=stall_s, quiet=quiet, watch=watch,
                   root=None if store is None else Path(store))
        return xr.open_zarr(group.store if store is None else str(store), zarr_format=STORE_FORMAT)


SWEEP_FILE_OPTIONS = ("images", "derivatives", "derivative_seeds", "max_renders_per_worker", "stall_s")


def read_sweep_file(path: str | Path, overrides: Sequence[str] = ()) -> tuple[Scene, dict[str, Any], dict[str, Any]]:
    """Read a sweep TOML file: ``scene`` (a scene file, relative to the sweep file; default: the
    thesis's scene, with ``overrides`` as ``--set`` gives them), an ``[axes]`` table as :func:`sweep`
    takes it, and options (``images``, ``derivatives``, ``derivative_seeds``, ``max_renders_per_worker``, ``stall_s``).

    Returns ``(scene, axes, options)``: ``sf.sweep(scene, axes, store=..., **options)`` runs it.
    """
    data = read_scene_dict(path)  # the same checks and messages as a scene file's
    for key in data:
        check_choice(f"sweep file {str(path)!r}: key", key, ("scene", "axes", *SWEEP_FILE_OPTIONS))
    if "images" in data:
        check_flag(f"sweep file {str(path)!r}: images", data["images"])
    if not isinstance(data.get("derivatives", []), list):
        raise InputTypeError(f"sweep file {str(path)!r}: `derivatives` must be a list of parameter names, got {quote(data['derivatives'])}.")
    if "axes" not in data:
        raise InputError(f"sweep file {str(path)!r} has no [axes] table of swept scene keys.")
    scene_file = data.get("scene")
    if scene_file is not None and not isinstance(scene_file, str):
        raise InputError(f"sweep file {str(path)!r}: `scene` must be a path to a scene file, got {quote(scene_file)}.")
    scene = load_scene(Path(path).parent / scene_file if scene_file else None, list(overrides))
    return scene, data["axes"], {k: data[k] for k in SWEEP_FILE_OPTIONS if k in data}


def parsed_seeds(scene: Scene, axes: list[Axis]) -> list[int]:
    """The render seeds a sweep uses: the swept ``render.seed`` values, else the scene's."""
    swept = [v for a in axes for k, vals in a.values.items() if k == "render.seed" for v in vals]
    return [int(s) for s in swept] or [scene.render.seed]


def run_points(todo: list[tuple[int, ...]], task_of: Callable[[tuple[int, ...]], Task], group: Any, *, total: int,
               cluster: Cluster | None, max_renders_per_worker: int, stall_s: float, quiet: bool,
               watch: Watch | None = None, root: Path | None = None) -> None:
    """Render the points ``todo`` in-process or on dask, writing each to ``group`` as it finishes;
    with a ``watch`` of the input files, a point is marked done only while they are unchanged."""
    bar = progress_bar(total, "sweep", initial=total - len(todo), quiet=quiet)
    written: list[tuple[int, ...]] = []
    try:
        with deferred_interrupts() as interrupts:
            results: Iterator[tuple[tuple[int, ...], dict[str, np.ndarray]]]
            if cluster is None:
                results = ((index, worker.run_task(task_of(index))) for index in todo)
            else:
                results = run_on_dask(todo, task_of, cluster=cluster,
                                      max_renders_per_worker=max_renders_per_worker, stall_s=stall_s)
            for index, result in results:
                if watch is not None and (edited := watch.check()):
                    raise _changed(edited, "the point rendered after the change is not marked done")
                write_point(group, index, result, root)
                written.append(index)
                bar.update()
                interrupts.check()
            if watch is not None and (edited := watch.final()):
                for index in written:
                    group["done"][index] = False
                raise _changed(edited, f"the {len(written):,} points rendered in this run are not marked done")
    finally:
        bar.close()


def _changed(paths: Sequence[str], kept: str) -> InputError:
    return InputError(f"the input file(s) {', '.join(map(repr, paths))} changed while the sweep ran (SHA-256 not the "
                      f"start's); {kept}. Restore them and rerun to finish this store, or start a new store.")
