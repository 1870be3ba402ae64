"""A disk cache of Dr.Jit's ``@dr.syntax`` rewrites of Mitsuba's own functions.

Setting a Mitsuba variant (re)imports its Python AD integrators (``mitsuba.python.ad.integrators``:
PRB, its volumetric and projective forms), and each ``@dr.syntax`` there reads its function's source
again, parses it, rewrites its loops and branches and compiles the result: 0.07 s of every process's
first variant and of each switch, more than Embree takes to build the default scene's BVH. The
rewrite is a function of the source file and of Dr.Jit alone, so :func:`cached_syntax` keeps the
compiled code object (``marshal``) in the mesh cache's folder
(:func:`spacefit.geometry.cache.cache_dir`, ``syntax/``), named by the SHA-256 of its producer's
identity (:func:`identity`): the Python bytecode's magic number, the versions of Dr.Jit and Mitsuba, the
bytes of Dr.Jit's rewriter (``drjit/ast.py``), the source file's bytes, the function's qualified name
and first line, and the decorator's ``recursive``, so a changed file, Dr.Jit or Python never reads an
old entry.

An entry is checked before it is used, never executed on trust: it holds that identity (one JSON
line), the SHA-256 of the marshalled code and the code; an entry whose identity is not the one asked
for, whose checksum fails, or whose code object is not the function's (name, file, first line, and
the qualified name Dr.Jit compiles it under) is discarded and Dr.Jit rewrites the function again (a bit flipped in marshalled code can
crash the interpreter, and another function's valid code would run silently as this one). Writers
write a temporary file and ``os.replace`` it (:func:`~spacefit.geometry.cache.write_atomically`), so
concurrent processes see a whole entry or none. A missing, damaged or unreadable entry costs time at
worst, never a wrong function.

Only functions of Mitsuba's modules are cached; any other function (a user's own ``@dr.syntax``),
and ``print_ast`` / ``print_code``, go to Dr.Jit's decorator unchanged. :func:`install` must run
before a variant is first set: :mod:`spacefit.rendering.backend` runs it between importing Dr.Jit
and Mitsuba.
"""

from __future__ import annotations

import functools
import hashlib
import importlib.util
import json
import marshal
import types
from collections.abc import Callable
from pathlib import Path
from typing import Any

import drjit as dr
import drjit.ast

from spacefit.geometry.cache import cache_dir, write_atomically
from spacefit.versions import package_version

FOLDER = "syntax"
# Layout version of an entry; raise it when what an entry holds changes.
FORMAT = 2
# Modules whose rewritten functions are cached: Mitsuba's, which change only with its version.
CACHED_MODULES = "mitsuba."

_dr_syntax = drjit.ast.syntax


@functools.cache
def _source_digest(filename: str) -> str:
    """SHA-256 (hex) of a source file's bytes, read once per process."""
    return hashlib.sha256(Path(filename).read_bytes()).hexdigest()


def identity(f: types.FunctionType, recursive: bool) -> dict[str, object] | None:
    """What decides the rewrite of ``f`` (see the module's docstring), or None when its source cannot be read."""
    code = f.__code__
    try:
        source = _source_digest(code.co_filename)
    except OSError:
        return None
    return {"format": FORMAT, "python": importlib.util.MAGIC_NUMBER.hex(), "drjit": dr.__version__,
            "mitsuba": package_version("mitsuba"), "rewriter": _source_digest(drjit.ast.__file__),
            "source": source, "qualname": f.__qualname__, "firstlineno": code.co_firstlineno,
            "recursive": recursive}


def entry_path(f: types.FunctionType, recursive: bool) -> tuple[Path, bytes] | None:
    """Where the rewrite of ``f`` is kept and the identity line its entry starts with, or None when the
    cache is off or the source cannot be read."""
    folder = cache_dir()
    made_by = identity(f, recursive)
    if folder is None or made_by is None:
        return None
    line = json.dumps(made_by, sort_keys=True).encode()
    return folder / FOLDER / f"{hashlib.sha256(line).hexdigest()[:40]}.code", line


def _entry(line: bytes, code: types.CodeType) -> bytes:
    """The bytes of an entry: the identity line, the SHA-256 (hex) of the marshalled code, the code."""
    payload = marshal.dumps(code)
    return b"\n".join((line, hashlib.sha256(payload).hexdigest().encode(), payload))


def _is_rewrite_of(code: object, f: types.FunctionType) -> bool:
    """Whether ``code`` is Dr.Jit's rewrite of ``f`` itself: its name, file and first line, and the qualified name Dr.Jit
    compiles it under, its bare name (it compiles the function's source alone: a method ``PRBIntegrator.sample`` is
    ``sample``; compared with ``f``'s own, every method's entry was discarded and rewritten in every process)."""
    own = f.__code__
    return (isinstance(code, types.CodeType) and code.co_name == own.co_name and code.co_qualname == own.co_name
            and code.co_filename == own.co_filename and code.co_firstlineno == own.co_firstlineno)


def _read(path: Path, line: bytes, f: types.FunctionType) -> types.CodeType | None:
    """The code object stored at ``path`` when its identity is ``line``, its checksum holds and it is a
    rewrite of ``f``; else None (the entry is then rewritten)."""
    try:
        stored_line, checksum, payload = path.read_bytes().split(b"\n", 2)
    except (OSError, ValueError):
        return None
    if stored_line != line or checksum != hashlib.sha256(payload).hexdigest().encode():
        return None
    try:
        code = marshal.loads(payload)
    except (EOFError, ValueError, TypeError):
        return None
    return code if _is_rewrite_of(code, f) else None


def cached_syntax(f: Callable | None = None, *, recursive: bool = False, print_ast: bool = False,
                  print_code: bool = False) -> Any:
    """``drjit.syntax`` (same arguments, same function returned), the rewrite of a Mitsuba function read
    from the disk cache when an intact entry exists."""
    if f is None:
        return functools.partial(cached_syntax, recursive=recursive, print_ast=print_ast, print_code=print_code)
    eligible = (isinstance(f, types.FunctionType) and not (print_ast or print_code)
                and (f.__module__ or "").startswith(CACHED_MODULES))
    entry = entry_path(f, recursive) if eligible else None
    if entry is None:
        return _dr_syntax(f, recursive=recursive, print_ast=print_ast, print_code=print_code)
    path, line = entry
    code = _read(path, line, f)
    if code is None:
        rewritten = _dr_syntax(f, recursive=recursive)
        write_atomically(path, lambda file: file.write(_entry(line, rewritten.__code__)))
        return rewritten
    rewritten = types.FunctionType(code, f.__globals__)  # as Dr.Jit builds it from its compiled code
    rewritten.__defaults__ = f.__defaults__
    return rewritten


def install() -> None:
    """Make ``dr.syntax`` :func:`cached_syntax` (Mitsuba's modules look it up as they are imported)."""
    dr.syntax = cached_syntax
