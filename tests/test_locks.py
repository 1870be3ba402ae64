"""One writer per store and output folder: locks held, broken when their holder died, kept when it
runs on another host; what a refused or killed run leaves (nothing), and write errors in one line."""

from __future__ import annotations

import errno
import json
import os
import re
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
from helpers import small_scene, write_sphere_obj

import spacefit as sf
from spacefit.cli import INTERRUPTED, main
from spacefit.locks import hold_lock, lock_file
from spacefit.output import STAGE_PREFIX, prepare_output, staged_output

HOLD = "import sys, time\nfrom spacefit.locks import hold_lock\nwith hold_lock(sys.argv[1]):\n    print('held', flush=True)\n    time.sleep(600)\n"


def listing(folder: Path) -> list[str]:
    return sorted(os.listdir(folder)) if folder.exists() else []


def dead_pid() -> int:
    return int(subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True).stdout)


def write_lock(folder: Path, **fields: object) -> Path:
    """A lock file as a process that did not release it leaves it."""
    record = {"pid": dead_pid(), "host": socket.gethostname(), "command": "spacefit sweep s.toml --out x", "started": 1.0e9, **fields}
    path = lock_file(folder)
    path.write_text(json.dumps(record))
    return path


def test_a_held_lock_refuses_a_second_writer_naming_it_and_a_killed_holder_is_broken(tmp_path):
    out = tmp_path / "out"
    holder = subprocess.Popen([sys.executable, "-c", HOLD, str(out)], stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline() == "held\n"
        with pytest.raises(sf.InputError, match=rf"`--out` '.*out' is in use by spacefit process {holder.pid} on host") as err:
            with hold_lock(out):
                pass
        assert "started" in str(err.value) and "hold_lock" in str(err.value)  # its start time and command line
    finally:
        holder.kill()  # SIGKILL: its lock file stays
        holder.wait()
    assert lock_file(out).exists()
    with pytest.warns(UserWarning, match=rf"broke the lock .* of spacefit process {holder.pid} .* which no longer runs"):
        with hold_lock(out) as path:
            assert json.loads(path.read_text())["pid"] == os.getpid()
    assert not lock_file(out).exists() and listing(tmp_path) == []  # released: nothing left


def test_a_render_into_a_folder_in_use_is_refused_and_changes_nothing(tmp_path, capsys):
    out = tmp_path / "out"
    out.mkdir()
    (out / "render.json").write_text(json.dumps({"versions": {"spacefit": "0.1.0"}}))  # a previous render
    holder = subprocess.Popen([sys.executable, "-c", HOLD, str(out)], stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline() == "held\n"
        assert main(["render", "--out", str(out), "--overwrite", "--quiet"]) == 2
    finally:
        holder.kill()
        holder.wait()
    err = capsys.readouterr().err
    assert err.startswith(f"spacefit: error: `--out` '{out}' is in use by spacefit process {holder.pid}") and len(err.splitlines()) == 1
    assert listing(out) == ["render.json"]


@pytest.mark.parametrize("target", ["file", "dangling", "fifo"])
def test_a_lock_file_that_is_a_link_or_a_pipe_is_refused_and_touches_nothing(tmp_path, capsys, target):
    """Issue 35's data loss: with the lock's name a symbolic link to a user's notes, a render replaced them
    with the lock's record. Now it exits 2 naming the link, and the notes, the link and the folder stay as they were."""
    notes = tmp_path / "my_notes.txt"
    notes.write_text("field notes\n")
    lock = tmp_path / ".symlock.spacefit-lock"
    if target == "fifo":
        os.mkfifo(lock)
    else:
        lock.symlink_to(notes if target == "file" else tmp_path / "gone.txt")
    before = listing(tmp_path)
    assert main(["render", "--out", str(tmp_path / "symlock"), "--quiet"]) == 2
    err = capsys.readouterr().err
    words = "is a symbolic link" if target != "fifo" else "is not a regular file"
    assert err.startswith(f"spacefit: error: the lock file '{lock}' of `--out` '{tmp_path / 'symlock'}' {words}") and len(err.splitlines()) == 1
    assert notes.read_text() == "field notes\n" and listing(tmp_path) == before
    assert not (tmp_path / "gone.txt").exists()


def test_a_stale_lock_of_this_host_is_broken_and_one_of_another_host_is_kept(tmp_path):
    store = tmp_path / "store.zarr"
    stale = write_lock(store)
    with pytest.warns(UserWarning, match=r"broke the lock .* of spacefit process \d+ on host .*spacefit sweep s.toml"):
        with hold_lock(store, "`store`"):
            pass
    # a PID that runs another process (started at another time) is a dead holder too
    write_lock(store, pid=os.getppid())
    with pytest.warns(UserWarning, match=rf"process {os.getppid()} .* no longer runs"):
        with hold_lock(store, "`store`"):
            pass
    other = write_lock(store, host="elsewhere.example", pid=os.getpid())
    with pytest.raises(sf.InputError, match=rf"locked by spacefit process {os.getpid()} on host 'elsewhere.example'.* "
                                            rf"remove '{re.escape(str(stale))}'"):
        with hold_lock(store, "`store`"):
            pass
    assert json.loads(other.read_text())["host"] == "elsewhere.example"  # not broken


def test_a_lock_of_a_live_process_is_never_broken_even_unlocked(tmp_path):
    """A lock file naming this very process (its PID and start time), without the system's lock on it."""
    import psutil

    write_lock(tmp_path / "out", pid=os.getpid(), started=psutil.Process().create_time())
    with pytest.raises(sf.InputError, match=rf"in use by spacefit process {os.getpid()}"):
        with hold_lock(tmp_path / "out"):
            pass


def test_without_file_system_locks_the_record_alone_decides(tmp_path, monkeypatch):
    """flock failing with ENOLCK (a network mount without locks): a live holder is still refused, a dead one broken."""
    import fcntl

    out = tmp_path / "out"
    holder = subprocess.Popen([sys.executable, "-c", HOLD, str(out)], stdout=subprocess.PIPE, text=True)
    assert holder.stdout.readline() == "held\n"

    def no_locks(fd: int, operation: int) -> None:
        raise OSError(errno.ENOLCK, "No locks available")

    monkeypatch.setattr(fcntl, "flock", no_locks)
    try:
        with pytest.raises(sf.InputError, match=rf"in use by spacefit process {holder.pid} .*did not lock"):
            with hold_lock(out):
                pass
    finally:
        holder.kill()
        holder.wait()
    with pytest.warns(UserWarning, match=rf"process {holder.pid} .* no longer runs"):
        with hold_lock(out):
            pass
    assert listing(tmp_path) == []


def test_the_lock_is_released_on_errors_and_interruptions(tmp_path):
    for error in (ValueError, KeyboardInterrupt):
        with pytest.raises(error):
            with hold_lock(tmp_path / "out"):
                raise error()
        assert listing(tmp_path) == []


@pytest.fixture
def slow_sweep(tmp_path) -> Path:
    """A sweep file of 200 points at 256 spp: minutes of work, points written every few tenths of a second."""
    mesh = write_sphere_obj(tmp_path / "sphere.obj", subdivisions=2)
    (tmp_path / "scene.toml").write_text(small_scene(mesh, {"material": "white_paint"}, render={"spp": 256}).to_toml())
    (tmp_path / "sweep.toml").write_text('scene = "scene.toml"\n[axes]\n"sun.elevation_deg" = {linspace = [10, 90, 200]}\n')
    return tmp_path / "sweep.toml"


def done_points(store: Path) -> int:
    return sum(1 for p in (store / "done").glob("*") if not p.name.startswith("."))


def test_overwrite_of_a_store_in_use_is_refused_and_the_first_sweep_keeps_its_points(slow_sweep, tmp_path):
    store = tmp_path / "s.zarr"
    command = [sys.executable, "-m", "spacefit.cli", "sweep", str(slow_sweep), "--out", str(store), "--quiet"]
    first = subprocess.Popen(command, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.time() + 180
        while (not store.exists() or done_points(store) < 2) and first.poll() is None and time.time() < deadline:
            time.sleep(0.05)
        before = done_points(store)
        second = subprocess.run([*command, "--overwrite"], capture_output=True, text=True, timeout=180)
        assert second.returncode == 2, second.stderr
        assert second.stderr.startswith(f"spacefit: error: `store` '{store}' is in use by spacefit process {first.pid} on host")
        assert len(second.stderr.splitlines()) == 1 and "--out" in second.stderr  # its command line
        assert first.poll() is None  # the first sweep goes on
        while done_points(store) <= before and time.time() < deadline:
            time.sleep(0.05)
    finally:
        first.send_signal(signal.SIGINT)
        _, err = first.communicate(timeout=120)
    assert first.returncode == INTERRUPTED, err
    ds = xr.open_zarr(store)
    finished = ds.done.values
    assert int(finished.sum()) > before and np.all(np.isfinite(ds.mean_radiance.values[finished]))
    assert not lock_file(store).exists()  # released on Ctrl-C


def test_a_stage_left_in_the_parent_by_a_killed_store_creation_is_removed(tmp_path):
    scene = small_scene(write_sphere_obj(tmp_path / "sphere.obj", subdivisions=1), {"material": "white_paint"},
                        render={"resolution": [8, 8], "spp": 1})
    store = tmp_path / "runs" / "s.zarr"
    store.parent.mkdir()
    pid = dead_pid()
    stale = store.parent / f"{STAGE_PREFIX}{pid}-x1y2-s.zarr"
    other = store.parent / f"{STAGE_PREFIX}{pid}-x1y2-other.zarr"  # another store's: not this sweep's to judge
    for stage in (stale, other):
        (stage / "store").mkdir(parents=True)
    with pytest.warns(UserWarning, match=rf"removed .*{stale.name}"):
        sf.sweep(scene, {"parts.sphere.kd": [0.5]}, store=store, quiet=True)
    assert listing(store.parent) == sorted([other.name, "s.zarr"])


@pytest.mark.parametrize("address", ["foo://x:1", "tcp://127.0.0.1:1", "nohost"])
def test_a_refused_scheduler_leaves_nothing(slow_sweep, tmp_path, capsys, address):
    before = listing(tmp_path)
    assert main(["sweep", str(slow_sweep), "--out", str(tmp_path / "s.zarr"), "--scheduler", address, "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"spacefit: error: `scheduler` {address!r}") and len(err.splitlines()) == 1
    assert listing(tmp_path) == before


def test_overwrite_refusal_names_only_the_foreign_files(tmp_path, capsys):
    out = tmp_path / "out"
    out.mkdir()
    for name in ("fit.json", "comparison.png", "notes.txt"):
        (out / name).write_text("x")
    assert main(["render", "--out", str(out), "--overwrite", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "did not write (comparison.png, fit.json, notes.txt)" in err  # a fit's files are not a render's
    (out / "render.json").write_text("{}")
    for name in ("fit.json", "comparison.png"):
        (out / name).unlink()
    with pytest.raises(sf.InputError, match=r"did not write \(notes.txt, render.json\)"):
        prepare_output(out, "fit", overwrite=True)
    earlier = tmp_path / "earlier"  # a fit's folder of spacefit before residuals.png became comparison.png's third column
    earlier.mkdir()
    (earlier / "fit.json").write_text('{"versions": {"spacefit": "0.1"}}')
    (earlier / "residuals.png").write_text("x")
    assert prepare_output(earlier, "fit", overwrite=True) == earlier


# spacefit's command line under a file-size limit of 150 kB (`ulimit -f`); Python ignores SIGXFSZ, so a write past it fails
LIMITED = ("import resource, runpy\nresource.setrlimit(resource.RLIMIT_FSIZE, (150_000, 150_000))\n"
           "runpy.run_module('spacefit.cli', run_name='__main__')\n")


def test_a_write_past_the_file_size_limit_is_one_line_and_leaves_nothing(tmp_path):
    # radiance.exr is 260 kB, over the limit; every other file a render writes (the caches' too) is under it
    scene = small_scene(write_sphere_obj(tmp_path / "sphere.obj", subdivisions=3), {"material": "white_paint", "kd": 0.5},
                        render={"resolution": [512, 512], "spp": 1})
    (tmp_path / "scene.toml").write_text(scene.to_toml())
    out = tmp_path / "out"
    run = subprocess.run([sys.executable, "-c", LIMITED, "render", str(tmp_path / "scene.toml"), "--out", str(out), "--quiet"],
                         capture_output=True, text=True, timeout=300)
    assert run.returncode == 1, run.stderr
    assert run.stderr.splitlines() == [f"spacefit: error: file system error on '{out / 'radiance.exr'}': File too large "
                                       "(past the file-size limit, ulimit -f)."]
    assert listing(tmp_path) == ["scene.toml", "sphere.obj"]
    # a sweep's store: the point whose image chunk failed is not done, and a rerun finishes it
    (tmp_path / "sweep.toml").write_text('scene = "scene.toml"\nimages = true\n[axes]\n"parts.sphere.kd" = [0.3, 0.5]\n')
    arguments = ["sweep", str(tmp_path / "sweep.toml"), "--out", str(tmp_path / "s.zarr"), "--quiet"]
    run = subprocess.run([sys.executable, "-c", LIMITED, *arguments], capture_output=True, text=True, timeout=300)
    assert run.returncode == 1 and run.stderr.splitlines() == [
        f"spacefit: error: file system error on '{tmp_path / 's.zarr'}': File too large (past the file-size limit, ulimit -f)."]
    assert subprocess.run([sys.executable, "-m", "spacefit.cli", *arguments], capture_output=True, text=True, timeout=300).returncode == 0
    assert bool(xr.open_zarr(tmp_path / "s.zarr").done.all())


@pytest.mark.parametrize(("error", "named"), [
    (lambda stage: OSError(errno.EFBIG, "File too large", str(stage / "residuals.fits")), "residuals.fits"),
    (lambda stage: OSError(errno.ENOSPC, "No space left on device"), ""),  # a writer that names no file: the folder
])
def test_a_write_error_names_the_output_file_not_its_stage(tmp_path, error, named):
    out = tmp_path / "out"
    with pytest.raises(OSError) as raised:
        with staged_output(out) as stage:
            (stage / "fit.json").write_text("{}")
            raise error(stage)
    assert raised.value.filename == str(out / named if named else out) and raised.value.errno == error(out).errno
    assert listing(tmp_path) == []


def test_this_process_as_a_holder_is_what_psutil_reads_of_it():
    """A render records its start time and command line without importing psutil; another process reads them
    back through psutil (Holder.runs), so the two must agree (within the start-time tolerance, here exactly)."""
    import shlex

    import psutil

    from spacefit.errors import shorten
    from spacefit.locks import START_TOLERANCE_S, this_process

    me, process = this_process(), psutil.Process()
    assert abs(me.started - process.create_time()) < START_TOLERANCE_S / 100
    assert me.command == shorten(" ".join(shlex.join(process.cmdline()).split()), 300)
    assert me.host == socket.gethostname() and me.pid == os.getpid() and me.runs()


def test_a_holder_psutil_may_not_inspect_is_taken_to_run_and_its_lock_kept(tmp_path, monkeypatch):
    """A lock whose holder's process exists but psutil is denied reading (another user's, under a
    hardened /proc): refused as in use, never broken, the lock file unchanged."""
    import psutil

    path = write_lock(tmp_path / "out")
    before = path.read_bytes()

    def denied(pid: int) -> None:
        raise psutil.AccessDenied(pid)

    monkeypatch.setattr(psutil, "Process", denied)
    with pytest.raises(sf.InputError, match=r"`--out` '.*out' is in use by spacefit process \d+ on host"):
        with hold_lock(tmp_path / "out"):
            pass
    assert path.read_bytes() == before and listing(tmp_path) == [path.name]


def test_every_spelling_of_a_folder_shares_its_lock(tmp_path):
    """The folder named through a symlink, and through a/../ where a is a symlink elsewhere (the system
    follows a before ..), takes the lock of the folder itself."""
    real = tmp_path / "deep" / "data" / "out"
    real.parent.mkdir(parents=True)
    (tmp_path / "link").symlink_to(real)
    (tmp_path / "a").symlink_to(tmp_path / "deep" / "data" / "sub", target_is_directory=True)
    (tmp_path / "deep" / "data" / "sub").mkdir()
    spellings = [tmp_path / "link", tmp_path / "a" / ".." / "out", tmp_path / "deep" / "." / "data" / "out"]
    with hold_lock(real):
        for spelling in spellings:
            assert lock_file(spelling) == lock_file(real)
            with pytest.raises(sf.InputError, match="is in use by spacefit process"):
                with hold_lock(spelling):
                    pass
    assert listing(real.parent) == ["sub"]  # released: nothing left
