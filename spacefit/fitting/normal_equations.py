"""Least squares by the normal equations, formed a few Jacobian columns at a time.

A joint fit's Jacobian has a row per pixel of every frame and a column per free value, frames'
own values included, so held whole it grows as frames^2: the 12-frame, 64-parameter pass held
0.3 GB per copy at 128 x 128 px, and a dense QR keeps several. :class:`NormalEquations` is a lineax
solver for the solvers' linearised (damped) Jacobian operator that never holds it: it applies the
operator and its transpose to ``chunk`` unit vectors at a time and keeps only J^T J (columns^2),
then solves J^T J dx = J^T b by a symmetric eigendecomposition, the pseudo-inverse where J^T J is
singular (the minimum-norm step of an undetermined direction, as the SVD gives). Forming J^T J
squares the condition number, harmless in float64 for the fits' conditioning (measured against QR
in tests/test_normal_equations.py).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import lineax as lx
import lineax.internal as lxi
from jaxtyping import Array, PyTree

# Columns applied at once: at most this many, and at most CHUNK_ELEMENTS values of rows-long vectors
# (2^24 float64: 128 MiB) at a time.
MAX_CHUNK = 8
CHUNK_ELEMENTS = 1 << 24


def chunk_for(rows: int) -> int:
    """How many columns of a ``rows``-long linear map :func:`by_columns` applies at once."""
    return max(1, min(MAX_CHUNK, CHUNK_ELEMENTS // max(rows, 1)))


def by_columns(fn: Callable[[Array], Array], n: int, dtype: Any, chunk: int) -> Array:
    """The matrix whose column j is ``fn(e_j)``, e_j the j-th of the ``n`` unit vectors, ``chunk`` at a
    time: one vmapped call per chunk, run as it comes (op by op where called outside a compiled
    program, as the covariance is; a scan of the same, compiled, took XLA minutes on a pass)."""
    basis = jnp.eye(n, dtype=dtype)
    return jnp.concatenate([jax.vmap(fn)(basis[i:i + chunk]) for i in range(0, n, chunk)]).T


def gram(operator: lx.AbstractLinearOperator, chunk: int | None = None) -> Array:
    """J^T J of a linear operator J, ``chunk`` columns at a time (default :func:`chunk_for` its rows)."""
    packed = lxi.pack_structures(operator)
    transposed = operator.transpose()
    dtype = jnp.result_type(*[leaf.dtype for leaf in jax.tree_util.tree_leaves(operator.in_structure())])

    def column(e: Array) -> Array:
        image = operator.mv(lxi.unravel_solution(e, packed))
        return lxi.ravel_vector(transposed.mv(image), lxi.transpose_packed_structures(packed))

    # inside the solver's compiled step: one loop body, not a copy per chunk
    n, chunk = operator.in_size(), chunk or chunk_for(operator.out_size())
    blocks = -(-n // chunk)
    basis = jnp.eye(blocks * chunk, n, dtype=dtype).reshape(blocks, chunk, n)
    g = jax.lax.map(jax.vmap(column), basis).reshape(blocks * chunk, n)[:n]
    return 0.5 * (g + g.T)


class NormalEquations(lx.AbstractLinearSolver):
    """The least-squares (pseudo-inverse) solution of J dx = b from J^T J, formed by :func:`gram`.

    Attributes:
        chunk: Jacobian columns applied at once (None: :func:`chunk_for` the operator's rows).
        rcond: eigenvalues of J^T J below ``rcond`` times the largest count as zero (default: machine
            epsilon times the number of columns, J^T J's own round-off).
    """

    chunk: int | None = eqx.field(static=True, default=None)
    rcond: float | None = None

    def init(self, operator: lx.AbstractLinearOperator, options: dict[str, Any]) -> Any:
        del options
        values, vectors = jnp.linalg.eigh(gram(operator, self.chunk))
        return (values, vectors), operator.transpose(), lxi.pack_structures(operator)

    def compute(self, state: Any, vector: PyTree[Array], options: dict[str, Any]) -> tuple[PyTree[Array], lx.RESULTS, dict[str, Any]]:
        del options
        (values, vectors), transposed, packed = state
        rhs = lxi.ravel_vector(transposed.mv(vector), lxi.transpose_packed_structures(packed))
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
