"""spacefit: a differentiable renderer for BRDF parameter fitting of space targets.

Importing spacefit enables JAX's 64-bit mode: the W-M heights and their derivatives in D and G are
computed in float64 and only rounded to float32 where Mitsuba takes them.
"""

import jax

jax.config.update("jax_enable_x64", True)

__version__ = "0.1.0"
