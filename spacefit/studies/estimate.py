"""A sweep's size before anything is allocated: its points, its store on disk, its index in memory.

:func:`check_estimate` refuses a sweep that would not fit in memory, and unless asked, one of more
than :data:`MAX_POINTS` points or whose new store may not fit on its disk.
"""

from __future__ import annotations

import math
import shutil
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from spacefit.errors import InputError
from spacefit.rendering import memory as render_memory
from spacefit.scene.schema import Scene
from spacefit.studies.axes import AxesSpec, axis_lengths
from spacefit.studies.store_layout import CHECKSUM, point_variables

# A sweep of more points is refused unless allow_large: a store holds a file per point and variable.
MAX_POINTS = 1_000_000
FILE_BLOCK_BYTES = 4096  # a chunk file takes at least a file-system block
# The index of points to compute, per point: the done flag, np.nonzero's int64 per axis, and a
# tuple in a list (sorted copy included): 72 bytes, plus 36 per axis (an int and its pointer).
INDEX_BYTES_PER_POINT, INDEX_BYTES_PER_POINT_AXIS = 73, 44


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
    if found.points > MAX_POINTS and not allow_large:
        raise InputError(f"a sweep of {found.points:,} points is more than {MAX_POINTS:,} (a file per point and "
                         f"variable; {found.sizes}); split it, or pass allow_large=True (--large) to run it.")
    memory = render_memory.available_memory_bytes()
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
