"""A sweep's renders on dask.distributed: a local cluster (``workers=N``) or a running scheduler.

Each task is one whole render (:func:`spacefit.studies.worker.run_task`, 0.05 s to seconds), so the
scheduler's overhead (about 1 ms a task) stays small. A worker process keeps its loaded scene
between tasks, as the in-process sweep does, and gives the same numbers for the same seeds
(renders are deterministic). Mitsuba leaks memory and has crashed over thousands of renders in one
process, so a worker is restarted by its nanny after ``max_renders_per_worker`` renders; a task
running there then is sent to another worker. At most two tasks per worker are in flight, so
that Ctrl-C stops soon and a restart loses little. Only this process writes the store.
"""

from __future__ import annotations

import logging
import socket
from collections.abc import Callable, Iterator

import numpy as np

from spacefit.errors import InputError, InputTypeError, quote
from spacefit.studies import worker
from spacefit.studies.worker import Task

IN_FLIGHT_PER_WORKER = 2


def render_on_worker(task: Task) -> tuple[dict[str, np.ndarray], str, int]:
    """Run one task on a dask worker: its result, the worker's address and its process's render count."""
    from distributed import get_worker  # here: dask.distributed takes seconds to import; only a cluster needs it

    result = worker.run_task(task)
    return result, get_worker().address, worker.render_count()


# dask.distributed's schemes for a scheduler's address (an address without one is tcp://).
SCHEDULER_SCHEMES = ("tcp", "tls", "ws", "wss", "ucx")
# How long a check waits for a scheduler to accept a connection (s).
PROBE_TIMEOUT_S = 5.0


def check_scheduler(address: object) -> None:
    """Refuse a ``scheduler`` address before anything is made: not ``SCHEME://HOST:PORT`` with a scheme
    of :data:`SCHEDULER_SCHEMES`, or (for the schemes over TCP) nothing accepting connections there
    within :data:`PROBE_TIMEOUT_S`. None (no scheduler) passes.

    Raises:
        InputError: naming the address and what is wrong with it.
    """
    if address is None:
        return
    if not isinstance(address, str):
        raise InputTypeError(f"`scheduler` must be an address such as 'tcp://host:8786', got {quote(address)}.")
    scheme, sep, rest = address.strip().partition("://")
    if not sep:
        scheme, rest = "tcp", address.strip()
    if scheme not in SCHEDULER_SCHEMES:
        raise InputError(f"`scheduler` {address!r} has the scheme {scheme!r}; use one of "
                         f"{', '.join(s + '://' for s in SCHEDULER_SCHEMES)} (e.g. tcp://host:8786).")
    host, _, port = rest.rstrip("/").rpartition(":")
    if not host or not port.isdigit():
        raise InputError(f"`scheduler` {address!r} must be SCHEME://HOST:PORT, e.g. tcp://host:8786.")
    if scheme != "ucx":
        try:
            socket.create_connection((host.strip("[]"), int(port)), timeout=PROBE_TIMEOUT_S).close()
        except OSError as err:
            raise InputError(f"`scheduler` {address!r}: no dask scheduler answered ({err.strerror or err}).") from None


def connect(workers: int | None, scheduler: str | None) -> tuple[object, Callable[[], None]]:
    """A dask client, on a new local cluster of ``workers`` single-threaded processes or on the
    scheduler at ``scheduler``, and the function that closes what this call opened."""
    from distributed import Client, LocalCluster  # here: only a cluster needs dask.distributed (seconds to import)

    if scheduler is not None:
        try:
            client = Client(scheduler, timeout="20s")
        except (OSError, TimeoutError) as err:
            raise InputError(f"`scheduler` {scheduler!r}: no dask scheduler answered ({err}).") from None
        return client, client.close
    cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None,
                           silence_logs=logging.ERROR)
    client = Client(cluster)

    def close() -> None:
        client.close()
        cluster.close()

    return client, close


def run_on_dask(todo: list[tuple[int, ...]], task_of: Callable[[tuple[int, ...]], Task], *, workers: int | None,
                scheduler: str | None, max_renders_per_worker: int) -> Iterator[tuple[tuple[int, ...], dict[str, np.ndarray]]]:
    """Yield ``(index, result)`` for every point of ``todo`` as dask workers finish them."""
    from distributed import as_completed  # here: only a cluster needs dask.distributed (seconds to import)

    client, close = connect(workers, scheduler)
    try:
        n = max(1, len(client.scheduler_info(n_workers=-1)["workers"]))
        queue = iter(todo)
        index_of = {}

        def submit() -> object | None:
            index = next(queue, None)
            if index is None:
                return None
            future = client.submit(render_on_worker, task_of(index), pure=False)
            index_of[future.key] = index
            return future

        running = as_completed([f for f in (submit() for _ in range(IN_FLIGHT_PER_WORKER * n)) if f is not None])
        for future in running:
            result, address, renders = future.result()
            yield index_of.pop(future.key), result
            if renders >= max_renders_per_worker:
                client.restart_workers([address])
            following = submit()
            if following is not None:
                running.add(following)
    finally:
        close()
