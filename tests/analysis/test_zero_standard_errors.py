"""A measured FRF with a standard error of zero is refused by name, not silently floored."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from analysis.calibration.objective import FRFObjective
from analysis.calibration.parameters import ParameterSpace
from analysis.cli import main
from analysis.diagnosis import compare
from analysis.measurement_file import read_measurement
from analysis.model import load_model
from analysis.predict import SteppedSinePredictor, ZeroStandardError
from tests.analysis.measurement_samples import sample_step_records, write_sample_stepped_sine


@pytest.fixture(scope="module")
def zero_std(tmp_path_factory):
    """The sample run with the tip channel (acc7) and the force exact at its first 4 steps."""
    records = sample_step_records()
    for i in range(4):
        r = records[i]
        std = r.response_std.copy()
        std[0] = std[2] = 0.0  # the drive force (its copy force_std) and the tip
        records[i] = dataclasses.replace(r, force_std=np.zeros_like(r.force_std), response_std=std)
    return write_sample_stepped_sine(
        tmp_path_factory.mktemp("zero") / "zero_std.h5", records=records
    )


def test_compare_refuses_and_names_the_file_and_the_channel(zero_std, capsys) -> None:
    with pytest.raises(ZeroStandardError) as info:
        compare(load_model(), read_measurement(zero_std))
    text = str(info.value)
    assert text.startswith(f"{zero_std}: standard errors of zero in channel(s) acc7 (12 values)")
    assert "acc3" not in text
    assert main(["compare", str(zero_std)]) == 2
    assert "acc7 (12 values)" in capsys.readouterr().err


def test_the_calibration_metric_refuses_them_and_points_to_identity(zero_std) -> None:
    data = read_measurement(zero_std)
    model = load_model()
    pred = SteppedSinePredictor(model, data)
    space = ParameterSpace.from_model(model, ["k_c"])
    with pytest.raises(ZeroStandardError, match=r"acc7 \(12 values\).*--identity"):
        FRFObjective(pred, space)
    obj = FRFObjective(pred, space, weighting="identity")  # the user's explicit choice
    assert obj.weighting == "identity" and np.all(obj.sigma == 1.0)
    n, C = pred.measured()[0].shape[:2]
    later = np.zeros((n, C), bool)
    later[4:] = True  # steps with their standard errors: weighted as before
    assert FRFObjective(pred, space, mask=later).weighting == "uncertainty"
