"""A file with no steps, or of a run that did not end normally, is met with a clear answer."""

from __future__ import annotations

import argparse
import logging
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from analysis.cli import main
from analysis.measurement_file import (
    create_stepped_sine,
    incomplete_note,
    planned_steps,
    read_measurement,
)
from tests.analysis.measurement_samples import sample_step_records, sample_stepped_sine_kwargs

#: 2 levels x up and down x 22-28 Hz in 1 Hz (7 frequencies, 25 Hz in both ranges once)
PLAN = {
    "frequencies": {
        "direction": "up-down",
        "ranges": [
            {"start_hz": 22.0, "stop_hz": 28.0, "step_hz": 1.0},
            {"start_hz": 25.0, "stop_hz": 25.0, "step_hz": 0.5},
        ],
    },
    "excitation": {"levels_n": [2.0, 4.0]},
}
REASON = "pretest: the drive-point acceleration exceeded 50 m/s^2 at 0.2 V"


def _kwargs() -> dict:
    return {**sample_stepped_sine_kwargs(), "config": {"plan": PLAN}}


@pytest.fixture
def no_steps(tmp_path):
    """A run that ended in its pretest: the writer's file, aborted, no step."""
    path = tmp_path / "pretest_abort.h5"
    writer = create_stepped_sine(path, **_kwargs())
    writer.finish("aborted", REASON)
    return path


@pytest.fixture
def killed(tmp_path):
    """A run killed after 5 steps: status still 'running' (the process never closed it)."""
    path = tmp_path / "killed.h5"
    script = textwrap.dedent(
        f"""
        import os
        from analysis.measurement_file import create_stepped_sine
        from tests.analysis.measurement_samples import sample_step_records
        from tests.analysis.test_run_status import _kwargs
        w = create_stepped_sine({str(path)!r}, **_kwargs())
        for r in sample_step_records()[:5]:
            w.append_step(r)
        os._exit(0)
        """
    )
    root = Path(__file__).resolve().parents[2]
    r = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, timeout=60, cwd=root
    )
    assert r.returncode == 0, r.stderr
    return path


def test_the_planned_steps_are_counted_as_the_rig_counts_them(no_steps) -> None:
    from rig.config.plans import load_plan

    data = read_measurement(no_steps)
    assert planned_steps(data) == 28
    paper = load_plan("paper")
    assert planned_steps(_with_plan(data, paper.to_dict())) == paper.n_steps == 224
    assert planned_steps(_with_plan(data, {})) is None


def _with_plan(data, plan):
    import dataclasses

    return dataclasses.replace(data, config={"plan": plan})


def test_compare_of_a_file_with_no_steps_names_it_and_why_the_run_ended(no_steps, capsys):
    from analysis.diagnosis import compare
    from analysis.model import load_model

    with pytest.raises(ValueError, match="holds no steps") as info:
        compare(load_model(), read_measurement(no_steps))
    text = str(info.value)
    assert str(no_steps) in text and "0 of 28 planned steps recorded" in text
    assert f"status 'aborted' ({REASON})" in text
    assert main(["compare", str(no_steps)]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"error: {no_steps} holds no steps") and "IndexError" not in err


def test_calibrate_of_a_file_with_no_steps_names_it(no_steps, tmp_path, capsys):
    assert (
        main(
            [
                "calibrate",
                str(no_steps),
                "--out",
                str(tmp_path / "cal"),
                "--workers",
                "1",
                "--starts",
                "2",
            ]
        )
        == 2
    )
    err = capsys.readouterr().err
    assert f"error: {no_steps} holds no steps (0 of 28 planned steps recorded)" in err
    assert REASON in err


def test_the_objective_names_the_file_when_nothing_is_selected(tmp_path) -> None:
    import numpy as np

    from analysis.calibration.objective import FRFObjective
    from analysis.calibration.parameters import ParameterSpace
    from analysis.model import load_model
    from analysis.predict import SteppedSinePredictor

    path = tmp_path / "run.h5"
    with create_stepped_sine(path, **_kwargs()) as w:
        for r in sample_step_records():
            w.append_step(r)
        w.finish("success")
    data = read_measurement(path)
    model = load_model()
    pred = SteppedSinePredictor(model, data)
    space = ParameterSpace.from_model(model, ["k_c"])
    n, C = pred.measured()[0].shape[:2]
    with pytest.raises(ValueError, match=rf"{path}: the selection contains no measured FRF"):
        FRFObjective(pred, space, mask=np.zeros((n, C), bool))


def test_an_incomplete_run_is_noted_with_what_is_missing(killed, tmp_path, caplog) -> None:
    data = read_measurement(killed)
    assert data.exit_status == "running" and data.n_steps == 5
    note = incomplete_note(data)
    assert note.startswith(f"{killed}: an incomplete run, 5 of 28 planned steps recorded")
    assert "status 'running'" in note and "killed" in note
    aborted = tmp_path / "aborted.h5"
    with create_stepped_sine(aborted, **_kwargs()) as w:
        for r in sample_step_records()[:3]:
            w.append_step(r)
        w.finish("aborted", "operator pressed Stop")
    note = incomplete_note(read_measurement(aborted))
    assert "3 of 28 planned steps" in note and "status 'aborted' (operator pressed Stop)" in note
    from analysis.logs import note_inputs

    caplog.set_level(logging.WARNING)
    notes = note_inputs(argparse.Namespace(run=str(killed), linear_run=str(aborted)))
    assert len(notes) == 2
    assert [r.getMessage() for r in caplog.records] == [f"note: {t}" for t in notes]


def test_a_complete_run_gets_no_note(tmp_path) -> None:
    path = tmp_path / "ok.h5"
    with create_stepped_sine(path, **_kwargs()) as w:
        w.append_step(sample_step_records()[0])
        w.finish("success")
    assert incomplete_note(read_measurement(path)) is None
