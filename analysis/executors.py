"""Executors for independent work (Latin hypercube candidates, folds, planning sweeps).

A local process pool by default; a Dask ``distributed`` cluster when a scheduler address is
given. Dask moves pickled Python objects between machines: use it only on a lab's own trusted
cluster, never with a scheduler reachable from outside.
"""

from __future__ import annotations

import concurrent.futures as cf
import contextlib
import os
from collections.abc import Iterator

__all__ = ["make_executor"]


@contextlib.contextmanager
def make_executor(
    workers: int | None = None, scheduler: str | None = None
) -> Iterator[cf.Executor | None]:
    """Yield an executor: ``None`` (serial) for ``workers <= 1``, a process pool, or Dask.

    Parameters
    ----------
    workers : int, optional
        Local worker processes (default: the number of CPUs).
    scheduler : str, optional
        Address of a Dask scheduler (``tcp://host:8786``); needs the ``dask`` extra.
    """
    if scheduler:
        try:
            from distributed import Client
        except ImportError:
            raise RuntimeError(
                "a Dask scheduler was given but 'distributed' is not installed: "
                "pip install 'clearance-rig[dask]'"
            ) from None
        client = Client(scheduler)
        try:
            yield client.get_executor()
        finally:
            client.close()
        return
    n = (os.cpu_count() or 1) if workers is None else workers
    if n <= 1:
        yield None
        return
    with cf.ProcessPoolExecutor(max_workers=n) as ex:
        yield ex
