"""Least squares by the normal equations, formed a few Jacobian columns at a time.

A joint fit's Jacobian has a row per pixel of every frame and a column per free value, frames'
own values included, so held whole it grows as frames^2: the 12-frame, 64-parameter pass held
0.3 GB per copy at 128 x 128 px, and a dense QR keeps several. :class:`NormalEquations` is a lineax
solver for the solvers' linearised (damped) Jacobian operator that never holds it: it applies the
operator and its transpose to a few directions at a time and keeps only J^T J (columns^2), then
solves J^T J dx = J^T b by a symmetric eigendecomposition, the pseudo-inverse where J^T J is
singular (the minimum-norm step of an undetermined direction, as the SVD gives). Forming J^T J
squares the condition number, harmless in float64 for the fits' conditioning (measured against QR
in tests/test_normal_equations.py). Where no column is an observation's own (an image fitted alone),
J's columns are held instead (columns x rows, one image's) and J^T J and J^T b are their products:
forward products only, half the image model's FFTs of products with J and J^T, no transpose of J
traced, and every sum over the rows in float64, where J^T of a render's float32 Jacobian sums in float32.

A frame's own values (its attitude, its shift) move its own pixels only, so the own columns of
different frames are structurally orthogonal: one direction carries the same kind of own value
of every frame at once (:func:`probes`), and J^T J is read back from the products
(:func:`unpack`). Each product applies every frame's linearised model once; applied column by
column, a pass of F frames with p own values each applied it F x p times for the own columns
alone (the 12-frame pass: 9 directions against 64 columns; 100 frames: 9 against 504).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import lineax as lx
import lineax.internal as lxi
import numpy as np
from jaxtyping import Array, PyTree

# Columns applied at once: at most this many, and at most CHUNK_ELEMENTS values of rows-long vectors
# (2^24 float64: 128 MiB) at a time. Fewer (2^21: a 48-frame pass of 128 x 128 px a column at a time, 19 MiB a
# vector) did not lower that pass's peak (docs/measurements/performance-history.md, "A pass's memory: programs and the allocator"),
# nor a product's own: one covariance product of 24 frames of 128 x 128 px rose 300 MiB above its start 5 and 3 directions
# at a time, 500 MiB one at a time (experiments/results/pass_memory/products_chunk_128px_24frames.txt).
MAX_CHUNK = 8
CHUNK_ELEMENTS = 1 << 24


def chunk_for(rows: int) -> int:
    """How many columns of a ``rows``-long linear map :func:`by_columns` applies at once."""
    return max(1, min(MAX_CHUNK, CHUNK_ELEMENTS // max(rows, 1)))


def probes(owners: Sequence[int]) -> tuple[np.ndarray, np.ndarray]:
    """The directions a product is applied to, given each column's owner (``owners[j]``: the
    observation whose residuals alone column j moves, -1 for a column that moves several), and
    which of them carries each column: a shared column alone (its unit vector), and the j-th own
    column of every owner together (Curtis, Powell & Reid 1974's grouping of structurally
    orthogonal columns), so that a joint fit of F frames applies a product to shared + per-frame
    directions, not to shared + F x per-frame columns. Returns the (m, n) directions and, per
    column, its direction's index."""
    owners = np.asarray(owners, dtype=int)
    shared = np.flatnonzero(owners < 0)
    probe_of = np.zeros(owners.size, dtype=int)
    probe_of[shared] = np.arange(shared.size)
    for owner in np.unique(owners[owners >= 0]):
        own = np.flatnonzero(owners == owner)
        probe_of[own] = shared.size + np.arange(own.size)
    basis = np.zeros((int(probe_of.max(initial=-1)) + 1, owners.size))
    basis[probe_of, np.arange(owners.size)] = 1.0
    return basis, probe_of


def unpack(applied: Array, owners: Sequence[int], transposed: Array | None = None) -> Array:
    """The n x n matrix M from its products with :func:`probes`' directions (``applied``: (m, n),
    row p M times direction p), for an M that joins no two owners' columns (M[i, j] = 0 where i and
    j are columns of different owners: J^T W J with W joining no two observations' residuals). A
    direction of one owner's columns gives their rows of that owner and of the shared columns
    mixed over the owners, so a shared row of an own column is taken from the shared column's
    product with M^T: ``transposed`` (row s: M^T times the s-th shared column's unit vector; None:
    M is symmetric, and M's own products give it)."""
    owners = np.asarray(owners, dtype=int)
    _, probe_of = probes(owners)
    shared = owners < 0
    taken = applied[probe_of].T  # taken[i, j]: row i of M times column j's direction
    if transposed is None:
        shared_rows = taken.T
    else:
        shared_rows = jnp.zeros_like(taken).at[np.flatnonzero(shared)].set(transposed)
    own_block = shared[None, :] | (owners[:, None] == owners[None, :])
    return jnp.where(own_block, taken, jnp.where(shared[:, None], shared_rows, 0.0))


def batched(directions: np.ndarray, chunk: int, size: int | None = None) -> np.ndarray:
    """``directions`` (m, n) as (batches, size, n), the last batch filled up with zero directions: ``size``
    the fewest at most ``chunk`` that take them in as few batches (9 in 2 of 5, not 8 and 1), so that
    every batch of a product has one shape (op by op, each shape compiles each op again)."""
    if size is None:
        size = -(-len(directions) // -(-len(directions) // chunk))
    padded = np.zeros((-(-len(directions) // size) * size, directions.shape[1]))
    padded[:len(directions)] = directions
    return padded.reshape(-1, size, directions.shape[1])


def by_columns(fn: Callable[[Array], Array], n: int, dtype: Any, chunk: int, owners: Sequence[int] | None = None,
               transposed: Callable[[Array], Array] | None = None) -> Array:
    """The n x n matrix M whose column j is ``fn(e_j)``, e_j the j-th of the ``n`` unit vectors, for
    ``fn`` a linear map that joins no two owners' columns (:func:`unpack`; ``owners`` None: every
    column shared), applied to :func:`probes`' directions in :func:`batched` batches of at most
    ``chunk``; ``transposed``: M^T's map (None: M is symmetric). One vmapped call per batch, run as it
    comes (op by op where called outside a compiled program, as the covariance is; a scan of the
    same, compiled, took XLA minutes on a pass)."""
    owners = (-1,) * n if owners is None else owners
    basis, _ = probes(owners)
    batches = batched(basis, chunk)

    def apply(fn: Callable[[Array], Array], batches: np.ndarray, count: int) -> np.ndarray:  # joined on the host: no program
        return np.concatenate([np.asarray(jax.vmap(fn)(jnp.asarray(batch, dtype=dtype))) for batch in batches])[:count]

    applied = apply(fn, batches, len(basis))
    shared = np.eye(n)[np.asarray(owners) < 0]
    if transposed is None or len(shared) in (0, len(basis)):  # no shared row of an own column to read, or no own column
        return _unpacked(applied, tuple(owners))
    return _unpacked(applied, tuple(owners), apply(transposed, batched(shared, chunk, batches.shape[1]), len(shared)))


# one program: run operation by operation (by_columns's products are), the unpacking made some 10 single-operation
# programs per fit, each traced and lowered in every process
_unpacked = jax.jit(unpack, static_argnums=1)


def all_shared(owners: Sequence[int] | None) -> bool:
    """Whether every column of ``owners`` (None: every one) is shared: J^T J is then read from J's images alone."""
    return owners is None or all(o < 0 for o in owners)


def images(operator: lx.AbstractLinearOperator) -> Array:
    """J's columns: the images of the unit vectors under the linear operator J, raveled, (n, rows), one after another
    (a loop of forward products: vmapped, JAX traced the operator's program again to batch it, 0.2 s of CPU in the
    8-parameter observation fit's step)."""
    packed = lxi.pack_structures(operator)
    dtype = jnp.result_type(*[leaf.dtype for leaf in jax.tree_util.tree_leaves(operator.in_structure())])

    def image(e: Array) -> Array:
        return lxi.ravel_vector(operator.mv(lxi.unravel_solution(e, packed)), packed)

    return jax.lax.map(image, jnp.eye(operator.in_size(), dtype=dtype))


def held_columns(residual: Callable[[Array, Any], Array]) -> Callable[[Array, Any], Array]:
    """``residual`` ((y, args) -> residuals, y a vector) whose JVP forms J's columns at y (:func:`images` of its
    linearisation) and applies them, so that a linearisation holds J's columns (n x rows) alone, not the model's
    intermediates (the 8-parameter observation fit's: some 80 arrays of 128 x 128 x 3 values, 31 MiB, which each
    solver step's program took in and copied with its state; its step's run 90 to 60 ms, its first call's tracing and
    lowering 0.1 s less). The columns are one jitted function, whose trace the solver's ``init`` and its step share.
    For an image fitted alone, whose columns :class:`NormalEquations` forms anyway; a joint fit's (frames' own
    columns, rows x columns growing as frames^2) are never held. ``args`` are not differentiated."""

    @jax.jit
    def with_columns(y: Array, args: Any) -> tuple[Array, Array]:
        r, linear = jax.linearize(lambda z: residual(z, args), y)
        return r, images(lx.FunctionLinearOperator(linear, jax.eval_shape(lambda: y)))

    @jax.custom_jvp
    def held(y: Array, args: Any) -> Array:
        return residual(y, args)

    @held.defjvp
    def held_jvp(primals: tuple[Array, Any], tangents: tuple[Array, Any]) -> tuple[Array, Array]:
        (y, args), t = primals, tangents[0]
        r, columns = with_columns(y, args)
        return r, jnp.reshape(t @ columns, r.shape)

    return held


def gram(operator: lx.AbstractLinearOperator, chunk: int | None = None, owners: Sequence[int] | None = None) -> Array:
    """J^T J of a linear operator J: where every column is shared (:func:`all_shared`), the products of J's columns
    (:func:`images`); else applied with J^T to :func:`probes`' directions of the columns' ``owners`` in
    :func:`batched` batches of at most ``chunk`` (default :func:`chunk_for` its rows)."""
    if all_shared(owners):
        return _products(images(operator))
    packed = lxi.pack_structures(operator)
    transposed = operator.transpose()
    dtype = jnp.result_type(*[leaf.dtype for leaf in jax.tree_util.tree_leaves(operator.in_structure())])

    def column(e: Array) -> Array:
        image = operator.mv(lxi.unravel_solution(e, packed))
        return lxi.ravel_vector(transposed.mv(image), lxi.transpose_packed_structures(packed))

    basis, _ = probes(owners)
    batches = batched(basis, chunk or chunk_for(operator.out_size()))
    # inside the solver's compiled step: one loop body, not a copy per batch
    applied = jax.lax.map(jax.vmap(column), jnp.asarray(batches, dtype=dtype)).reshape(-1, operator.in_size())
    return _symmetric(unpack(applied[:len(basis)], owners))


def _symmetric(g: Array) -> Array:
    return 0.5 * (g + g.T)


def _products(columns: Array) -> Array:
    """J^T J from J's columns (n, rows)."""
    return _symmetric(columns @ columns.T)


class NormalEquations(lx.AbstractLinearSolver):
    """The least-squares (pseudo-inverse) solution of J dx = b from J^T J, formed by :func:`gram`.

    Attributes:
        chunk: Jacobian columns applied at once with J^T (None: :func:`chunk_for` the operator's rows); J's own
            columns, where every one is shared, are applied one at a time (:func:`images`).
        owners: per column of the operator, the observation whose residuals alone it moves, -1 for a
            shared column (:func:`probes`; None: every column shared).
        rcond: eigenvalues of J^T J below ``rcond`` times the largest count as zero (default: machine
            epsilon times the number of columns, J^T J's own round-off).
    """

    chunk: int | None = eqx.field(static=True, default=None)
    owners: tuple[int, ...] | None = eqx.field(static=True, default=None)
    rcond: float | None = None

    def init(self, operator: lx.AbstractLinearOperator, options: dict[str, Any]) -> Any:
        del options
        packed = lxi.pack_structures(operator)
        if all_shared(self.owners):
            # J's columns held, J^T b their products with b (the module's docstring)
            columns = images(operator)
            return jnp.linalg.eigh(_products(columns)), lx.MatrixLinearOperator(columns), packed
        return jnp.linalg.eigh(gram(operator, self.chunk, self.owners)), operator.transpose(), packed

    def compute(self, state: Any, vector: PyTree[Array], options: dict[str, Any]) -> tuple[PyTree[Array], lx.RESULTS, dict[str, Any]]:
        del options
        (values, vectors), adjoint, packed = state
        if isinstance(adjoint, lx.MatrixLinearOperator):  # J's columns (init)
            rhs = adjoint.mv(lxi.ravel_vector(vector, packed))
        else:
            rhs = lxi.ravel_vector(adjoint.mv(vector), lxi.transpose_packed_structures(packed))
        n = values.shape[0]
        rcond = (jnp.finfo(values.dtype).eps * n) if self.rcond is None else self.rcond
        keep = values > rcond * jnp.maximum(jnp.max(values), 0.0)
        inverse = jnp.where(keep, 1.0 / jnp.where(keep, values, 1.0), 0.0)
        solution = vectors @ (inverse * (vectors.T @ rhs))
        return lxi.unravel_solution(solution, packed), lx.RESULTS.successful, {"rank": keep.sum()}

    def transpose(self, state: Any, options: dict[str, Any]) -> Any:
        raise NotImplementedError("NormalEquations holds J^T J only: a solve with J^T (J J^T, rows^2) is not supported.")

    def conj(self, state: Any, options: dict[str, Any]) -> Any:
        return state, options  # real operators only

    def assume_full_rank(self) -> bool:
        return False
