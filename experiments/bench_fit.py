"""Fit benchmark: per solver, steps, wall time and final errors of the five-parameter material fit
and of the D, G fit, at 128 x 128 (targets on 2 CPU cores: material fit under 20 s, D and G under
120 s). Run: ``.venv/bin/python experiments/bench_fit.py [--solvers lm gn ...] [--cases materials wrinkles_128]``.
"""

from __future__ import annotations

import argparse

from studyio import machine

import spacefit as sf
from spacefit import SOLVERS, Adam, Observation, fit

CASES = {name: sf.load_case(name) for name in ("materials", "wrinkles_128")}


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
    args = p.parse_args()
    print(f"machine: {machine()}; errors: D absolute, others relative")
    for name in args.cases:
        for solver in args.solvers:
            row = run(CASES[name], solver, args.max_steps)
            errs = ", ".join(f"{k.split('.')[-1]} {v:+.4f}" if k == "wrinkles.D" else f"{k.split('.', 1)[1]} {v:+.2%}"
                             for k, v in row["errors"].items())
            print(f"{name:13s} {solver:6s} steps {row['steps']:3d}  {row['wall_s']:6.1f} s  {errs}  [{row['status']}]", flush=True)


if __name__ == "__main__":
    main()
