"""The JAX programs that issue 33's 8-parameter observation fit lowers in one ``spacefit fit`` process, each with
where it came from: the fit of ``bench_fit_process.py`` run in this process (``spacefit.cli.main`` with its
arguments, which ends without ``os._exit``) under a ``jax.monitoring`` listener, its JAX cache folder warmed first
by one child process. Prints each program's name and its last spacefit frames (a program named after one
operation, ``jit(add)``, is an operation run on concrete values outside any compiled program), then the listener's
totals: tracing, lowering, compiling (from the cache) and reading the cache, and the lowered modules' sizes (JAX's dump
of each, ``jax_dump_ir_to``: an array a program closes over is a constant in its module, development.md).
Run: ``.venv/bin/python experiments/fit_programs.py``.
"""

from __future__ import annotations

import collections
import os
import tempfile
import traceback
from pathlib import Path

import jax.monitoring
from bench_fit_process import run_fit, write_inputs

from spacefit.cli import main as cli_main
from spacefit.fitting.compile_cache import ENV as JAX_CACHE_ENV

LOWERED = "/jax/core/compile/jaxpr_to_mlir_module_duration"


def main() -> None:
    totals: dict[str, list[float]] = collections.defaultdict(lambda: [0.0, 0])
    programs: list[tuple[str, str]] = []

    def listener(event: str, seconds: float, **kwargs: object) -> None:
        totals[event][0] += seconds
        totals[event][1] += 1
        if event == LOWERED:
            frames = [f for f in traceback.extract_stack() if f"{os.sep}spacefit{os.sep}" in f.filename]
            programs.append((str(kwargs.get("fun_name")), " <- ".join(f"{Path(f.filename).name}:{f.lineno} {f.name}" for f in reversed(frames[-3:]))))

    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        args = write_inputs(folder)
        run_fit(args, folder / "warm", str(folder / "jax"))  # the cache warmed, as a user's second fit finds it
        os.environ[JAX_CACHE_ENV] = str(folder / "jax")
        jax.config.update("jax_dump_ir_to", str(folder / "ir"))
        jax.monitoring.register_event_duration_secs_listener(listener)
        cli_main(["fit", *args, "--out", str(folder / "out")])
        modules = sorted(((p.stat().st_size, p.name) for p in (folder / "ir").glob("*_compile.mlir")), reverse=True)
    print(f"{len(programs)} programs lowered:")
    for name, origin in programs:
        print(f"  {name:32s} {origin}")
    for event, (seconds, count) in sorted(totals.items(), key=lambda kv: -kv[1][0]):
        print(f"{seconds:8.3f} s {count:4d}  {event}")
    print(f"{len(modules)} modules lowered, {sum(size for size, _ in modules) / 1e6:.2f} MB in all; the largest:")
    for size, name in modules[:6]:
        print(f"  {size / 1e6:7.3f} MB  {name}")


if __name__ == "__main__":
    main()
