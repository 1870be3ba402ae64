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

The axes are read and checked in :mod:`spacefit.studies.axes`, the store is written, verified and
repaired in :mod:`spacefit.studies.store`, and a sweep's size is checked first in
:mod:`spacefit.studies.estimate`; this module runs the points.
"""

from __future__ import annotations

import contextlib
import json
import math
import sys
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from spacefit import __version__
from spacefit.digests import Watch
from spacefit.errors import InputError, InputTypeError, check_choice, check_count, check_flag, check_name_list, check_range, quote
from spacefit.interrupts import deferred_interrupts
from spacefit.locks import hold_lock
from spacefit.progress import progress_bar
from spacefit.scene.schema import Scene
from spacefit.scene.sections import check_scene
from spacefit.scene.toml import load_scene, read_scene_dict
from spacefit.scene.parameters import GEOMETRY, MOVES_VERTICES, check_names, scene_with_values
from spacefit.executors import Cluster, cluster_of
from spacefit.studies.axes import Axis, AxesSpec, in_place_names, parse_axes, parsed_seeds
from spacefit.studies.cluster import STALL_S, run_on_dask
from spacefit.studies.estimate import check_estimate, estimate
from spacefit.studies.store import STORE_FORMAT, open_store, pending, repair, write_point
from spacefit.studies.store_layout import template
from spacefit.studies import worker
from spacefit.studies.worker import Task

RENDER_ARGUMENTS = ("render.seed", "render.spp")


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


def tasks(scene: Scene, axes: list[Axis], *, images: bool, derivatives: tuple[str, ...], derivative_seeds: int
          ) -> Callable[[tuple[int, ...]], Task]:
    """The task of each point (its index along every axis)."""
    names = in_place_names(scene)
    in_place = [k for a in axes for k in a.values if k in names]
    crop = not any(k in MOVES_VERTICES for k in in_place)
    base = Task(scene.to_toml(), tuple(worker.regions(scene)), crop=crop, images=images, derivatives=derivatives, derivative_seeds=derivative_seeds)
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
        axes: the swept values (the Studies guide): key -> list, or axis name -> {key: list} (zipped).
        store: a Zarr folder written point by point (None: in memory). An existing store of the
            same sweep is completed, not recomputed. It is locked while the sweep runs: a store another process writes is refused, naming it.
        images: store each point's radiance image (W m^-2 sr^-1) too.
        derivatives: registered parameters whose derivatives of each region's mean radiance to
            store at every point, with their Monte Carlo standard errors (:func:`sf.sensitivity`).
        derivative_seeds: independent seeds of each derivative (>= 2).
        overwrite: replace a store that holds another sweep.
        cluster: where the points render: None, this process; an int N, a new
            local dask.distributed cluster of N worker processes; a scheduler address (``tcp://host:8786``);
            a ``distributed.Client`` (left open).
        max_renders_per_worker: restart a dask worker after this many renders (Mitsuba leaks).
        allow_large: run a sweep of more than :data:`MAX_POINTS` points, or whose store may not fit
            on its disk (:func:`check_estimate`; the size is printed first unless ``quiet``).
        stall_s: on dask, stop with :class:`ClusterError` when no point
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

    Raises:
        InputError: an unknown key or a value the scene refuses (before any render), a store that
            holds another sweep (without ``overwrite``) or that another process writes, a sweep too
            large without ``allow_large``.
        ClusterError: on dask, a point whose worker died three times, or no point finished in ``stall_s``.

    Example:
        >>> import spacefit as sf
        >>> scene = sf.default_scene().with_values({"render.resolution": [48, 48], "camera.pixel_pitch_mm": 50, "render.spp": 4})
        >>> ds = sf.sweep(scene, {"sun.elevation_deg": [30, 60]}, store="sweep.zarr", quiet=True)
        >>> ds["mean_radiance"].sel(region="target").shape  # one value per point
        (2,)
    """
    import xarray as xr  # here: only a sweep's store needs xarray (slow to import)

    check_scene(scene)
    check_count("derivative_seeds", derivative_seeds, 2, optional=False)
    check_count("max_renders_per_worker", max_renders_per_worker, optional=False)
    stall_s = check_range("stall_s", stall_s, 0.0, lo_open=True, unit="s")
    cluster = cluster_of(cluster, workers, scheduler)
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

    Args:
        path: the sweep TOML file.
        overrides: ``"key=value"`` scene overrides (TOML values), as ``--set`` gives them.

    Returns:
        ``(scene, axes, options)``: ``sf.sweep(scene, axes, store=..., **options)`` runs it.

    Raises:
        InputError: a missing or malformed file, an unknown option, a scene the overrides break.

    Example:
        >>> import spacefit as sf
        >>> with open("sweep.toml", "w") as f:
        ...     print('[axes]', file=f)
        ...     print('"sun.elevation_deg" = [30, 60]', file=f)
        >>> scene, axes, options = sf.read_sweep_file("sweep.toml", ["render.spp=4"])
        >>> axes, scene.render.spp
        ({'sun.elevation_deg': [30, 60]}, 4)
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
