"""
A first fit
===========

Recover the legs' albedo and the panels' roughness of the synthetic ``panels`` case from a render
with many samples, starting far off; then the fit's convergence and its residuals.
"""

import spacefit as sf

case = sf.load_case("panels")
scene = case.truth_scene.with_values({"render.resolution": [32, 32], "camera.pixel_pitch_mm": 75.0})
reference = sf.render(scene.with_values({"render.spp": 256}))
result = sf.fit(sf.Observation(scene, reference), ["parts.legs.kd", "parts.panels.alpha_x"],
                start={"parts.legs.kd": 0.3, "parts.panels.alpha_x": 0.1})
print(sf.format_result(result))

# spacefit's plot functions return their axes (pass ax= or fig= to draw into your own layout)
convergence = sf.plot_convergence(result)
comparison = sf.plot_comparison(result, [reference])
