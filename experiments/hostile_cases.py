"""Issue 35's hostile cases rerun as a user meets them, each judged and counted (``make soak`` runs it).

Every case is what a hostile run found on an earlier commit (the lock through a symbolic link, the
damaged caches and stores, the input slips, the caller's Mitsuba variant, the dependency warnings),
done through the public API or the command line in this process, in a scratch folder. Each ends as:

- ``ok``: a refusal is one line of ``sf.InputError`` (exit 2 on the command line) and leaves every
  file as it was; a valid input is accepted with the right value;
- **data loss**: a file that was there before (the user's, or a store's data) changed or went;
- **wrong accepted**: a slip accepted, or a damaged input passed as sound;
- **crash**: any other exception, a traceback, or an exit code the README does not promise;
- **unclear**: refused, but in more than one line or with files left behind.

The exit status is 1 when anything but ``ok`` was counted. The soak (``tools/soak.py``) covers the
signals, kills, full disks and dying workers; ``experiments/fit_memory.py`` the memory per fit.

Usage: python experiments/hostile_cases.py
"""

from __future__ import annotations

import contextlib
import datetime
import io
import os
import platform
import subprocess
import sys
import tempfile
import warnings
from collections import Counter
from collections.abc import Callable
from pathlib import Path

import mitsuba as mi
import numpy as np
from astropy.io import fits
from studyio import commit

import spacefit as sf
from spacefit.cli import DAMAGED, main

PANELS = Path(__file__).resolve().parents[1] / "spacefit" / "synthetic" / "panels.toml"
OK, LOSS, WRONG, CRASH, UNCLEAR = "ok", "data loss", "wrong accepted", "crash", "unclear"
TINY = {"render.resolution": [32, 32], "render.spp": 4, "camera.pixel_pitch_mm": 42.0}  # the whole lander in 32 px


def snapshot(folder: Path) -> dict[str, bytes | str]:
    """Every entry under ``folder``: a file's bytes, a link's target."""
    out: dict[str, bytes | str] = {}
    for path in sorted(folder.rglob("*")):
        key = str(path.relative_to(folder))
        out[key] = f"-> {os.readlink(path)}" if path.is_symlink() else (path.read_bytes() if path.is_file() else "dir")
    return out


def compare(before: dict[str, bytes | str], after: dict[str, bytes | str]) -> str | None:
    """LOSS if an entry of ``before`` changed or went, UNCLEAR if new ones appeared, else None."""
    if any(after.get(k) != v for k, v in before.items()):
        return LOSS
    return UNCLEAR if set(after) - set(before) else None


def refused(folder: Path, call: Callable[[], object], words: str) -> tuple[str, str]:
    """A call that must raise a one-line ``sf.InputError`` containing ``words`` and change nothing."""
    before = snapshot(folder)
    try:
        call()
    except sf.InputError as e:
        text = str(e)
        changed = compare(before, snapshot(folder))
        if changed:
            return changed, text
        return (OK if words in text and len(text.splitlines()) == 1 else UNCLEAR), text
    except Exception as e:  # noqa: BLE001 - any other exception is the crash being counted
        return CRASH, f"{type(e).__name__}: {e}"
    return compare(before, snapshot(folder)) or WRONG, "accepted"


def command(folder: Path, args: list[str], code: int, words: str) -> tuple[str, str]:
    """A command line that must exit ``code`` saying ``words`` (on stderr or stdout), every file of
    ``folder`` that was there before unchanged; a refusal (exit 2) in one line that writes nothing."""
    before = snapshot(folder)
    err, out = io.StringIO(), io.StringIO()
    try:
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(out):
            got = main(args)
    except SystemExit as e:  # argparse's own refusals
        got = e.code
    except Exception as e:  # noqa: BLE001
        return CRASH, f"{type(e).__name__}: {e}"
    errors, said = err.getvalue().strip(), (err.getvalue() + out.getvalue()).strip()
    if "Traceback" in errors:
        return CRASH, errors.splitlines()[-1]
    changed = compare(before, snapshot(folder))
    if changed == LOSS:
        return LOSS, said
    if got == 0 and code != 0:
        return WRONG, f"exit 0: {said[-200:]}"
    if got != code:
        return CRASH, f"exit {got}: {said[-200:]}"
    refusal_kept = code != 2 or (len(errors.splitlines()) <= 1 and not changed)
    return (OK if words in said and refusal_kept else UNCLEAR), said.splitlines()[-1] if said else ""


def sweep_store(folder: Path) -> Path:
    """A finished store of a 4-point sweep of a tiny scene."""
    store = folder / "store.zarr"
    sf.sweep(sf.default_scene().with_values(TINY), {"parts.legs.kd": [0.3, 0.6], "render.seed": [1, 2]}, store=store, quiet=True)
    return store


# --- the cases ------------------------------------------------------------------------------------------


def lock_through_a_link(tmp: Path) -> tuple[str, str]:
    notes = tmp / "my_notes.txt"
    notes.write_text("field notes\n")
    (tmp / ".symlock.spacefit-lock").symlink_to(notes)
    return command(tmp, ["render", "--out", str(tmp / "symlock"), "--quiet"], 2, "is a symbolic link")


def out_a_dangling_link(tmp: Path) -> tuple[str, str]:
    (tmp / "out").symlink_to(tmp / "nowhere")
    return command(tmp, ["render", "--out", str(tmp / "out"), "--quiet"], 2, "is a symbolic link")


def fits_file(tmp: Path, header: dict, compressed: bool = False) -> Path:
    path = tmp / "frame.fits"
    data = np.full((32, 32), 100, np.uint16)
    if compressed:
        fits.HDUList([fits.PrimaryHDU(), fits.CompImageHDU(data, fits.Header(header), compression_type="RICE_1")]).writeto(path)
    else:
        fits.PrimaryHDU(data, fits.Header(header)).writeto(path)
    return path


def fits_gain(value: float) -> Callable[[Path], tuple[str, str]]:
    def case(tmp: Path) -> tuple[str, str]:
        path = fits_file(tmp, {"EXPTIME": 0.01, "GAIN": value, "RDNOISE": 2.0})
        return refused(tmp, lambda: sf.Observation.from_file(path, sf.default_scene().with_values(TINY), sensor_defaults="illustrative"),
                       "GAIN")
    return case


def rice_fits_is_read(tmp: Path) -> tuple[str, str]:
    path = fits_file(tmp, {"EXPTIME": 0.01, "GAIN": 2.0, "RDNOISE": 2.0}, compressed=True)
    try:
        obs = sf.Observation.from_file(path, sf.default_scene().with_values(TINY), sensor_defaults="illustrative")
    except sf.InputError as e:
        return WRONG, f"a valid file refused: {e}"
    except Exception as e:  # noqa: BLE001
        return CRASH, f"{type(e).__name__}: {e}"
    return (OK if np.all(np.asarray(obs.reference) == 100) else WRONG), "read"


def brdf_table(value: str) -> Callable[[Path], tuple[str, str]]:
    def case(tmp: Path) -> tuple[str, str]:
        rows = ["theta_i_deg,phi_i_deg,theta_o_deg,phi_o_deg,brdf_sr", "10,180,10,0,0.05", f"20,180,20,0,{value}", "30,180,30,0,0.04"]
        (tmp / "slip.csv").write_text("\n".join(rows) + "\n")
        return refused(tmp, lambda: sf.read_brdf_table(tmp / "slip.csv"), "row 2")
    return case


def missing_brdf_table(tmp: Path) -> tuple[str, str]:
    return refused(tmp, lambda: sf.read_brdf_table(tmp / "nowhere.csv"), "no BRDF table file")


def pass_from_none(tmp: Path) -> tuple[str, str]:
    return refused(tmp, lambda: sf.Pass.read(None), "`path` must be a path")


def frame_twice(column: str) -> Callable[[Path], tuple[str, str]]:
    files, times = (["a.exr", "b.exr", "a.exr"], [0.0, 10.0, 20.0]) if column == "file" else (["a.exr", "b.exr", "c.exr"], [0.0, 10.0, 10.0])
    return lambda tmp: refused(tmp, lambda: sf.Pass.from_columns({"file": files, "time": times}, tmp), "same")


def sun_given_twice(tmp: Path) -> tuple[str, str]:
    both = {"sun.direction": [0.0, 0.0, -1.0], "sun.elevation_deg": 30.0, "sun.azimuth_deg": 10.0}
    return refused(tmp, lambda: sf.default_scene().with_values(both), "`sun.direction` and both")


def sun_given_twice_in_a_file(tmp: Path) -> tuple[str, str]:
    (tmp / "scene.toml").write_text("[sun]\ndirection = [0.0, 0.0, -1.0]\nelevation_deg = 30.0\nazimuth_deg = 10.0\n")
    return refused(tmp, lambda: sf.load_scene(tmp / "scene.toml"), "`sun.direction` and both")


def exposure(value: float) -> Callable[[Path], tuple[str, str]]:
    return lambda tmp: refused(tmp, lambda: sf.Sensor(exposure_time_s=value), "exposure_time_s")


def store_damage(kind: str) -> Callable[[Path], tuple[str, str]]:
    def case(tmp: Path) -> tuple[str, str]:
        store = sweep_store(tmp)
        if kind == "coordinate flipped":
            chunk = next((store / "parts.legs.kd").glob("[0-9]*"))
            chunk.write_bytes(bytes([chunk.read_bytes()[0] ^ 1]) + chunk.read_bytes()[1:])
        elif kind == "coordinate deleted":
            next((store / "render.seed").glob("[0-9]*")).unlink()
        elif kind == "points swapped":
            for variable in ("mean_radiance", "pixels", "irradiance", "checksum"):
                suffix = "" if variable == "checksum" else ".0"
                a, b = store / variable / f"0.0{suffix}", store / variable / f"1.1{suffix}"
                first, second = a.read_bytes(), b.read_bytes()
                a.write_bytes(second)
                b.write_bytes(first)
        else:  # a .zarray that is not UTF-8
            path = store / "mean_radiance" / ".zarray"
            path.write_bytes(b"\xff\xfe" + path.read_bytes()[2:])
            return command(store, ["sweep", str(store), "--verify"], 2, "is damaged")
        return command(store, ["sweep", str(store), "--verify"], DAMAGED,
                       "failed their checksum" if kind == "points swapped" else "damaged coordinates")
    return case


def damaged_syntax_cache(kind: str) -> Callable[[Path], tuple[str, str]]:
    """A derivative render with every cached rewrite damaged (a flipped bit, or another function's valid
    code under each name) must equal the clean cache's, in a fresh process each (the cache is per process)."""
    script = ("import numpy as np, spacefit as sf; s = sf.default_scene().with_values({'render.resolution': [32, 32], 'render.spp': 4, 'camera.pixel_pitch_mm': 42.0}); "
              "j = sf.jacobian(s, ['parts.panels.alpha_x']); print(repr(float(np.abs(np.asarray(j.columns['parts.panels.alpha_x'])).sum())))")

    def run(cache: Path) -> subprocess.CompletedProcess:
        env = {**os.environ, "SPACEFIT_CACHE_DIR": str(cache), "PYTHONPATH": str(Path(__file__).resolve().parents[1])}
        return subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, env=env, timeout=600)

    def case(tmp: Path) -> tuple[str, str]:
        clean = run(tmp / "cache")
        if clean.returncode != 0:
            return CRASH, f"the clean run failed: {clean.stderr.strip().splitlines()[-1:]}"
        entries = sorted(p for p in (tmp / "cache").rglob("*") if p.is_file())
        if not entries:
            return UNCLEAR, "no cache entry written"
        if kind == "bit flips":
            for p in entries:
                data = bytearray(p.read_bytes())
                data[len(data) // 2] ^= 0x10
                p.write_bytes(bytes(data))
        else:
            donor = entries[0].read_bytes()
            for p in entries[1:]:
                p.write_bytes(donor)
        damaged = run(tmp / "cache")
        if damaged.returncode != 0:
            return CRASH, f"exit {damaged.returncode}: {damaged.stderr.strip().splitlines()[-1:]}"
        same = damaged.stdout.strip().splitlines()[-1] == clean.stdout.strip().splitlines()[-1]
        return (OK if same else WRONG), f"{len(entries)} entries damaged; jacobian sum {damaged.stdout.strip()} vs {clean.stdout.strip()}"
    return case


def caller_variant(tmp: Path) -> tuple[str, str]:
    truth = 0.5  # the legs' albedo in the panels case, seen at 32 px; the reference at other seeds
    scene = sf.load_scene(PANELS, {"render.resolution": [32, 32], "camera.pixel_pitch_mm": 75.0})
    reference = np.asarray(sf.render(scene.with_values({"render.spp": 256, "render.seed": 99})))
    before = mi.variant()
    mi.set_variant("scalar_rgb")
    try:
        result = sf.fit([sf.Observation(scene, reference, sigma=0.01)], ["parts.legs.kd"], start={"parts.legs.kd": 0.3}, max_steps=10)
        kept = mi.variant() == "scalar_rgb"
    except Exception as e:  # noqa: BLE001
        return CRASH, f"{type(e).__name__}: {e}"
    finally:
        mi.set_variant(before or "llvm_ad_rgb")
    got, error = result.values["parts.legs.kd"], result.stderr["parts.legs.kd"]
    right = result.status.success and abs(got - truth) < 3 * error
    return (OK if kept and right else WRONG), f"{result.status.name}, kd {got:.4f} +- {error:.4f} (truth {truth}), variant kept: {kept}"


def dates_past_the_leap_second_table(tmp: Path) -> tuple[str, str]:
    path = tmp / "frames.csv"
    path.write_text("file,time\na.fits,2035-06-01T00:00:00\nb.fits,2035-06-01T00:00:10\n")
    with warnings.catch_warnings(record=True) as seen:  # every warning, not only the first of each place
        warnings.simplefilter("always")
        try:
            frames = sf.Pass.read(path)
        except Exception as e:  # noqa: BLE001
            return CRASH, f"{type(e).__name__}: {e}"
    times = [f.time_s for f in frames.frames]
    exact = times[1] - times[0] == 10.0
    return (OK if not seen and exact else UNCLEAR), f"{len(seen)} warnings; frame spacing {times[1] - times[0]!r} s"


CASES: dict[str, Callable[[Path], tuple[str, str]]] = {
    "lock file a link to the user's notes": lock_through_a_link,
    "--out a dangling link": out_a_dangling_link,
    "FITS GAIN = 0": fits_gain(0.0),
    "FITS GAIN < 0": fits_gain(-2.0),
    "Rice tile-compressed FITS (valid)": rice_fits_is_read,
    "BRDF table value 1e30": brdf_table("1e30"),
    "BRDF table value negative": brdf_table("-0.5"),
    "BRDF table missing": missing_brdf_table,
    "Pass.read(None)": pass_from_none,
    "pass lists a file twice": frame_twice("file"),
    "pass lists a time twice": frame_twice("time"),
    "sun as angles and direction (values)": sun_given_twice,
    "sun as angles and direction (file)": sun_given_twice_in_a_file,
    "exposure 1e300 s": exposure(1e300),
    "exposure 0 s": exposure(0.0),
    "store: coordinate chunk flipped": store_damage("coordinate flipped"),
    "store: coordinate chunk deleted": store_damage("coordinate deleted"),
    "store: two points swapped with checksums": store_damage("points swapped"),
    "store: .zarray not UTF-8": store_damage("zarray"),
    "syntax cache: a bit flipped in every entry": damaged_syntax_cache("bit flips"),
    "syntax cache: another function's code in every entry": damaged_syntax_cache("other code"),
    "caller's variant scalar_rgb, then a fit": caller_variant,
    "pass dated past the leap-second table": dates_past_the_leap_second_table,
}


def run_cases() -> Counter:
    """Run every case in a scratch folder of its own; print each outcome and return the counts."""
    counts: Counter = Counter()
    for name, case in CASES.items():
        with tempfile.TemporaryDirectory() as tmp:
            outcome, detail = case(Path(tmp))
        counts[outcome] += 1
        print(f"{outcome:>14}  {name}: {detail[:160]}", flush=True)
    return counts


def main_() -> int:
    print(f"{datetime.datetime.now(datetime.timezone.utc):%Y-%m-%d %H:%M} UTC, commit {commit()}, {platform.processor() or platform.machine()}, "
          f"{os.cpu_count()} CPUs, load {os.getloadavg()[0]:.1f}", flush=True)
    counts = run_cases()
    print(f"{sum(counts.values())} cases: " + ", ".join(f"{k} {counts[k]}" for k in (OK, LOSS, WRONG, CRASH, UNCLEAR)))
    return 0 if counts[OK] == sum(counts.values()) else 1


if __name__ == "__main__":
    sys.exit(main_())
