"""Resuming a run from its file: completed plan indices are skipped, the rest is measured."""

import dataclasses

import numpy as np
import pytest

from analysis.measurement_file import read_measurement
from rig.events import StepFinished
from rig.runner import TestRun
from tests.rig.rig_helpers import reduced_plan, run_on_sim, setup_at, sim_daq

PLAN = reduced_plan(levels_n=(2.0, 4.0), ranges=((21.0, 23.0, 1.0),))


@pytest.fixture(scope="module")
def interrupted(tmp_path_factory):
    path = tmp_path_factory.mktemp("resume") / "run.h5"
    setup = setup_at()
    holder = {}

    def stop_after_three(event):
        if isinstance(event, StepFinished) and event.n_done == 3:
            holder["run"].engine.abort("stopped for the night")

    daq = sim_daq(setup)
    run = TestRun(daq, PLAN, setup, path)
    holder["run"] = run
    run.engine.bus.subscribe(stop_after_three)
    summary = run.execute()
    daq.close()
    assert summary.status == "aborted" and summary.n_done == 3
    return path, read_measurement(path)


def test_resume_completes_the_file(interrupted, tmp_path):
    path, before = interrupted
    copy = tmp_path / "copy.h5"
    copy.write_bytes(path.read_bytes())
    events = []
    summary, run, daq = run_on_sim(None, copy, resume=True, subscribers=[events.append])
    assert summary.status == "success" and summary.written_this_run == 3
    after = read_measurement(copy)
    assert after.complete and after.exit_status == "success"
    assert sorted(after.plan_index) == list(range(PLAN.n_steps))
    assert len(set(after.plan_index)) == PLAN.n_steps
    for field in ("force", "response", "frequency_hz", "drive"):  # old steps untouched
        assert np.array_equal(getattr(after, field)[:3], getattr(before, field))
    finished = [e.record.plan_index for e in events if isinstance(e, StepFinished)]
    assert finished == [3, 4, 5]
    # the resumed run starts from gains predicted from the steps on disk
    assert after.control_iterations[3] <= 3 and np.all(after.control_converged)


def test_resume_refuses_other_plans_and_finished_files(interrupted, tmp_path):
    path, _ = interrupted
    copy = tmp_path / "copy.h5"
    copy.write_bytes(path.read_bytes())
    other = dataclasses.replace(
        PLAN, excitation=dataclasses.replace(PLAN.excitation, levels_n=(2.0, 5.0))
    )
    daq = sim_daq(setup_at())
    with pytest.raises(ValueError, match="other settings than the plan given"):
        TestRun.resume(daq, copy, plan=other)
    run = TestRun.resume(daq, copy, plan=PLAN, setup=setup_at())  # the same plan is fine
    run.execute()
    daq.close()
    with pytest.raises(ValueError, match="the run is complete"):
        TestRun.resume(sim_daq(setup_at()), copy)
