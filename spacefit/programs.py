"""JAX programs that take the arrays their functions close over as operands, not as constants.

JAX embeds an array that a traced function closes over (a reference image, a mask, a sensor's per-pixel factors, a
mesh's vertices, a NumPy grid of frequencies) as a constant in the lowered module of every program that traces it:
lowering, the persistent cache's hashing of the module and its reads grow with it, and each compiled program holds a
copy of its own (issue 33's 8-parameter observation fit: modules of 14.7, 11.9, 5.6 and 3 x 4.1 MB, 45 MB in all;
1.3 MB once its arrays were operands). Here a function is traced once (:func:`jax.make_jaxpr`) and its arrays are
handed to its program as operands (:func:`operand_program`): :func:`operand_jit` for one function called on concrete
values, :class:`AlikePrograms` for callers whose functions trace alike but for their arrays (a pass's frames), which
then share one program. A function traced inside another program has its arrays handed to that program as operands
by its caller (the fit's image models: :meth:`spacefit.fitting.frame_models.FrameModels.operands`). The rule and its
test: docs/reference/development.md.
"""

from __future__ import annotations

import hashlib
import threading
from collections.abc import Callable
from typing import Any

import jax
import numpy as np
from jax.extend.core import ClosedJaxpr, jaxpr_as_fun

from spacefit.precision import on_device


def operand_program(traced: ClosedJaxpr, name: str = "program") -> Callable[..., list[jax.Array]]:
    """``traced``'s function with its arrays as its first operand, ``(arrays, *args) -> outputs`` (both flat), for the
    programs that evaluate it to take them as theirs, not to embed them as constants; ``name``: its name (a program's:
    ``jit(name)``)."""
    jaxpr = traced.jaxpr  # not its arrays: the caller holds those, once

    def program(arrays: list[jax.Array], *args: Any) -> list[jax.Array]:
        return jaxpr_as_fun(ClosedJaxpr(jaxpr, arrays))(*jax.tree.leaves(args))

    program.__name__ = program.__qualname__ = name
    return program


def traced_alike(traced: ClosedJaxpr) -> tuple[str, tuple[tuple[tuple[int, ...], np.dtype], ...]]:
    """What makes two traced programs one program but for their arrays: their printed form (literals included) and
    the arrays' shapes and dtypes."""
    return str(traced.jaxpr), tuple((np.shape(c), np.asarray(c).dtype) for c in traced.consts)


class AlikePrograms:
    """Functions compiled once for every caller whose function traces alike (:func:`traced_alike`: a pass's frames'
    pixel grid, whose programs differ in their arrays alone, the reference, the mask, a sensor's factors), each
    traced once per key and its arrays handed to the shared program as operands, held for the callers' life: each
    array once, those equal between keys shared (a pass's frames' response matrices and frequency grids, 10 of a
    128 x 128 px frame's 11.4 MiB; their references and masks are their own). ``share`` False (one caller of a
    kind, an image fitted alone): each key's program its own, its traced form not printed; its arrays its operands
    still (:func:`operand_program`)."""

    def __init__(self, share: bool = True) -> None:
        self.share = share
        self._programs: dict[object, Callable[..., list[jax.Array]]] = {}  # per kind: jitted, or compiled ahead
        self._kinds: dict[object, object] = {}  # per key, its kind
        self._traced: dict[object, tuple[Callable[..., list[jax.Array]], list[jax.Array], Any]] = {}
        self._held: dict[tuple[tuple[int, ...], str, bytes], jax.Array] = {}
        self._holding = threading.Lock()  # keys traced first on concurrent threads: each array still held once

    def __call__(self, key: object, fn: Callable[..., Any], *args: Any) -> Any:
        """``fn(*args)``, by the program of its kind: traced for ``key`` (which names ``fn`` and its arguments' shapes
        and dtypes: they must not change between calls with one key) on its first call."""
        program, consts, outputs = self._trace(key, fn, args)
        return jax.tree.unflatten(outputs, program(consts, *args))

    def compile_ahead(self, key: object, fn: Callable[..., Any], *args: Any) -> None:
        """Trace ``fn`` for ``key`` and compile its kind's program for arguments shaped as ``args`` (their values
        unused), without running it: a thread may make a program while others run (the pixel grid's last one beside its
        fixed point's iterations, :func:`~spacefit.fitting.pixel_grid.grid_step`), and the call with ``key`` then runs
        the compiled program with no tracing, lowering or cache read. The same program: the same outputs bit for bit."""
        program, consts, _ = self._trace(key, fn, args)
        if not isinstance(program, jax.stages.Compiled):
            kind = self._kinds[key]
            self._programs[kind] = program.lower(consts, *args).compile()
            self._traced[key] = (self._programs[kind], *self._traced[key][1:])

    def _trace(self, key: object, fn: Callable[..., Any], args: tuple[Any, ...]) -> tuple[Callable[..., list[jax.Array]], list[jax.Array], Any]:
        """``key``'s program, its arrays and its outputs' structure, ``fn`` traced on ``args`` for it first."""
        if key not in self._traced:
            traced, shapes = jax.make_jaxpr(fn, return_shape=True)(*args)
            kind = self._kinds[key] = traced_alike(traced) if self.share else key
            if kind not in self._programs:
                self._programs[kind] = jax.jit(operand_program(traced, getattr(fn, "__name__", "program")))
            self._traced[key] = (self._programs[kind], [self._once(c) for c in traced.consts], jax.tree.structure(shapes))
        return self._traced[key]

    def _once(self, array: object) -> jax.Array:
        """``array`` on the device, the one held already where an equal one is (same shape, dtype and bytes)."""
        host = np.asarray(array)
        key = (host.shape, host.dtype.str, hashlib.blake2b(host.tobytes(), digest_size=16).digest())
        with self._holding:
            held = self._held.get(key)
            if held is None or not np.array_equal(np.asarray(held), host):
                held = self._held[key] = on_device(host, host.dtype)
        return held


def operand_jit(fn: Callable[..., Any]) -> Callable[..., Any]:
    """``jax.jit(fn)`` with the arrays ``fn`` closes over its program's operands (held on the device), traced once per
    structure, shapes and dtypes of its arguments. For calls on concrete values: called inside another program, its
    arrays would be that program's constants."""
    programs = AlikePrograms(share=False)

    def call(*args: Any) -> Any:
        leaves, structure = jax.tree.flatten(args)
        return programs((structure, *(jax.typeof(a) for a in leaves)), fn, *args)

    return call
