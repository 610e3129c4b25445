"""Where independent jobs run (Latin hypercube starts, cross-validation folds, planning sweeps,
diagnosis fits): in-process, a local process pool, or Dask.

Any ``concurrent.futures.Executor`` will do (jobs are picklable specs and the work function is
a top-level function). :func:`open_executor` makes the usual ones:

- ``workers=1``: none (serial, in this process);
- otherwise a local ``ProcessPoolExecutor`` (BLAS limited to one thread per worker);
- with a scheduler address, the executor of a Dask ``distributed.Client``. Dask moves pickles
  between machines and unpickling runs code: connect only to a lab's own, trusted cluster.
"""

from __future__ import annotations

import contextlib
import functools
import logging
import os
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import Executor, Future, ProcessPoolExecutor, as_completed
from typing import Generic, TypeVar

__all__ = ["Deferred", "one_blas_thread", "open_executor", "run_jobs"]

log = logging.getLogger(__name__)

J = TypeVar("J")
R = TypeVar("R")


def _one_blas_thread() -> None:
    """Worker initialiser: small dense solves are slowed badly by BLAS threads."""
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # pragma: no cover - threadpoolctl is a dependency
        return
    threadpool_limits(limits=1)


@functools.cache
def _blas_controller():
    # made at the first use, when the BLAS libraries that will be used are loaded: a
    # controller acts only on the libraries it found when made
    from threadpoolctl import ThreadpoolController

    return ThreadpoolController()


@contextlib.contextmanager
def one_blas_thread() -> Iterator[None]:
    """BLAS limited to one thread while the block runs, then as it was.

    For work on small matrices (a few hundred rows): a BLAS thread costs more to wake than it
    saves there, and two such jobs side by side, each with a thread per core, spend the cores
    waiting on each other. The limit is the process's (BLAS has no other), so other threads
    of the process get one BLAS thread meanwhile too.
    """
    with _blas_controller().limit(limits=1):
        yield


@contextlib.contextmanager
def open_executor(
    workers: int | None = None, scheduler: str | None = None
) -> Iterator[Executor | None]:
    """An executor for independent jobs, shut down on exit.

    Parameters
    ----------
    workers : int, optional
        Local worker processes (default: the CPU count); 1 gives ``None`` (serial).
    scheduler : str, optional
        Address of a Dask scheduler (``"tcp://host:8786"``); ``distributed`` is imported only
        then. Only for a trusted cluster: Dask sends pickled jobs and results.

    Yields
    ------
    Executor or None
    """
    if scheduler:
        try:
            import distributed
        except ImportError:
            raise ValueError(
                "a scheduler address needs the 'distributed' package "
                "(pip install 'clearance-rig[dask]')"
            ) from None
        client = distributed.Client(scheduler)
        log.info("running jobs on the Dask scheduler at %s", scheduler)
        try:
            yield client.get_executor()
        finally:
            client.close()
        return
    n = (os.cpu_count() or 1) if workers is None else int(workers)
    if n < 1:
        raise ValueError(f"workers: must be >= 1, got {workers}")
    if n == 1:
        yield None
        return
    with ProcessPoolExecutor(max_workers=n, initializer=_one_blas_thread) as pool:
        log.info("running jobs on %d local worker processes", n)
        yield pool


def run_jobs(
    fn: Callable[[J], R],
    jobs: Sequence[J],
    executor: Executor | None,
    on_done: Callable[[int], None] | None = None,
) -> list[R]:
    """``[fn(job) for job in jobs]``, on ``executor`` if given; results in job order.

    Parameters
    ----------
    fn : callable
        A picklable (top-level) function.
    jobs : sequence
        Picklable job specs.
    executor : Executor or None
        ``None`` runs serially in this process.
    on_done : callable, optional
        ``on_done(k)`` each time a job finishes, ``k`` the number finished so far (progress).
    """
    if executor is None:
        out = []
        for job in jobs:
            out.append(fn(job))
            if on_done:
                on_done(len(out))
        return out
    futures = [executor.submit(fn, job) for job in jobs]
    if on_done:
        for k, _ in enumerate(as_completed(futures), 1):
            on_done(k)
    return [f.result() for f in futures]


class Deferred(Generic[J, R]):
    """``fn(job)``: started on ``executor`` at once, or, without one, computed in this process
    when :meth:`result` is first asked for (so work that is never asked for is never done
    serially, and the order of the asks is the order of the work)."""

    def __init__(self, executor: Executor | None, fn: Callable[[J], R], job: J) -> None:
        self._future: Future[R] | None = executor.submit(fn, job) if executor is not None else None
        self._fn, self._job = fn, job
        self._done: list[R] = []

    def result(self) -> R:
        if self._future is not None:
            return self._future.result()
        if not self._done:
            self._done.append(self._fn(self._job))
        return self._done[0]
