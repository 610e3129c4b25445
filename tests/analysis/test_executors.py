"""Deferred jobs: on an executor at once, or in this process when first asked for."""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

from analysis.executors import Deferred


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
