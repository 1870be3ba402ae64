"""The solvers' drivers (spacefit.fitting.drivers): what they keep of a solver's state between its steps."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from spacefit.fitting import drivers
from spacefit.fitting.solvers import SOLVERS
from spacefit.precision import float64

TAGS: frozenset = frozenset()


def rosenbrock(y: jax.Array, args: None) -> tuple[jax.Array, None]:
    """Rosenbrock's residuals and a cubic: from (-1.2, 1, 3) Levenberg-Marquardt rejects trial points on its way."""
    return jnp.stack([10.0 * (y[1] - y[0] ** 2), 1.0 - y[0], 0.5 * y[2] ** 3 - 1.0]), None


def arrays(tree: object) -> list[jax.Array]:
    return jax.tree_util.tree_leaves(eqx.filter(tree, eqx.is_array))


@pytest.mark.parametrize("name", ["lm", "gn", "dogleg"])
@float64
def test_a_state_holding_its_linearisation_once_steps_the_same_bits(name):
    """After every step, accepted or rejected, optimistix's two copies of the accepted point's linearisation (``f_info``
    and a damped Newton descent's ``descent_state.f_info``) are equal, so a state holding one (the driver's) takes the
    same steps bit for bit as the solver's own; the one held is shared, not copied."""
    solver = SOLVERS[name]()
    y = jnp.asarray([-1.2, 1.0, 3.0])
    f_struct = jax.eval_shape(lambda y: rosenbrock(y, None)[0], y)
    own = solver.init(rosenbrock, y, None, {}, f_struct, None, TAGS)
    held = drivers._linearisation_once(own)
    step = eqx.filter_jit(solver.step)
    y_held, rejected = y, 0
    for _ in range(12):
        y, after, _ = step(rosenbrock, y, None, {}, own, TAGS)
        y_held, held_after, _ = step(rosenbrock, y_held, None, {}, held, TAGS)
        rejected += int(after.num_accepted_steps) == int(own.num_accepted_steps)
        np.testing.assert_array_equal(np.asarray(y_held), np.asarray(y))
        for a, b in zip(arrays(held_after), arrays(after), strict=True):
            np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
        if getattr(after.descent_state, "f_info", None) is not None:
            for a, b in zip(arrays(after.descent_state.f_info), arrays(after.f_info), strict=True):
                np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
        own, held = after, drivers._linearisation_once(held_after)
        if getattr(held.descent_state, "f_info", None) is not None:
            assert all(a is b for a, b in zip(arrays(held.descent_state.f_info), arrays(held.f_info), strict=True))
    if name == "lm":
        assert rejected > 0


def _rendered_first_rosenbrock(columns_held: bool) -> drivers.RenderedFirst:
    """Rosenbrock's residuals as renders made first: the 'renders' the point's own coordinates, read back by the residual
    through its operands (a Gauss-Newton step's arguments), so that every step's operands move with its trial point."""
    return drivers.RenderedFirst(lambda u, jacobian: (jnp.asarray(u),), lambda u, operands: operands,
                                 lambda y, operands: rosenbrock(y + 0.0 * operands[0], None)[0], columns_held=columns_held)


@pytest.mark.parametrize("name", ["lm", "gn", "dogleg"])
@float64
def test_a_solve_holding_the_jacobians_columns_takes_the_same_steps(name):
    """With its Jacobian's columns held in the state (an image fitted alone), a solver evaluates the same trial points
    with the same losses, to the round-off of its linearisation applied as columns, accepted and rejected alike."""
    y = jnp.asarray([-1.2, 1.0, 3.0])
    solves = [list(drivers.drive(SOLVERS[name](), None, y, 12, None, _rendered_first_rosenbrock(held))) for held in (False, True)]
    assert len(solves[0]) == len(solves[1]) > 3
    for a, b in zip(*solves):
        np.testing.assert_allclose(a.u, b.u, rtol=1e-12, atol=1e-14)
        assert a.loss == pytest.approx(b.loss, rel=1e-12, abs=1e-24)
