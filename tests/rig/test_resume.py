"""Resuming a run from its file: completed plan indices are skipped, the rest is measured."""

import dataclasses

import h5py
import numpy as np
import pytest

from analysis.measurement_file import FORMAT_VERSION, MeasurementFileError, read_measurement
from rig.run.events import StepFinished
from rig.run.session import TestRun
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


def test_a_resumed_file_records_that_it_was_interrupted_and_resumed(interrupted, tmp_path):
    path, before = interrupted
    assert before.resumes == () and before.output_at_zero is True
    copy = tmp_path / "copy.h5"
    copy.write_bytes(path.read_bytes())
    run_on_sim(None, copy, resume=True)
    after = read_measurement(copy)
    assert after.format_version == FORMAT_VERSION and after.output_at_zero is True
    (event,) = after.resumes
    assert event.steps_on_disk == 3 and event.next_plan_index == 3
    assert event.previous_status == "aborted"
    assert "stopped for the night" in event.previous_message
    assert event.time.endswith("Z") and event.time[:4].isdigit()


def test_a_version_1_file_still_reads_and_is_upgraded_when_resumed(interrupted, tmp_path):
    path, _ = interrupted
    copy = tmp_path / "v1.h5"
    copy.write_bytes(path.read_bytes())
    with h5py.File(copy, "r+") as f:  # what a version-1 writer made
        f.attrs["format_version"] = np.int64(1)
        del f.attrs["output_at_zero"], f.attrs["resumes"]
    old = read_measurement(copy)
    assert old.format_version == 1 and old.output_at_zero is None and old.resumes == ()
    assert old.n_steps == 3
    summary, _, _ = run_on_sim(None, copy, resume=True)
    assert summary.status == "success"
    new = read_measurement(copy)
    assert new.format_version == FORMAT_VERSION and new.n_steps == PLAN.n_steps
    assert [e.steps_on_disk for e in new.resumes] == [3]


def test_resumes_that_are_not_a_list_of_events_are_refused(interrupted, tmp_path):
    path, _ = interrupted
    copy = tmp_path / "bad.h5"
    copy.write_bytes(path.read_bytes())
    with h5py.File(copy, "r+") as f:
        f.attrs["resumes"] = '[{"time": "x", "steps_on_disk": -1}]'
    with pytest.raises(MeasurementFileError, match=r"resumes.*entry 0"):
        read_measurement(copy)
