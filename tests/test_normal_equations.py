"""The solvers' linear solve by normal equations formed a few columns at a time
(spacefit.fitting.normal_equations): the same steps as a dense QR / SVD, the minimum-norm step where
the Jacobian is rank deficient, and J^T J equal to the dense product whatever the chunk."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import lineax as lx
import numpy as np
import optimistix as optx
import pytest

from spacefit.fitting.normal_equations import NormalEquations, gram
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
