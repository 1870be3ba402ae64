"""A sweep's renders on dask.distributed (its ``cluster``, :mod:`spacefit.executors`): a local cluster or a running scheduler.

Each task is one whole render (:func:`spacefit.studies.worker.run_task`, 0.05 s to seconds), so the
scheduler's overhead (about 1 ms a task) stays small. A worker process keeps its loaded scene
between tasks, as the in-process sweep does, and gives the same numbers for the same seeds
(renders are deterministic). Mitsuba leaks memory and has crashed over thousands of renders in one
process, so a worker is restarted by its nanny after ``max_renders_per_worker`` renders; a task
running there then is sent to another worker. At most two tasks per worker are in flight, so
that Ctrl-C stops soon and a restart loses little. Only this process writes the store. A point
whose worker dies (a crash, a memory limit) is retried :data:`RETRIES_PER_POINT` times, then the
sweep stops naming it; a sweep where no point finishes for ``stall_s`` stops too (:class:`ClusterError`),
counted from the last point that finished: workers that die again and again (each death ends a task,
with an error) do not keep it going.
"""

from __future__ import annotations

import itertools
import time
from collections.abc import Callable, Iterator
from typing import Any

import numpy as np

from spacefit.executors import Cluster, ClusterError, connect
from spacefit.studies import worker
from spacefit.studies.worker import Task

IN_FLIGHT_PER_WORKER = 2
# Times a point is sent again after the worker rendering it died, before the sweep stops naming it.
RETRIES_PER_POINT = 2
# Seconds a sweep on dask waits for any point to finish before it stops, saying so (`stall_s`).
STALL_S = 600.0


def render_on_worker(task: Task) -> tuple[dict[str, np.ndarray], str, int]:
    """Run one task on a dask worker: its result, the worker's address and its process's render count."""
    from distributed import get_worker  # here: dask.distributed takes seconds to import; only a cluster needs it

    result = worker.run_task(task)
    return result, get_worker().address, worker.render_count()


def run_on_dask(todo: list[tuple[int, ...]], task_of: Callable[[tuple[int, ...]], Task], *, cluster: Cluster,
                max_renders_per_worker: int, stall_s: float = STALL_S,
                retries: int = RETRIES_PER_POINT, render: Callable[[Any], Any] = render_on_worker,
                ) -> Iterator[tuple[tuple[int, ...], dict[str, np.ndarray]]]:
    """Yield ``(index, result)`` for every point of ``todo`` as dask workers finish them.

    A point whose worker dies while rendering it (a crash, or its nanny killing it past its memory
    limit) is sent again, at most ``retries`` times; on a local cluster the scheduler reports every
    death at once (``allowed-failures`` 0), so the budget is this one (a running scheduler's own
    ``allowed-failures`` multiplies it).

    Raises:
        ClusterError: a point lost ``retries + 1`` times (naming it and its worker's memory limit), or
            no point finished for ``stall_s`` seconds (workers dying meanwhile or not).
    """
    from distributed import wait  # here: only a cluster needs dask.distributed (seconds to import)
    from distributed.scheduler import KilledWorker

    # A local cluster's scheduler is made here: it reports each death at once (the budget is ``retries``)
    # and gives a worker only the task it runs, so that a death loses that point only, not one queued behind it.
    try:
        client, close = connect(cluster, {"distributed.scheduler.allowed-failures": 0, "distributed.scheduler.worker-saturation": 1.0})
    except RuntimeError as err:  # a worker process died while its nanny started it
        raise ClusterError(f"the local dask cluster did not start ({err}); nothing was rendered, rerun the same "
                           "command.") from None
    try:
        n = max(1, len(client.scheduler_info(n_workers=-1)["workers"]))
        queue = iter(todo)
        pending: dict[Any, tuple[tuple[int, ...], int]] = {}  # future -> (point, times its worker died)

        def submit(index: tuple[int, ...], lost: int = 0) -> None:
            pending[client.submit(render, task_of(index), pure=False)] = (index, lost)

        for index in itertools.islice(queue, IN_FLIGHT_PER_WORKER * n):
            submit(index)
        stall = ClusterError(f"no point of the sweep finished in {stall_s:g} s (`stall_s`): the dask workers are stuck, "
                             "gone or dying; every finished point is in the store (rerun the same command to finish, or "
                             "raise `stall_s` for renders that long).")
        deadline = time.monotonic() + stall_s  # a point finished by then, or the sweep stops
        while pending:
            left = deadline - time.monotonic()
            if left <= 0:
                raise stall
            try:
                done, _ = wait(list(pending), timeout=left, return_when="FIRST_COMPLETED")
            except TimeoutError:
                raise stall from None
            for future in done:
                index, lost = pending.pop(future)
                try:
                    result, address, renders = future.result()
                except KilledWorker as err:
                    if lost >= retries:
                        raise ClusterError(_lost(index, task_of(index), lost + 1, err)) from None
                    submit(index, lost + 1)
                    continue
                deadline = time.monotonic() + stall_s
                yield index, result
                if renders >= max_renders_per_worker:
                    restart(client, address, stall_s)
                following = next(queue, None)
                if following is not None:
                    submit(following)
    finally:
        close()


def restart(client: Any, address: str, timeout_s: float) -> None:
    """Restart the worker at ``address`` (its renders done), waiting at most ``timeout_s``; a worker gone
    meanwhile, or one that does not come back in time, is left to its nanny (the sweep goes on)."""
    client.restart_workers([address], timeout=timeout_s, raise_for_error=False)


def _lost(index: tuple[int, ...], task: Any, times: int, err: Exception) -> str:
    """Why a point could not be rendered on dask: its worker died ``times`` times, in words."""
    where = ", ".join(f"{k} = {v:g}" for k, v in task.in_place) if isinstance(task, Task) else ""
    worker = getattr(err, "last_worker", None)
    limit = getattr(worker, "memory_limit", 0)
    memory = f"a worker's memory limit is {limit / 2**30:.1f} GiB" if limit else "the workers have no memory limit"
    return (f"the dask worker rendering point {index}{f' ({where})' if where else ''} died {times} times: a crash in "
            f"the render, or its nanny's memory limit ({memory}; the nanny's log says which). Every finished point is "
            "in the store; rerun the same command with fewer workers, a smaller render, or without this point.")
