"""Inputs recorded by content: SHA-256 of the files a sweep or a fit reads, checked again before
their results are trusted (at each sweep point, at the end of a sweep, and on a fit's --resume)."""

from __future__ import annotations

import hashlib
import os
from collections.abc import Iterable, Mapping
from pathlib import Path


CHUNK_BYTES = 1 << 20


def file_digest(path: str | Path) -> str:
    """SHA-256 (hex) of a file's bytes, read in 1 MiB chunks; "missing" for a file that is gone."""
    digest = hashlib.sha256()
    try:
        with open(path, "rb") as f:
            while block := f.read(CHUNK_BYTES):
                digest.update(block)
    except FileNotFoundError:
        return "missing"
    return digest.hexdigest()


def digests(paths: Iterable[str | Path]) -> dict[str, str]:
    """SHA-256 of each file, by its path as given (each path once)."""
    return {str(p): file_digest(p) for p in dict.fromkeys(map(str, paths))}


def changed(recorded: Mapping[str, str]) -> list[str]:
    """The paths of ``recorded`` whose contents are not the recorded ones now (edited, replaced or deleted)."""
    return [path for path, digest in recorded.items() if file_digest(path) != digest]


def status(paths: Iterable[str]) -> tuple[tuple[str, tuple[int, int, int] | None], ...]:
    """(path, (inode, size, modification time in ns)) of each file, None for a missing one: cheap
    to take, and it changes when a file is edited or replaced."""
    return tuple((path, _stat(path)) for path in paths)


class Watch:
    """Files whose contents a long job depends on: :meth:`check` between steps compares their
    status (inode, size, modification time; SHA-256 when one moved), :meth:`final` their SHA-256."""

    def __init__(self, paths: Iterable[str | Path]) -> None:
        self.recorded = digests(paths)
        self.stats = {path: _stat(path) for path in self.recorded}

    def check(self) -> list[str]:
        """The files changed since the start (cheap while nothing was touched)."""
        moved = {path: digest for path, digest in self.recorded.items() if _stat(path) != self.stats[path]}
        edited = changed(moved)
        for path in set(moved) - set(edited):  # touched or rewritten with the same bytes
            self.stats[path] = _stat(path)
        return edited

    def final(self) -> list[str]:
        """The files whose SHA-256 is not the start's (an edit that kept the status included)."""
        return changed(self.recorded)


def _stat(path: str) -> tuple[int, int, int] | None:
    try:
        st = os.stat(path)
    except FileNotFoundError:
        return None
    return st.st_ino, st.st_size, st.st_mtime_ns
