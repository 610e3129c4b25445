"""One WARNING line for a flood of expected warnings (analysis.logs)."""

from __future__ import annotations

import logging
import subprocess
import sys
import textwrap
from concurrent.futures import ProcessPoolExecutor

import pytest

from analysis.logs import summarise_repeats

MHB = logging.getLogger("analysis.mhb.sweep")


def _fail_steps(n: int, start: int = 0) -> int:
    for i in range(start, start + n):
        MHB.warning(
            "MHB step %d (%.4g Hz) did not converge: %s", i, 20 + 0.1 * i, "line search failed"
        )
    return n


def _warnings(caplog):
    return [r for r in caplog.records if r.levelno >= logging.WARNING]


def test_500_failures_give_one_warning_with_the_count_and_the_detail_at_debug(caplog) -> None:
    caplog.set_level(logging.DEBUG, logger="analysis")
    with summarise_repeats("calibrate") as counts:
        _fail_steps(500)
        logging.getLogger("analysis.mhb.sweep").warning("something else")
    warnings = _warnings(caplog)
    assert [r.getMessage() for r in warnings] == [
        "something else",
        "calibrate: 500 MHB steps did not converge (expected for trial parameters far from "
        "the data); run with --debug for each",
    ]
    detail = [r for r in caplog.records if r.levelno == logging.DEBUG]
    assert len(detail) == 500 and "line search failed" in detail[0].getMessage()
    assert list(counts.counts.values()) == [500]


def test_without_debug_the_detail_is_dropped_and_outside_a_stage_nothing_changes(caplog) -> None:
    caplog.set_level(logging.WARNING)
    with summarise_repeats("plan"):
        _fail_steps(30)
    assert len(caplog.records) == 1 and "plan: 30 MHB steps" in caplog.records[0].getMessage()
    caplog.clear()
    _fail_steps(2)
    assert len(_warnings(caplog)) == 2  # the library's own warnings are untouched
    assert MHB.filters == []


def test_nested_stages_count_each_record_once(caplog) -> None:
    caplog.set_level(logging.WARNING)
    with summarise_repeats("diagnose"):
        _fail_steps(3)
        with summarise_repeats("augment"):
            _fail_steps(7)
    assert [r.getMessage().split(" MHB")[0] for r in caplog.records] == [
        "augment: 7",
        "diagnose: 3",
    ]


def test_forked_workers_count_into_the_stage(caplog) -> None:
    caplog.set_level(logging.WARNING)
    with summarise_repeats("calibrate"), ProcessPoolExecutor(2) as pool:
        assert sum(pool.map(_fail_steps, [40, 60], [0, 40])) == 100
    assert [r.getMessage().split(" MHB")[0] for r in caplog.records] == ["calibrate: 100"]


@pytest.mark.slow
def test_the_command_line_prints_one_line_and_every_step_with_debug(tmp_path) -> None:
    script = textwrap.dedent(
        """
        import sys, logging
        import analysis.cli as cli
        def noisy(args):
            log = logging.getLogger("analysis.mhb.sweep")
            for i in range(500):
                log.warning("MHB step %d (20 Hz) did not converge: line search failed", i)
            return {}
        parser = cli.build_parser
        def build():
            p = parser()
            sub = p._subparsers._group_actions[0]
            sp = sub.add_parser("noisy")
            sp.add_argument("--json", action="store_true")
            sp.set_defaults(func=noisy)
            return p
        cli.build_parser = build
        sys.exit(cli.main(sys.argv[1:]))
        """
    )
    run = [sys.executable, "-c", script]
    r = subprocess.run([*run, "noisy"], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert r.stderr.splitlines() == [
        "WARNING analysis: noisy: 500 MHB steps did not converge (expected for trial parameters "
        "far from the data); run with --debug for each"
    ]
    r = subprocess.run([*run, "--debug", "noisy"], capture_output=True, text=True, timeout=120)
    lines = r.stderr.splitlines()
    assert len(lines) == 501 and lines[0].startswith("DEBUG analysis.mhb.sweep: MHB step 0")


def test_one_failure_is_said_in_the_singular(caplog) -> None:
    caplog.set_level(logging.WARNING)
    with summarise_repeats("compare"):
        _fail_steps(1)
    assert caplog.records[0].getMessage().startswith("compare: 1 MHB step did not converge")
