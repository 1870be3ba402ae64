"""A joint fit's batched renders (spacefit.fitting.render_batches): evaluated eagerly, they wait for their callback."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import spacefit

# Two frames rendered through JAX inside the batch's callback, as each frame's bridge function renders, called eagerly on
# free values still being computed (an asynchronous program), with 128 reductions then queued on the images. XLA's CPU
# client runs a bounded number of computations at once (32 here): queued on images the callback has not made, they
# held every slot that the callback's own renders waited for (c753e3f: a light-curve fit hung in its verdict).
EAGER_RENDERS_THEN_REDUCTIONS = """
from types import SimpleNamespace

import jax
import jax.numpy as jnp
import numpy as np

from spacefit.fitting.render_batches import batched_renders


class Renders:
    def map(self, fn, keys, specs, again, xs, seeds):
        return [np.asarray(jax.jit(lambda v: jnp.full((4, 4, 3), v.sum()))(jnp.asarray(x))) for x in xs]


render = batched_renders(Renders(), [SimpleNamespace(key=str(k)) for k in range(2)], [np.array([0])] * 2, [(4, 4, 3)] * 2)
slow = jax.jit(lambda b: jax.lax.fori_loop(0, 50, lambda i, c: jnp.tanh(c @ b), b)[0, :1] + 1.0)  # about 0.4 s
b, seeds = jnp.eye(512) * 0.5, jnp.zeros(2, dtype=jnp.uint32)
(images,) = render(slow(b), seeds)
float(images.sum() * 2)  # every program compiled
(images,) = render(slow(b), seeds)  # its callback waits for the free values
sums = [images.sum() * k for k in range(128)]
print(sum(float(s) for s in sums))
"""


def test_batched_renders_evaluated_eagerly_wait_for_their_callback_before_work_is_queued_on_them():
    """Run in a process of its own with a deadline (a hang holds XLA's threads for good): with the batch's callback not
    waited for, the process hangs (killed at the deadline, measured); waited for, it ends in seconds with the sums of
    the images, 48 pixel values of 1 each, times 0 to 127."""
    here = str(Path(spacefit.__file__).resolve().parents[1])
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([here, os.environ.get("PYTHONPATH", "")])}
    try:
        out = subprocess.run([sys.executable, "-c", EAGER_RENDERS_THEN_REDUCTIONS], env=env, capture_output=True, text=True, timeout=120)
    except subprocess.TimeoutExpired:
        raise AssertionError("eager batched renders hung with reductions queued on their images") from None
    assert out.returncode == 0, out.stderr[-4000:]
    assert float(out.stdout) == 96.0 * sum(range(128))
