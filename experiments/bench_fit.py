"""Fit benchmark: per solver, steps, wall time and final errors of the five-parameter material fit,
of the D, G fit, at 128 x 128 (targets on 2 CPU cores: material fit under 20 s, D and G under
120 s), and of an observation of a sensor (``--observed``: the panels case at 128 x 128, its
materials, PSF width, shift and two attitude angles free, 32 spp; target 20 s wall, issue 23).
Run: ``.venv/bin/python experiments/bench_fit.py [--solvers lm gn ...] [--cases materials wrinkles_128] [--observed]``.
"""

from __future__ import annotations

import argparse
import time

import jax.numpy as jnp
import numpy as np
from studyio import machine

import spacefit as sf
from spacefit import SOLVERS, Adam, Observation, fit
from spacefit.fitting.nuisance import image_model
from spacefit.scene.assembly import assemble
from spacefit.detector import electrons_per_radiance

CASES = {name: sf.load_case(name) for name in ("materials", "wrinkles_128")}
# The observed fit's truths away from the scene's pose and the image model's defaults (deg, px), as in
# experiments/coverage.py; the materials start 20 % off.
OBSERVED_TRUTH = {"target.attitude_x_deg": 0.3, "target.attitude_z_deg": -0.2, "image.shift_x_px": 0.4,
                  "image.shift_y_px": -0.25, "image.blur_sigma_px": 0.8}
PEAK_ELECTRONS = 20000.0  # in the brightest pixel of the truth, before the sensor's PSF
SENSOR_PSF_PX = 1.0


def observed(spp: int = 32, truth_spp: int = 256, seed: int = 0) -> tuple[sf.Case, sf.Observation, dict[str, float], dict[str, float]]:
    """The panels case at 128 x 128 as a sensor sees it: the truth rendered at ``truth_spp`` at the
    turned pose, blurred and shifted by the fit's image model, exposed (shot and read noise, 16 bits)
    with noise seed ``seed``; the fit at ``spp``. Returns the case, the observation, the truths and the start."""
    case = sf.load_case("panels").with_values({"render.spp": spp})
    pose = {n: v for n, v in OBSERVED_TRUTH.items() if n.startswith("target.")}
    render = np.asarray(sf.render(case.truth_scene.with_values({"render.spp": truth_spp, "target.attitude_deg": [
        pose["target.attitude_x_deg"], 0.0, pose["target.attitude_z_deg"]]})), dtype=float)
    image = [n for n in OBSERVED_TRUTH if n not in pose]
    truth = np.maximum(np.asarray(image_model(image)(jnp.asarray(render), jnp.asarray([OBSERVED_TRUTH[n] for n in image]), 0)), 0.0)
    intrinsics = assemble(case.scene()).intrinsics
    unit = sf.Sensor(exposure_time_s=1.0, psf_sigma_px=SENSOR_PSF_PX, full_well_electrons=None, bit_depth=16)
    per_second = float((truth * electrons_per_radiance(unit, intrinsics, 3)).max())
    sensor = sf.Sensor(exposure_time_s=PEAK_ELECTRONS / per_second, psf_sigma_px=SENSOR_PSF_PX, full_well_electrons=None, bit_depth=16)
    dn = sf.observe(truth, sensor, intrinsics, seed).astype(float)
    start = {n: 1.2 * v for n, v in case.truth.items()}
    return case, sf.Observation(case.scene(), dn, sensor=sensor), {**case.truth, **OBSERVED_TRUTH}, start


def run_observed(solver: str, max_steps: int) -> dict[str, object]:
    """Fit :func:`observed`; a row of the benchmark table, with the fit's whole wall time (set-up,
    solve and errors) and each value's error in its standard errors."""
    case, obs, truths, start = observed()
    t0 = time.perf_counter()
    result = fit(obs, list(truths), solver=solver, start=start, max_steps=max_steps)
    wall = time.perf_counter() - t0
    errors = {k: result.values[k] - v for k, v in truths.items()}
    return {"case": "observed", "solver": solver, "steps": result.steps, "wall_s": wall, "solve_s": result.wall_time_s,
            "status": result.status, "errors": errors, "stderr": result.stderr,
            "rejected": sum(not h["accepted"] for h in result.history), "goodness": result.goodness.line()}


def run(case: sf.Case, solver: str, max_steps: int) -> dict[str, object]:
    """Fit ``case`` from its start with ``solver``; return a row of the benchmark table."""
    reference, _ = case.reference()
    result = fit(Observation(case.scene(), reference), list(case.free), solver=Adam(0.1) if solver == "adam" else solver,
                 start=case.start, max_steps=max_steps)
    errors = {k: result.values[k] - v if k == "wrinkles.D" else result.values[k] / v - 1.0 for k, v in case.truth.items()}
    return {"case": case.name, "solver": solver, "steps": result.steps, "wall_s": result.wall_time_s,
            "status": result.status, "errors": errors, "stderr": result.stderr}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--solvers", nargs="+", default=list(SOLVERS), choices=SOLVERS)
    p.add_argument("--cases", nargs="+", default=list(CASES), choices=list(CASES))
    p.add_argument("--max-steps", type=int, default=40)
    p.add_argument("--observed", action="store_true", help="only the fit of an observation of a sensor (LM, 50 steps at most)")
    args = p.parse_args()
    if args.observed:
        row = run_observed("lm", 50)
        errs = ", ".join(f"{k.split('.')[-1]} {v:+.4g} ({v / row['stderr'][k]:+.1f} se)" for k, v in row["errors"].items())
        print(f"observed (8 free, 128 x 128, 32 spp, LM): {row['wall_s']:.1f} s wall ({row['solve_s']:.1f} s after the set-up), "
              f"{row['steps']} steps, {row['rejected']} rejected [{row['status'].name}]\n  errors: {errs}\n  {row['goodness']}", flush=True)
        return
    print(f"machine: {machine()}; errors: D absolute, others relative")
    for name in args.cases:
        for solver in args.solvers:
            row = run(CASES[name], solver, args.max_steps)
            errs = ", ".join(f"{k.split('.')[-1]} {v:+.4f}" if k == "wrinkles.D" else f"{k.split('.', 1)[1]} {v:+.2%}"
                             for k, v in row["errors"].items())
            print(f"{name:13s} {solver:6s} steps {row['steps']:3d}  {row['wall_s']:6.1f} s  {errs}  [{row['status']}]", flush=True)


if __name__ == "__main__":
    main()
