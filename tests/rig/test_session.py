"""RunSession: the one way the command line, the GUI and the service start a run. A pause or
an abort asked for before the engine exists is held and given to it when it does."""

import threading

import numpy as np

from analysis.measurement_file import read_measurement
from rig.run.events import RunPaused, StepFinished
from rig.run.session import RunSession, previous_rig
from tests.rig.rig_helpers import reduced_plan, setup_at, sim_daq

PLAN = reduced_plan(levels_n=(2.0,), ranges=((21.0, 22.0, 1.0),))


def test_an_abort_asked_for_before_the_engine_exists_ends_the_run_at_once(tmp_path):
    setup = setup_at()
    daq = sim_daq(setup, record_output=True)
    session = RunSession()
    session.abort("the operator changed their mind")  # the rig is still opening
    run = session.prepare(daq, PLAN, setup, tmp_path / "a.h5")
    summary = session.execute(run)
    assert summary.status == "aborted" and "changed their mind" in summary.message
    data = read_measurement(tmp_path / "a.h5")
    assert data.n_steps == 0 and "changed their mind" in data.exit_message
    # nothing was driven, so nothing was ramped down, and the file says so
    assert "Output at 0 V (never driven)" in data.exit_message and "ramped" not in data.exit_message
    out = daq.output_samples()
    assert out.size and not np.any(out)
    assert session.engine is None


def test_a_held_pause_pauses_the_new_engine_and_resume_continues_it(tmp_path):
    setup = setup_at()
    daq = sim_daq(setup)
    session = RunSession()
    session.pause()
    paused = threading.Event()
    events = []

    def on_event(event):
        events.append(event)
        if isinstance(event, RunPaused):
            paused.set()

    run = session.prepare(daq, PLAN, setup, tmp_path / "p.h5", subscribers=[on_event])
    thread = threading.Thread(target=lambda: events.append(session.execute(run)))
    thread.start()
    assert paused.wait(60), "the held pause did not reach the engine"
    assert not any(isinstance(e, StepFinished) for e in events)
    session.resume()
    thread.join(120)
    summary = events[-1]
    assert summary.status == "success" and summary.n_done == 2
    # the session is free again: a request now is held for the next run, not lost in this one
    session.abort()
    run2 = session.prepare(daq, PLAN, setup, tmp_path / "p2.h5")
    assert session.execute(run2).status == "aborted"


def test_resume_continues_the_file_with_its_stored_plan(tmp_path):
    setup = setup_at()
    daq = sim_daq(setup)
    first = RunSession()
    stop_after_one = [lambda e: isinstance(e, StepFinished) and first.abort("power cut")]
    run = first.prepare(daq, PLAN, setup, tmp_path / "r.h5", subscribers=stop_after_one)
    assert first.execute(run).n_done == 1
    again = RunSession()
    run = again.prepare(daq, None, None, tmp_path / "r.h5", resume=True)
    summary = again.execute(run)
    assert summary.status == "success"
    data = read_measurement(tmp_path / "r.h5")
    assert data.n_steps == 2 and len(data.resumes) == 1


def test_the_rig_a_file_was_made_on_is_read_from_its_config() -> None:
    sim = {"run": {"backend": "sim", "backend_options": {"truth": "damper_p4", "seed": 3}}}
    assert previous_rig(sim) == ("sim", {"truth": "damper_p4", "seed": 3})
    # only what the file records, with the right types: a seed of True is no seed
    odd = {"run": {"backend": "sim", "backend_options": {"truth": 4, "seed": True}}}
    assert previous_rig(odd) == ("sim", {})
    ni = {"run": {"backend": "ni", "backend_options": {"device": "cDAQ1"}}}
    assert previous_rig(ni) == ("ni", {})
    assert previous_rig({}) == (None, {}) == previous_rig({"run": "x"}) == previous_rig(None)
