"""Issue 33's light-curve figure: a 24-point light curve of the default lander over the solar phase angle
(5 to 120 deg) at 0.5 % precision per point (the relative Monte Carlo standard error of each point's
irradiance), target at most 10 s a call to ``sf.light_curve`` on a quiet 2-core machine.

The timed call is ``sf.light_curve(scene, phase_deg=..., precision=0.005)``: pilots of each point's
error pixel by pixel, then each point with the samples it needs where it needs them
(``spacefit.studies.lightcurve_sizing``), all inside the call. Its wall and CPU time are printed with the load, then the precision it reached, measured from
independent seeds: the call's own standard errors (four seeds a point), the same call repeated with other
seeds (``--repeats``, default 3 more), their standard errors pooled (4 x calls seeds a point), and the
scatter of the calls' means about their mean (the error a call really has, measured without trusting
any call's own estimate). Run: ``.venv/bin/python experiments/bench_light_curve.py [--repeats N]``.
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np
from studyio import commit, machine

import spacefit as sf

PHASES_DEG = np.linspace(5.0, 120.0, 24)
TARGET_PRECISION = 0.005
TARGET_S = 10.0
SEEDS = 4


def call(scene: sf.Scene, first_seed: int) -> tuple[sf.LightCurve, float, float]:
    """One call at the target precision with seeds ``first_seed`` onwards: the curve, wall and CPU time (s)."""
    t0, c0 = time.perf_counter(), time.process_time()
    curve = sf.light_curve(scene, phase_deg=PHASES_DEG, precision=TARGET_PRECISION,
                           seeds=list(range(first_seed, first_seed + SEEDS)), quiet=True)
    return curve, time.perf_counter() - t0, time.process_time() - c0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3, help="calls with other seeds that measure the precision reached")
    args = parser.parse_args()
    scene = sf.load_scene(None)
    sf.light_curve(scene.with_values({"render.spp": 1}), phase_deg=PHASES_DEG[:2], seeds=[0, 1], quiet=True)  # imports, kernels
    print(f"machine: {machine()}; commit {commit()}; {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}; default lander, "
          f"{len(PHASES_DEG)} phases {PHASES_DEG[0]:g} to {PHASES_DEG[-1]:g} deg, precision {TARGET_PRECISION:.1%}, {SEEDS} seeds a point")
    load = os.getloadavg()[0]
    curve, wall, cpu = call(scene, 0)
    traced = curve.dataset["samples"].values
    own = curve.irradiance_se_w_m2 / curve.irradiance_w_m2
    print(f"24-point light curve at {TARGET_PRECISION:.1%} a point: {wall:.1f} s a call (target {TARGET_S:g} s: "
          f"{'met' if wall <= TARGET_S else 'NOT met'}), {cpu:.1f} s CPU; load {load:.1f} before, {os.getloadavg()[0]:.1f} after")
    pilots = curve.dataset["pilot_samples"].values
    print(f"samples traced a point (its seeds together): {', '.join(map(str, traced))}; in all {int(traced.sum()):,}, and "
          f"{int(pilots.sum()):,} by the pilots ({int(pilots.min()):,} to {int(pilots.max()):,} a point)")
    print(f"the call's own errors (from its {SEEDS} seeds): worst point {own.max():.2%}, median {np.median(own):.2%}")
    means, variances = [curve.irradiance_w_m2], [curve.irradiance_se_w_m2**2]
    for r in range(args.repeats):
        other, wall, cpu = call(scene, SEEDS * (r + 1))
        means.append(other.irradiance_w_m2)
        variances.append(other.irradiance_se_w_m2**2)
        print(f"repeat {r + 1}: {wall:.1f} s, {cpu:.1f} s CPU, load {os.getloadavg()[0]:.1f}; worst point's own error "
              f"{np.max(other.irradiance_se_w_m2 / other.irradiance_w_m2):.2%}")
    means = np.array(means)
    grand = means.mean(axis=0)
    pooled = np.sqrt(np.mean(variances, axis=0)) / grand  # a call's standard error, from 4 x calls seeds
    scatter = means.std(axis=0, ddof=1) / grand if len(means) > 1 else np.full(grand.shape, np.nan)
    worst = int(np.argmax(pooled))
    print(f"a call's error, pooled over {len(means)} calls' seeds ({SEEDS * len(means)} a point): worst point "
          f"{pooled.max():.2%} (phase {PHASES_DEG[worst]:.0f} deg), {int(np.sum(pooled > TARGET_PRECISION))} of "
          f"{len(grand)} points above {TARGET_PRECISION:.1%}")
    if len(means) > 1:
        # the calls' means scatter by a call's true error: over all points, the mean square of scatter / pooled is about 1
        print(f"scatter of the {len(means)} calls' means: worst point {np.nanmax(scatter):.2%}; mean square of "
              f"scatter / pooled error over the points {np.nanmean((scatter / pooled) ** 2):.2f} (1 if the errors are honest)")
    for phase, p, s, n in zip(PHASES_DEG, pooled, scatter, traced):
        print(f"  phase {phase:6.1f} deg: {n:9,d} samples, pooled error {p:.3%}, calls' scatter {s:.3%}")


if __name__ == "__main__":
    main()
