"""Installed versions of packages, read from the header of their metadata.

``importlib.metadata.version`` parses the whole metadata file, long description included (7 ms for
SciPy's, 4 ms for colour-science's), and a render asks for 13 versions: its sidecar's and its mesh
cache's keys. The header's ``Version`` field is the same string, read in 0.1 ms.
"""

from __future__ import annotations

import functools
from importlib import metadata


@functools.cache
def package_version(name: str) -> str | None:
    """The installed version of distribution ``name`` (what ``importlib.metadata.version`` gives), or None
    when it is not installed."""
    try:
        dist = metadata.distribution(name)
    except metadata.PackageNotFoundError:
        return None
    for line in (dist.read_text("METADATA") or dist.read_text("PKG-INFO") or "").splitlines():
        if not line.strip():  # the header ends at the first blank line
            break
        if line[0] in " \t":  # a folded line of the field before
            continue
        key, sep, value = line.partition(":")
        if sep and key.strip().lower() == "version":
            return value.strip()
    return dist.version
