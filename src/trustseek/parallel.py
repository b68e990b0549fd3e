"""Work over processes: the one bound on their number (``--jobs``) and one way to run independent
calls side by side, their results in order and the same whatever the number of processes."""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from typing import TYPE_CHECKING, TypeVar

from .errors import TrustseekError

#: the most worker processes (or threads) a computation starts: with the fork start method a pool
#: starts all of its workers at once, so --jobs 1000000000 would fork until the machine gives out
MAX_JOBS = 256
T = TypeVar("T")
K = TypeVar("K")

if TYPE_CHECKING:
    from concurrent.futures import ProcessPoolExecutor


def check_jobs(jobs: int | None, option: str = "jobs") -> None:
    """Refuse a number of workers below 1 or above :data:`MAX_JOBS` (``option``: what the caller's
    user sets it with, named in the message); None (all cores) passes."""
    if jobs is not None and not 1 <= jobs <= MAX_JOBS:
        raise TrustseekError([f"{option} must be between 1 and {MAX_JOBS} worker processes, got {jobs}"])


def in_processes(calls: Sequence[Callable[[], T]], n_jobs: int | None, done: Callable[[int, int], None]) -> list[T]:
    """Every one of ``calls`` (picklable, without arguments), their results in order, over ``n_jobs``
    processes (None: all cores; in this process for one, or for a single call); ``done(i,
    finished)`` as call ``i`` finishes.  The results do not depend on the number of processes."""
    from concurrent.futures import as_completed  # (not at the command line's start)

    results: dict[int, T] = {}
    jobs = _jobs(n_jobs)
    if jobs <= 1 or len(calls) <= 1:
        for i, call in enumerate(calls):
            results[i] = call()
            done(i, len(results))
        return [results[i] for i in range(len(calls))]
    with _pool(min(jobs, len(calls)), lambda: f"after {len(results)} of {len(calls)} parts") as ex:
        futures = {ex.submit(call): i for i, call in enumerate(calls)}
        for f in as_completed(futures):
            results[futures[f]] = f.result()
            done(futures[f], len(results))
    return [results[i] for i in range(len(calls))]


@contextmanager
def beside(calls: Mapping[K, Callable[[], T]], n_jobs: int | None) -> Iterator[Callable[[K], T]]:
    """``calls`` (by name; picklable, without arguments) started, in their order, over as many as
    ``n_jobs`` other processes (None: all cores) while the ``with`` body runs in this one; the body's
    ``result(name)`` is that call's result, waited for.  With one job each call runs in this process
    when its result is asked for.  The results do not depend on the number of processes."""
    jobs = _jobs(n_jobs)
    if jobs <= 1 or not calls:
        yield lambda name: calls[name]()
        return
    with _pool(min(jobs, len(calls)), lambda: "beside this one") as ex:
        futures = {name: ex.submit(call) for name, call in calls.items()}  # the workers start now, before the body starts threads
        try:
            yield lambda name: futures[name].result()
        except BaseException:  # (an interrupt too): the calls' results are not wanted, so stop them now
            workers = list((getattr(ex, "_processes", None) or {}).values())  # (Python 3.14: ex.terminate_workers())
            ex.shutdown(wait=False, cancel_futures=True)
            for process in workers:
                process.terminate()
            raise


def _jobs(n_jobs: int | None) -> int:
    jobs = n_jobs or os.cpu_count() or 1
    if jobs > 1:
        check_jobs(jobs)
    return jobs


@contextmanager
def _pool(workers: int, where: Callable[[], str]) -> Iterator[ProcessPoolExecutor]:
    """A pool of ``workers`` processes; a worker that dies is one :class:`TrustseekError` (``where``:
    how far the work had come)."""
    from concurrent.futures import ProcessPoolExecutor
    from concurrent.futures.process import BrokenProcessPool

    try:
        with ProcessPoolExecutor(max_workers=workers) as ex:
            yield ex
    except BrokenProcessPool:
        raise TrustseekError(
            [f"a worker process ended abruptly (killed, or out of memory) {where()}: "
             "nothing was written; run again, or with --jobs 1 (in this process)"]
        ) from None  # fmt: skip
