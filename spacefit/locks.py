"""One writer per output folder and per sweep store: a lock that a dead process does not hold forever.

The lock of a folder or store ``NAME`` is the file ``.NAME.spacefit-lock`` beside it, in its parent:
the same file whether the folder exists yet or not, and kept when ``--overwrite`` replaces a store
whole (the parent must be writable; a store is made there in any case). It holds the holder's PID,
host, command line and start time, and the holder keeps an exclusive ``flock`` on it, which the
system lets go however the process ends (on a file system without locks, the record alone
decides). A second writer is refused at once, naming the holder. A
lock left by a killed process (SIGKILL) of this host, whose PID no longer runs (or runs another
program: its start time differs), is broken by the next writer with a warning naming the dead
process; one of another host is never broken (this host cannot tell whether it runs): the message
names its host and PID and the file to remove once it has stopped.
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import functools
import inspect
import json
import os
import platform
import shlex
import stat
import sys
import warnings
from collections.abc import Callable, Iterator
from dataclasses import asdict, dataclass
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, TypeVar

from spacefit.errors import InputError, InputTypeError, quote, shorten

LOCK_SUFFIX = ".spacefit-lock"
# Two processes' start times as psutil reads them differ by more than this: the same PID, another process.
START_TOLERANCE_S = 1.0
F = TypeVar("F", bound=Callable[..., Any])
# flock's errors on a file system that has no locks.
NO_LOCKS = (errno.ENOLCK, errno.EOPNOTSUPP, errno.ENOTSUP)


@dataclass(frozen=True)
class Holder:
    """The process that holds a lock: PID, host name, command line and start time (s since the epoch)."""

    pid: int
    host: str
    command: str
    started: float

    def describe(self) -> str:
        """The holder in words: PID, host, start time (UTC) and command line."""
        when = datetime.fromtimestamp(self.started, timezone.utc).strftime("%Y-%m-%d %H:%M:%S UTC")
        return f"spacefit process {self.pid} on host {self.host!r} (started {when}: {self.command})"

    def runs(self) -> bool:
        """Whether the holder, a process of this host, still runs: its PID is alive, not a zombie, and
        started when the lock says (a PID reused by another process started later)."""
        import psutil  # here: only a lock found held needs it

        try:
            process = psutil.Process(self.pid)
            return (process.status() != psutil.STATUS_ZOMBIE
                    and abs(process.create_time() - self.started) < START_TOLERANCE_S)
        except psutil.NoSuchProcess:
            return False
        except psutil.AccessDenied:
            return True


def this_process() -> Holder:
    """This process as a lock's holder: its command line as it was started (``sys.orig_argv``, what
    psutil reads from the system) and its start time (:func:`start_time`)."""
    command = " ".join(shlex.join(sys.orig_argv).split())  # on one line: messages are one line
    return Holder(os.getpid(), platform.node(), shorten(command, 300), start_time())  # node: the host name, as gethostname


def start_time() -> float:
    """This process's start time (s since the epoch) as psutil's ``create_time`` gives it, which
    :meth:`Holder.runs` compares. On Linux it is computed as psutil computes it, the boot time plus the
    process's start in clock ticks (``/proc``), so that a render need not import psutil (0.011 s)."""
    try:
        with open("/proc/self/stat") as f:
            ticks = int(f.read().rsplit(")", 1)[1].split()[19])  # field 22, after the command's parentheses
        with open("/proc/stat") as f:
            boot = next(int(line.split()[1]) for line in f if line.startswith("btime "))
        return boot + ticks / os.sysconf("SC_CLK_TCK")
    except (OSError, ValueError, IndexError, StopIteration):  # not Linux
        import psutil

        return psutil.Process().create_time()


def lock_file(folder: str | Path) -> Path:
    """The lock file of ``folder``: ``.NAME.spacefit-lock`` beside it (its path resolved, so that every
    spelling of a folder shares one lock)."""
    resolved = Path(folder).resolve()
    return resolved.parent / f".{resolved.name}{LOCK_SUFFIX}"


def is_lock_file(name: str) -> bool:
    """Whether a file name is a spacefit lock's."""
    return name.startswith(".") and name.endswith(LOCK_SUFFIX)


def _read(fd: int) -> Holder | None:
    """The holder a lock file names, or None when it is empty or unreadable."""
    try:
        return Holder(**json.loads(os.pread(fd, 65536, 0).decode()))
    except (ValueError, TypeError, UnicodeDecodeError):
        return None


def _is_file_at(fd: int, path: Path) -> bool:
    """Whether the open file ``fd`` is still the file at ``path`` (a releasing holder removes it)."""
    try:
        return os.path.samestat(os.fstat(fd), os.lstat(path))
    except FileNotFoundError:
        return False


def _open_lock(path: Path, what: str) -> int:
    """Open (or create) the lock file ``path`` without following a symbolic link or opening anything but a
    regular file: a lock never writes through a link into a user's file, nor into a device or a pipe.

    Raises:
        InputError: ``path`` is a symbolic link or not a regular file, naming it and what to do.
    """
    try:
        fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW | os.O_NONBLOCK, 0o644)
    except OSError as err:
        if err.errno != errno.ELOOP:
            raise
        raise InputError(f"the lock file {str(path)!r} of {what} is a symbolic link (to {os.readlink(path)!r}); spacefit never "
                         "writes a lock through a link: remove the link and run again.") from None
    if not stat.S_ISREG(os.fstat(fd).st_mode):
        os.close(fd)
        raise InputError(f"the lock file {str(path)!r} of {what} is not a regular file; remove it and run again.")
    return fd


def _take(path: Path, what: str) -> int:
    """Open and lock ``path`` (refusing when another process holds it, breaking it when its holder
    died), write this process into it and return its descriptor."""
    while True:
        fd = _open_lock(path, what)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = _read(fd)
            os.close(fd)
            raise InputError(f"{what} is in use by {holder.describe() if holder else 'another spacefit process'}; "
                             "wait for it to end or stop it, or choose another folder.") from None
        except OSError as err:
            if err.errno not in NO_LOCKS:
                os.close(fd)
                raise
            # a file system without locks (some network mounts): the record alone decides, below
        if _is_file_at(fd, path):
            break
        os.close(fd)  # its holder removed it as we opened it: take the new one
    try:
        previous, me = _read(fd), this_process()
        if previous is not None and previous.host != me.host:
            raise InputError(f"{what} is locked by {previous.describe()}; this host cannot tell whether it still runs. "
                             f"Once it has stopped, remove {str(path)!r} and run again.")
        if previous is not None and previous.runs():
            raise InputError(f"{what} is in use by {previous.describe()} (the file system did not lock {str(path)!r}); "
                             "wait for it to end or stop it, or choose another folder.")
        if previous is not None:
            warnings.warn(f"broke the lock {str(path)!r} of {previous.describe()}, which no longer runs.", stacklevel=2)
        elif os.fstat(fd).st_size:
            warnings.warn(f"replaced the unreadable lock file {str(path)!r}, which no process held.", stacklevel=2)
        os.ftruncate(fd, 0)
        os.pwrite(fd, json.dumps(asdict(me)).encode(), 0)
    except BaseException:
        os.close(fd)
        raise
    return fd


@contextlib.contextmanager
def hold_lock(folder: str | Path, name: str = "`--out`") -> Iterator[Path]:
    """Hold the lock of ``folder`` (a folder or a store, existing or not) while the block runs; yield
    the lock file. On every exit (an error, Ctrl-C) the lock is released and its file removed.
    ``name`` is the folder's argument as messages name it.

    Raises:
        InputError: ``folder`` is not a path, blank, a file, or in use by another process (named: PID, host,
            start time and command), or its lock's folder is not writable.
    """
    if not isinstance(folder, (str, os.PathLike)):
        raise InputTypeError(f"{name} must be a folder's path, got {quote(folder)}.")
    if not str(folder).strip():
        raise InputError(f"{name} must name a folder, got an empty string.")
    target = Path(folder)
    what = f"{name} {str(target)!r}"
    if target.exists() and not target.is_dir():
        raise InputError(f"{what} exists and is not a folder.")
    path = lock_file(target)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd = _take(path, what)
    except OSError as err:
        raise InputError(f"{what} cannot be locked: {str(path)!r} is not writable ({err.strerror}).") from None
    try:
        yield path
    finally:
        if _is_file_at(fd, path):
            path.unlink()
        os.close(fd)


def holding_lock(argument: str) -> Callable[[F], F]:
    """Run the decorated function holding the lock (:func:`hold_lock`) of the output folder its
    argument ``argument`` names."""

    def decorate(function: F) -> F:
        signature = inspect.signature(function)

        @functools.wraps(function)
        def locked(*args: Any, **kwargs: Any) -> Any:
            with hold_lock(signature.bind(*args, **kwargs).arguments[argument]):
                return function(*args, **kwargs)

        return locked  # type: ignore[return-value]

    return decorate
