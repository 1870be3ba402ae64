"""Where work runs: this process or a dask.distributed cluster, named by one ``cluster=`` argument.

Fits (:func:`fit`), sweeps (:func:`spacefit.sweep`) and light curves (:func:`spacefit.light_curve`)
take the same ``cluster``: None, this process; an int N, a new local cluster of N single-threaded
worker processes (closed when the work ends); a scheduler's address (``tcp://host:8786``); or a
``distributed.Client`` of the caller's (left open; a subclass's too). :func:`check_cluster` refuses
anything else before work starts, in one line (:func:`cluster_of` checks a function's ``cluster`` and
its deprecated spellings), :func:`connect` opens it, and an :class:`Executor` runs one function per item in a fixed
order: :class:`InProcess` one after another here, :class:`OnDask` all at once on the workers, each item
sent back to the worker that ran it last (a soft placement: a lost worker's items run elsewhere).

This module imports dask.distributed only when a cluster is asked for (it takes seconds to import).
"""

from __future__ import annotations

import logging
import socket
import warnings
from collections.abc import Callable, Mapping, Sequence
from typing import Any, Protocol

import numpy as np

from spacefit.errors import InputError, InputTypeError, check_count, quote

# What a ``cluster`` argument may be: None, a worker count, a scheduler address, a ``distributed.Client``.
Cluster = int | str | Any
# dask.distributed's schemes for a scheduler's address (an address without one is tcp://); inproc://
# is a scheduler in this process (``LocalCluster(processes=False)``'s).
SCHEDULER_SCHEMES = ("tcp", "tls", "ws", "wss", "ucx", "inproc")
# The schemes whose scheduler a check cannot reach with a TCP connection (it is left to the client).
UNPROBED_SCHEMES = ("ucx", "inproc")
# How long a check waits for a scheduler to accept a connection (s).
PROBE_TIMEOUT_S = 5.0
# How long a batch waits for a worker when the cluster has none (s).
WAIT_FOR_WORKERS_S = 120.0
# How long closing a local cluster may take (s): workers that keep dying must not hold the caller.
CLOSE_S = 20.0
CLUSTER_WORDS = "None, a number of local workers, a scheduler address or a dask Client"


class ClusterError(RuntimeError):
    """Work on dask that cannot go on, in one line (the CLI exits 1): a point whose worker died more
    than its retry budget allows, naming the point and the likely cause, or no point finished for the
    stated time. Everything finished before it is kept.

    A ``RuntimeError``: not a bad input but a cluster that failed. A rerun of the sweep with the same
    store computes only the points left.

    Example:
        >>> import spacefit as sf
        >>> issubclass(sf.ClusterError, RuntimeError)
        True
    """


def is_client(cluster: object) -> bool:
    """Whether ``cluster`` is a ``distributed.Client`` or of a subclass (dask-gateway's, a cloud
    provider's), recognised without importing dask."""
    return any(c.__name__ == "Client" and c.__module__.split(".")[0] == "distributed" for c in type(cluster).__mro__)


def check_scheduler(address: object, argument: str = "cluster") -> None:
    """Refuse a scheduler address before anything is made: not ``SCHEME://HOST:PORT`` with a scheme
    of :data:`SCHEDULER_SCHEMES` (``inproc://`` takes dask's own form), or (for the schemes over TCP)
    nothing accepting connections there within :data:`PROBE_TIMEOUT_S`.

    Raises:
        InputError: naming ``argument``, the address and what is wrong with it.
    """
    if not isinstance(address, str):
        raise InputTypeError(f"`{argument}` must be an address such as 'tcp://host:8786', got {quote(address)}.")
    scheme, sep, rest = address.strip().partition("://")
    if not sep:
        scheme, rest = "tcp", address.strip()
    if scheme not in SCHEDULER_SCHEMES:
        raise InputError(f"`{argument}` {address!r} has the scheme {scheme!r}; use one of "
                         f"{', '.join(s + '://' for s in SCHEDULER_SCHEMES)} (e.g. tcp://host:8786).")
    if scheme == "inproc":
        return
    host, _, port = rest.rstrip("/").rpartition(":")
    if not host or not port.isdigit():
        raise InputError(f"`{argument}` {address!r} must be SCHEME://HOST:PORT, e.g. tcp://host:8786.")
    if scheme not in UNPROBED_SCHEMES:
        try:
            socket.create_connection((host.strip("[]"), int(port)), timeout=PROBE_TIMEOUT_S).close()
        except OSError as err:
            raise InputError(f"`{argument}` {address!r}: no dask scheduler answered ({err.strerror or err}).") from None


def check_cluster(cluster: object, argument: str = "cluster") -> None:
    """Refuse a ``cluster`` that is none of :data:`Cluster`'s forms (a worker count below 1, a bool, an
    address no scheduler answers at), naming ``argument``; None passes."""
    if cluster is None or is_client(cluster):
        return
    if isinstance(cluster, bool):
        raise InputTypeError(f"`{argument}` must be {CLUSTER_WORDS}, got {cluster!r}.")
    if isinstance(cluster, (int, np.integer)):
        check_count(argument, int(cluster))
    elif isinstance(cluster, str):
        check_scheduler(cluster, argument)
    else:
        raise InputTypeError(f"`{argument}` must be {CLUSTER_WORDS}, got {quote(cluster)}.")


def cluster_of(cluster: Cluster | None, workers: int | None = None, scheduler: str | None = None) -> Cluster | None:
    """``cluster``, checked (:func:`check_cluster`), or the same from the ``workers=`` / ``scheduler=``
    arguments that sweeps and light curves took before ``cluster=`` (deprecated: a DeprecationWarning
    says so).

    Raises:
        InputError: more than one of the three is given, or what is given is none of :data:`Cluster`'s forms.
    """
    given = [name for name, v in (("cluster", cluster), ("workers", workers), ("scheduler", scheduler)) if v is not None]
    if len(given) > 1:
        raise InputError(f"give one of `cluster`, `workers` and `scheduler`, not {' and '.join(f'`{g}`' for g in given)}.")
    if workers is not None or scheduler is not None:
        warnings.warn(f"`{given[0]}=` is deprecated: give `cluster=` (a number of local workers, a scheduler address or a "
                      "dask Client), as fits take it.", DeprecationWarning, stacklevel=3)
        cluster = workers if workers is not None else scheduler
    check_cluster(cluster, given[0] if given else "cluster")
    return cluster


def connect(cluster: Cluster, config: Mapping[str, Any] | None = None) -> tuple[Any, Callable[[], None]]:
    """A dask client for ``cluster`` (not None; :func:`check_cluster` it first) and the function that
    closes what this call opened: a new local cluster of N single-threaded processes, the scheduler
    at an address, or the caller's own client (left open). ``config``: dask settings in force while a
    local cluster's scheduler is made (a running scheduler keeps its own)."""
    import dask  # here: only a cluster needs dask.distributed (seconds to import)
    from distributed import Client, LocalCluster

    if is_client(cluster):
        return cluster, lambda: None
    if isinstance(cluster, str):
        try:
            client = Client(cluster, timeout="20s")
        except (OSError, TimeoutError) as err:
            raise InputError(f"`cluster` {cluster!r}: no dask scheduler answered ({err}).") from None
        return client, client.close
    logging.getLogger("distributed").setLevel(logging.ERROR)
    with dask.config.set(dict(config or {})):
        local = LocalCluster(n_workers=int(cluster), threads_per_worker=1, processes=True, dashboard_address=None,
                             silence_logs=logging.ERROR)
    client = Client(local)

    def close() -> None:
        client.close(timeout=CLOSE_S)
        local.close(timeout=CLOSE_S)

    return client, close


class Executor(Protocol):
    """Runs ``fn`` once per item and returns the results in item order."""

    def map(self, fn: Callable[..., Any], keys: Sequence[str], *per_item: Sequence[Any]) -> list[Any]:
        """``[fn(*args_k) for each item k]``; ``keys[k]`` names item k's state (what a worker keeps for it)."""
        ...

    def close(self) -> None:
        """Release what this executor opened."""
        ...


class InProcess:
    """Every item in this process, one after another."""

    def map(self, fn: Callable[..., Any], keys: Sequence[str], *per_item: Sequence[Any]) -> list[Any]:
        """``[fn(*args_k)]`` in item order."""
        return [fn(*(args[k] for args in per_item)) for k in range(len(keys))]

    def close(self) -> None:
        """Nothing to release."""


def _on_worker(fn: Callable[..., Any], *args: Any) -> tuple[Any, str]:
    """Run ``fn`` on a dask worker: its result and the worker's address."""
    from distributed import get_worker  # here: only a worker runs it

    return fn(*args), get_worker().address


class OnDask:
    """Every item as one dask task, all at once; each item goes back to the worker that ran it last
    (``allow_other_workers``: a lost worker's items run elsewhere)."""

    def __init__(self, client: Any, close: Callable[[], None] | None = None) -> None:
        self.client = client
        self._close = close
        self.home: dict[str, str] = {}  # item key -> the worker that holds its state

    def _placement(self, keys: Sequence[str]) -> list[str]:
        """Each item's worker: its home if alive, else the live worker with the fewest items."""
        alive = list(self.client.scheduler_info(n_workers=-1)["workers"])
        if not alive:  # a lost worker's nanny may be starting it again
            try:
                self.client.wait_for_workers(1, timeout=WAIT_FOR_WORKERS_S)
            except TimeoutError:
                raise InputError(f"the dask cluster has had no workers for {WAIT_FOR_WORKERS_S:g} s.") from None
            alive = list(self.client.scheduler_info(n_workers=-1)["workers"])
        load = {w: 0 for w in alive}
        for key in keys:
            if self.home.get(key) in load:
                load[self.home[key]] += 1
        out = []
        for key in keys:
            if self.home.get(key) not in load:
                self.home[key] = min(alive, key=lambda w: load[w])
                load[self.home[key]] += 1
            out.append(self.home[key])
        return out

    def map(self, fn: Callable[..., Any], keys: Sequence[str], *per_item: Sequence[Any]) -> list[Any]:
        """``[fn(*args_k)]`` in item order, on the workers."""
        places = self._placement(keys)
        futures = [self.client.submit(_on_worker, fn, *(args[k] for args in per_item), workers=[places[k]],
                                      allow_other_workers=True, pure=False)
                   for k in range(len(keys))]
        out = []
        for key, (result, address) in zip(keys, self.client.gather(futures)):
            self.home[key] = address  # where its state is now
            out.append(result)
        return out

    def close(self) -> None:
        """Close the client and cluster this executor opened (not a client it was given)."""
        if self._close is not None:
            self._close()


def executor_of(cluster: Cluster | None) -> Executor:
    """The executor of a ``cluster`` argument (module docstring): None, :class:`InProcess`; else
    :class:`OnDask` on the cluster it names.

    Raises:
        InputError: ``cluster`` is none of :data:`Cluster`'s forms, or no scheduler answers at its address.
    """
    check_cluster(cluster)
    if cluster is None:
        return InProcess()
    return OnDask(*connect(cluster))
