"""The pixel grid's fixed point (:func:`spacefit.fitting.pixel_grid.grid_step`) on a fit: how many changes to the model
made at 4x its iterations took, the CPU and wall time of the pixel grid's phase (its iterations, the settled models and
the feedback's steps), the whole fit's, the fit's peak memory (Linux's VmHWM, reset after the simulation) before and
after that phase, each evaluated point's largest move from the last in standard errors, and where the step ended against the fixed point of a long plain iteration from the same renders (``--long N``: up to N steps, until every
value moves by less than 1e-4 of a standard error).

Cases: ``pass SIZE FRAMES`` (:mod:`bench_pass`'s pass: simulated at 256 spp, fitted at 16 spp, 12 LM steps at most) and
``single`` (the 8-parameter observation of ``bench_fit_process.py``, its DN rounded as its FITS file holds them, fitted
with its defaults). Runs any checkout (``PYTHONPATH`` its own; the grid step's return read either way) and writes a JSON
file; ``--against OTHER.json`` (another checkout's run of the same case) prints both steps' distances to the fixed point
of whichever file has a long iteration, and how far the values moved between them, in standard errors.
Run: ``python experiments/pixel_grid_fixed_point.py OUT.json {pass SIZE FRAMES | single} [--long N] [--against OTHER.json]``.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import tempfile
import time
from pathlib import Path

import jax
import numpy as np
from bench_fit import observed
from bench_pass import FIT_SPP, MATERIALS, MAX_STEPS, PER_FRAME, SENSOR, SIMULATE_SPP, START, base
from studyio import commit, machine

import spacefit as sf
from spacefit.fitting import uncertainty
from spacefit.fitting.pixel_grid import GridChanges


def cpu() -> float:
    """This process's CPU seconds so far (user + system, every thread)."""
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime + usage.ru_stime


def high_water_mib() -> float:
    """This process's peak resident memory since the last :func:`reset_high_water` (Linux's VmHWM), MiB."""
    line = next(line for line in Path("/proc/self/status").read_text().splitlines() if line.startswith("VmHWM:"))
    return int(line.split()[1]) / 1024


def reset_high_water() -> None:
    """Start :func:`high_water_mib` afresh from the present resident memory (Linux's clear_refs, 5)."""
    Path("/proc/self/clear_refs").write_text("5")


def fit_pass(size: int, n: int, folder: Path) -> tuple[sf.FitResult, float, float]:
    """:mod:`bench_pass`'s pass of ``n`` frames of ``size`` px fitted: the result, its CPU and wall seconds."""
    rng = np.random.default_rng(3)
    errors = [{"target.attitude_x_deg": float(a), "target.attitude_z_deg": float(b)} for a, b in rng.uniform(-0.3, 0.3, (n, 2))]
    frames = sf.simulate_pass(base(size), sf.arc_pass(n), folder / "pass", errors=errors, sensor=SENSOR, spp=SIMULATE_SPP)
    obs = [sf.Observation.from_file(f.file, s) for f, s in zip(frames.frames, frames.scenes(base(size)))]
    free = [*MATERIALS, "image.blur_sigma_px", *[f"{name}@{k}" for k in range(n) for name in PER_FRAME]]
    c0, t0 = cpu(), time.perf_counter()
    reset_high_water()  # the simulation's peak left out
    result = sf.fit(obs, free, start=START, render=sf.FitRender(spp=FIT_SPP), max_steps=MAX_STEPS)
    return result, cpu() - c0, time.perf_counter() - t0


def fit_single() -> tuple[sf.FitResult, float, float]:
    """``bench_fit_process.py``'s observation fitted: the result, its CPU and wall seconds."""
    case, obs, truths, start = observed()
    obs = sf.Observation(obs.scene, np.rint(obs.reference).astype(np.uint16).astype(float), sensor=obs.sensor)
    c0, t0 = cpu(), time.perf_counter()
    reset_high_water()  # the simulation's peak left out
    result = sf.fit(obs, list(truths), start=start)
    return result, cpu() - c0, time.perf_counter() - t0


def plain(changes: GridChanges, step: object, x: np.ndarray, stderr: np.ndarray, steps: int) -> tuple[list[np.ndarray], list[float]]:
    """The plain iteration delta = step(d_S(x + delta)) from 0, up to ``steps`` times or until every value moves by
    less than 1e-4 of ``stderr``: each iteration's delta and largest move in standard errors."""
    iterates, moves = [np.zeros(len(x))], []
    while len(moves) < steps and (not moves or moves[-1] >= 1e-4):
        iterates.append(step(changes.fine(x + iterates[-1]).mean(axis=0)))
        moves.append(float(np.abs((iterates[-1] - iterates[-2]) / stderr).max()))
        print(f"  plain iteration {len(moves)}: moved {moves[-1]:.3g} standard errors", flush=True)
    return iterates[1:], moves


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("out", type=Path)
    p.add_argument("case", nargs="+", help="pass SIZE FRAMES, or single")
    p.add_argument("--long", type=int, default=0, help="the plain iteration's steps at most for the fixed point (0: none)")
    p.add_argument("--against", type=Path, help="another checkout's JSON file of the same case")
    args = p.parse_args()
    print(f"machine: {machine()}; commit {commit()} (spacefit from {Path(sf.__file__).parent}); {' '.join(args.case)}; "
          f"load {os.getloadavg()[0]:.1f}", flush=True)
    seen: dict[str, object] = {}
    real = uncertainty.grid_step

    def recorded(changes: GridChanges, step: object, x: np.ndarray, stderr: np.ndarray, columns: object) -> object:
        points: list[np.ndarray] = []
        # settled without its `last`: the renders kept for the plain iterations after the fit
        counted = GridChanges(lambda y: points.append(np.array(y)) or changes.fine(y), lambda y, columns, last=False: changes.settled(y, columns))
        c0, t0, before = cpu(), time.perf_counter(), high_water_mib()
        out = real(counted, step, x, stderr, columns)
        seen.update(peak_before_grid_mib=before, peak_after_grid_mib=high_water_mib(), changes=changes, step=step, x=np.array(x), stderr=np.array(stderr), cpu=cpu() - c0, wall=time.perf_counter() - t0,
                    points=points, delta=np.array(out.delta if hasattr(out, "delta") else out[0]),
                    short=None if not hasattr(out, "short") else np.array(out.short),
                    feedback=np.array(out.feedback if hasattr(out, "feedback") else out[3]))
        return out

    uncertainty.grid_step = recorded
    with tempfile.TemporaryDirectory() as tmp:
        result, fit_cpu, fit_wall = fit_pass(int(args.case[1]), int(args.case[2]), Path(tmp)) if args.case[0] == "pass" else fit_single()
    peak = high_water_mib()
    x, stderr, delta, points = seen["x"], seen["stderr"], seen["delta"], seen["points"]
    moves = [float(np.abs((b - a) / stderr).max()) for a, b in zip(points, points[1:])]
    names = list(result.extras["pixel_grid_error"])
    record = {"commit": commit(), "source": str(Path(sf.__file__).parent), "case": args.case, "load": os.getloadavg()[0], "status": result.status.name, "steps": result.steps,
              "fit_cpu_s": fit_cpu, "fit_wall_s": fit_wall, "fit_peak_mib": peak, "peak_before_grid_mib": seen["peak_before_grid_mib"],
              "peak_after_grid_mib": seen["peak_after_grid_mib"], "grid_cpu_s": seen["cpu"],
              "grid_wall_s": seen["wall"], "evaluations": len(points), "moves_se": moves, "names": names, "x": x.tolist(),
              "stderr": stderr.tolist(), "delta": delta.tolist(), "points": [(p - x).tolist() for p in points], "values": result.values, "value_stderr": result.stderr,
              "feedback": seen["feedback"].tolist(), "short_se": None if seen["short"] is None else seen["short"].tolist(),
              "unsettled": [w for w in result.warnings if "did not settle" in w]}
    print(f"{result.status.name}, {result.steps} steps; fit {fit_cpu:.1f} s CPU, {fit_wall:.1f} s wall, peak {peak:.0f} MiB (before the "
          f"pixel grid's phase {seen['peak_before_grid_mib']:.0f}, after it {seen['peak_after_grid_mib']:.0f}); the pixel grid's phase "
          f"{seen['cpu']:.1f} s CPU, {seen['wall']:.1f} s wall, {len(points)} evaluations at 4x; moves (standard errors) "
          + ", ".join(f"{m:.3g}" for m in moves), flush=True)
    if args.long:
        c0 = cpu()
        with jax.enable_x64(True):  # as the fit's programs were traced
            iterates, long_moves = plain(seen["changes"], seen["step"], x, stderr, args.long)
        record.update(fixed=iterates[-1].tolist(), long_moves_se=long_moves, long_cpu_s=cpu() - c0,
                      long_iterates=[d.tolist() for d in iterates])
    args.out.write_text(json.dumps(record))
    if args.against:
        compare(record, json.loads(args.against.read_text()))


def compare(a: dict[str, object], b: dict[str, object]) -> None:
    """Print each run's step's distance to the fixed point (of whichever has one) and the values' moves between them, in
    standard errors (the iteration's, solver coordinates; the values' own, user coordinates)."""
    print(f"{a['source']} against {b['source']}: the fit's estimate the same: {a['x'] == b['x']}")
    fixed = a.get("fixed", b.get("fixed"))
    stderr, names = np.asarray(a["stderr"]), a["names"]
    if fixed is not None:
        for run in (a, b):
            gap = (np.asarray(run["delta"]) - np.asarray(fixed)) / stderr
            worst = int(np.argmax(np.abs(gap)))
            print(f"  {run['source']}: {run['evaluations']} evaluations, the pixel grid's phase {run['grid_cpu_s']:.1f} s CPU; "
                  f"its step {np.abs(gap).max():.3g} standard errors from the fixed point at most ({names[worst]}), rms {np.sqrt(np.mean(gap**2)):.3g}")
    moved = {n: (a["values"][n] - b["values"][n]) / b["value_stderr"][n] for n in b["values"]}
    worst = max(moved, key=lambda n: abs(moved[n]))
    print(f"  values moved by {abs(moved[worst]):.3g} standard errors at most ({worst}), rms {np.sqrt(np.mean(np.square(list(moved.values())))):.3g}; "
          f"standard errors changed by {max(abs(a['value_stderr'][n] / b['value_stderr'][n] - 1) for n in b['values']):.3g} at most (relative)")


if __name__ == "__main__":
    main()
