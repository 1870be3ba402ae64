"""A disk cache of Dr.Jit's ``@dr.syntax`` rewrites of Mitsuba's own functions.

Setting a Mitsuba variant (re)imports its Python AD integrators (``mitsuba.python.ad.integrators``:
PRB, its volumetric and projective forms), and each ``@dr.syntax`` there reads its function's source
again, parses it, rewrites its loops and branches and compiles the result: 0.07 s of every process's
first variant and of each switch, more than Embree takes to build the default scene's BVH. The
rewrite is a function of the source file and of Dr.Jit alone, so :func:`cached_syntax` keeps the
compiled code object (``marshal``) in the mesh cache's folder
(:func:`spacefit.geometry.cache.cache_dir`, ``syntax/``), named by the SHA-256 of the Python
bytecode's magic number, Dr.Jit's version and the bytes of its rewriter (``drjit/ast.py``), the
source file's bytes, the function's qualified name and first line, and the decorator's
``recursive``: a changed file, Dr.Jit or Python never reads an old entry. A missing, damaged or unreadable entry is rewritten by Dr.Jit (and stored when it can be), so
the cache costs time at worst, never a wrong function.

Only functions of Mitsuba's modules are cached; any other function (a user's own ``@dr.syntax``),
and ``print_ast`` / ``print_code``, go to Dr.Jit's decorator unchanged. :func:`install` must run
before a variant is first set: :mod:`spacefit.rendering.backend` runs it between importing Dr.Jit
and Mitsuba.
"""

from __future__ import annotations

import functools
import hashlib
import importlib.util
import marshal
import types
from collections.abc import Callable
from pathlib import Path
from typing import Any

import drjit as dr
import drjit.ast

from spacefit.geometry.cache import cache_dir, write_atomically

FOLDER = "syntax"
# Modules whose rewritten functions are cached: Mitsuba's, which change only with its version.
CACHED_MODULES = "mitsuba."

_dr_syntax = drjit.ast.syntax


@functools.cache
def _source_digest(filename: str) -> str:
    """SHA-256 (hex) of a source file's bytes, read once per process."""
    return hashlib.sha256(Path(filename).read_bytes()).hexdigest()


def entry_path(f: types.FunctionType, recursive: bool) -> Path | None:
    """Where the rewrite of ``f`` is kept, or None when the cache is off or the source cannot be read."""
    folder = cache_dir()
    if folder is None:
        return None
    code = f.__code__
    try:
        source = _source_digest(code.co_filename)
    except OSError:
        return None
    key = hashlib.sha256("|".join((importlib.util.MAGIC_NUMBER.hex(), dr.__version__, _source_digest(drjit.ast.__file__),
                                   source, f.__qualname__, str(code.co_firstlineno), str(recursive))).encode()).hexdigest()
    return folder / FOLDER / f"{key[:40]}.code"


def _read(path: Path, name: str) -> types.CodeType | None:
    """The code object stored at ``path`` when it is intact and named ``name``, else None."""
    try:
        code = marshal.loads(path.read_bytes())
    except (OSError, EOFError, ValueError, TypeError):
        return None
    return code if isinstance(code, types.CodeType) and code.co_name == name else None


def cached_syntax(f: Callable | None = None, *, recursive: bool = False, print_ast: bool = False,
                  print_code: bool = False) -> Any:
    """``drjit.syntax`` (same arguments, same function returned), the rewrite of a Mitsuba function read
    from the disk cache when an intact entry exists."""
    if f is None:
        return functools.partial(cached_syntax, recursive=recursive, print_ast=print_ast, print_code=print_code)
    eligible = (isinstance(f, types.FunctionType) and not (print_ast or print_code)
                and (f.__module__ or "").startswith(CACHED_MODULES))
    path = entry_path(f, recursive) if eligible else None
    if path is None:
        return _dr_syntax(f, recursive=recursive, print_ast=print_ast, print_code=print_code)
    code = _read(path, f.__name__)
    if code is None:
        rewritten = _dr_syntax(f, recursive=recursive)
        write_atomically(path, lambda f: f.write(marshal.dumps(rewritten.__code__)))
        return rewritten
    rewritten = types.FunctionType(code, f.__globals__)  # as Dr.Jit builds it from its compiled code
    rewritten.__defaults__ = f.__defaults__
    return rewritten


def install() -> None:
    """Make ``dr.syntax`` :func:`cached_syntax` (Mitsuba's modules look it up as they are imported)."""
    dr.syntax = cached_syntax
