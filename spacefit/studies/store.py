"""A sweep's resumable Zarr store: opened, written point by point, verified and repaired (what it holds,
its variables and coordinates: :mod:`spacefit.studies.store_layout`).

Each point's variables are one chunk each; a point is written data first, then the checksum of its
bytes as read back (BLAKE2b keyed with the point's index, so that two points' chunks swapped, their
checksums with them, fail), flushed to the disk, then its ``done`` flag. A reopened store's done
points are read back against their checksums: :func:`verify_store` reports, :func:`repair` clears
those that fail so that the sweep computes them again. The coordinates' digests are kept in the
store's attributes (:data:`COORDINATES`) and read back too: a damaged or deleted coordinate chunk is
reported by name. A metadata file (``.zgroup``, ``.zattrs``, ``.zarray``, ``.zmetadata``) that is not
JSON is a one-line :class:`~spacefit.errors.InputError` naming it, never a traceback. A new store is
made beside its place and moved there whole.
"""

from __future__ import annotations

import hashlib
import itertools
import json
import math
import os
import shutil
import tempfile
import warnings
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from spacefit.errors import InputError
from spacefit.output import STAGE_PREFIX, check_writable, clean_stale_stages
from spacefit.studies.store_layout import CHECKSUM, COORDINATES, coordinate_digest

METADATA_FILES = (".zgroup", ".zattrs", ".zarray", ".zmetadata", "zarr.json")
VERIFY_BATCH_BYTES = 64 << 20  # a store is verified in reads of about this many bytes
STORE_FORMAT = 2  # Zarr format 2: readable by every Zarr library (format 3 has no string type yet)


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
        if target.is_dir() and (target / ".zgroup").is_file():
            check_metadata(target)
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


def point_checksum(values: Sequence[np.ndarray], index: tuple[int, ...]) -> np.uint64:
    """The checksum of the point ``index``: BLAKE2b (8 bytes, keyed with the index) of its variables'
    bytes, in the order given."""
    digest = hashlib.blake2b(digest_size=8, key=",".join(map(str, index)).encode())
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
    group[CHECKSUM][index] = point_checksum([np.asarray(group[name][index]) for name in names], index)
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
    checksum (or whose flag is unreadable), the variables missing from the store and the coordinates
    whose values are not those recorded when it was made.

    Example:
        >>> import spacefit as sf
        >>> scene = sf.default_scene().with_values({"render.resolution": [48, 48], "camera.pixel_pitch_mm": 50, "render.spp": 4})
        >>> _ = sf.sweep(scene, {"sun.elevation_deg": [30, 60]}, store="sweep.zarr", quiet=True)
        >>> report = sf.verify_store("sweep.zarr")
        >>> report.points, report.verified, report.damaged
        (2, 2, False)
    """

    points: int
    done: int
    verified: int
    failed: tuple[tuple[int, ...], ...]
    missing_variables: tuple[str, ...]
    damaged_coordinates: tuple[str, ...] = ()

    @property
    def missing(self) -> int:
        """Points not done (never computed, or failed)."""
        return self.points - self.verified

    @property
    def damaged(self) -> bool:
        """Some done point failed its checksum, a variable is missing or a coordinate is damaged."""
        return bool(self.failed or self.missing_variables or self.damaged_coordinates)

    def __str__(self) -> str:
        lines = [f"{self.points:,} points: {self.done:,} done, {self.verified:,} verified, {len(self.failed):,} failed "
                 f"their checksum, {self.missing:,} to compute"]
        if self.missing_variables:
            lines.append(f"missing variables: {', '.join(self.missing_variables)}")
        if self.damaged_coordinates:
            lines.append(f"damaged coordinates (chunks changed or missing): {', '.join(self.damaged_coordinates)}")
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
            start = tuple(s.start for s in slab)
            for local in zip(*np.nonzero(done)):
                index = tuple(int(a + b) for a, b in zip(start, local))
                ok = not bad_sum[local] and not any(b[local] for _, b in data)
                bad[local] = not (ok and stored[local] != 0 and point_checksum([v[local] for v, _ in data], index) == stored[local])
        verified += int((done & ~bad).sum())
        start = tuple(s.start for s in slab)
        failed += [tuple(int(a + b) for a, b in zip(start, local)) for local in zip(*np.nonzero(bad))]
    return StoreReport(points, done_count, verified, tuple(failed), missing, _damaged_coordinates(group))


def _damaged_coordinates(group: Any) -> tuple[str, ...]:
    """The coordinates whose values (read back) are not those recorded in :data:`COORDINATES` when the
    store was made (an unreadable or deleted one included); none checked in a store that records none."""
    damaged = []
    for name, recorded in sorted(dict(group.attrs.get(COORDINATES, {})).items()):
        try:
            values = np.asarray(group[name][...])
        except Exception:  # noqa: BLE001  (a damaged chunk raises whatever its codec raises; a deleted array KeyError)
            damaged.append(name)
            continue
        if coordinate_digest(values) != recorded:
            damaged.append(name)
    return tuple(damaged)


def check_metadata(root: Path) -> None:
    """Raise a one-line InputError naming the first metadata file of the store in ``root`` that is not
    a JSON object (damaged, truncated, not UTF-8)."""
    for path in sorted(p for name in METADATA_FILES for p in [root / name, *root.glob(f"*/{name}")] if p.is_file()):
        try:
            data = json.loads(path.read_bytes().decode("utf-8"))
        except (OSError, UnicodeDecodeError, ValueError) as err:
            reason = type(err).__name__
        else:
            if isinstance(data, dict):
                continue
            reason = f"a JSON {type(data).__name__}, not an object"
        raise InputError(f"`store` {str(root)!r}: its metadata file {str(path.relative_to(root))!r} is damaged ({reason}); "
                         "restore it from a copy, or rerun the sweep with overwrite=True (--overwrite) to compute the store again.")


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
        InputError: ``store`` is not a spacefit sweep store, or one of its metadata files is damaged
            (named).

    Args:
        store: the sweep's Zarr folder.

    Example:
        >>> import spacefit as sf
        >>> scene = sf.default_scene().with_values({"render.resolution": [48, 48], "camera.pixel_pitch_mm": 50, "render.spp": 4})
        >>> _ = sf.sweep(scene, {"sun.elevation_deg": [30, 60]}, store="sweep.zarr", quiet=True)
        >>> print(sf.verify_store("sweep.zarr"))
        2 points: 2 done, 2 verified, 0 failed their checksum, 0 to compute
    """
    import zarr  # here: only a sweep's store needs Zarr (slow to import)

    path = Path(store)
    if path.is_dir() and (path / ".zgroup").is_file():
        check_metadata(path)
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
    if report.damaged_coordinates:
        _rewrite_coordinates(root, make(), report.damaged_coordinates)
    gone = ", ".join(report.missing_variables)
    if "done" in report.missing_variables:
        said = f"the variable(s) {gone} were missing and are recreated; every point is computed again"
    elif report.missing_variables:
        said = f"the variable(s) {gone} were missing and are recreated; the {report.done:,} done points are recomputed"
    else:
        said = (f"{len(report.failed):,} of {report.done:,} done points failed their checksum (data chunk missing or "
                "damaged) and are recomputed")
    if report.damaged_coordinates:
        said += f"; the damaged coordinate(s) {', '.join(report.damaged_coordinates)} are written again"
    if report.damaged:
        warnings.warn(f"store {str(root)!r}: {said}", stacklevel=3)
    return group


def _rewrite_coordinates(root: Path, made: Any, names: Sequence[str]) -> None:
    """Write the coordinates ``names`` of the store in ``root`` again from its template ``made`` (the
    same sweep's, so the same values); one deleted whole is a one-line InputError naming it."""
    import zarr  # here: only a sweep's store needs Zarr (slow to import)

    plain = zarr.open_group(str(root), mode="r+", zarr_format=STORE_FORMAT, use_consolidated=False)
    for name in names:
        try:
            plain[name][...] = made[name].values
        except KeyError:
            raise InputError(f"`store` {str(root)!r}: its coordinate {name!r} is gone; rerun the sweep with overwrite=True "
                             "(--overwrite) to compute the store again.") from None
