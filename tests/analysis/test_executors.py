"""Deferred jobs: on an executor at once, or in this process when first asked for; BLAS
threads limited for a block."""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import pytest

from analysis.executors import Deferred, one_blas_thread


def test_a_deferred_job_runs_once_in_this_process_when_asked_for() -> None:
    ran: list[int] = []

    def square(x: int) -> int:
        ran.append(x)
        return x * x

    later = [Deferred(None, square, x) for x in (3, 4)]
    assert ran == []  # nothing runs before it is asked for
    assert later[1].result() == 16 and later[1].result() == 16
    assert ran == [4]  # once, and in the order asked
    assert later[0].result() == 9 and ran == [4, 3]


def test_a_deferred_job_starts_at_once_on_an_executor() -> None:
    ran: list[int] = []

    def square(x: int) -> int:
        ran.append(x)
        return x * x

    with ThreadPoolExecutor(1) as ex:
        later = Deferred(ex, square, 5)
        ex.submit(lambda: None).result()  # the pool's one thread has taken the job before this
        assert ran == [5]
        assert later.result() == 25


def _blas_threads() -> list[int]:
    from threadpoolctl import threadpool_info

    return [i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"]


def test_one_blas_thread_holds_inside_the_block_and_restores_after() -> None:
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=2):
        assert set(_blas_threads()) == {2}
        with one_blas_thread():
            assert set(_blas_threads()) == {1}
        assert set(_blas_threads()) == {2}
        with pytest.raises(RuntimeError), one_blas_thread():
            raise RuntimeError("a failing block restores the limit too")
        assert set(_blas_threads()) == {2}
