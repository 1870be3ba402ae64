"""On-disk cache of meshes that every run would otherwise rebuild identically.

Refining the default wrinkled body and displacing it by eq. 2-1 takes about 2 s and gives the same
arrays on every run, so :func:`cached` keeps them in ``$SPACEFIT_CACHE_DIR`` (default
``$XDG_CACHE_HOME/spacefit``, else ``~/.cache/spacefit``; ``SPACEFIT_CACHE_DIR=off`` disables it).

An entry is one ``.npz`` file named by the SHA-256 of everything that decides its arrays: the
caller's inputs, the spacefit version, :data:`FORMAT`, the versions of :data:`PACKAGES` and the
source of :data:`SOURCES` (so a changed algorithm never reads an old entry). It holds
that key and a SHA-256 of its arrays; a file that fails to load or whose key or checksum differs is
rebuilt, never trusted. Writers write a temporary file in the folder and ``os.replace`` it into
place, so concurrent processes see a whole entry or none. A cache that cannot be read or written
costs time, never a render: the arrays are built as if it were off.
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import os
import tempfile
import zipfile
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path
from typing import IO, Any

import numpy as np

from spacefit import __version__
from spacefit.versions import package_version

ENV = "SPACEFIT_CACHE_DIR"
DISABLED = "off"
# Layout version of an entry; raise it when what an entry holds changes.
FORMAT = 1
# Above this total size the least recently used entries are removed (an entry of the default body
# is about 10 MB).
MAX_BYTES = 1 << 30
# Packages and geometry modules whose code decides cached vertices (Delaunay, the W-M sum, the
# lander's primitives): part of every key.
PACKAGES = ("numpy", "scipy", "jax", "jaxlib", "trimesh")
SOURCES = ("cache.py", "lander.py", "mesh.py", "wm.py", "wrinkle.py")


def cache_dir() -> Path | None:
    """The cache folder, or None when ``SPACEFIT_CACHE_DIR=off``."""
    configured = os.environ.get(ENV, "").strip()
    if configured.lower() == DISABLED:
        return None
    if configured:
        return Path(configured).expanduser()
    base = os.environ.get("XDG_CACHE_HOME", "").strip()
    return (Path(base) if base else Path.home() / ".cache") / "spacefit"


@functools.cache
def _code_identity() -> str:
    """The spacefit version, :data:`FORMAT`, the versions of :data:`PACKAGES` and the SHA-256 of :data:`SOURCES`."""
    h = hashlib.sha256(f"{__version__}|{FORMAT}".encode())
    for name in PACKAGES:
        h.update(f"|{name} {package_version(name) or 'none'}".encode())
    here = Path(__file__).parent
    for name in SOURCES:
        h.update((here / name).read_bytes())
    return h.hexdigest()


def _digest(h: Any, parts: Iterable[object]) -> str:
    """Feed ``parts`` to the hashlib hash ``h`` (arrays by dtype, shape and bytes, anything else by
    ``repr``: floats as their exact ``repr``) and return its hex digest."""
    for part in parts:
        if isinstance(part, np.ndarray):
            array = np.ascontiguousarray(part)
            h.update(f"|array {array.dtype.str} {array.shape}|".encode())
            h.update(array.reshape(-1).view(np.uint8))  # its bytes, as tobytes() gives them, without the copy
        else:
            h.update(f"|{type(part).__name__} {part!r}".encode())
    return h.hexdigest()


def cache_key(kind: str, parts: Iterable[object]) -> str:
    """SHA-256 (hex) of ``kind``, the code's identity (:func:`_code_identity`) and ``parts``."""
    return _digest(hashlib.sha256(f"{kind}|{_code_identity()}".encode()), parts)


def _checksum(arrays: Mapping[str, np.ndarray]) -> str:
    """SHA-256 (hex) of an entry's arrays and their names."""
    return _digest(hashlib.sha256(), [x for name in sorted(arrays) for x in (name, np.asarray(arrays[name]))])


def _read(path: Path, key: str) -> dict[str, np.ndarray] | None:
    """The arrays of the entry at ``path``, or None when it is missing, unreadable or not intact."""
    try:
        with np.load(path, allow_pickle=False) as data:
            arrays = {name: data[name] for name in data.files}
    except (OSError, ValueError, EOFError, KeyError, zipfile.BadZipFile):
        return None
    stored_key, checksum = arrays.pop("__key__", None), arrays.pop("__checksum__", None)
    if stored_key is None or checksum is None or str(stored_key) != key or str(checksum) != _checksum(arrays):
        return None
    return arrays


def write_atomically(path: Path, write: Callable[[IO[bytes]], object]) -> bool:
    """Write the file ``path`` through ``write(file)`` atomically: a temporary file in its folder (made if
    missing), then ``os.replace``, so that other processes see the whole file or none. False, with
    nothing written and nothing left, on OSError (a cache that cannot be written costs time only)."""
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=".tmp-", suffix=path.suffix, dir=path.parent)
        try:
            with os.fdopen(fd, "wb") as f:
                write(f)
            os.replace(tmp, path)
        except BaseException:
            Path(tmp).unlink(missing_ok=True)
            raise
    except OSError:
        return False
    return True


def _write(folder: Path, path: Path, key: str, arrays: Mapping[str, np.ndarray]) -> None:
    """Write an entry (:func:`write_atomically`), then prune the folder; give up silently on OSError."""
    if write_atomically(path, lambda f: np.savez(f, __key__=np.array(key), __checksum__=np.array(_checksum(arrays)), **arrays)):
        with contextlib.suppress(OSError):
            _prune(folder)


def _prune(folder: Path) -> None:
    """Remove the least recently used entries while the folder holds more than :data:`MAX_BYTES`."""
    entries = []
    for p in folder.glob("*.npz"):
        try:
            st = p.stat()
        except OSError:  # removed by another process meanwhile
            continue
        entries.append((st.st_atime, st.st_size, p))
    total = sum(size for _, size, _ in entries)
    for _, size, p in sorted(entries, key=lambda e: e[0]):
        if total <= MAX_BYTES:
            break
        p.unlink(missing_ok=True)
        total -= size


def cached(
    kind: str, key_parts: Iterable[object], build: Callable[[], Mapping[str, np.ndarray]]
) -> tuple[dict[str, np.ndarray], str]:
    """The arrays ``build()`` returns, from the disk cache when an intact entry exists.

    Args:
        kind: what the entry holds (part of the key and of the file name), e.g. ``"refinement"``.
        key_parts: everything that decides the arrays (see :func:`cache_key`).
        build: computes the arrays on a miss.

    Returns:
        The arrays and how they were obtained: ``"hit"``, ``"miss"`` (built and stored; also when a
        damaged entry was replaced) or ``"off"`` (cache disabled).
    """
    folder = cache_dir()
    if folder is None:
        return dict(build()), "off"
    key = cache_key(kind, key_parts)
    path = folder / f"{kind}-{key[:32]}.npz"
    arrays = _read(path, key)
    if arrays is not None:
        return arrays, "hit"
    arrays = {name: np.asarray(value) for name, value in build().items()}
    _write(folder, path, key, arrays)
    return arrays, "miss"
