"""Synthetic fitting cases shared by the fit tests and benchmarks: scene, truth, start, reference.

Each case is a list of scene overrides of the thesis's default scene. References are rendered
with seed 7; fits use seeds 1 and 2, so a fit never shares random numbers with its reference.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from spacefit.render import Renderer
from spacefit.scene.assembly import assemble
from spacefit.scene.config import Scene, load_scene

REFERENCE_SEED = 7
NOISE_SEED = 11


@dataclass(frozen=True)
class Case:
    """A scene (overrides), the true values of its free parameters and a start for the fit."""

    name: str
    overrides: tuple[str, ...]
    truth: dict[str, float]
    start: dict[str, float]
    reference_spp: int
    notes: str = ""
    extra: tuple[str, ...] = field(default=())

    def scene(self, *more: str) -> Scene:
        """The scene the fit starts from (truth not applied)."""
        return load_scene(None, [*self.overrides, *self.extra, *more])

    def reference(self, noise: float = 0.0, *more: str) -> tuple[np.ndarray, float | None]:
        """Reference radiance at the truth, and the Gaussian noise sigma added (``noise`` times the
        mean radiance of lit pixels), or None."""
        truth = [f"{k}={v}" for k, v in self.truth.items()]
        scene = self.scene(*truth, f"render.spp={self.reference_spp}", f"render.seed={REFERENCE_SEED}", *more)
        image = Renderer(assemble(scene)).render()
        if not noise:
            return image, None
        sigma = noise * float(image[image.max(axis=-1) > 0].mean())
        return image + np.random.default_rng(NOISE_SEED).normal(0.0, sigma, image.shape).astype(np.float32), sigma

    def with_overrides(self, *more: str, name: str | None = None) -> Case:
        """The same case with more scene overrides (e.g. another view or range)."""
        return Case(name or self.name, self.overrides, self.truth, self.start, self.reference_spp, self.notes, self.extra + more)


# Panels seen near their specular direction, legs lit, no wrinkles; starts 50 % off.
PANELS = Case(
    "panels",
    ("render.resolution=[128, 128]", "camera.pixel_pitch_mm=18.75", "render.spp=16", "wrinkles.enabled=false",
     "camera.position_m=[4, 3, 25]", "camera.look_at_m=[0, 0, 0]", "target.attitude_deg=[0, 0, 0]"),
    {"parts.panels.alpha_x": 0.15, "parts.panels.alpha_y": 0.03, "parts.legs.kd": 0.5},
    {"parts.panels.alpha_x": 0.075, "parts.panels.alpha_y": 0.045, "parts.legs.kd": 0.25},
    reference_spp=16,
)

# The five-parameter material fit of the benchmark: panels (alpha_x, alpha_y, eta), legs, MLI roughness.
MATERIALS = Case(
    "materials",
    PANELS.overrides,
    {**PANELS.truth, "parts.panels.eta": 1.6, "parts.body.alpha": 0.1},
    {**PANELS.start, "parts.panels.eta": 2.4, "parts.body.alpha": 0.05},
    reference_spp=16,
)

# D and G identifiable: the body 11.6 m away at 7.8 cm per pixel, so the W-M scales (40 cm down to
# 12 cm) span 1.5 to 5 px; direct light (depth 1); G / L = 0.1, where G is not too sensitive to
# errors in D at a fixed rms height (d ln G / dD = -ln(G / L) / (D - 2) = 5.8).
WRINKLES = Case(
    "wrinkles",
    ("render.resolution=[64, 64]", "camera.pixel_pitch_mm=47.03", "render.spp=64", "render.depth=1",
     "camera.position_m=[3, -4, 10]", "camera.look_at_m=[0, 0, 0]", "target.attitude_deg=[0, 0, 0]",
     "sun.direction=[0.4, 0.3, -1]", "wrinkles.L=0.4", "wrinkles.Ls=0.1", "wrinkles.spacing_m=0.03"),
    {"wrinkles.D": 2.4, "wrinkles.G": 0.04},
    {"wrinkles.D": 2.55, "wrinkles.G": 0.06},
    reference_spp=256,
)

# The same at 128 x 128 (the benchmark's size).
WRINKLES_128 = WRINKLES.with_overrides("render.resolution=[128, 128]", "camera.pixel_pitch_mm=23.52", "render.spp=32",
                                       name="wrinkles_128")

# D and G not identifiable: 60 m away a pixel is 40 cm, as large as the largest wrinkle.
WRINKLES_FAR = WRINKLES.with_overrides("camera.position_m=[18, -24, 60]", "render.spp=16", name="wrinkles_far")
