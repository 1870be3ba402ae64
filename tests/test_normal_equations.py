"""The solvers' linear solve by normal equations formed a few columns at a time
(spacefit.fitting.normal_equations): the same steps as a dense QR / SVD, the minimum-norm step where
the Jacobian is rank deficient, and J^T J equal to the dense product whatever the chunk, applied
column by column or, frames' own columns grouped, one direction per kind of own column."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import lineax as lx
import numpy as np
import optimistix as optx
import pytest

from spacefit.fitting.normal_equations import NormalEquations, by_columns, gram, held_columns, probes
from spacefit.precision import float64


def decays(u: jax.Array, t: jax.Array) -> jax.Array:
    """Two exponential decays and an offset: a classic ill-conditioned nonlinear least squares."""
    return u[0] * jnp.exp(-u[1] * t) + u[2] * jnp.exp(-u[3] * t) + u[4]


@float64
def test_levenberg_marquardt_takes_the_qr_steps():
    t = jnp.linspace(0.0, 4.0, 400)
    truth = jnp.asarray([2.0, 1.3, 0.7, 0.2, 0.1])
    data = decays(truth, t) + 1e-3 * jax.random.normal(jax.random.PRNGKey(0), t.shape)
    fn = lambda u, _: decays(u, t) - data  # noqa: E731
    start = jnp.asarray([1.0, 2.0, 1.0, 0.5, 0.0])
    ends = [optx.least_squares(fn, optx.LevenbergMarquardt(1e-10, 1e-12, linear_solver=solver), start, max_steps=200).value
            for solver in (lx.QR(), NormalEquations(chunk=2))]
    np.testing.assert_allclose(ends[1], ends[0], rtol=1e-7)
    assert np.max(np.abs(np.asarray(ends[1]) - np.asarray(truth))) < 0.05


@float64
@pytest.mark.parametrize("chunk", [1, 3, 8])
def test_gram_is_the_dense_product_and_the_solve_the_pseudo_inverse(chunk):
    rng = np.random.default_rng(1)
    J = rng.normal(size=(50, 5))
    J[:, 4] = J[:, 0] - 2.0 * J[:, 1]  # a direction no data determine
    operator = lx.FunctionLinearOperator(lambda v: (jnp.asarray(J) @ v[0], 3.0 * v[1]),
                                         (jax.ShapeDtypeStruct((5,), jnp.float64), jax.ShapeDtypeStruct((2,), jnp.float64)))
    dense = np.block([[J.T @ J, np.zeros((5, 2))], [np.zeros((2, 5)), 9.0 * np.eye(2)]])
    np.testing.assert_allclose(gram(operator, chunk), dense, rtol=1e-12, atol=1e-12)
    b = (jnp.asarray(rng.normal(size=50)), jnp.asarray(rng.normal(size=2)))
    got = lx.linear_solve(operator, b, NormalEquations(chunk=chunk)).value
    full = np.block([[J, np.zeros((50, 2))], [np.zeros((2, 5)), 3.0 * np.eye(2)]])
    want = np.linalg.lstsq(full, np.concatenate([np.asarray(b[0]), np.asarray(b[1])]), rcond=None)[0]
    np.testing.assert_allclose(np.concatenate([np.asarray(got[0]), np.asarray(got[1])]), want, rtol=1e-8, atol=1e-10)


@float64
def test_a_float32_jacobians_normal_equations_sum_in_float64():
    """An image's Jacobian is rendered in float32, its tangent J t formed in float32 (the fits' renders'): J^T J and
    J^T b, from J's columns, sum the rows in float64 (J^T applied to a float32 cotangent summed in float32, 1e-6 off)."""
    rng = np.random.default_rng(4)
    J = rng.normal(size=(100_000, 3)).astype(np.float32)
    operator = lx.FunctionLinearOperator(lambda v: (jnp.asarray(J) @ v.astype(jnp.float32)).astype(jnp.float64),
                                         jax.ShapeDtypeStruct((3,), jnp.float64))
    dense = J.astype(float).T @ J.astype(float)
    np.testing.assert_allclose(gram(operator), dense, rtol=1e-13)
    b = rng.normal(size=J.shape[0])
    got = lx.linear_solve(operator, jnp.asarray(b), NormalEquations()).value
    np.testing.assert_allclose(got, np.linalg.solve(dense, J.astype(float).T @ b), rtol=1e-10)


def frames_jacobian(rng: np.random.Generator, owners: tuple[int, ...], rows: tuple[int, ...]) -> np.ndarray:
    """A random Jacobian of frames of ``rows`` residuals each whose own columns (``owners[j]`` >= 0) move
    only their frame's rows."""
    frame = np.repeat(np.arange(len(rows)), rows)
    own = np.asarray(owners)
    J = rng.normal(size=(frame.size, own.size))
    J[(own[None, :] >= 0) & (own[None, :] != frame[:, None])] = 0.0
    return J


OWNERS = (-1, 0, 0, 0, 1, 1, -1, 2, 2, 2)  # two shared columns; frames of 3, 2 and 3 own columns, interleaved
ROWS = (20, 15, 25)


def test_probes_are_one_per_shared_column_and_one_per_kind_of_own_column():
    basis, probe_of = probes(OWNERS)
    assert basis.shape == (2 + 3, len(OWNERS))
    np.testing.assert_array_equal(basis.sum(axis=0), 1.0)  # each column in exactly one direction
    np.testing.assert_array_equal(probe_of, [0, 2, 3, 4, 2, 3, 1, 2, 3, 4])
    np.testing.assert_array_equal(probes((-1, -1, -1))[0], np.eye(3))


@float64
def test_gram_of_frames_own_columns_is_the_dense_product():
    chunk = 3  # 5 directions: the last chunk part empty
    J = frames_jacobian(np.random.default_rng(2), OWNERS, ROWS)
    n = len(OWNERS)
    operator = lx.FunctionLinearOperator(lambda v: (jnp.asarray(J) @ v, 0.5 * v), jax.ShapeDtypeStruct((n,), jnp.float64))
    np.testing.assert_allclose(gram(operator, chunk, OWNERS), J.T @ J + 0.25 * np.eye(n), rtol=1e-12, atol=1e-12)


@float64
@pytest.mark.parametrize("owners", [OWNERS, (0, 0, 1, 1, 2, 2)], ids=["shared-and-own", "all-own"])
def test_by_columns_of_frames_own_columns_is_the_dense_product_symmetric_or_not(owners):
    """J1^T W J2 with W joining no two frames' rows: from M's and M^T's maps, and a symmetric one from
    its own; also where no column is shared (two images' own PSF widths and shifts only)."""
    chunk = 3
    rng = np.random.default_rng(3)
    J1, J2 = frames_jacobian(rng, owners, ROWS), frames_jacobian(rng, owners, ROWS)
    blocks = [rng.normal(size=(m, m)) for m in ROWS]
    W = jax.scipy.linalg.block_diag(*(b + b.T for b in blocks))
    n = len(owners)

    def product(A: np.ndarray, B: np.ndarray):
        return lambda e: jnp.asarray(A).T @ (W @ (jnp.asarray(B) @ e))

    got = by_columns(product(J1, J2), n, jnp.float64, chunk, owners, product(J2, J1))
    np.testing.assert_allclose(got, J1.T @ W @ J2, rtol=1e-11, atol=1e-11)
    np.testing.assert_allclose(by_columns(product(J1, J1), n, jnp.float64, chunk, owners), J1.T @ W @ J1, rtol=1e-11, atol=1e-11)
    np.testing.assert_allclose(by_columns(product(J1, J2), n, jnp.float64, chunk), J1.T @ W @ J2, rtol=1e-11, atol=1e-11)


@pytest.mark.slow
@float64
def test_levenberg_marquardt_of_frames_own_columns_takes_the_qr_steps():
    """Three 'frames' each with its own decay rate and the offset shared: the steps told the owners are QR's."""
    t = jnp.linspace(0.0, 4.0, 100)
    owners = (-1, 0, 1, 2)
    truth = jnp.asarray([0.1, 1.3, 0.7, 2.0])

    def frames(u: jax.Array) -> jax.Array:
        return jnp.concatenate([jnp.exp(-u[k + 1] * t) + u[0] for k in range(3)])

    data = frames(truth) + 1e-3 * jax.random.normal(jax.random.PRNGKey(1), (3 * t.size,))
    fn = lambda u, _: frames(u) - data  # noqa: E731
    start = jnp.asarray([0.0, 1.0, 1.0, 1.0])
    ends = [optx.least_squares(fn, optx.LevenbergMarquardt(1e-10, 1e-12, linear_solver=solver), start, max_steps=100).value
            for solver in (lx.QR(), NormalEquations(chunk=2, owners=owners))]
    np.testing.assert_allclose(ends[1], ends[0], rtol=1e-7)
    assert np.max(np.abs(np.asarray(ends[1]) - np.asarray(truth))) < 0.01


@float64
def test_a_residual_with_held_columns_is_linearised_as_its_columns_alone():
    """:func:`held_columns`: the same residuals and tangents, and a linearisation that holds J's columns (n x rows) and
    nothing else, where the model's own holds its intermediates."""
    t = jnp.linspace(0.0, 4.0, 400)
    data = decays(jnp.asarray([2.0, 1.3, 0.7, 0.2, 0.1]), t)
    fn = lambda u, offset: decays(u, t) - data + offset  # noqa: E731
    u, tangent = jnp.asarray([1.0, 2.0, 1.0, 0.5, 0.0]), jnp.asarray([0.3, -0.1, 0.2, 0.05, 1.0])
    held = held_columns(fn)
    np.testing.assert_array_equal(held(u, 0.5), fn(u, 0.5))
    np.testing.assert_allclose(jax.jvp(lambda v: held(v, 0.5), (u,), (tangent,))[1],
                               jax.jvp(lambda v: fn(v, 0.5), (u,), (tangent,))[1], rtol=1e-13, atol=1e-15)
    kept = {name: [c.shape for c in jax.make_jaxpr(jax.linearize(lambda v, f=f: f(v, 0.5), u)[1])(u).consts]
            for name, f in (("model", fn), ("held", held))}
    assert kept["held"] == [(5, 400)]
    assert len(kept["model"]) > 2
