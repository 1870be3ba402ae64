"""Why the six-frame pass fitted with each frame's attitude about x and z (``pass.ipynb``) ended with
the verdict ``misfit`` under the old rule, and what the verdict render (:mod:`spacefit.fitting.goodness`)
gives: at the TRUE values (materials and every frame's two angles), per frame, at 8, 32 and 128 spp,
the old rule (the fit's own render, the noise sigma at its DN, the references taken as real) and the
verdict (the mean of k renders, sigma at that mean, the references' 1024-spp render noise counted);
and chi^2 per value at 32 spp with the noise sigma at the model's own DN, at the reference's, and at
a 1024-spp model's, against the render noise v measured with the last.

    python experiments/pass_misfit.py            # 6 frames at 32 x 32 px, references at 1024 spp (some minutes)

Prints the figures with the machine's load average.
"""

from __future__ import annotations

import os
import tempfile
import time
from pathlib import Path

import jax.numpy as jnp
import numpy as np

import spacefit as sf
from spacefit.formation import noise_variance_dn
from spacefit.fitting.goodness import goodness
from spacefit.fitting.judging import judged_goodness, per_observation
from spacefit.fitting.problem import setup
from spacefit.precision import float64

TRUTH = {"parts.panels.alpha_x": 0.15, "parts.panels.alpha_y": 0.03, "parts.legs.kd": 0.5}
SENSOR = sf.Sensor(radiometric_scale_dn_per_w_m2_sr=500.0, gain_dn_per_electron=0.5, bias_dn=100.0, read_noise_electrons=5.0,
                   bit_depth=16, full_well_electrons=None, diffraction=False, psf_sigma_px=0.0)
FRAMES = 6


@float64
def main() -> None:
    print(f"load average {os.getloadavg()} at {time.strftime('%Y-%m-%d %H:%M:%S', time.gmtime())} UTC")
    base = sf.load_scene("spacefit/synthetic/panels.toml", {"render.resolution": [32, 32], "camera.pixel_pitch_mm": 75.0})
    errors = [{"target.attitude_x_deg": float(a), "target.attitude_z_deg": float(b)}
              for a, b in np.random.default_rng(3).uniform(-0.3, 0.3, (FRAMES, 2))]  # pass.ipynb's
    frames = sf.simulate_pass(base, sf.arc_pass(FRAMES), Path(tempfile.mkdtemp()) / "pass", errors=errors, sensor=SENSOR, spp=1024)
    obs = [sf.Observation.from_file(f.file, s) for f, s in zip(frames.frames, frames.scenes(base))]
    free = [*TRUTH, *frames.per_frame(["target.attitude_x_deg", "target.attitude_z_deg"])]
    truth = {**TRUTH, **{f"{name}@{k}": e[name] for k, e in enumerate(errors) for name in e}}

    def at_truth(render: sf.FitRender) -> tuple[object, list[np.ndarray], list[np.ndarray]]:
        s = setup(obs, free, start=truth, render=render)
        x = jnp.asarray(s.x0)
        models = [np.asarray(m, dtype=float) for m in s.problem.renders_x(x)]
        return s, models, [np.asarray(r, dtype=float) for r in s.problem.references]

    for spp in (8, 32, 128):
        s, _, _ = at_truth(sf.FitRender(spp=spp))
        x = jnp.asarray(s.x0)
        r, r_alt = np.asarray(s.problem.residual_x(x)), np.asarray(s.problem.residual_x_independent(x))
        old = goodness(r, (r - r_alt) / np.sqrt(2.0), len(free), True)
        print(f"{spp} spp, at the truth, the old rule: chi^2/dof {old.chi2_dof:.3f}, v {old.render_noise:.3f}, limit {old.limit:.3f}: "
              f"{'MISFIT' if old.misfit else 'within the expected range'}")
        t0 = time.perf_counter()
        new, r, noise, _, _ = judged_goodness(s, x, "pixel")
        print(f"  the verdict ({time.perf_counter() - t0:.1f} s): {new.line()}")
        for k, gk in enumerate(per_observation(r, noise, s, new.samples_factor)):
            print(f"  frame {k}: chi^2/dof {gk.chi2_dof:.3f}, v {gk.render_noise:.3f}, v_ref {gk.reference_noise:.3f}, above its "
                  f"expectation by {gk.chi2_dof - 1 - gk.render_noise - gk.reference_noise:+.3f}, limit {gk.limit:.3f}")

    _, m32, refs = at_truth(sf.FitRender(spp=32))
    _, m32_alt, _ = at_truth(sf.FitRender(spp=32, seed=77))
    _, m1024, _ = at_truth(sf.FitRender(spp=1024, seed=5))

    def variance(dn: np.ndarray) -> np.ndarray:
        return np.asarray(noise_variance_dn(jnp.asarray(dn), SENSOR), dtype=float)

    def mean(values: list[np.ndarray]) -> float:
        return float(np.mean(np.concatenate([v.ravel() for v in values])))

    ks = range(FRAMES)
    print("32 spp at the truth, chi^2 per value (every pixel):")
    print(f"  sigma at the model's DN (the fit's)  {mean([(refs[k] - m32[k]) ** 2 / variance(m32[k]) for k in ks]):.3f}")
    print(f"  sigma at the reference's DN          {mean([(refs[k] - m32[k]) ** 2 / variance(refs[k]) for k in ks]):.3f}")
    print(f"  sigma at a 1024-spp model's DN       {mean([(refs[k] - m32[k]) ** 2 / variance(m1024[k]) for k in ks]):.3f}")
    print(f"  render noise v with that sigma       {mean([(m32[k] - m32_alt[k]) ** 2 / 2 / variance(m1024[k]) for k in ks]):.3f}")
    print(f"  a 1024-spp model against the reference {mean([(refs[k] - m1024[k]) ** 2 / variance(m1024[k]) for k in ks]):.3f}")
    print(f"load average {os.getloadavg()} at the end")


if __name__ == "__main__":
    main()
