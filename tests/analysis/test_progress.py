"""Progress reports (analysis.progress): the time left, the text and JSON forms, the throttle,
and the counts the long stages report."""

import io
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest

from analysis.executors import run_jobs
from analysis.progress import (
    PREFIX,
    Progress,
    ProgressReporter,
    format_duration,
    parse_line,
    time_left,
)


def test_time_left_is_the_pace_so_far_times_the_work_left():
    assert time_left(50.0, 25, 75) == pytest.approx(150.0)
    assert time_left(0.0, 1, 99) is None and time_left(3.0, 0, 100) is None
    p = Progress("starts", 25, 100, 50.0, left_s=150.0)
    assert "about 2 min 30 s left" in p.text() and "25/100" in p.text()
    assert Progress("starts", 100, 100, 200.0).finished
    assert "done in 3 min 20 s" in Progress("starts", 100, 100, 200.0).text()
    assert "left" not in Progress("LM iterations", 7, None, 3.0).text()


def test_the_pace_is_taken_from_the_units_timed(monkeypatch):
    # the first report of a stage the reporter did not begin is its clock's start: one unit is
    # done at t = 0 and says nothing of the pace
    now = [100.0]
    monkeypatch.setattr("analysis.progress.time.perf_counter", lambda: now[0])
    stream = io.StringIO()
    reporter = ProgressReporter("json", stream)
    reporter.update("records", 1, 5)
    first = parse_line(stream.getvalue().splitlines()[-1])
    assert first.left_s is None
    now[0] = 110.0
    reporter.update("records", 2, 5)  # one unit in 10 s, three to come
    assert parse_line(stream.getvalue().splitlines()[-1]).left_s == pytest.approx(30.0)


@pytest.mark.parametrize(
    "seconds, text", [(4.4, "4 s"), (65, "1 min 05 s"), (3725, "1 h 02 min"), (float("nan"), "?")]
)
def test_durations_read_as_a_person_says_them(seconds, text):
    assert format_duration(seconds) == text


def test_json_lines_round_trip_and_other_lines_are_not_progress():
    stream = io.StringIO()
    reporter = ProgressReporter("json", stream)
    reporter.update("folds", 3, 9, "metric 1.2")
    line = stream.getvalue().strip()
    assert line.startswith(PREFIX)
    p = parse_line(line)
    assert (p.stage, p.done, p.total, p.note) == ("folds", 3, 9, "metric 1.2")
    assert parse_line("WARNING analysis: something") is None
    assert parse_line(PREFIX + "{not json") is None
    assert parse_line(PREFIX + '{"stage": "x"}') is None


def test_text_lines_are_throttled_but_the_end_is_always_shown():
    stream = io.StringIO()
    reporter = ProgressReporter("text", stream, prefix="calibration: ", interval_s=60.0)
    for k in range(1, 101):
        reporter.update("starts", k, 100)
    lines = stream.getvalue().splitlines()
    assert len(lines) == 2, lines  # the first update, then nothing until the last
    assert lines[0].startswith("calibration: starts 1/100")
    assert "100/100" in lines[-1] and "done in" in lines[-1]
    with pytest.raises(ValueError, match="progress mode"):
        ProgressReporter("bar")


@pytest.mark.parametrize("executor", [None, "threads"])
def test_run_jobs_counts_every_finished_job(executor):
    seen = []
    with ThreadPoolExecutor(2) if executor else _null() as ex:
        out = run_jobs(abs, [-1, -2, -3, -4, -5], ex, seen.append)
    assert out == [1, 2, 3, 4, 5]
    assert seen == [1, 2, 3, 4, 5]


class _null:
    def __enter__(self):
        return None

    def __exit__(self, *exc):
        return False


def test_the_workflow_shows_a_stage_s_progress_and_keeps_its_result(capsys):
    from rig.cli.workflow import _stage

    script = (
        "import sys, json\n"
        "from analysis.progress import ProgressReporter\n"
        "r = ProgressReporter('json')\n"
        "print('WARNING something', file=sys.stderr)\n"
        "[r.update('starts', k, 4) for k in range(1, 5)]\n"
        "print(json.dumps({'answer': 42}))\n"
    )
    log = []
    out = _stage("test stage", ["-c", script], log, quiet=False)
    assert out == {"answer": 42}
    err = capsys.readouterr().err
    assert "== test stage" in err and "starts 1/4" in err and "starts 4/4" in err
    assert "done in" in err and "WARNING" not in err and PREFIX not in err


def test_a_failing_stage_quotes_its_error_output_not_its_progress():
    from rig.cli.workflow import StageError, _stage

    script = (
        "import sys\nfrom analysis.progress import ProgressReporter\n"
        "ProgressReporter('json').update('starts', 1, 4)\n"
        "sys.exit('bad input: the file holds no steps')\n"
    )
    with pytest.raises(StageError, match="the file holds no steps") as err:
        _stage("broken", ["-c", script], [], quiet=True)
    assert PREFIX not in str(err.value)


def test_lhs_costs_report_every_start():
    from analysis.calibration.nonlinear import evaluate_costs

    class Cost:
        def cost(self, t):
            return float(np.sum(t**2))

    seen = []
    costs = evaluate_costs(
        None, np.ones((6, 2)), None, Cost(), on_done=lambda k, n: seen.append((k, n))
    )
    assert costs.tolist() == [2.0] * 6
    assert seen == [(k, 6) for k in range(0, 7)]


def test_analysis_events_are_shown_and_milestones_round_trip_as_json():
    """A reporter is a listener of :mod:`analysis.events`: a counted unit updates its stage,
    an optimiser's last iteration ends its count, a milestone is a line at once (as text, and
    as a JSON line ``parse_line`` reads back)."""
    from analysis.events import Iteration, StageDone, UnitDone

    text = io.StringIO()
    r = ProgressReporter("text", text, prefix="calibration: ")
    r.event(UnitDone("Latin hypercube starts", 100, 100, cost=3.2))
    r.event(Iteration("Levenberg-Marquardt", 7, 1.25, last=True))
    r.event(StageDone("Latin hypercube starts", count=100, cost=3.2, seconds=41.0))
    lines = text.getvalue().splitlines()
    assert lines[0].startswith("calibration: Latin hypercube starts 100/100")
    assert "Levenberg-Marquardt iterations 7/7" in lines[1] and "metric 1.25" in lines[1]
    assert lines[2] == "calibration: Latin hypercube starts: 100, metric 3.2, 41.0 s"

    stream = io.StringIO()
    ProgressReporter("json", stream).event(StageDone("screened", count=226, seconds=12.5))
    p = parse_line(stream.getvalue().strip())
    assert p is not None and (p.stage, p.done, p.total, p.elapsed_s) == ("screened", 226, 226, 12.5)
