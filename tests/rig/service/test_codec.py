"""Events as strict JSON: complex phasors as [re, im] pairs, NaN as null, nested dataclasses."""

from __future__ import annotations

import json
import math
from fractions import Fraction

import numpy as np
import pytest

from analysis.measurement_file import StepRecord
from rig.config.plans import load_plan
from rig.procedures.pretest import ChannelCheck, PretestReport
from rig.run.events import (
    ControlIteration,
    FaultRaised,
    PretestFinished,
    RunFinished,
    RunPaused,
    RunResumed,
    RunStarted,
    RunWarning,
    StepFinished,
    StepStarted,
)
from rig.service.codec import encode_event, event_line, to_jsonable
from rig.service.state import RunState


def _roundtrip(obj):
    return json.loads(event_line(obj))


def _record():
    return StepRecord(
        plan_index=4,
        level_index=1,
        sweep_direction=1,
        frequency_target_hz=25.0,
        frequency_hz=24.9756,
        force=np.array([2.0 + 0.5j, 0.04j, -0.04 + 0j]),
        force_std=np.array([1e-3, 2e-4, 2e-4]),
        response=np.array([[2.0 + 0.5j, 0.04j, -0.04], [1 - 1j, 2j, 3.0]]),
        response_std=np.full((2, 3), 1e-3),
        drive=np.array([0.1 - 0.2j, 0.01j, 0.01]),
        n_blocks=48,
        control_iterations=3,
        control_converged=True,
        control_error=0.004,
        timestamp=1.7e9,
    )


def test_complex_arrays_become_re_im_pairs_and_nan_becomes_null():
    a = np.array([[1 + 2j, math.nan + 1j], [3 - 4j, 0j]])
    assert to_jsonable(a) == [[[1.0, 2.0], [None, 1.0]], [[3.0, -4.0], [0.0, 0.0]]]
    assert to_jsonable(np.array([1.0, np.inf, -np.inf, 2.0])) == [1.0, None, None, 2.0]
    assert to_jsonable(np.array([True, False])) == [True, False]
    assert to_jsonable(np.int64(3)) == 3 and type(to_jsonable(np.int64(3))) is int
    assert to_jsonable(np.float32(0.5)) == 0.5 and to_jsonable(np.float64(math.nan)) is None
    assert to_jsonable(np.complex128(1 - 1j)) == [1.0, -1.0]
    assert to_jsonable((Fraction(1, 2), Fraction(3))) == ["1/2", "3"]
    assert to_jsonable({1: math.nan}) == {"1": None}


def test_a_step_finished_event_is_strict_json_with_every_phasor():
    event = StepFinished(_record(), None, ("force3", "acc7"), n_done=5, n_steps=10, time_s=12.5)
    obj = _roundtrip(encode_event(event, "r0007", 42))
    assert obj["seq"] == 42 and obj["run"] == "r0007" and obj["type"] == "StepFinished"
    assert obj["time_s"] == 12.5
    d = obj["data"]
    assert d["n_done"] == 5 and d["channel_names"] == ["force3", "acc7"] and d["control"] is None
    r = d["record"]
    assert r["force"] == [[2.0, 0.5], [0.0, 0.04], [-0.04, 0.0]]
    response = np.array(r["response"])
    assert response.shape == (2, 3, 2)
    np.testing.assert_array_equal(response[..., 0] + 1j * response[..., 1], _record().response)
    assert r["control_converged"] is True and r["n_blocks"] == 48


def test_every_event_class_encodes():
    plan = load_plan("quick")
    report = PretestReport(
        25.0,
        (ChannelCheck("acc3", 3, "ok", 1e-4, math.nan, math.nan, ""),),
        np.array([0.02 + 0j]),
        np.array([1.5 - 0.1j]),
        None,
    )
    events = [
        RunStarted("quick", "stepped-sine", 10, 0, "/x.h5"),
        PretestFinished(report),
        StepStarted(plan.steps()[3], 10),
        ControlIteration(
            3,
            1,
            "continue",
            False,
            0.02,
            25.0,
            np.ones(3, complex),
            np.ones(3, complex),
            np.zeros(3),
        ),
        StepFinished(_record(), None, ("a", "b"), 1, 10),
        RunWarning("not-settled", "slow", "acc7"),
        FaultRaised("clipping", "acc3 clipped", "acc3", paused=True),
        RunPaused("operator"),
        RunResumed(),
        RunFinished("aborted", "enough"),
        RunState("queued", "", 0, 10),
    ]
    for seq, event in enumerate(events, 1):
        obj = _roundtrip(encode_event(event, "r1", seq))
        assert obj["type"] == type(event).__name__ and obj["seq"] == seq
        assert "time_s" not in obj["data"]
    pretest = _roundtrip(encode_event(events[1], "r1", 2))["data"]["report"]
    assert pretest["channels"][0]["response"] is None and pretest["gain_n_per_v"] is None
    step = _roundtrip(encode_event(events[2], "r1", 3))["data"]["step"]
    assert step["plan_index"] == 3 and step["level_n"] == 2.0


def test_event_lines_refuse_nan_rather_than_write_invalid_json():
    with pytest.raises(ValueError):
        event_line({"x": math.nan})
    assert event_line({"x": 1}).endswith(b"\n")
