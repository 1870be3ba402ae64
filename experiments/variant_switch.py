"""What Mitsuba's variant switch costs a caller who keeps another variant: ``renders`` small renders
(sf.Renderer.render) with the caller's variant set to ``variant`` before each (docs/reference/api.md).

Usage: python experiments/variant_switch.py VARIANT [RENDERS]; time it as a whole process against llvm_ad_rgb
(no switch), runs in turn, e.g. ``/usr/bin/time -v python experiments/variant_switch.py scalar_rgb`` then the same
with ``llvm_ad_rgb``, and compare the CPU time (user + system).
"""

from __future__ import annotations

import sys

import spacefit as sf
from spacefit.rendering.backend import mi  # the user's `import mitsuba`, after spacefit has pointed Dr.Jit at a libLLVM

variant, renders = sys.argv[1], int(sys.argv[2]) if len(sys.argv) > 2 else 10
renderer = sf.Renderer(sf.load_case("panels").scene().with_values({"render.resolution": [32, 32], "render.spp": 1}))
for _ in range(renders):
    mi.set_variant(variant)
    renderer.render()
assert mi.variant() == variant
