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

import hashlib
import json
import math
import os
import shutil
import tempfile
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from spacefit import __version__
from spacefit.errors import InputError, InputTypeError, check_count, check_name_list, check_vector, quote
from spacefit.interrupts import deferred_interrupts
from spacefit.output import STAGE_PREFIX, check_writable
from spacefit.progress import progress_bar
from spacefit.scene.schema import Scene, check_scene
from spacefit.scene.toml import load_scene, read_scene_dict
from spacefit.scene.parameters import GEOMETRY, MOVES_VERTICES, available, check_names, parameter, scene_with_values
from spacefit.studies.cluster import run_on_dask
from spacefit.studies.sensitivity import SUMMARY_VARIABLES, normalisation
from spacefit.studies import worker
from spacefit.studies.worker import Task, regions

RENDER_ARGUMENTS = ("render.seed", "render.spp")
# Scene keys a sweep cannot vary: they fix the shape of the store's images and part lists.
FIXED_KEYS = ("render.resolution", "target.mesh")
SUFFIX_UNITS = {"_m": "m", "_mm": "mm", "_deg": "deg", "_w_m2": "W m^-2", "_px": "px"}
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
        for kind in set(spec) & {"linspace", "arange"}:  # [start, stop, num or step]
            check_vector(f"axes[{key!r}].{kind}", spec[kind])
        if set(spec) == {"linspace"} and len(spec["linspace"]) == 3:
            start, stop, num = spec["linspace"]
            check_count(f"axes[{key!r}].linspace num", num)
            return np.linspace(float(start), float(stop), int(num)).tolist()
        if set(spec) == {"arange"} and len(spec["arange"]) == 3:
            start, stop, step = (float(v) for v in spec["arange"])
            if not step or not math.isfinite(step) or (stop - start) / step <= 0:
                raise InputError(f"`axes[{key!r}].arange` = {spec['arange']} gives no values; use [start, stop, step] "
                                 "with a step towards stop.")
            return np.arange(start, stop, step).tolist()
        raise InputError(f"`axes[{key!r}]` must be a list of values, {{linspace = [start, stop, num]}} or "
                         f"{{arange = [start, stop, step]}}, got {quote(dict(spec))}.")
    if isinstance(spec, (str, bytes)) or not isinstance(spec, Sequence | np.ndarray) or len(spec) == 0:
        raise InputError(f"`axes[{key!r}]` must be a non-empty list of values, got {quote(spec)}.")
    return [np.asarray(v).tolist() for v in spec]


def parse_axes(scene: Scene, axes: AxesSpec) -> list[Axis]:
    """Check a sweep's axes against the scene (every key and value) and return them in order."""
    if not isinstance(axes, Mapping) or not axes:
        raise InputTypeError(f"`axes` must be a non-empty mapping of scene keys to lists of values, got {quote(axes)}.")
    parsed = []
    for name, spec in axes.items():
        zipped = isinstance(spec, Mapping) and not ({"linspace"} == set(spec) or {"arange"} == set(spec))
        values = {k: _values(k, v) for k, v in spec.items()} if zipped else {name: _values(name, spec)}
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


def _canonical(scene: Scene, axes: list[Axis], options: Mapping[str, Any]) -> str:
    """The arguments that decide a store's contents, as JSON: a rerun must match them (numbers
    compared as floats, so that ``[30, 60]`` and ``[30.0, 60.0]`` are the same sweep), and so must
    the contents of the mesh files the scene reads (an edited mesh at the same path is another sweep)."""
    axes_json = [[a.name, {k: _floats(v) for k, v in a.values.items()}] for a in axes]
    return json.dumps({"scene": scene.to_toml(), "axes": axes_json, "mesh_files": _mesh_digests(scene), **options},
                      sort_keys=True)


def _mesh_digests(scene: Scene) -> dict[str, str]:
    """SHA-256 of each mesh file the scene reads (none for the built-in lander)."""
    paths = [p for p in (scene.target.mesh, *(part.file for part in scene.parts.values())) if p not in ("", "builtin")]
    return {p: hashlib.sha256(Path(p).read_bytes()).hexdigest() for p in dict.fromkeys(paths)}


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


def template(scene: Scene, axes: list[Axis], *, images: bool, derivatives: tuple[str, ...], attrs: Mapping[str, Any]) -> Any:
    """The store's empty Dataset (dask arrays, never computed): dimensions, coordinates, chunks of one point."""
    import dask.array as da  # here: dask and xarray take a second to import; only a sweep's store needs them
    import xarray as xr

    dims = tuple(a.name for a in axes)
    shape = tuple(a.size for a in axes)
    one = (1,) * len(dims)
    names = regions(scene)
    variables: dict[str, Any] = {}

    def add(name: str, extra: tuple[str, ...], size: tuple[int, ...], dtype: Any, fill: Any, unit: str, doc: str) -> None:
        data = da.full(shape + size, fill, dtype=dtype, chunks=one + size)
        variables[name] = (dims + extra, data, {"units": unit, "description": doc})

    add("mean_radiance", ("region",), (len(names),), np.float64, np.nan, "W m^-2 sr^-1",
        "mean over the pixels whose centre sees the region of the RGB mean radiance")
    add("pixels", ("region",), (len(names),), np.int32, -1, "1", "pixels whose centre sees the region")
    add("irradiance", ("region",), (len(names),), np.float64, np.nan, "W m^-2",
        "sum of radiance times pixel solid angle over the region's pixels (target: the whole image), at the pinhole")
    if images:
        w, h = scene.render.resolution
        add("radiance", ("y", "x", "channel"), (h, w, 3), np.float32, np.nan, "W m^-2 sr^-1", "the rendered image")
    if derivatives:
        for name, (dtype, fill, unit, doc) in SUMMARY_VARIABLES.items():
            add(name, ("parameter", "region"), (len(derivatives), len(names)), dtype, fill, unit, doc)
    variables["done"] = (dims, da.zeros(shape, dtype=bool, chunks=one), {"description": "the point is written"})
    coords = {**_coords(axes), "region": np.array(names, dtype=object)}
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
    stage = Path(tempfile.mkdtemp(prefix=f"{STAGE_PREFIX}{os.getpid()}-", dir=target.parent))
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


def write_point(group: Any, index: tuple[int, ...], result: Mapping[str, np.ndarray]) -> None:
    """Write one point's variables, then its ``done`` flag (each a chunk of its own, written atomically)."""
    for name, value in result.items():
        group[name][index] = value
    group["done"][index] = True


def sweep(
    scene: Scene,
    axes: AxesSpec,
    *,
    store: str | Path | None = None,
    images: bool = False,
    derivatives: Sequence[str] = (),
    derivative_seeds: int = 4,
    overwrite: bool = False,
    workers: int | None = None,
    scheduler: str | None = None,
    max_renders_per_worker: int = 500,
    quiet: bool = False,
) -> Any:
    """Render ``scene`` at every point of ``axes`` and return the results as a labelled xarray Dataset.

    Args:
        scene: the scene every point starts from.
        axes: the swept values (module docstring): key -> list, or axis name -> {key: list} (zipped).
        store: a Zarr folder written point by point (None: in memory). An existing store of the
            same sweep is completed, not recomputed.
        images: store each point's radiance image (W m^-2 sr^-1) too.
        derivatives: registered parameters whose derivatives of each region's mean radiance to
            store at every point, with their Monte Carlo standard errors (:func:`sf.sensitivity`).
        derivative_seeds: independent seeds of each derivative (>= 2).
        overwrite: replace a store that holds another sweep.
        workers: run on a local dask.distributed cluster of this many worker processes.
        scheduler: run on the dask.distributed scheduler at this address (``tcp://host:8786``).
        max_renders_per_worker: restart a dask worker after this many renders (Mitsuba leaks).
        quiet: no progress bar.

    Returns:
        The Dataset, read back from the store (lazily: arrays load when used).

    Ctrl-C (or SIGTERM) stops after the point being rendered; every finished point stays in the
    store and KeyboardInterrupt is raised.
    """
    import xarray as xr  # here: only a sweep's store needs xarray (slow to import)

    check_scene(scene)
    check_count("derivative_seeds", derivative_seeds, 2, optional=False)
    check_count("max_renders_per_worker", max_renders_per_worker, optional=False)
    check_count("workers", workers)
    if workers is not None and scheduler is not None:
        raise InputError("give `workers` (a local cluster) or `scheduler` (an address), not both.")
    derivatives = check_name_list("derivatives", derivatives)
    if derivatives:
        check_names(scene, derivatives, "derivatives")
    parsed = parse_axes(scene, axes)
    options = {"images": bool(images), "derivatives": list(derivatives), "derivative_seeds": derivative_seeds}
    spec = _canonical(scene, parsed, options)
    seeds = parsed_seeds(scene, parsed)
    attrs = {"spacefit_version": __version__, "scene_toml": scene.to_toml(), "seeds": seeds,
             "spacefit_sweep": spec, "description": "spacefit sweep: radiance of each region at each point"}
    group = open_store(store, spec, lambda: template(scene, parsed, images=images, derivatives=derivatives, attrs=attrs),
                       overwrite)
    task_of = tasks(scene, parsed, images=images, derivatives=derivatives, derivative_seeds=derivative_seeds)
    names = in_place_names(scene)
    # points that load another scene vary slowest, so that a scene is loaded once per value
    order = sorted(range(len(parsed)), key=lambda a: all(k in names or k in RENDER_ARGUMENTS for k in parsed[a].values))
    todo = pending(np.asarray(group["done"][...]), order)
    total = math.prod(a.size for a in parsed)
    run_points(todo, task_of, group, total=total, workers=workers, scheduler=scheduler,
               max_renders_per_worker=max_renders_per_worker, quiet=quiet)
    return xr.open_zarr(group.store if store is None else str(store), zarr_format=STORE_FORMAT)


SWEEP_FILE_OPTIONS = ("images", "derivatives", "derivative_seeds", "max_renders_per_worker")


def read_sweep_file(path: str | Path, overrides: Sequence[str] = ()) -> tuple[Scene, dict[str, Any], dict[str, Any]]:
    """Read a sweep TOML file: ``scene`` (a scene file, relative to the sweep file; default: the
    thesis's scene, with ``overrides`` as ``--set`` gives them), an ``[axes]`` table as :func:`sweep`
    takes it, and options (``images``, ``derivatives``, ``derivative_seeds``, ``max_renders_per_worker``).

    Returns ``(scene, axes, options)``: ``sf.sweep(scene, axes, store=..., **options)`` runs it.
    """
    data = read_scene_dict(path)  # the same checks and messages as a scene file's
    unknown = set(data) - {"scene", "axes", *SWEEP_FILE_OPTIONS}
    if unknown:
        raise InputError(f"sweep file {str(path)!r}: unknown keys {sorted(unknown)}; valid: scene, axes, "
                         f"{', '.join(SWEEP_FILE_OPTIONS)}.")
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
               workers: int | None, scheduler: str | None, max_renders_per_worker: int, quiet: bool) -> None:
    """Render the points ``todo`` in-process or on dask, writing each to ``group`` as it finishes."""
    bar = progress_bar(total, "sweep", initial=total - len(todo), quiet=quiet)
    try:
        with deferred_interrupts() as interrupts:
            results: Iterator[tuple[tuple[int, ...], dict[str, np.ndarray]]]
            if workers is None and scheduler is None:
                results = ((index, worker.run_task(task_of(index))) for index in todo)
            else:
                results = run_on_dask(todo, task_of, workers=workers, scheduler=scheduler,
                                      max_renders_per_worker=max_renders_per_worker)
            for index, result in results:
                write_point(group, index, result)
                bar.update()
                interrupts.check()
    finally:
        bar.close()
