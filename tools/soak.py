"""Soak: hostile cases over many runs (issue 20, item 6). ``make soak``; not in CI (minutes).

Every case runs the ``spacefit`` command line in real processes and compares what it leaves with an
uninterrupted reference run of the same command:

- ``sweep-kill`` / ``sweep-int`` / ``sweep-term``: kill -9, Ctrl-C or SIGTERM at a random moment of a
  sweep (and, for kill -9, sometimes of its first rerun too), then a rerun;
- ``render-kill`` / ``render-int`` / ``render-term``: the same during a render, then a rerun;
- ``fit-kill``: kill -9 at a random moment of a fit, then ``--resume`` (or a fresh run if nothing was kept);
- ``damaged-store``: a finished store with a data chunk deleted or truncated, then a rerun;
- ``concurrent``: two sweeps writing one store at once, then a rerun;
- ``dask-worker-kill``: kill -9 of a dask worker process during ``sweep --workers 2``;
- ``full-disk``: a sweep with images into a 256 KiB tmpfs (needs root; skipped otherwise);
- ``file-size-limit``: a render under RLIMIT_FSIZE of 16 KiB.

Each case ends as: ok; **data loss** (a point marked done, or a result folder, whose data are not
the reference's, or a finished result gone); **wrong result** (the final store or result differs from
the reference, or the rerun did not finish it); **crash** (a traceback, or an exit code the README
does not promise); skipped (with its reason). The exit status is 1 when a data loss, wrong result or
crash was counted, else 0.

Usage: python tools/soak.py [--runs N | --minutes M] [--quick] [--seed S] [--work DIR]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import random
import resource
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
OK, LOSS, WRONG, CRASH, SKIPPED = "ok", "data loss", "wrong result", "crash", "skipped"
COUNTED = (LOSS, WRONG, CRASH)
EXIT = {signal.SIGINT: 130, signal.SIGTERM: 143}
# A signal outside spacefit's handlers: in Python's start-up, before the first module sets them, or in
# the interpreter's exit after the work is done and written (Python restores the default handlers
# there): the default action, the process ends by the signal, silently (a shell reports 130 / 143
# as for the handled exit). A traceback is a crash in any case.
BY_THE_SIGNAL = {signal.SIGTERM: (-signal.SIGTERM,), signal.SIGINT: (-signal.SIGINT,)}
RENDER_FILES = {"preview.png", "radiance.exr", "render.json", "scene.toml"}
SIGNAL_OF = {"kill": signal.SIGKILL, "int": signal.SIGINT, "term": signal.SIGTERM}
SCENE = {"render.resolution": "[96, 96]", "render.spp": "24", "camera.pixel_pitch_mm": "14"}
SWEEP_POINTS = 10


@dataclass
class Outcome:
    case: str
    kind: str
    detail: str = ""


class Run:
    """A ``spacefit`` process: its exit code and stderr once it ends."""

    def __init__(self, args: list[str], limit: int | None = None) -> None:
        def prepare() -> None:
            if limit is not None:
                resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))

        env = {**os.environ, "PYTHONPATH": str(ROOT), "PYTHONUNBUFFERED": "1"}
        self.t0 = time.monotonic()
        self.p = subprocess.Popen([sys.executable, "-m", "spacefit.cli", *args], stdout=subprocess.DEVNULL,
                                  stderr=subprocess.PIPE, text=True, env=env, cwd=ROOT, preexec_fn=prepare)

    def finish(self, timeout: float = 600) -> tuple[int, str]:
        _, err = self.p.communicate(timeout=timeout)
        return self.p.returncode, err

    def after(self, seconds: float, sig: int) -> tuple[int, str]:
        """Send ``sig`` ``seconds`` after the start (if still running) and wait for the end."""
        try:
            self.p.wait(timeout=max(0.0, seconds - (time.monotonic() - self.t0)))
        except subprocess.TimeoutExpired:
            self.p.send_signal(sig)
        return self.finish()


def crashed(code: int, err: str, allowed: set[int]) -> str:
    """Why an exit is a crash ('' if it is not): a traceback, or an exit code outside ``allowed``."""
    if "Traceback" in err:
        return "traceback: " + err.strip().splitlines()[-1][:200]
    if code not in allowed:
        return f"exit {code}: " + (err.strip().splitlines() or [""])[-1][:200]
    return ""


def read_store(path: Path) -> dict[str, np.ndarray] | None:
    """A store's variables as arrays (None if it cannot be read)."""
    import xarray as xr

    try:
        with xr.open_zarr(str(path)) as ds:
            return {name: np.asarray(ds[name].values) for name in ds.data_vars}
    except Exception:  # noqa: BLE001  (an unreadable store is what the caller reports)
        return None


def differing(store: dict[str, np.ndarray], reference: dict[str, np.ndarray], only_done: bool) -> list[str]:
    """The variables of ``store`` that differ from the reference's (at its done points if ``only_done``)."""
    done = store["done"] if only_done else np.ones_like(reference["done"])
    if not only_done and not store["done"].all():
        return ["done"]
    return [name for name, ref in reference.items() if name != "done" and
            not np.array_equal(store[name][done], ref[done], equal_nan=True)]


class Soak:
    def __init__(self, work: Path, rng: random.Random) -> None:
        self.work, self.rng, self.n = work, rng, 0
        self.sweep_file = work / "sweep.toml"
        values = ", ".join(str(10 + 7 * i) for i in range(SWEEP_POINTS))
        self.sweep_file.write_text(f"images = true\n[axes]\n\"sun.elevation_deg\" = [{values}]\n")
        self.sets = [a for k, v in SCENE.items() for a in ("--set", f"{k}={v}")]
        t0 = time.monotonic()
        code, err = Run(self.sweep_args(work / "reference.zarr")).finish()
        self.sweep_s = time.monotonic() - t0
        assert code == 0, err
        self.reference = read_store(work / "reference.zarr")
        code, err = Run(self.render_args(work / "reference-render")).finish()
        assert code == 0, err
        self.radiance = (work / "reference-render" / "radiance.exr").read_bytes()
        self.fit_reference: dict | None = None

    def fresh(self, name: str) -> Path:
        self.n += 1
        return self.work / f"{self.n:04d}-{name}"

    def sweep_args(self, store: Path, *extra: str) -> list[str]:
        return ["sweep", str(self.sweep_file), "--out", str(store), "--quiet", *self.sets, *extra]

    def render_args(self, out: Path, *extra: str) -> list[str]:
        return ["render", "--out", str(out), "--quiet", "--set", "render.spp=3000", "--set", "render.resolution=[128, 128]", *extra]

    def moment(self, span: float) -> float:
        return self.rng.uniform(0.2, span)

    # sweeps ---------------------------------------------------------------------------------------

    def finish_sweep(self, case: str, store: Path, before: str = "") -> Outcome:
        """Rerun the sweep on ``store`` and compare it with the reference."""
        code, err = Run(self.sweep_args(store)).finish()
        why = crashed(code, err, {0})
        if why:
            return Outcome(case, CRASH, f"{before}rerun: {why}")
        final = read_store(store)
        if final is None:
            return Outcome(case, WRONG, f"{before}the rerun's store is unreadable")
        bad = differing(final, self.reference, only_done=False)
        return Outcome(case, WRONG, f"{before}rerun differs in {bad}") if bad else Outcome(case, OK, before)

    def kept(self, case: str, store: Path) -> Outcome | None:
        """A data loss if a point marked done in ``store`` does not hold the reference's data."""
        if not store.exists():
            return None
        partial = read_store(store)
        if partial is None:
            return None  # a store being created: the rerun must make it
        bad = differing(partial, self.reference, only_done=True)
        return Outcome(case, LOSS, f"done points differ in {bad}") if bad else None

    def sweep_signal(self, how: str) -> Outcome:
        case, sig = f"sweep-{how}", SIGNAL_OF[how]
        store = self.fresh(case) / "s.zarr"
        store.parent.mkdir()
        at = self.moment(self.sweep_s * 1.1)
        code, err = Run(self.sweep_args(store)).after(at, sig)
        why = crashed(code, err, {0, EXIT.get(sig, -sig), *BY_THE_SIGNAL.get(sig, ())})
        if why:
            return Outcome(case, CRASH, f"at {at:.1f} s: {why}")
        loss = self.kept(case, store)
        if loss:
            return loss
        before = f"at {at:.1f} s; "
        if sig == signal.SIGKILL and self.rng.random() < 0.5:  # the rerun killed too
            again = self.moment(self.sweep_s)
            code, err = Run(self.sweep_args(store)).after(again, sig)
            if crashed(code, err, {0, -sig}):
                return Outcome(case, CRASH, f"{before}killed rerun: {crashed(code, err, {0, -sig})}")
            loss = self.kept(case, store)
            if loss:
                return loss
            before += f"rerun killed at {again:.1f} s; "
        return self.finish_sweep(case, store, before)

    def damaged_store(self) -> Outcome:
        case = "damaged-store"
        store = self.fresh(case) / "s.zarr"
        shutil.copytree(self.work / "reference.zarr", store)
        chunks = sorted(p for var in ("mean_radiance", "radiance") for p in (store / var).iterdir() if not p.name.startswith("."))
        victim = self.rng.choice(chunks)
        how = self.rng.choice(["deleted", "truncated"])
        if how == "deleted":
            victim.unlink()
        else:
            victim.write_bytes(victim.read_bytes()[: max(1, victim.stat().st_size // 2)])
        return self.finish_sweep(case, store, f"{victim.parent.name}/{victim.name} {how}; ")

    def concurrent(self) -> Outcome:
        case = "concurrent"
        store = self.fresh(case) / "s.zarr"
        store.parent.mkdir()
        first = Run(self.sweep_args(store))
        time.sleep(self.moment(self.sweep_s * 0.8))
        second = Run(self.sweep_args(store, *self.rng.choice([(), ("--overwrite",)])))
        for name, run in (("first", first), ("second", second)):
            code, err = run.finish()
            why = crashed(code, err, {0, 1, 2})
            if why:
                return Outcome(case, CRASH, f"{name}: {why}")
        return self.finish_sweep(case, store)

    def dask_worker_kill(self) -> Outcome:
        import psutil

        case = "dask-worker-kill"
        store = self.fresh(case) / "s.zarr"
        store.parent.mkdir()
        run = Run(self.sweep_args(store, "--workers", "2"))
        at, killed = None, 0  # a random moment of the first 0.5 s after the first point is written
        while run.p.poll() is None and not killed:
            time.sleep(0.05)
            # the worker processes: spawned by the nannies, which run in the sweep's process
            try:
                workers = [c for c in psutil.Process(run.p.pid).children(recursive=True)
                           if "spawn_main" in " ".join(c.cmdline())]
            except psutil.Error:
                continue
            started = (store / "done").is_dir() and any(p.name[0].isdigit() for p in (store / "done").iterdir())
            if workers and started and at is None:
                at = time.monotonic() + self.rng.uniform(0.0, 0.5)
            if workers and at is not None and time.monotonic() >= at:
                self.rng.choice(workers).kill()
                killed = 1
        code, err = run.finish()
        why = crashed(code, err, {0, 1})
        if why:
            return Outcome(case, CRASH, why)
        if code == 1:  # the cluster did not start (one line): the rerun, in-process, must finish the store
            return self.finish_sweep(case, store, err.strip().splitlines()[-1][:100] + "; ")
        final = read_store(store)
        bad = ["unreadable"] if final is None else differing(final, self.reference, only_done=False)
        if bad:
            return Outcome(case, WRONG, f"differs in {bad}")
        return Outcome(case, OK, "a worker killed") if killed else Outcome(case, SKIPPED, "the sweep ended before the kill")

    def full_disk(self) -> Outcome:
        case = "full-disk"
        disk = self.fresh(case)
        disk.mkdir()
        mounted = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=256k", "tmpfs", str(disk)], capture_output=True, text=True)
        if mounted.returncode:
            return Outcome(case, SKIPPED, f"no tmpfs ({mounted.stderr.strip()[:100]}): needs root")
        try:
            store = disk / "s.zarr"
            # --large: past the size check (which refuses a store larger than the free space), into the full disk
            code, err = Run([*self.sweep_args(store), "--large"]).finish()
            why = crashed(code, err, {0, 1})
            if why:
                return Outcome(case, CRASH, why)
            loss = self.kept(case, store)
            if loss:
                return loss
            if code == 0:
                return self.finish_sweep(case, store, "it fitted; ")
            return Outcome(case, OK, "refused: " + err.strip().splitlines()[-1][:120])
        finally:
            subprocess.run(["umount", str(disk)], capture_output=True)

    # renders and fits -----------------------------------------------------------------------------

    def render_result(self, case: str, out: Path, before: str) -> Outcome | None:
        """A data loss or wrong result if ``out`` holds anything but nothing or the reference render."""
        names = {p.name for p in out.iterdir()} if out.exists() else set()
        if not names:
            return None
        if names != RENDER_FILES:
            return Outcome(case, LOSS, f"{before}half-written folder: {sorted(names)}")
        if (out / "radiance.exr").read_bytes() != self.radiance:
            return Outcome(case, WRONG, f"{before}radiance differs from the reference")
        return None

    def render_signal(self, how: str) -> Outcome:
        case, sig = f"render-{how}", SIGNAL_OF[how]
        out = self.fresh(case)
        at = self.moment(5.0)
        first, err = Run(self.render_args(out)).after(at, sig)
        why = crashed(first, err, {0, EXIT.get(sig, -sig), *BY_THE_SIGNAL.get(sig, ())})
        if why:
            return Outcome(case, CRASH, f"at {at:.1f} s: {why}")
        bad = self.render_result(case, out, f"at {at:.1f} s: ")
        if bad:
            return bad
        code, err = Run(self.render_args(out, "--overwrite")).finish()
        why = crashed(code, err, {0})
        if why:
            return Outcome(case, CRASH, f"rerun: {why}")
        return self.render_result(case, out, "rerun: ") or Outcome(case, OK, f"at {at:.1f} s: exit {first}")

    def file_size_limit(self) -> Outcome:
        case = "file-size-limit"
        out = self.fresh(case)
        code, err = Run(self.render_args(out), limit=16 * 1024).finish()
        why = crashed(code, err, {0, 1})
        if why:
            return Outcome(case, CRASH, why)
        return self.render_result(case, out, "") or Outcome(case, OK, (err.strip().splitlines() or ["exit 0"])[-1][:120])

    def fit_args(self, out: Path, *extra: str) -> list[str]:
        case = self.work / "fitcase"
        return ["fit", str(case / "ref.exr"), "--scene", str(case / "scene.toml"), "--free", "parts.body.alpha_x",
                "--out", str(out), "--quiet", "--max-steps", "12", *extra]

    def fit_kill(self) -> Outcome:
        case = "fit-kill"
        if self.fit_reference is None:
            self.make_fit_case()
        out = self.fresh(case)
        at = self.moment(self.fit_s)
        code, err = Run(self.fit_args(out)).after(at, signal.SIGKILL)
        if crashed(code, err, {-9, *self.fit_codes}):
            return Outcome(case, CRASH, f"at {at:.1f} s: {crashed(code, err, {-9, *self.fit_codes})}")
        resume = ("--resume",) if (out / "checkpoint.json").exists() else ()
        if code == -9:
            code, err = Run(self.fit_args(out, *resume, *(("--overwrite",) if (out / "fit.json").exists() and not resume else ()))).finish()
        why = crashed(code, err, set(self.fit_codes))
        if why:
            return Outcome(case, CRASH, f"killed at {at:.1f} s; {' '.join(resume)} rerun: {why}")
        got = json.loads((out / "fit.json").read_text())
        ref = self.fit_reference
        same = got["status"] == ref["status"] and all(
            abs(got["values"][k] - v) <= 1e-3 * abs(v) for k, v in ref["values"].items())
        detail = f"killed at {at:.1f} s, {'resumed' if resume else 'rerun'}: {got['status'][:40]}, {got['values']}"
        return Outcome(case, OK if same else WRONG, detail)

    def make_fit_case(self) -> None:
        """A reference image of the default scene with its body's roughness alpha_x at 0.3 and a scene starting at its default."""
        case = self.work / "fitcase"
        case.mkdir()
        code, err = Run(["render", "--out", str(case / "truth"), "--quiet", *self.sets, "--set", "parts.body.alpha_x=0.3"]).finish()
        assert code == 0, err
        shutil.copy(case / "truth" / "radiance.exr", case / "ref.exr")
        code, err = Run(["scene", "--out", str(case / "scene.toml"), *self.sets]).finish()
        assert code == 0, err
        t0 = time.monotonic()
        code, err = Run(self.fit_args(case / "reference-fit")).finish()
        self.fit_s = time.monotonic() - t0
        self.fit_codes = (0, 3, 4, 5, 6)
        assert code in self.fit_codes, err
        self.fit_reference = json.loads((case / "reference-fit" / "fit.json").read_text())


CASES: dict[str, Callable[[Soak], Outcome]] = {
    "sweep-kill": lambda s: s.sweep_signal("kill"),
    "sweep-int": lambda s: s.sweep_signal("int"),
    "sweep-term": lambda s: s.sweep_signal("term"),
    "render-kill": lambda s: s.render_signal("kill"),
    "render-int": lambda s: s.render_signal("int"),
    "render-term": lambda s: s.render_signal("term"),
    "fit-kill": Soak.fit_kill,
    "damaged-store": Soak.damaged_store,
    "concurrent": Soak.concurrent,
    "dask-worker-kill": Soak.dask_worker_kill,
    "full-disk": Soak.full_disk,
    "file-size-limit": Soak.file_size_limit,
}
# How often each case is drawn after the first round (every case runs once first).
WEIGHTS = {"sweep-kill": 6, "sweep-int": 2, "sweep-term": 2, "render-kill": 2, "render-int": 2, "render-term": 2,
           "fit-kill": 2, "damaged-store": 2, "concurrent": 2, "dask-worker-kill": 1, "full-disk": 1, "file-size-limit": 1}
QUICK = ("sweep-kill", "render-int", "full-disk")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--runs", type=int, help="number of cases (default: every case once, then random ones until --minutes)")
    p.add_argument("--minutes", type=float, default=10.0, help="time box of the whole soak (default 10)")
    p.add_argument("--quick", action="store_true", help=f"only {', '.join(QUICK)}, once each (about a minute)")
    p.add_argument("--case", action="append", choices=list(CASES), help="run only this case (repeatable; once each)")
    p.add_argument("--seed", type=int, default=0, help="random seed of the moments and choices")
    p.add_argument("--work", help="folder for the runs (default: a temporary one, removed after)")
    args = p.parse_args(argv)
    rng = random.Random(args.seed)
    work = Path(args.work) if args.work else Path(tempfile.mkdtemp(prefix="spacefit-soak-"))
    work.mkdir(parents=True, exist_ok=True)
    t0 = time.monotonic()
    try:
        soak = Soak(work, rng)
        order = list(args.case or (QUICK if args.quick else CASES))
        outcomes: list[Outcome] = []
        while True:
            if args.runs is not None and len(outcomes) >= args.runs:
                break
            if not order:
                if args.quick or args.case or (args.runs is None and time.monotonic() - t0 > 60 * args.minutes):
                    break
                order = rng.choices(list(WEIGHTS), weights=list(WEIGHTS.values()), k=1)
            name = order.pop(0)
            try:
                outcome = CASES[name](soak)
            except Exception as err:  # noqa: BLE001  (the soak's own failure is a crash it reports)
                outcome = Outcome(name, CRASH, f"soak: {type(err).__name__}: {err}")
            outcomes.append(outcome)
            print(f"{len(outcomes):4d} {outcome.case:<17} {outcome.kind:<13} {outcome.detail}", flush=True)
    finally:
        if not args.work:
            shutil.rmtree(work, ignore_errors=True)
    return report(outcomes, time.monotonic() - t0)


def report(outcomes: list[Outcome], seconds: float) -> int:
    """Print the counts; 1 if a data loss, wrong result or crash was counted."""
    counted = Counter(o.kind for o in outcomes)
    print(f"soak: {len(outcomes)} cases in {seconds / 60:.1f} min on {platform.node()} ({os.cpu_count()} cores), "
          f"{time.strftime('%Y-%m-%d')}: data loss {counted[LOSS]}, wrong results {counted[WRONG]}, crashes {counted[CRASH]}; "
          f"skipped {counted[SKIPPED]}")
    return 1 if any(counted[k] for k in COUNTED) else 0


if __name__ == "__main__":
    sys.exit(main())
